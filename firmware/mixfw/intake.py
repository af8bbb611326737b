# Intake: bytes from a console -> a receive ring -> complete lines in one fixed-size
# buffer. As in Marlin, a `;` comment is not stored, so long slicer comments never fill
# the buffer; the parser still handles `;` and `( )` for lines that reach it. A line
# that overflows the buffer, or holds a control byte, is flagged and answered with an
# error when its end arrives; the stream goes on. Bytes above 127 are kept: free text
# (M117 Druck läuft) is UTF-8 as slicers write it, and the parser refuses them in words.
#
# Every byte a host sends passes through here twice (into the ring, then into the
# line), so both loops are viper: in bytecode they would cost about 100 us a byte on
# an RP2040, 3 ms of a 30-byte G1 line.
from array import array

LINE_OK = const(1)
_LINE_TOO_LONG = const(2)
_LINE_BAD_BYTE = const(3)
LINE_CUT = const(4)  # the stream ended inside a line

_RX_BYTES = const(256)  # the receive ring; a power of two
_RX_MASK = const(255)
_SCAN_BYTES = const(16)  # the start of each line, kept for the emergency commands

# Words of the state array.
_HEAD = const(0)  # the ring's first byte
_COUNT = const(1)  # bytes in the ring
_SCAN_N = const(2)
_LEN = const(3)  # bytes of the line so far
_FAULT = const(4)
_BAD_BYTE = const(5)
_IN_COMMENT = const(6)
_SCAN_M = const(7)  # an M among the scanned bytes
_WORDS = const(8)
SCANNED = const(0x10000)  # _put's answer: at + scanned bytes * SCANNED


@micropython.viper
def ring_put(rings, src_buf, at: int, end: int) -> int:
    """src[at:end] into the ring, up to and including the first newline; the first
    SCAN_BYTES of the line also into scan; rings: an Intake's (ring, st, scan). Returns
    where it stopped, plus, where a line
    ended there and an M (or m) is among its scanned bytes, their count times
    SCANNED: only such a line can be an emergency command, and most lines are G1, told
    here without a call. The caller leaves room for the bytes."""
    ring = ptr8(rings[0])
    st = ptr32(rings[1])
    src = ptr8(src_buf)
    scan = ptr8(rings[2])
    tail = st[_HEAD] + st[_COUNT]
    scan_n = st[_SCAN_N]
    m_seen = st[_SCAN_M]
    start = at
    scanned = 0
    while at < end:
        c = src[at]
        at += 1
        ring[tail & _RX_MASK] = c
        tail += 1
        if c == 10:
            if m_seen:
                scanned = scan_n * SCANNED
            scan_n = 0
            m_seen = 0
            break
        if scan_n < _SCAN_BYTES:
            scan[scan_n] = c
            scan_n += 1
            if c == 77 or c == 109:
                m_seen = 1
    st[_COUNT] = st[_COUNT] + (at - start)
    st[_SCAN_N] = scan_n
    st[_SCAN_M] = m_seen
    return at + scanned


@micropython.viper
def _take(ring_buf, st_buf, line_buf, size: int) -> int:
    """Ring bytes into the line until a line ends: its status, or 0."""
    ring = ptr8(ring_buf)
    st = ptr32(st_buf)
    line = ptr8(line_buf)
    head = st[_HEAD]
    count = st[_COUNT]
    n = st[_LEN]
    fault = st[_FAULT]
    in_comment = st[_IN_COMMENT]
    status = 0
    while count > 0:
        c = ring[head]
        head = (head + 1) & _RX_MASK
        count -= 1
        if c == 10:
            status = fault if fault else LINE_OK
            break
        if c == 13 or fault or in_comment:
            continue
        if c == 59:
            in_comment = 1
        elif (c < 32 and c != 9) or c == 127:
            fault = _LINE_BAD_BYTE
            st[_BAD_BYTE] = c
        elif n >= size:
            fault = _LINE_TOO_LONG
        else:
            line[n] = c
            n += 1
    st[_HEAD] = head
    st[_COUNT] = count
    st[_LEN] = n
    st[_FAULT] = fault
    st[_IN_COMMENT] = in_comment
    return status


@micropython.viper
def line_taken(st_buf):
    """Intake.take() of the intake whose state array st_buf is: the printer calls it
    for every line, where a method's bytecode call would cost the chip tens of us."""
    st = ptr32(st_buf)
    st[_LEN] = 0
    st[_FAULT] = 0
    st[_IN_COMMENT] = 0


class Intake:
    def __init__(self, size):
        self.buf = bytearray(size)
        self.size = size
        self.ring = bytearray(_RX_BYTES)
        self.scan = bytearray(_SCAN_BYTES)
        self.st = array("i", [0] * _WORDS)
        self.rings = (self.ring, self.st, self.scan)  # as ring_put takes them

    @property
    def n(self):
        """Bytes of the line in buf."""
        return self.st[_LEN]

    @property
    def fault(self):
        return self.st[_FAULT]

    @property
    def waiting(self):
        """Bytes in the ring."""
        return self.st[_COUNT]

    def room(self):
        return _RX_BYTES - self.st[_COUNT]

    def put(self, src, at, end):
        """src[at:end] into the ring (room() must hold them), up to and including the
        first newline. Returns where it stopped (below SCANNED); if a line ended there
        that may be an emergency command, plus SCANNED times the count of its first
        bytes in scan."""
        return ring_put(self.rings, src, at, end)

    def fill_from(self, f):
        """For a file: its next bytes into the ring, which must be empty (next_line
        takes bytes until a line ends or none are left), as many as it holds. Returns
        the count read, 0 at the file's end."""
        n = f.readinto(self.ring) or 0
        st = self.st
        st[_HEAD] = 0
        st[_COUNT] = n
        return n

    def next_line(self):
        """Feed ring bytes to the line until it ends: its status (LINE_OK or a fault),
        or 0. The line is buf[:n] until take() is called."""
        return _take(self.ring, self.st, self.buf, self.size)

    def reset(self):
        """Forget every byte, as if none had come."""
        self.take()
        self.st[_HEAD] = 0
        self.st[_COUNT] = 0
        self.st[_SCAN_N] = 0
        self.st[_SCAN_M] = 0

    def take(self):
        """Forget the line just returned so the next one starts empty."""
        line_taken(self.st)

    def cut_text(self, status):
        """A line too long that shows a message (M117, M118, without a line number,
        whose checksum would no longer match) is cut, as Marlin cuts it, at the last
        whole UTF-8 character that fits: LINE_OK then. Any other status is returned
        as it is."""
        if status != _LINE_TOO_LONG:
            return status
        buf = self.buf
        n = self.size
        i = 0
        while i < n - 5 and (buf[i] == 32 or buf[i] == 9):
            i += 1
        if (buf[i] | 32) != 109 or buf[i + 1] != 49 or buf[i + 2] != 49 or \
                buf[i + 3] not in (55, 56) or buf[i + 4] not in (32, 9):
            return status
        lead = n - 1
        while lead > 0 and buf[lead] & 0xC0 == 0x80:
            lead -= 1
        c = buf[lead]
        if c >= 0xC0 and lead + (2 if c < 0xE0 else (3 if c < 0xF0 else 4)) > n:
            n = lead
        self.st[_LEN] = n
        return LINE_OK

    def error_text(self, status):
        if status == LINE_CUT:
            return "line cut off by the end of the stream (no newline); not run"
        if status == _LINE_TOO_LONG:
            return "line longer than %d bytes" % self.size
        return "byte 0x%02x is a control character" % self.st[_BAD_BYTE]
