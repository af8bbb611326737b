# Intake: bytes from a console -> complete lines in one fixed-size buffer.
# As in Marlin, a `;` comment is not stored, so long slicer comments never fill the
# buffer; the parser still handles `;` and `( )` for lines that reach it. A line that
# overflows the buffer, or holds bytes that are not printable ASCII, is
# flagged and answered with an error when its end arrives; the stream goes on.

LINE_OK = 1
LINE_TOO_LONG = 2
LINE_BAD_BYTE = 3
LINE_CUT = 4  # the stream ended inside a line


class Intake:
    def __init__(self, size):
        self.buf = bytearray(size)
        self.size = size
        self.n = 0
        self.fault = 0
        self.bad_byte = 0
        self.in_comment = False

    def feed(self, c):
        """Take one byte. Returns 0 until a line ends, then LINE_OK or a fault code.
        The line is buf[:n] until take() is called."""
        if c == 10:
            return self.fault or LINE_OK
        if c == 13 or self.fault or self.in_comment:
            return 0
        if c == 59:
            self.in_comment = True
            return 0
        if (c < 32 and c != 9) or c > 126:
            self.fault = LINE_BAD_BYTE
            self.bad_byte = c
        elif self.n >= self.size:
            self.fault = LINE_TOO_LONG
        else:
            self.buf[self.n] = c
            self.n += 1
        return 0

    def take(self):
        """Forget the line just returned so the next one starts empty."""
        self.n = 0
        self.fault = 0
        self.in_comment = False

    def error_text(self, status):
        if status == LINE_CUT:
            return "line cut off by the end of the stream (no newline); not run"
        if status == LINE_TOO_LONG:
            return "line longer than %d bytes" % self.size
        return "byte 0x%02x is not printable ASCII" % self.bad_byte
