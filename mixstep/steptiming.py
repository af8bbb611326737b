"""Step timing error: every step the simulated printer took against the time the
physics of its block's motion gives that step (`make bench`, and the tests).

The reference
    A step's ideal time comes from the motion's physics alone: the block's entry speed
    v0, its acceleration a, its cruise speed vn, its exit speed v1 and its n lead
    steps, moved at constant acceleration (v^2 = v0^2 + 2 a s, v = v0 + a t) up to
    the cruise speed, cruising, and braking at a to v1 by the end. It is not worked
    out from the step loop's tick-by-tick rate schedule (the firmware's
    planner.ramp_ticks and ramp.ramp_into), so a mistake there shows up here as
    timing error instead of being copied into the reference. analyse() uses
    ideal_times_us, that physics in closed form; physics_times_us works the same
    times out a second way, with the pieces of the motion found by bisection, and
    the tests (host_tests/test_step_timing.py) hold the closed form to it.

Method
    1. boards/sim/step_times_sim.py runs a G-code file on the simulated printer (the
       firmware unchanged, MicroPython unix port) with every GPIO edge recorded. It
       wraps the timer callback and, for each block the step loop starts, keeps the
       block record as the step loop runs it (lead-axis steps n, steps per axis, and
       the fixed-point rates per tick B_RATE_INIT, B_RATE_NOM, B_RATE_FINAL, B_ACCEL,
       RATE_SHIFT 28) and the block's origin: one tick before its velocity ramp
       starts (after the DIR setup ticks when DIR changed), where the lead axis stands
       at the phase carried over from the block before (a fraction of a step).
    2. The block's motion, in steps and microseconds, from its record: entry speed
       v0 = RATE_INIT, cruise vn = RATE_NOM, exit v1 = RATE_FINAL (steps per tick /
       tick_us), acceleration a = ACCEL (steps per tick per tick / tick_us^2);
       accelerate from v0 to vn, cruise, decelerate to v1 at step n. When the ramps
       meet before vn, the peak is where they meet. The lead-axis position is
       s(t) = phase + distance(t), so the k-th lead step's ideal time t(k) solves
       s(t) = k. ideal_times_us solves it in closed form: under constant acceleration
       t = (sqrt(v0^2 + 2 a d) - v0) / a for a distance d into the ramp, d / vn while
       cruising, and the mirror of the first form while decelerating.
       physics_times_us takes the fastest v(s) that v^2 = v0^2 + 2 a s, the cruise
       speed and the braking to v1 allow, finds its pieces by bisection and adds up
       the time of each; the tests hold the closed form to it.
    3. The edges are split into blocks by the block origins. In each block, the k-th
       rising STEP edge of the lead axis (for E: of any mixing drive) is the k-th
       lead step; its error is its edge time minus origin + t(k). Every other axis is
       compared at the lead step where Bresenham puts its steps (the j-th of m steps
       at lead step floor((j n - ceil(n/2)) / m) + 1, as the step loop counts), so
       that figure adds nothing for Bresenham's own rounding, only timing.
    Homing and dwell blocks are left out (homing stops at the endstop, a dwell has
    no steps). A block whose edge count differs from its record fails the
    measurement.

A step can only fall on a tick: a step loop that follows the plan exactly takes each
step at the first tick at or after its ideal time, 0 to tick_us late (tick_us / 2 on
average). Errors beyond that come from the velocity ramp leaving the plan, from the
STEP high/low time holding a step back, and from rounding in the planner's integer
records.
"""
import json
import subprocess

import numpy as np

from mixstep import paths, trace

ONE = 1 << 28
F_DWELL = 1
F_HOMING = 2
E_AXIS = 3


def ideal_times_us(k, phase, n, v0, vn, v1, a):
    """Ideal time (from the block origin) of lead-axis positions k (array, steps) in a
    trapezoid from v0 through vn to v1 over n steps at acceleration a."""
    d_acc = max(0.0, (vn * vn - v0 * v0) / (2 * a))
    d_dec = max(0.0, (vn * vn - v1 * v1) / (2 * a))
    if d_acc + d_dec > n:  # nominal never reached: the ramps meet at the peak
        peak2 = max(v0 * v0, v1 * v1, a * n + (v0 * v0 + v1 * v1) / 2)
        vn = np.sqrt(peak2)
        d_acc = max(0.0, min(float(n), (peak2 - v0 * v0) / (2 * a)))
        d_dec = n - d_acc
    d_cruise = n - d_acc - d_dec
    s = np.asarray(k, dtype=float) - phase
    s = np.clip(s, 0.0, None)
    t_acc_end = (vn - v0) / a
    t_cruise_end = t_acc_end + d_cruise / vn
    t = np.empty_like(s)
    acc = s < d_acc
    t[acc] = (np.sqrt(v0 * v0 + 2 * a * s[acc]) - v0) / a
    cruise = (~acc) & (s < d_acc + d_cruise)
    t[cruise] = t_acc_end + (s[cruise] - d_acc) / vn
    dec = ~(acc | cruise)
    d = s[dec] - d_acc - d_cruise
    t[dec] = t_cruise_end + (vn - np.sqrt(np.clip(vn * vn - 2 * a * d, 0.0, None))) / a
    return t


def physics_times_us(k, phase, n, v0, vn, v1, a):
    """The same times as ideal_times_us, worked out from the motion's physics instead
    of the trapezoid's corner formulas: the reference the tests hold it to.

    A block starts at speed v0, may not exceed vn, and must be able to stop down to v1
    by its end, at acceleration a either way. By v^2 = v0^2 + 2 a s, the fastest it
    can be at distance s is v(s) = min(vn, sqrt(v0^2 + 2 a s), sqrt(v1^2 + 2 a (n - s))),
    and that is how it moves. The three curves' crossings split the block into pieces
    (found by bisection on v(s), not solved for); on a piece where v follows one of
    the square roots the time taken is the change of speed over a (v = v0 + a t), and
    where it cruises it is the distance over vn."""
    def up(s):
        return np.sqrt(v0 * v0 + 2 * a * s)

    def down(s):
        return np.sqrt(max(v1 * v1 + 2 * a * (n - s), 0.0))

    def crossing(f, g, lo, hi):
        """Where f - g changes sign on [lo, hi] (f - g <= 0 at lo), by bisection."""
        for _ in range(200):
            mid = (lo + hi) / 2
            if f(mid) - g(mid) <= 0:
                lo = mid
            else:
                hi = mid
        return lo

    cruise = lambda s: vn
    # Where accelerating stops: at vn, or earlier where braking must begin.
    end_up = crossing(up, lambda s: min(vn, down(s)), 0.0, float(n)) if up(0) < min(vn, down(0)) else 0.0
    # Where braking starts: where the cruise meets the braking curve; at the peak if
    # there is no cruise; nowhere (the end) if the exit speed is the cruise speed.
    if down(n) >= vn:
        start_down = float(n)
    elif down(end_up) > vn:
        start_down = crossing(lambda s: -down(s), lambda s: -vn, end_up, float(n))
    else:
        start_down = end_up

    def t_of(s):
        if s <= end_up:
            return (up(s) - v0) / a
        t = (up(end_up) - v0) / a
        if s <= start_down:
            return t + (s - end_up) / vn
        t += (start_down - end_up) / vn
        return t + (down(start_down) - down(s)) / a

    s = np.clip(np.asarray(k, dtype=float) - phase, 0.0, None)
    return np.array([t_of(x) for x in s])


def read_blocks(path):
    blocks = []
    with open(path) as f:
        for line in f:
            (origin, phase, flags, n, sx, sy, sz, se, r0, rn, r1, acc,
             accel_until, decel_after) = json.loads(line)
            blocks.append({"origin_us": origin, "phase": phase / ONE, "flags": flags, "n": n,
                           "steps": (sx, sy, sz, se), "r0": r0, "rn": rn, "r1": r1, "acc": acc})
    return blocks


def analyse(edges_path, blocks_path, tick_us, pins):
    """Timing errors (us) of lead-axis steps and of all axes' steps. pins: the board's
    pin map; E is every mixing drive's STEP pin. Positive errors are late steps."""
    times, gpios, levels = trace.read_edges(edges_path)
    rising = (levels == 1) & (times > 0)
    axis_pins = [[pins["x_step"]], [pins["y_step"]], [pins["z_step"]],
                 [g for name, g in pins.items() if name.startswith("e") and name.endswith("_step")]]
    axis_times = [np.sort(times[rising & np.isin(gpios, p)]).astype(np.int64) for p in axis_pins]
    blocks = read_blocks(blocks_path)
    lead_err = []
    all_err = []
    checked = 0
    for i, b in enumerate(blocks):
        start = b["origin_us"]
        end = blocks[i + 1]["origin_us"] if i + 1 < len(blocks) else np.iinfo(np.int64).max
        in_block = [t[(t > start) & (t <= end)] for t in axis_times]
        if b["flags"] & (F_DWELL | F_HOMING):
            continue
        n = b["n"]
        v0, vn, v1 = (b[r] / ONE / tick_us for r in ("r0", "rn", "r1"))
        a = b["acc"] / ONE / (tick_us * tick_us)
        lead = int(np.argmax(b["steps"]))
        for axis in range(4):
            m = b["steps"][axis]
            got = in_block[axis]
            if len(got) != m:
                raise RuntimeError("block %d (origin %d us): axis %d has %d steps in the trace, "
                                   "%d in its record" % (i, start, axis, len(got), m))
            if m == 0:
                continue
            j = np.arange(1, m + 1, dtype=np.int64)
            k = (j * n - (n - n // 2)) // m + 1  # Bresenham's lead step for each step
            err = got - (start + ideal_times_us(k, b["phase"], n, v0, vn, v1, a))
            all_err.append(err)
            if axis == lead:
                lead_err.append(err)
        checked += 1
    lead_signed = np.concatenate(lead_err)
    lead_abs = np.abs(lead_signed)
    all_signed = np.concatenate(all_err)
    all_abs = np.abs(all_signed)
    return {
        "step_time_error_max_us": float(lead_abs.max()),
        "step_time_error_p99_us": float(np.percentile(lead_abs, 99)),
        "step_time_error_mean_signed_us": float(lead_signed.mean()),
        "step_time_error_earliest_us": float(all_signed.min()),
        "step_time_error_all_axes_max_us": float(all_abs.max()),
        "step_time_error_all_axes_p99_us": float(np.percentile(all_abs, 99)),
        "step_time_blocks": checked,
        "step_time_lead_steps": int(len(lead_abs)),
    }


def snippet(gcode_path, lines):
    """The first lines of a G-code file as the measurement runs them: cold extrusion
    allowed and the heating waits left out (nothing to wait for)."""
    with open(gcode_path) as f:
        head = f.read().splitlines()[:lines]
    keep = [ln for ln in head if not ln.startswith(("M109", "M190"))]
    return "M302 P1\n" + "\n".join(keep) + "\n"


def record(gcode_path, edges_path, blocks_path, heap="8M"):
    """Run a G-code file on the simulated printer with the edges and block records
    kept (step 1 above). Returns the run's summary: blocks, sim_us, tick_us, errors."""
    script = paths.BOARDS / "sim" / "step_times_sim.py"
    cmd = [paths.micropython(), "-X", "heapsize=" + heap, str(script),
           str(gcode_path), str(edges_path), str(blocks_path)]
    done = subprocess.run(cmd, cwd=paths.ROOT, env=paths.micropython_env("sim"),
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError("step_times_sim.py failed: %s" % done.stderr.strip()[-2000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def measure(gcode_path, work_dir):
    """Record a G-code file and analyse it; the figures of analyse() plus tick_us and
    the errors the firmware answered."""
    edges = work_dir / "steps.edges"
    blocks = work_dir / "steps.blocks"
    run = record(gcode_path, edges, blocks)
    res = analyse(edges, blocks, run["tick_us"], paths.load_board("sim")["PINS"])
    res["step_time_tick_us"] = run["tick_us"]
    res["firmware_errors"] = run["errors"]
    return res
