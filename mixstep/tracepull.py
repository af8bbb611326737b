"""`mixstep trace pull`: fetch the board's own step capture and write it as a VCD.

The firmware records the GPIO writes of its step loop into a preallocated ring buffer
(`M7300 S1` starts, `M7300 S0` stops) and `M7301` dumps it as console lines before its
`ok`:

    trace:begin tick_us=<int> records=<int> overrun=<int>
    trace:<tick>,<set_mask>,<clr_mask>        one per record, decimal
    trace:end

tick counts step-loop ticks since recording started; set/clr are the masks written in
that tick, bit g for GPIO g, except that GPIO 32 and up (ESP32's second register) sit
at bit g - 4. The board's PINS name the bits. Other console lines (echo:, busy:) are
ignored. In the VCD (timescale 1 us, time = tick * tick_us) every STEP, DIR and ENABLE
signal starts at 0 at #0; within a tick the masks apply in order, set before clear as
the register writes go, and only each tick's final level is written.
"""
import os
import re
import socket
import sys

import vcd

from mixstep import trace

_BEGIN = re.compile(r"trace:begin\s+tick_us=(\d+)\s+records=(\d+)\s+overrun=(\d+)\s*$")
_RECORD = re.compile(r"trace:(\d+),(\d+),(\d+)\s*$")


class PullError(Exception):
    """A dump that cannot be read: the command exits with status 2."""


def parse_dump(lines):
    """Console lines -> {"tick_us", "overrun", "records": [(tick, set, clr)]}. A host
    may drain the ring with M7301 again and again while the board records; the dumps
    of one recording follow each other, so their records are joined in order."""
    head = None
    dumps = []
    records = []
    for raw in lines:
        line = raw.strip()
        if not line.startswith("trace:"):
            continue
        if line.startswith("trace:begin"):
            m = _BEGIN.match(line)
            if not m:
                raise PullError("malformed header %r" % line)
            if head is not None:
                raise PullError("trace:begin inside a dump: %r" % line)
            head = [int(v) for v in m.groups()]
            records = []
        elif line == "trace:end":
            if head is None:
                raise PullError("trace:end without trace:begin")
            if len(records) != head[1]:
                raise PullError("header says %d records, got %d" % (head[1], len(records)))
            dumps.append((head, records))
            head = None
        else:
            m = _RECORD.match(line)
            if head is None or not m:
                raise PullError("unexpected line %r" % line)
            records.append(tuple(int(v) for v in m.groups()))
    if head is not None:
        raise PullError("the dump ends before trace:end")
    if not dumps:
        raise PullError("no complete dump (trace:begin ... trace:end) in the input")
    if len({h[0] for h, _ in dumps}) != 1:
        raise PullError("dumps with different tick_us: not one recording")
    joined = [r for _, recs in dumps for r in recs]
    return {"tick_us": dumps[0][0][0], "overrun": max(h[2] for h, _ in dumps),
            "records": joined}


def mask_bits(board="sim"):
    """Mask bit -> signal name for the board's STEP, DIR and ENABLE outputs."""
    return {(g if g < 32 else g - 4): name for g, name in trace.signal_names(board).items()}


def write_vcd(dump, vcd_path, board="sim"):
    """Write a parsed dump as a VCD. Returns how many bits were both set and cleared in
    one record (a pulse shorter than the VCD can show)."""
    bits = mask_bits(board)
    order = sorted(bits, key=lambda b: trace._name_order(bits[b]))
    tick_us = dump["tick_us"]
    both = 0
    with open(vcd_path, "w") as f, vcd.VCDWriter(f, timescale="1 us", date="mixstep capture",
                                                 version="mixstep") as w:
        var = {b: w.register_var("mixstep", bits[b], "wire", size=1, init=0) for b in order}
        level = dict.fromkeys(order, 0)
        written = dict(level)
        touched = set()
        pending = None

        def flush(tick):
            for b in sorted(touched):
                if level[b] != written[b]:
                    w.change(var[b], tick * tick_us, level[b])
                    written[b] = level[b]
            touched.clear()

        for tick, set_mask, clr_mask in dump["records"]:
            if pending is not None and tick != pending:
                flush(pending)
            pending = tick
            both += bin(set_mask & clr_mask).count("1")
            m = set_mask | clr_mask
            while m:
                b = (m & -m).bit_length() - 1
                m &= m - 1
                if b in level:
                    level[b] = 0 if (clr_mask >> b) & 1 else 1
                    touched.add(b)
        if pending is not None:
            flush(pending)
    return both


def _lines_from(readline, timeout_s):
    """Console lines until the `ok` that ends M7301's reply."""
    while True:
        raw = readline()
        if not raw:
            raise PullError("no `ok` within %g s" % timeout_s)
        line = raw.decode("ascii", "replace").strip()
        yield line
        if line == "ok" or line.startswith("ok "):
            return


def fetch_serial(port, baud=115200, timeout_s=30.0):
    import serial  # pyserial: only needed for a serial port
    with serial.Serial(port, baud, timeout=timeout_s) as s:
        s.reset_input_buffer()
        s.write(b"M7301\n")
        return list(_lines_from(s.readline, timeout_s))


def fetch_tcp(address, timeout_s=30.0, password=None):
    """password: the board's net_password (default: the environment's
    MIXSTEP_NET_PASSWORD, so it stays off the command line), sent first if set."""
    host, _, port = address.rpartition(":")
    password = password or os.environ.get("MIXSTEP_NET_PASSWORD")
    with socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout_s) as c:
        if password:
            c.sendall(password.encode() + b"\n")
        c.sendall(b"M7301\n")
        with c.makefile("rb") as f:
            return list(_lines_from(f.readline, timeout_s))


def pull(out_path, board="sim", port=None, tcp=None, log=None, baud=115200, timeout_s=30.0):
    """Fetch (or read from a saved log) a dump and write it as a VCD. Returns a summary."""
    if log:
        with open(log, "r", encoding="ascii", errors="replace") as f:
            dump = parse_dump(f)
    elif port:
        dump = parse_dump(fetch_serial(port, baud, timeout_s))
    elif tcp:
        dump = parse_dump(fetch_tcp(tcp, timeout_s))
    else:
        raise PullError("say where the dump comes from: --port, --tcp or --log")
    both = write_vcd(dump, out_path, board)
    return {"records": len(dump["records"]), "tick_us": dump["tick_us"],
            "overrun": dump["overrun"], "set_and_cleared_bits": both, "vcd": str(out_path)}


def add_parser(sub):
    p = sub.add_parser("pull", help="fetch the board's step capture (M7301) and write a VCD")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="serial port of the board, e.g. /dev/ttyACM0")
    src.add_argument("--tcp", metavar="HOST:PORT",
                     help="the board's TCP console (its password: MIXSTEP_NET_PASSWORD in "
                          "the environment)")
    src.add_argument("--log", help="a saved console log holding an M7301 dump")
    p.add_argument("-o", "--output", required=True, help="VCD file to write")
    p.add_argument("--board", default="sim", help="board whose PINS name the mask bits")
    p.add_argument("--baud", type=int, default=115200)
    p.add_argument("--timeout-s", type=float, default=30.0, help="longest wait for a line")
    p.set_defaults(run=_run)


def _run(args):
    try:
        summary = pull(args.output, args.board, args.port, args.tcp, args.log, args.baud,
                       args.timeout_s)
    except (PullError, OSError) as e:
        print("mixstep trace pull: %s" % e, file=sys.stderr)
        return 2
    print("%(records)d records at %(tick_us)d us per tick -> %(vcd)s" % summary)
    if summary["set_and_cleared_bits"]:
        print("warning: %d bits were set and cleared within one record; the VCD shows "
              "their final level" % summary["set_and_cleared_bits"], file=sys.stderr)
    if summary["overrun"]:
        print("error: the capture overran its buffer (overrun=%d): records are missing; "
              "record a shorter stretch" % summary["overrun"], file=sys.stderr)
        return 1
    return 0
