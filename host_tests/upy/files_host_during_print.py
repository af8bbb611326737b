# A file (argv[1], part.gcode) printed by the real Printer and Job while a host's line
# (M115) waits from the start, with handlers that only record: each command run (the
# host's as "host") and the file's line number then. argv[2:]: the file's commands.
import json
import sys

from mixfw.files import Job
from mixfw.printer import Printer


class Host:  # one line, there from the start, then the end of its stream
    def __init__(self):
        self.data = b"M115\n"

    def readinto(self, mv, block=False):
        if not self.data:
            return -1
        n = len(self.data)
        mv[:n] = self.data
        self.data = b""
        return n

    def write(self, text):
        pass


ran = []
p = Printer(96, lambda: None, ())
job = Job(sys.argv[1], "part.gcode", lambda text: None, 96)


def record(line):
    ran.append(["%s%d" % (line.letter, line.number), job.line])


for name in sys.argv[2:]:
    p.register(name, record)
p.register("M115", lambda line: ran.append(["host", job.line]))
p.add_channel(Host())
p.job = job
job.paused = False
p.serve()
print(json.dumps(ran))
