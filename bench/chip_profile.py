# Where a planned G1 line's time and heap go: bench/chip_rows.py (`python
# bench/chip_rows.py profile`) puts this file on the emulated Pico's flash beside
# chip_main.py, which answers `profile FILE` with it; bench/alloc_profile.py uses it on
# a unix port for the heap.
#
# Each function named in TIMED is wrapped so that every call adds what a counter
# (time.ticks_us, or gc.mem_alloc with the collector off) moved, inclusive of what it
# calls, to a total. A wrapper costs tens of microseconds per call on the chip and
# allocates its arguments' tuple, charged to the caller's total: the totals say where
# the time goes, and the unwrapped run beside them says how fast the lines really go.
import gc
import time
from mixfw import cmd_motion, planner as planner_mod, lookahead

# (label, owner, attribute): owner is a name looked up in `targets` below. The methods
# the firmware calls from their class (Planner._plan_e(self, ...)) are wrapped there.
TIMED = (
    ("parse", "parser", "parse"),
    ("g1", "commands", "G1"),
    ("motion.xyz_targets", "cmd_motion", "xyz_targets"),
    ("motion._queue", "motion_class", "_queue"),
    ("before_extrude", "before_extrude", 0),
    ("planner.add_move", "planner", "add_move"),
    ("planner._plan_e", "planner_class", "_plan_e"),
    ("block_weights", "planner_mod", "block_weights"),
    ("planner._xyz_steps", "planner_mod", "_xyz_steps"),
    ("planner._new_slot", "planner_class", "_new_slot"),
    ("planner._plan_move", "planner_mod", "_plan_move"),
    ("planner._remember_extrusion", "planner", "_remember_extrusion"),
    ("geometry.lengths", "planner_mod", "_lengths"),
    ("geometry.junction", "planner_mod", "_junction"),
    ("lookahead.plan_words", "planner_mod", "_plan_words"),
    ("lookahead.recalculate", "planner_mod", "_recalculate"),
    ("ramp.ramp_into", "lookahead", "ramp_into"),
)


def _wrap(fn, slot, totals, counter, diff):
    def timed(*args, **kwargs):
        t = counter()
        r = fn(*args, **kwargs)
        totals[slot] += diff(counter(), t)
        totals[slot + 1] += 1
        return r
    return timed


def _minus(a, b):
    return a - b


def _targets(printer):
    motion = printer.motion
    return {"parser": printer.parser, "commands": printer.commands, "motion": motion,
            "before_extrude": motion.before_extrude, "planner": printer.planner,
            "planner_class": type(printer.planner), "motion_class": type(motion),
            "planner_mod": planner_mod, "lookahead": lookahead, "cmd_motion": cmd_motion}


def install(printer, command_key, heap=False):
    """Wrap every TIMED function of this printer to total its time, or with heap its
    bytes allocated; returns (labels, totals)."""
    counter, diff = (gc.mem_alloc, _minus) if heap else (time.ticks_us, time.ticks_diff)
    targets = _targets(printer)
    totals = [0] * (2 * len(TIMED))
    labels = []
    for i, (label, owner, attr) in enumerate(TIMED):
        obj = targets[owner]
        if owner == "commands":
            attr = command_key(attr[0], int(attr[1:]))
        try:
            fn = obj[attr] if isinstance(obj, (dict, list)) else getattr(obj, attr)
        except (KeyError, IndexError, AttributeError):
            continue
        w = _wrap(fn, 2 * i, totals, counter, diff)
        if isinstance(obj, (dict, list)):
            obj[attr] = w
        else:
            setattr(obj, attr, w)
        labels.append((label, 2 * i))
    gc.collect()
    return labels, totals


def bytes_allocated(run_line, parse, lines):
    """What running the lines allocates, the collector held off (the heap must hold it
    all)."""
    gc.collect()
    gc.disable()
    before = gc.mem_alloc()
    for raw in lines:
        run_line(parse(raw, len(raw)))
    allocated = gc.mem_alloc() - before
    gc.enable()
    return allocated


def report(labels, totals, lines, unit="us"):
    return {label: {unit + "_per_line": totals[i] / lines,
                    "calls_per_line": totals[i + 1] / lines}
            for label, i in labels}
