# The real Printer (channel ring, M112 scanner, intake, parser, N/checksum checks,
# answer) fed the bytes on stdin from an in-memory console in odd-sized chunks, with
# stand-in handlers that read every word through the typed getters. Its replies go to
# stdout, then "//done".
import sys

from mixfw.printer import Printer


class Feed:
    blocking = True

    def __init__(self, data):
        self.data = data
        self.pos = 0
        self.size = 1

    def readinto(self, mv, block=False):
        if self.pos >= len(self.data):
            return -1
        self.size = self.size % 11 + 1
        n = min(len(mv), self.size, len(self.data) - self.pos)
        for i in range(n):
            mv[i] = self.data[self.pos + i]
        self.pos += n
        return n

    def write(self, text):
        sys.stdout.write(text)


def words(line):
    for c in "ABCDEFGHIJKLOPQRSUVWXYZ":
        if line.has(c):
            line.float(c, 0.0)
            if line.has_value(c):
                try:
                    line.int(c, lo=-1000, hi=1000)
                except ValueError:
                    pass
    line.require("S") if line.number == 163 else None


def text(line):
    line.args_text.encode()


p = Printer(96, lambda: None, (("M", 117), ("M", 118)))
for name in ("G0", "G1", "G4", "G28", "G90", "G91", "G92", "M104", "M106", "M114", "M163", "T"):
    p.register(name, words, guarded=True)
p.register("M117", text)
p.register("M118", text)
p.add_channel(Feed(sys.stdin.buffer.read()))
p.serve()
sys.stdout.write("//done\n")
