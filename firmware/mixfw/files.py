# G-code files on the board's flash filesystem: listing, selecting, printing
# (a job the printer core runs a line at a time between console lines) and uploading.
import os
from mixfw.intake import Intake



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
    the ring a line at a time, cost the chip about 0.3 ms a line)."""

    def __init__(self, path, name, announce, line_bytes):
        self.name = name
        self.f = open(path, "rb")
        self.size = os.stat(path)[6]
        self.read = 0  # bytes of the file read into the intake's ring
        self.line = 0
        self.paused = True
        self.announce = announce
        self.intake = Intake(line_bytes)

    @property
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
    def __init__(self, root, printer):
        self.root = root.rstrip("/") or ""
        self.printer = printer
        self.selected = None  # Job, printing or not
        self.upload = None  # open file while M28 writes
        self.upload_name = None

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
        if job.pos >= job.size:
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

    def begin_upload(self, name):
        path = self.path(name)
        self.upload = open(path + ".part", "w")
        self.upload_name = name
        self.printer.sink = self._write

    def _write(self, text):
        self.upload.write(text + "\n")

    def end_upload(self):
        self.printer.sink = None
        if self.upload is None:
            raise FileError("not writing a file (M28 <name> starts)")
        self.upload.close()
        path = self.path(self.upload_name)
        # The upload replaces a file of the same name only once it is complete.
        os.rename(path + ".part", path)
        name = self.upload_name
        self.upload = self.upload_name = None
        return name

    def delete(self, name):
        if self.selected is not None and self.selected.name == name:
            self.cancel()
        try:
            os.remove(self.path(name))
        except OSError:
            raise FileError("Deletion failed, File: %s." % name)
