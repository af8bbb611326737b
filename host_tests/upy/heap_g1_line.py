# Lines (stdin, JSON: [way, folder, lines]) served as from a host (way host, numbered
# or long: after metres of filament on three tools) or printed from folder/part.gcode
# (way file), planned against a full queue. For each line: whether its parse, and its
# way from arrival to `ok`, took anything from the heap; then the errors the host was
# sent and X's steps.
import json
import sys

from heap_probe import allocates
import simbuild
from plan_only import retire_one

printer = simbuild.printer()
printer.planner.idle = retire_one(printer.mem, printer.planner.queue)
parse = printer.parser.parse
for raw in (b"M302 P1", b"M83"):
    printer.run_line(parse(raw, len(raw)))


class Host:  # a console whose bytes are the line probed; the answers go nowhere
    def __init__(self):
        self.line = bytearray(257)
        self.n = self.at = self.errors = 0

    def readinto(self, mv, block=False):
        k = 0
        while self.at < self.n and k < len(mv):
            mv[k] = self.line[self.at]
            self.at += 1
            k += 1
        return k

    def write(self, text):
        if text.startswith("Error") or text.startswith("Resend"):
            self.errors += 1


host = Host()
printer.add_channel(host)
channel = printer.channels[0]
buf = bytearray(256)


def serve(a, b):  # one line, as Printer.serve takes it from a host
    printer.pump_all()
    printer.answer(channel, channel.next_line())


def run_job_line(a, b):  # one line, as Printer.serve takes it from the file printed
    printer.run_job_line()


way, root, lines = json.loads(sys.stdin.read())
if way == "long":
    # Past a metre of filament on every drive: positions in nm beyond small ints.
    for tool in (b"T0", b"T1", b"T2"):
        printer.run_line(parse(tool, 2))
        for _ in range(8):
            printer.run_line(parse(b"G1 E150 F6000", 13))
    for raw in (b"T0", b"G92 E0"):
        printer.run_line(parse(raw, len(raw)))
if way == "file":
    from mixfw.files import Files
    files = Files(root, printer)
    files.select("part.gcode")
    files.start()
    serve = run_job_line
out = []
for raw in lines:
    n = len(raw)
    buf[:n] = raw.encode()
    host.line[:n + 1] = buf[:n] + b"\n"
    host.n = n + 1
    host.at = 0
    out.append([allocates(printer.parser.parse, buf, n), allocates(serve, 0, 0)])
x_steps = printer.planner.position_steps[0]
print(json.dumps([out, host.errors, x_steps]))
