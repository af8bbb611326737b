"""`mixstep detool`: turn a multi-extruder slicer file into G-code for a mixing hot end.

APrinter's DeTool maps a slicer's tools onto physical extruders; here slicer tool T<n>
becomes virtual tool T<n>, whose mix is row n of a mixing matrix (Ovenbird's m x n
palette of m mixtures over n filaments, each row made stochastic).

- At the start (after the slicer's leading comment block, which some hosts read to
  recognise the file) it defines every tool the file uses with `M163 S<drive>
  P<weight>` for every drive, then `M164 S<tool>`.
- `T<n>` lines stay as they are: they now select the virtual tool.
- Temperature commands that name a tool (`M104 T1 S200`, `M109 T1 S200`): there is
  one hot end, so the one for the tool in use loses its T word, and one for another
  tool (a slicer's standby temperature for an idle nozzle) is dropped, left as a
  comment so the change is visible. Dropping matters: `M104 T1 S150` while T0 prints
  would cool the only nozzle.
- Every other line comes out byte for byte (the file is read and written as bytes).

The file is read twice (once to find the tools it uses), one line at a time, so memory
does not grow with the file.
"""
import os
import re

from mixstep import gcodeio
from mixstep.outfile import refuse_input, replacing

_COMMAND = re.compile(rb"\s*[A-Za-z]\s*[\d.]*")
_TOOL_WORD = re.compile(rb"[Tt]\s*(\d+)")
_TEMPERATURE_MCODES = ("M104", "M109")
MAX_TOOLS = 16  # the firmware's T0..T15


def parse_matrix(text):
    """A matrix from `1,0,0;0,1,0` or from a file's text (rows on lines or split by
    `;`, numbers split by commas or spaces, `#` comments). Rows are normalised."""
    if os.path.isfile(text):
        with open(text) as f:
            text = f.read()
    rows = []
    for chunk in re.split(r"[;\n]", text):
        chunk = chunk.split("#")[0].strip()
        if not chunk:
            continue
        try:
            rows.append([float(v) for v in re.split(r"[,\s]+", chunk) if v])
        except ValueError:
            raise ValueError("matrix row %r: not a list of numbers" % chunk)
    if not rows:
        raise ValueError("the matrix has no rows")
    width = len(rows[0])
    matrix = []
    for i, row in enumerate(rows):
        if len(row) != width:
            raise ValueError("matrix row %d has %d drives, row 0 has %d" % (i, len(row), width))
        if any(w < 0 for w in row):
            raise ValueError("matrix row %d has a negative weight: %r" % (i, row))
        total = sum(row)
        if total <= 0:
            raise ValueError("matrix row %d is all zero" % i)
        matrix.append([w / total for w in row])
    return matrix


def _tool_lines(f):
    """(raw, code, words) of every line of f, code and words read only for lines that
    can select or name a tool: any other line ("", None) is copied unread, which keeps
    detool as fast as copying the file."""
    for raw in f:
        if b"T" in raw or b"t" in raw:
            code, words = gcodeio.parse(raw)
            yield raw, code, words
        else:
            yield raw, "", None


def tools_used(path):
    """The tools a file selects, in order of first use."""
    used = []
    with open(path, "rb") as f:
        for _, code, _ in _tool_lines(f):
            tool = gcodeio.tool_of(code)
            if tool is not None and tool not in used:
                used.append(tool)
    return used


def decimal(x):
    """A weight as the firmware reads a number: plain decimals, never an exponent
    ("%g" writes 0.0001 as 1e-04, which a G-code parser takes for 1), to the millionth."""
    text = ("%.6f" % x).rstrip("0").rstrip(".")
    if text in ("0", "-0") and x:
        raise ValueError("a weight of %r is below the millionth G-code carries: scale the "
                         "matrix row" % x)
    return text or "0"


def header(matrix, tools, newline=b"\n"):
    lines = [b"; mixstep detool: slicer tool T<n> is virtual tool T<n>, mix = matrix row n"]
    for tool in sorted(tools):
        mix = matrix[tool]
        lines.append(b"; T%d mix %s" % (tool, ":".join(decimal(w) for w in mix).encode()))
        for drive, weight in enumerate(mix):
            lines.append(b"M163 S%d P%s" % (drive, decimal(weight).encode()))
        lines.append(b"M164 S%d" % tool)
    return newline.join(lines) + newline


def _temperature_line(raw, tool, active_tool):
    """The line to write for an M104/M109 that names tool (None: names none)."""
    if tool is None:
        return raw
    if tool != active_tool:
        body = raw.rstrip(b"\r\n")
        return (b"; mixstep detool: dropped, one hot end and T%d is in use: " % active_tool
                + body + raw[len(body):])
    code_part, sep, comment = raw.partition(b";")
    # Cut the T word out of the raw bytes, so the rest of the line stays as it was.
    word = _TOOL_WORD.search(code_part, _COMMAND.match(code_part).end())
    if word is None:
        return raw
    start, end = word.span()
    if start > 0 and code_part[start - 1:start].isspace():
        start -= 1  # take the space before the word with it
    return code_part[:start] + code_part[end:] + sep + comment


def detool(in_path, out_path, matrix):
    """Write the mixing-tool version of in_path. Returns a summary dict."""
    tools = tools_used(in_path)
    for t in tools:
        if t >= MAX_TOOLS:
            raise ValueError("the file selects T%d; the firmware has T0..T%d" % (t, MAX_TOOLS - 1))
        if t >= len(matrix):
            raise ValueError("the file selects T%d but the matrix has only %d rows"
                             % (t, len(matrix)))
    # Before its first T line a slicer's temperatures are for the tool it selects first.
    active = tools[0] if tools else 0
    converted = dropped = 0
    header_done = False
    refuse_input(out_path, in_path)
    with open(in_path, "rb") as fin, replacing(out_path, "wb") as fout:
        for raw, code, words in _tool_lines(fin):
            if not header_done:
                stripped = raw.strip()
                if stripped and not stripped.startswith(b";"):
                    newline = b"\r\n" if raw.endswith(b"\r\n") else b"\n"
                    fout.write(header(matrix, tools, newline))
                    header_done = True
            if not code:
                fout.write(raw)
                continue
            tool = gcodeio.tool_of(code)
            if tool is not None:
                active = tool
            elif code in _TEMPERATURE_MCODES:
                named = words.get("T", "")
                new = _temperature_line(raw, int(named) if named.isdigit() else None, active)
                if new is not raw:
                    if new.startswith(b"; mixstep detool: dropped"):
                        dropped += 1
                    else:
                        converted += 1
                raw = new
            fout.write(raw)
        if not header_done:
            fout.write(header(matrix, tools))
    return {"tools": tools, "temperatures_converted": converted,
            "temperatures_dropped": dropped}


def add_parser(sub):
    p = sub.add_parser("detool", help="multi-extruder slicer G-code -> mixing virtual tools")
    p.add_argument("gcode", help="the slicer's file")
    p.add_argument("-o", "--output", required=True, help="write the mixing G-code here")
    p.add_argument("--matrix", required=True,
                   help='mixing matrix, a file or rows like "1,0,0;0,1,0;0.5,0.5,0": '
                        "row n is the mix of tool T<n>, one column per drive")
    p.set_defaults(run=_run)


def _run(args):
    import sys
    try:
        summary = detool(args.gcode, args.output, parse_matrix(args.matrix))
    except ValueError as e:
        print("mixstep detool: %s" % e, file=sys.stderr)
        return 2
    print("tools %s; temperatures: %d converted, %d dropped -> %s" % (
        " ".join("T%d" % t for t in summary["tools"]), summary["temperatures_converted"],
        summary["temperatures_dropped"], args.output))
    return 0
