# Bed levelling, as Marlin's AUTO_BED_LEVELING_BILINEAR with a probe: G30 probes one
# point, G29 a grid of them into a mesh, M420 turns the mesh's correction on or off
# and sets its fade, M851 the probe's offsets. Loaded at the first of these commands,
# or at boot when the saved mesh is on: a board keeps a module's code in RAM.
#
# The correction is a stage in front of the queue (Motion.queue), as Transitions is:
# it takes the queue's moves in unlevelled machine steps, splits each where it
# crosses the mesh's grid lines (the correction is linear between them along a move's
# axis lines, as Marlin's segmented bilinear moves), and hands the queue the pieces
# with Z raised by the mesh's height at their ends. The logical position (M114, G92,
# soft limits) stays unlevelled. Everything is in integers: the mesh's heights in
# 1/16 of a Z step, a point's place in a cell in 1/4096 of the cell.
from array import array
from mixfw.gcode import GcodeError
from mixfw.filament import nm_from_mm, div_round, NM_PER_MM
from mixfw import stepper as st

_MAX_POINTS = const(5)
_FRAC_BITS = const(12)  # a point's place in its cell, and the fade, in 1/4096
_FRAC_ONE = const(4096)
_FRAC_HALF = const(2048)
_SUB_BITS = const(4)  # the mesh's heights in 1/16 of a Z step
_SUB_HALF = const(8)
# A BLTouch's servo: 50 Hz, a 647 us pulse deploys the pin and 1473 us stows it
# (Marlin's BLTOUCH angles 10 and 90 degrees), and each takes it 0.5 s (BLTOUCH_DELAY).
_SERVO_HZ = const(50)
_DEPLOY_US = const(647)
_STOW_US = const(1473)
_SERVO_S = 0.5

_levelling = None


def shared(printer, motion, pins, config, pin_map, machine):
    """The one Levelling every command of it uses (each lazy command builds its
    object by calling this)."""
    global _levelling
    if _levelling is None:
        _levelling = Levelling(printer, motion, pins, config, pin_map, machine)
    return _levelling


def _fmt(mm):
    """Marlin's float to serial: two decimals."""
    return "%.2f" % mm


class Stage:
    """In front of the queue (Motion.queue) while levelling is on: the queue's
    add_move and position_steps, the position unlevelled."""

    def __init__(self, levelling, queue):
        self.levelling = levelling
        self.queue = queue
        self.position_steps = list(queue.position_steps)
        self._out = array("i", bytes(4 * 3))

    @property
    def mix_id(self):  # M600's moves of one drive (Motion.feed_filament)
        return self.queue.mix_id

    def synchronize(self):
        self.queue.synchronize()

    def add_move(self, target_steps, feed_mm_s, dir_masks=None, e_nm=0, mix=None,
                 replay=False):
        lv = self.levelling
        p = self.position_steps
        q = self.queue
        out = self._out
        x0 = p[0]
        y0 = p[1]
        z0 = p[2]
        x1 = target_steps[0]
        y1 = target_steps[1]
        z1 = target_steps[2]
        dx = x1 - x0
        dy = y1 - y0
        dz = z1 - z0
        gx = lv.grid_x
        gy = lv.grid_y
        # The interior grid lines the move crosses, nearest first: kx, ky step by
        # sx, sy; a line at or beyond the end is none.
        sx = 1 if dx > 0 else -1
        sy = 1 if dy > 0 else -1
        kx = lv.cell(gx, lv.nx, x0) + (1 if dx > 0 else 0)
        ky = lv.cell(gy, lv.ny, y0) + (1 if dy > 0 else 0)
        if dx < 0 and gx[kx] >= x0:
            kx -= 1
        if dy < 0 and gy[ky] >= y0:
            ky -= 1
        adx = dx * sx
        ady = dy * sy
        e_done = 0
        if not lv.motion.enabled & 4:
            lv.motion.enable_for(4)  # Z follows the bed on a move that names none
        while True:
            nx = ny = -1
            if dx and 0 < kx < lv.nx - 1 and (gx[kx] - x1) * sx < 0:
                nx = (gx[kx] - x0) * sx
            if dy and 0 < ky < lv.ny - 1 and (gy[ky] - y1) * sy < 0:
                ny = (gy[ky] - y0) * sy
            if nx < 0 and ny < 0:
                break
            # The nearer crossing: nx / adx against ny / ady.
            if ny < 0 or (nx >= 0 and nx * ady <= ny * adx):
                num = nx
                den = adx
                if ny >= 0 and nx * ady == ny * adx:
                    ky += sy
                kx += sx
            else:
                num = ny
                den = ady
                ky += sy
            x = x0 + div_round(dx * num, den)
            y = y0 + div_round(dy * num, den)
            z = z0 + div_round(dz * num, den)
            e_at = e_nm * num // den
            out[0] = x
            out[1] = y
            out[2] = z + lv.lift_steps(x, y, z)
            q.add_move(out, feed_mm_s, dir_masks, e_at - e_done, mix, replay)
            e_done = e_at
        out[0] = x1
        out[1] = y1
        out[2] = z1 + lv.lift_steps(x1, y1, z1)
        q.add_move(out, feed_mm_s, dir_masks, e_nm - e_done, mix, replay)
        p[0] = x1
        p[1] = y1
        p[2] = z1
        return True

    def resync(self):
        """After the queue was dropped (M410, a halt): the unlevelled position of where
        the axes are, the correction taken at the levelled Z (within the fade's
        slope of the truth)."""
        at = self.queue.position_steps
        p = self.position_steps
        p[0] = at[0]
        p[1] = at[1]
        p[2] = at[2] - self.levelling.lift_steps(at[0], at[1], at[2])


class Levelling:
    def __init__(self, printer, motion, pins, config, pin_map, machine):
        self.printer = printer
        self.motion = motion
        self.planner = motion.planner
        self.pins = pins
        self.config = config
        self.settings = config.settings
        self.machine = machine
        gpio = pin_map.get("z_probe")
        self.probe_pin = None
        if gpio is not None:
            s = self.settings
            self.probe_pin = machine.Pin(
                gpio, machine.Pin.IN, machine.Pin.PULL_UP if s.get("endstop_pullup") else None)
        self.servo_gpio = pin_map.get("probe_servo")
        self.servo = None
        self.base = motion.queue  # the queue the stage stands in front of
        self.stage = None  # while levelling is on
        self.nx = self.ny = 0
        self.grid_x = array("i", bytes(4 * _MAX_POINTS))  # steps, machine
        self.grid_y = array("i", bytes(4 * _MAX_POINTS))
        self.lift_q = array("i", bytes(4 * _MAX_POINTS * _MAX_POINTS))  # 1/16 Z steps
        self.fade_steps = 0
        self._grid = None  # the grid options the tables were made from
        motion.before_home.append(self.off)  # G28 leaves levelling off, as Marlin's
        self._lift_nm = 0
        config.appliers.insert(0, self.before_apply)
        config.appliers.append(self.apply)
        self.apply(self.settings)

    # --- the mesh in steps ---
    def _grid_options(self, s):
        return (tuple(s["mesh_points"]), tuple(s["mesh_min_mm"]), tuple(s["mesh_max_mm"]))

    def grid_points_nm(self, axis):
        """Where G29 probes along axis 0 (X) or 1 (Y): the probe's machine positions."""
        s = self.settings
        n = s["mesh_points"][axis]
        lo = nm_from_mm(s["mesh_min_mm"][axis])
        hi = nm_from_mm(s["mesh_max_mm"][axis])
        return [lo + div_round((hi - lo) * i, n - 1) for i in range(n)]

    def _tables(self, settings):
        """The options as they are now in steps: the grid, the heights, the fade; a
        grid changed since the mesh was made clears it."""
        grid = self._grid_options(settings)
        if self._grid is not None and grid != self._grid and settings["mesh_probed"]:
            settings["mesh_probed"] = False
            settings["mesh_enabled"] = False
            self.printer.reply("echo:the mesh's grid changed: mesh cleared, G29 makes it again")
        self._grid = grid
        spm = self.planner.steps_per_mm
        self.nx, self.ny = settings["mesh_points"]
        for axis, table in ((0, self.grid_x), (1, self.grid_y)):
            for i, nm in enumerate(self.grid_points_nm(axis)):
                table[i] = div_round(nm * 1000 * int(spm[axis] * 1000 + 0.5), 10 ** 12)
        z_q = int(spm[2] * (1 << _SUB_BITS) * 1000 + 0.5)  # 1/16 steps per um
        z = settings["mesh_z_nm"]
        for k in range(self.nx * self.ny):
            self.lift_q[k] = div_round(z[k] * z_q, 10 ** 9)
        self.fade_steps = int(settings["mesh_fade_mm"] * spm[2] + 0.5)

    def apply(self, settings):
        """M930 (after Motion.apply, which put the planner at the unlevelled position
        in the new steps/mm): the tables anew, levelling on or off as the options say,
        and the planner's Z back where the axes stand, levelled as before."""
        self._tables(settings)
        on = settings["mesh_enabled"] and settings["mesh_probed"]
        if self.stage is not None and self._lift_nm:
            steps = self.motion.machine_steps()
            for i in range(3):
                self.stage.position_steps[i] = steps[i]
            at = list(self.planner.position_steps)
            at[2] = steps[2] + div_round(self._lift_nm * int(self.planner.steps_per_mm[2]
                                                              * 1000 + 0.5), 10 ** 9)
            self.planner.set_position_steps(at)
        self._lift_nm = 0
        self.enable(on)

    def before_apply(self, settings):
        """M930, before Motion.apply: how high the correction has the axes now (nm),
        in the tables and steps/mm they were levelled by."""
        self._lift_nm = 0
        if self.stage is not None:
            self.planner.synchronize()
            p = self.stage.position_steps
            self._lift_nm = div_round(self.lift_steps(p[0], p[1], p[2]) * NM_PER_MM * 1000,
                                      int(self.planner.steps_per_mm[2] * 1000 + 0.5))

    @staticmethod
    def cell(grid, n, v):
        """The cell (0..n-2) of grid (steps) that holds v, the edge cells also
        what lies beyond them (the correction extrapolates, as Marlin's)."""
        i = 0
        while i < n - 2 and v >= grid[i + 1]:
            i += 1
        return i

    def lift_steps(self, x, y, z):
        """The mesh's height at machine X Y (steps) in Z steps, faded at machine Z z:
        bilinear within a cell, in 1/16 of a Z step and 1/4096 of a cell."""
        nx = self.nx
        gx = self.grid_x
        gy = self.grid_y
        i = Levelling.cell(gx, nx, x)
        j = Levelling.cell(gy, self.ny, y)
        fx = (x - gx[i]) * _FRAC_ONE // (gx[i + 1] - gx[i])
        fy = (y - gy[j]) * _FRAC_ONE // (gy[j + 1] - gy[j])
        zq = self.lift_q
        k = j * nx + i
        a = (zq[k] * _FRAC_ONE + (zq[k + 1] - zq[k]) * fx + _FRAC_HALF) >> _FRAC_BITS
        k += nx
        b = (zq[k] * _FRAC_ONE + (zq[k + 1] - zq[k]) * fx + _FRAC_HALF) >> _FRAC_BITS
        lift = (a * _FRAC_ONE + (b - a) * fy + _FRAC_HALF) >> _FRAC_BITS
        fade = self.fade_steps
        if fade and z > 0:
            if z >= fade:
                return 0
            lift = (lift * ((fade - z) * _FRAC_ONE // fade) + _FRAC_HALF) >> _FRAC_BITS
        return (lift + _SUB_HALF) >> _SUB_BITS

    # --- on and off ---
    def enable(self, on):
        """Levelling on or off; the axes stay where they are, and the next move takes
        Z to the bed's (or back to the unlevelled) height."""
        m = self.motion
        self.settings["mesh_enabled"] = bool(on)
        if on and self.stage is None:
            self.planner.synchronize()
            self.base = m.queue
            self.stage = Stage(self, self.base)
            m.queue = self.stage
            p = self.printer
            for stops in (p.on_halt, p.on_quick_stop):
                stops.insert(stops.index(m.resync), self.stage.resync)
        elif not on and self.stage is not None:
            self.planner.synchronize()
            m.queue = self.base
            p = self.printer
            for stops in (p.on_halt, p.on_quick_stop):
                stops.remove(self.stage.resync)
            self.stage = None

    def off(self):
        self.enable(False)

    # --- probing ---
    def _need_probe(self):
        if self.probe_pin is None:
            raise GcodeError("this board has no bed probe (no z_probe pin)")

    def _servo(self, pulse_us):
        if self.servo_gpio is None:
            return
        if self.servo is None:
            self.servo = self.machine.PWM(self.machine.Pin(self.servo_gpio), freq=_SERVO_HZ,
                                          duty_u16=0)
        self.servo.duty_u16(pulse_us * _SERVO_HZ * 65535 // 1000000)
        self.planner.add_dwell(_SERVO_S)
        self.planner.synchronize()

    def _raw_move(self, x, y, z, feed_mm_s):
        """A move of the machine's own, unlevelled, to X Y Z steps (None: stays)."""
        p = self.planner
        target = list(p.position_steps)
        for i, v in enumerate((x, y, z)):
            if v is not None:
                target[i] = v
        self.motion.enable_for(7)
        p.add_move(target, feed_mm_s, dir_masks=self.motion.dir_masks)

    def nozzle_for(self, px_nm, py_nm):
        """The nozzle's machine X Y (nm) that puts the probe at px, py; refused where
        the nozzle can't go."""
        s = self.settings
        off = s["probe_offset_mm"]
        x = px_nm - nm_from_mm(off[0])
        y = py_nm - nm_from_mm(off[1])
        for v, i in ((x, 0), (y, 1)):
            if not 0 <= v <= nm_from_mm(s["travel_mm"][i]):
                raise GcodeError("the probe can't reach %s %s: the nozzle would be at %s, "
                                 "outside 0..%g" % ("XY"[i], _fmt((px_nm, py_nm)[i] / NM_PER_MM),
                                                    _fmt(v / NM_PER_MM), s["travel_mm"][i]))
        return x, y

    def check_homed(self):
        if self.motion.homed & 7 != 7:
            raise GcodeError("home X, Y and Z first (G28): probing needs the axes' "
                             "positions")

    def probe(self, px_nm, py_nm):
        """The bed's height (machine Z, nm) under the probe at machine px, py: the
        nozzle goes up to probe_clearance_mm, over the point, and dives at
        probe_feed_mm_s until the probe triggers; the nozzle stays there."""
        s = self.settings
        m = self.motion
        p = self.planner
        spm = p.steps_per_mm
        x_nm, y_nm = self.nozzle_for(px_nm, py_nm)
        p.synchronize()
        clear = int(s["probe_clearance_mm"] * spm[2] + 0.5)
        travel = s["probe_travel_feed_mm_s"]
        if p.position_steps[2] < clear:
            self._raw_move(None, None, clear, p.max_feed_mm_s[2])
        self._raw_move(int(x_nm * spm[0] / NM_PER_MM + 0.5), int(y_nm * spm[1] / NM_PER_MM + 0.5),
                       clear, travel)
        p.synchronize()
        self._servo(_DEPLOY_US)
        level = 1 if s["probe_active_high"] else 0
        pins = self.pins
        was = (pins.stops[2], pins.stop_levels[2])
        pins.stops[2] = self.probe_pin
        pins.stop_levels[2] = level
        feed = m.feed
        mem = p.mem
        dive = int(s["probe_dive_mm"] * spm[2] + 0.5)
        target = list(p.position_steps)
        target[2] -= dive
        try:
            if feed:
                feed.watch_endstop(self.probe_pin, level)
            p.add_move(target, s["probe_feed_mm_s"], homing_axes=4, dir_masks=m.dir_masks)
            if feed:
                m._home_on_feed(2)
            else:
                p.synchronize()
        finally:
            pins.stops[2], pins.stop_levels[2] = was
            if feed:
                feed.watch_endstop(None)
        hit = (mem[st.S_HOME_STOP] >> 2) & 1
        at = list(p.position_steps)
        at[2] = mem[st.S_POS + 2]
        p.set_position_steps(at)
        self._servo(_STOW_US)
        m.resync()
        if not hit:
            raise GcodeError("probing failed: the probe did not trigger within %g mm "
                             "(probe_dive_mm)" % s["probe_dive_mm"])
        return div_round(at[2] * NM_PER_MM * 1000, int(spm[2] * 1000 + 0.5)) \
            + nm_from_mm(s["probe_offset_mm"][2])

    def _raise_after(self):
        s = self.settings
        spm = self.planner.steps_per_mm
        self._raw_move(None, None, int(s["probe_clearance_mm"] * spm[2] + 0.5),
                       self.planner.max_feed_mm_s[2])
        self.planner.synchronize()
        self.motion.resync()

    # --- commands ---
    # G30 [X<mm>] [Y<mm>]: probe the bed once with the probe at X Y (default: where
    # it is now), and reply its height as Marlin's `Bed X: Y: Z:`. Levelling turns off
    # first, as Marlin's G30 does; the nozzle ends probe_clearance_mm up.
    # Example: G30 X100 Y100
    def g30(self, line):
        self._need_probe()
        self.check_homed()
        m = self.motion
        off = self.settings["probe_offset_mm"]
        at = [m.pos_nm[i] + m.offset_nm[i] + nm_from_mm(off[i]) for i in range(2)]
        for i in range(2):
            if line.has("XY"[i]):
                at[i] = nm_from_mm(line.float("XY"[i])) + m.offset_nm[i]
        self.nozzle_for(at[0], at[1])  # refused before anything moves
        self.enable(False)
        z_nm = self.probe(at[0], at[1])
        self._raise_after()
        self.printer.reply("Bed X: %s Y: %s Z: %s" % (
            _fmt((at[0] - m.offset_nm[0]) / NM_PER_MM), _fmt((at[1] - m.offset_nm[1]) / NM_PER_MM),
            _fmt(z_nm / NM_PER_MM)))

    # G29: probe the grid mesh_points (X by Y) from mesh_min_mm to mesh_max_mm (the
    # probe's machine positions) into the mesh, print it as M420 V does, and turn
    # levelling on (Marlin's bilinear G29). Needs the axes homed; every point is
    # checked reachable before anything moves. A point that fails stops it, the mesh
    # as it was. Example: G29
    def g29(self, line):
        self._need_probe()
        self.check_homed()
        xs = self.grid_points_nm(0)
        ys = self.grid_points_nm(1)
        for x in xs:
            for y in ys:
                self.nozzle_for(x, y)
        s = self.settings
        self.enable(False)
        self._tables(s)  # the grid as the options are now
        nx = len(xs)
        heights = list(s["mesh_z_nm"])
        for j, y in enumerate(ys):
            # a serpentine: each row the way the last one ended
            for i in (range(nx) if j % 2 == 0 else range(nx - 1, -1, -1)):
                heights[j * nx + i] = self.probe(xs[i], y)
        self._raise_after()
        self.config.update([("mesh_z_nm_%d" % k, heights[k]) for k in range(len(heights))]
                           + [("mesh_probed", True)])
        self._tables(s)
        self.enable(True)
        self.report()

    # M420 [S<0|1>] [Z<mm>] [V]: levelling off (S0) or on (S1, with a mesh G29 made or
    # M501 loaded), its fade height Z (the correction shrinks linearly to 0 at that Z;
    # Z0: never fades), and V prints the mesh. Replies as Marlin's: `echo:Bed Leveling
    # ON|OFF` and `echo:Fade Height <mm>|OFF`. Example: M420 S1 Z10 V
    def m420(self, line):
        s = self.settings
        on = None
        if line.has("S"):
            on = line.int("S", lo=0, hi=1)
            if on and not s["mesh_probed"]:
                raise GcodeError("M420 S1: no mesh to level by (G29 makes one)")
        if line.has("Z"):
            fade = line.float("Z")
            if not 0 <= fade <= 1000:
                raise GcodeError("M420 Z%s: the fade height is 0..1000 mm" % fade)
            if fade != s["mesh_fade_mm"]:
                self.planner.synchronize()
                self.config.update([("mesh_fade_mm", fade)])
                self._tables(s)
        if line.has("V") and s["mesh_probed"]:
            self.report_grid()
        if on is not None:
            self.enable(on)
        self.printer.reply("echo:Bed Leveling %s" % ("ON" if self.stage else "OFF"))
        fade = s["mesh_fade_mm"]
        self.printer.reply("echo:Fade Height %s" % (_fmt(fade) if fade > 0 else "OFF"))

    def report(self):
        self.report_grid()

    def report_grid(self):
        """The mesh as Marlin's print_bilinear_leveling_grid prints it: a header of X
        indexes, then a row per Y index (Y 0 first), each height with its sign and 3
        decimals, in mm."""
        reply = self.printer.reply
        nx, ny = self.settings["mesh_points"]
        z = self.settings["mesh_z_nm"]
        reply("Bilinear Leveling Grid:")
        reply("".join(" " * (6 if i < 10 else 5) + str(i) for i in range(nx)))
        for j in range(ny):
            reply("%2d" % j + "".join(" %+.3f" % (z[j * nx + i] / NM_PER_MM)
                                      for i in range(nx)))

    # M851 [X<mm>] [Y<mm>] [Z<mm>]: the probe's offsets from the nozzle (Marlin's
    # meaning: X Y where the probe is from the nozzle, Z the nozzle's height when the
    # probe triggers, negated); none: report as Marlin's `Probe Offset X Y Z`. M500
    # saves them. Example: M851 Z-1.52
    def m851(self, line):
        s = self.settings
        pairs = [("probe_offset_mm_" + ch.lower(), line.float(ch)) for ch in "XYZ"
                 if line.has(ch)]
        if pairs:
            self.config.update(pairs)
            return
        off = s["probe_offset_mm"]
        self.printer.reply("Probe Offset X%s Y%s Z%s" % (_fmt(off[0]), _fmt(off[1]),
                                                         _fmt(off[2])))
