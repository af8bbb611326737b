# Consoles: where G-code lines come from and replies go to.
import select

_READY = select.POLLIN | select.POLLHUP | select.POLLERR


class StreamConsole:
    """A byte stream pair such as USB/UART serial, or stdin/stdout on the unix port.

    blocking=False: readinto() returns at once with what has arrived (0 if nothing),
    so the main loop can idle while the step loop runs.
    blocking=True (lockstep): when the printer has nothing else to do it waits for the
    next byte instead of letting time pass. The simulation uses this so its virtual
    time advances only when the firmware itself waits, which makes a trace independent
    of how fast the host happens to be."""

    def __init__(self, rx, tx, blocking=False):
        self.rx = rx
        self.tx = tx
        self.blocking = blocking
        self.one = bytearray(1)
        self.one_mv = memoryview(self.one)
        self.poller = select.poll()
        self.poller.register(rx, select.POLLIN)
        self.write = tx.write  # the stream's own: one call less for every reply

    @micropython.native
    def readinto(self, mv, block=False):
        """Bytes read into mv, 0 if none are waiting, -1 at end of stream. block: wait
        for the first byte."""
        # A byte at a time, each after a poll: a stream's readinto (the rp2's USB stdin
        # among them) blocks until it has filled the whole buffer.
        n = 0
        limit = len(mv)
        one = self.one_mv
        byte = self.one
        # Locals: an attribute of self costs the chip a lookup a byte.
        poller = self.poller
        rx = self.rx
        while n < limit:
            if n or not block:
                ready = 0
                for _obj, ev in poller.ipoll(0):
                    ready = ev & _READY
                if not ready:
                    break
            if not rx.readinto(one):
                return n if n else -1
            c = byte[0]
            mv[n] = c
            n += 1
            if c == 10:
                break
            if c == 78 and n == 1 and limit > 1:
                # A numbered line (N...*checksum) comes from a host program, which
                # writes whole lines: the rest of it is read in one call, whose loop
                # runs in C (a byte at a time from Python costs the chip about 50 us).
                # Its bytes object is the only garbage a line makes.
                rest = rx.readline(limit - 1)
                if rest:
                    k = len(rest)
                    mv[1:1 + k] = rest
                    n += k
                break
        return n
