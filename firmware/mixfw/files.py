# G-code files on the board's flash filesystem: listing, selecting, printing
# (a job the printer core runs a line at a time between console lines) and uploading.
#
# Every write, rename and removal goes through the storage (config.FileStorage), which
# first waits for the queued moves to end: flash is programmed with interrupts off,
# far longer than the step path runs ahead. An upload is therefore kept in RAM and
# written a chunk at a time (one flash sector), and refused while a file prints from
# flash, which would otherwise stop at every chunk.
import os
from mixfw.config import FileStorage
from mixfw.intake import Intake

_UPLOAD_CHUNK_BYTES = const(4096)  # one flash sector: a write erases and programs one or two


class FileError(ValueError):
    pass


def _check_name(name):
    if not name:
        raise FileError("missing file name")
    if "/" in name or name.startswith(".") or len(name) > 64:
        raise FileError("bad file name %r: plain names only, up to 64 characters" % name)
    return name


class Job:
    """A file being printed, read a line at a time through an Intake, as a console's
    lines are, with the same comment stripping and the same limit on a line's words:
    the file is read straight into the intake's ring, which holds several lines, so
    that most lines cost a call into it and no more (a chunk of its own, copied into
    the ring a line at a time, would cost the chip about 0.3 ms a line)."""

    def __init__(self, path, name, announce, line_bytes):
        self.name = name
        self.f = open(path, "rb")
        self.size = os.stat(path)[6]
        self.read = 0  # bytes of the file read into the intake's ring
        self.line = 0
        self.paused = True
        self.announce = announce
        self.intake = Intake(line_bytes)

    # A method, not a property: a class with properties has every attribute store
    # looked up in the class first, and a line stores the line count.
    def pos(self):
        """The end of the line being run: what was read less what the ring holds."""
        return self.read - self.intake.waiting

    def next_line(self):
        """The next line into self.intake: its status (intake.LINE_OK, or a fault such as
        a line too long), or 0 at the end of the file. The caller takes the line."""
        # In small methods: a bytecode function whose locals and stack pass 11 words
        # takes its frame from the heap at every call (see printer.answer).
        intake = self.intake
        status = intake.next_line()
        while not status:
            # The ring is empty: next_line takes bytes until a line ends.
            n = intake.fill_from(self.f)
            if not n:
                if not (intake.n or intake.fault):
                    return 0
                intake.put(b"\n", 0, 1)  # a last line with no newline
            self.read += n
            status = intake.next_line()
        self.line += 1
        return status

    def seek(self, pos):
        self.f.seek(pos)
        self.read = pos
        self.intake.reset()

    def done(self):
        self.paused = True  # the file stays open: M26 rewinds it for another print
        self.announce("Done printing file")


class Files:
    def __init__(self, root, printer, storage=None):
        """storage: what writes the flash (config.FileStorage), shared with the
        configuration."""
        self.root = root.rstrip("/") or ""
        self.printer = printer
        self.storage = storage or FileStorage()
        self.selected = None  # Job, printing or not
        self.upload_name = None  # while M28 writes
        self.chunk = None  # the upload's lines not yet on flash
        self.chunk_n = 0
        self.part_written = False  # the first chunk creates `<name>.part`, the rest append
        self.upload_failed = None  # why a chunk could not be written: M29 reports it

    def path(self, name):
        return "%s/%s" % (self.root, _check_name(name))

    def listing(self):
        names = []
        for entry in os.ilistdir(self.root or "/"):
            name, kind = entry[0], entry[1]
            if kind == 0x8000 and name.lower().endswith((".gcode", ".gco", ".g")):
                names.append((name, os.stat(self.path(name))[6]))
        names.sort()
        return names

    def select(self, name):
        path = self.path(name)
        try:
            job = Job(path, name, self.printer.broadcast, self.printer.line_bytes)
        except OSError:
            raise FileError("open failed, File: %s." % name)
        self.cancel()
        self.selected = job
        return job

    def start(self):
        job = self.selected
        if job is None:
            raise FileError("no file selected (M23 <name>)")
        if job.pos() >= job.size:
            raise FileError("file %s has been printed; M26 rewinds it" % job.name)
        job.paused = False
        self.printer.job = job

    def pause(self):
        if self.selected is not None:
            self.selected.paused = True

    def cancel(self):
        job = self.selected
        if job is not None:
            if self.printer.job is job:
                self.printer.job = None
            try:
                job.f.close()
            except OSError:
                pass
            self.selected = None

    def printing(self):
        """The job printing from flash now (not paused), or None."""
        job = self.printer.job
        return job if job is not None and not job.paused else None

    def begin_upload(self, name):
        # A refused upload takes the lines that follow all the same, up to M29, which
        # then says nothing was saved: a host that sends the file anyway must never
        # have it run as G-code.
        self.chunk = None
        self.chunk_n = 0
        self.part_written = False
        self.upload_failed = None
        self.upload_name = name
        self.printer.sink = self._write
        try:
            job = self.printing()
            if job is not None:
                raise FileError("cannot write %s while %s prints: pause it (M25) first"
                                % (name, job.name))
            self.path(name)  # checks the name
            self.chunk = bytearray(_UPLOAD_CHUNK_BYTES)
        except (FileError, MemoryError) as e:
            self.upload_failed = str(e) or "out of memory"
            raise FileError("%s; the lines up to M29 are not run" % self.upload_failed)

    def _write(self, data):
        """One received line into the chunk, the chunk to flash when it is full. After
        a failed write the lines are still taken (never run as G-code) until M29."""
        if self.upload_failed is not None:
            return
        if self.chunk_n + len(data) + 1 > len(self.chunk):
            self._flush()
        n = self.chunk_n
        self.chunk[n:n + len(data)] = data
        self.chunk[n + len(data)] = 10
        self.chunk_n = n + len(data) + 1

    def _flush(self):
        path = self.path(self.upload_name) + ".part"
        try:
            f = self.storage.open(path, "ab" if self.part_written else "wb")
            try:
                f.write(memoryview(self.chunk)[:self.chunk_n])
            finally:
                f.close()
        except OSError as e:
            self.upload_failed = str(e)
            raise FileError("could not write %s: %s; M29 ends the upload"
                            % (self.upload_name, e))
        except Exception as e:  # a halt or M410 while waiting for the moves
            self.upload_failed = str(e)
            raise
        self.part_written = True
        self.chunk_n = 0

    def end_upload(self):
        self.printer.sink = None
        name = self.upload_name
        if name is None:
            raise FileError("not writing a file (M28 <name> starts)")
        try:
            if self.upload_failed is None:
                path = self.path(name)
                self._flush()
                # The upload replaces a file of the same name only once it is complete.
                self.storage.rename(path + ".part", path)
        except OSError as e:
            raise FileError("%s not saved: %s" % (name, e))
        finally:
            self.upload_name = self.chunk = None
        if self.upload_failed is not None:
            raise FileError("%s not saved: %s" % (name, self.upload_failed))
        return name

    def delete(self, name):
        job = self.selected
        if job is not None and job.name == name:
            if self.printing() is job:
                raise FileError("cannot delete %s while it prints: pause it (M25) first"
                                % name)
            self.cancel()
        try:
            self.storage.remove(self.path(name))
        except OSError:
            raise FileError("Deletion failed, File: %s." % name)
