# G-code files on the board's flash filesystem: listing, selecting, printing
# (a job the printer core runs a line at a time between console lines) and uploading.
import os
from array import array
from mixfw.compat import micropython, ptr8, ptr32

_BLOCK_BYTES = 256  # read from the file at a time: a line's readline() read it a byte
# at a time, about 0.1 ms a line on the chip, and made a bytes object of every line
# Words of a Job's read state (array 'i').
_AT = 0  # next byte of the block to take
_END = 1  # bytes the block holds
_N = 2  # the line's length so far, newline included (bytes past the buffer counted)


class FileError(ValueError):
    pass


@micropython.viper
def _take_line(block, text, st) -> int:
    """Bytes from block[st[_AT]:st[_END]] onto the line in text (st[_N] bytes so far),
    up to and including a newline: 1 once it ended, 0 if the block ran out first. A
    line longer than text is counted in st[_N] but only its start is kept."""
    b = ptr8(block)
    out = ptr8(text)
    s = ptr32(st)
    cap = int(len(text))
    i = s[0]
    end = s[1]
    n = s[2]
    while i < end:
        c = b[i]
        i += 1
        if n < cap:
            out[n] = c
        n += 1
        if c == 10:
            s[0] = i
            s[2] = n
            return 1
    s[0] = i
    s[2] = n
    return 0


def _check_name(name):
    if not name:
        raise FileError("missing file name")
    if "/" in name or name.startswith(".") or len(name) > 64:
        raise FileError("bad file name %r: plain names only, up to 64 characters" % name)
    return name


class Job:
    """A file being printed, read a line at a time into text (a bytearray the Files
    make once), through block."""

    def __init__(self, path, name, announce, block, text):
        self.name = name
        self.f = open(path, "rb")
        self.size = os.stat(path)[6]
        self.pos = 0
        self.line = 0
        self.paused = True
        self.announce = announce
        self.block = block
        self.text = text
        self.state = array("i", bytes(4 * 3))

    def next_line(self):
        """The next line into text: its length, newline included, or -1 at the end of
        the file. A line longer than text has only its start there (too_long())."""
        st = self.state
        st[_N] = 0
        while not _take_line(self.block, self.text, st):
            got = self.f.readinto(self.block)
            st[_AT] = 0
            st[_END] = got or 0
            if not got:
                break
        n = st[_N]
        if n == 0:
            return -1
        self.pos += n
        self.line += 1
        return n

    def too_long(self, n):
        """A line of n bytes cut short in text, with words (not only a comment) past
        its end."""
        return n > len(self.text) and self.text.find(b";") < 0

    def seek(self, pos):
        self.f.seek(pos)
        self.pos = pos
        self.state[_AT] = self.state[_END] = 0

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
        # Made at the first M23 and kept for every job after it: no heap for a board
        # that never prints from its flash.
        self._block = self._text = None

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
        if self._block is None:
            self._block = bytearray(_BLOCK_BYTES)
            self._text = bytearray(self.printer.line_bytes)
        try:
            job = Job(path, name, self.printer.broadcast, self._block, self._text)
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
