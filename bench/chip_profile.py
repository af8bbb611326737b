# Where a planned G1 line's time and heap go: bench/chip_rows.py (`python
# bench/chip_rows.py profile`) puts this file on the emulated Pico's flash beside
# chip_main.py, which answers `profile FILE` with it; bench/alloc_profile.py uses it on
# a unix port for the heap.
#
# Each function named in TIMED is wrapped so that every call adds what a counter
# (time.ticks_us, or gc.mem_alloc with the collector off) moved, inclusive of what it
# calls, to a total. A wrapper takes the function's own parameters, so that it
# allocates nothing: one taking *args allocated a tuple a call, and the collections
# that made (26 ms each on the chip) landed in whatever was being timed, several
# times a line's own time. A wrapper still costs about 15 us a call on the chip,
# charged to its caller's total: the totals say where the time goes, and the
# unwrapped run beside them says how fast the lines really go.
import gc
import time
from mixfw import cmd_motion, planner as planner_mod, lookahead
import plan_only

# (label, owner, attribute, parameters): owner is a name looked up in `targets`
# below. The methods the firmware calls from their class (Planner._new_slot(self, ...))
# are wrapped there. parameters: the function's, as its callers pass them.
TIMED = (
    ("parse", "parser", "parse", "buf, n"),
    ("g1", "commands", "G1", "line"),
    ("motion.xyz_targets", "cmd_motion", "xyz_targets", "a, b, c, d, e"),
    ("motion._queue", "cmd_motion", "_queue", "motion, steps, xyz, e_nm, feed_mm_s"),
    ("before_extrude", "before_extrude", 0, "z, e_nm"),
    ("planner.add_move", "planner", "add_move",
     "target_steps, feed_mm_s, dir_masks=None, e_nm=0, mix=None, replay=False, "
     "homing_axes=0"),
    ("filament.plan_e_words", "planner_mod", "plan_e_words", "a, b, c, d"),
    ("filament.plan_e", "planner_mod", "plan_e", "pl, e_nm, weights=None"),
    ("block_weights", "planner_mod", "block_weights", "a"),
    ("planner._xyz_steps", "planner_mod", "_xyz_steps", "a, b"),
    ("planner._new_slot", "planner_class", "_new_slot", "self, slot"),
    ("planner._plan_move", "planner_mod", "_plan_move", "a, b, c, d, e"),
    ("filament.remember_extrusion", "planner_mod", "remember_extrusion",
     "pl, weights, counts"),
    ("geometry.lengths", "planner_mod", "_lengths", "a"),
    ("geometry.junction", "planner_mod", "_junction", "a"),
    ("lookahead.plan_words", "planner_mod", "_plan_words", "a"),
    ("lookahead.recalculate", "planner_mod", "_recalculate", "a, b"),
    ("stepper.schedule", "plan_only", "schedule", "a, b, c"),
)

# Its globals start with _w_: no parameter of a wrapped function may hide them.
_WRAPPER = """
def timed(%s):
    _w_t = _w_counter()
    _w_r = _w_fn(%s)
    _w_totals[_w_slot] += _w_diff(_w_counter(), _w_t)
    _w_totals[_w_slot + 1] += 1
    return _w_r
"""


def _wrap(fn, slot, totals, counter, diff, params):
    names = ", ".join(p.split("=")[0].strip() for p in params.split(","))
    scope = {"_w_fn": fn, "_w_slot": slot, "_w_totals": totals, "_w_counter": counter,
             "_w_diff": diff}
    exec(_WRAPPER % (params, names), scope)
    return scope["timed"]


def _minus(a, b):
    return a - b


def _targets(printer):
    motion = printer.motion
    return {"parser": printer.parser, "commands": printer.commands, "motion": motion,
            "before_extrude": motion.before_extrude, "planner": printer.planner,
            "planner_class": type(printer.planner),
            "planner_mod": planner_mod, "lookahead": lookahead, "cmd_motion": cmd_motion,
            "plan_only": plan_only}


def install(printer, command_key, heap=False):
    """Wrap every TIMED function of this printer to total its time, or with heap its
    bytes allocated; returns (labels, totals)."""
    counter, diff = (gc.mem_alloc, _minus) if heap else (time.ticks_us, time.ticks_diff)
    targets = _targets(printer)
    totals = [0] * (2 * len(TIMED))
    labels = []
    for i, (label, owner, attr, params) in enumerate(TIMED):
        obj = targets[owner]
        if owner == "commands":
            attr = command_key(attr[0], int(attr[1:]))
        try:
            fn = obj[attr] if isinstance(obj, (dict, list)) else getattr(obj, attr)
        except (KeyError, IndexError, AttributeError):
            continue
        w = _wrap(fn, 2 * i, totals, counter, diff, params)
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
