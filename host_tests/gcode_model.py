"""What a G-code file asks of each axis and drive, worked out independently of the
firmware: modal state, G92 offsets and tool changes give each drive's total filament,
and each axis and drive ends at its absolute position rounded to the nearest step
(half away from zero). Tools here are single drives (T<n> = 100 % drive n)."""
import re

WORD = re.compile(r"([A-Za-z])\s*([-+]?[0-9]*\.?[0-9]*)")


def _steps(mm, spm):
    v = mm * spm
    return int(v + 0.5) if v >= 0 else -int(0.5 - v)


def expected_steps(path, steps_per_mm, drives=6):
    pos = [0.0] * 4
    off = [0.0] * 4
    absolute = absolute_e = True
    tool = 0
    drive_mm = [0.0] * drives
    for raw in open(path):
        code = raw.split(";")[0].strip()
        if not code:
            continue
        words = [(l.upper(), v) for l, v in WORD.findall(code)]
        cmd = words[0][0] + words[0][1]
        if cmd in ("M117", "M118"):
            continue  # free text: its letters and digits are no parameters
        params = {l: (float(v) if v else None) for l, v in words[1:]}
        if cmd in ("G0", "G1"):
            target = list(pos)
            for i, ch in enumerate("XYZE"):
                if ch in params:
                    rel = not (absolute_e if i == 3 else absolute)
                    target[i] = target[i] + params[ch] if rel else params[ch]
            drive_mm[tool] += target[3] - pos[3]
            pos = target
        elif cmd == "G92":
            named = [i for i, ch in enumerate("XYZE") if ch in params] or range(4)
            for i in named:
                v = params.get("XYZE"[i]) or 0.0
                off[i] += pos[i] - v
                pos[i] = v
        elif cmd == "G28":
            for i in [i for i in range(3) if "XYZ"[i] in params] or range(3):
                pos[i] = off[i] = 0.0
        elif cmd == "G90":
            absolute = absolute_e = True
        elif cmd == "G91":
            absolute = absolute_e = False
        elif cmd == "M82":
            absolute_e = True
        elif cmd == "M83":
            absolute_e = False
        elif cmd.startswith("T"):
            tool = int(cmd[1:])
    result = {a: _steps(pos[i] + off[i], steps_per_mm[i]) for i, a in enumerate("xyz")}
    result.update({"e%d" % d: _steps(drive_mm[d], steps_per_mm[3]) for d in range(drives)})
    return result
