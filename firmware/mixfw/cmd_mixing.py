# Mixing commands: M163 (one drive's weight), M164 (store as a virtual tool), M165
# (Marlin: the whole mix at once; R reports every tool), M567 (RepRapFirmware: a tool's
# mix), T<n>. Virtual tools live in the configuration (options tool_mixes_<n>), so
# M500 keeps them across a reboot and M503 prints them.
from mixfw.gcode import GcodeError
from mixfw.mixer import normalize
from mixfw.gradient import Gradient, ALONG_Z, ALONG_E
from mixfw.filament import NM_PER_MM
from mixfw.stepper import S_DRIVE_POS

_MARLIN_LETTERS = const("ABCDHI")  # Marlin's letters for drives 0..5 in M165


class Mixing:
    def __init__(self, planner, settings, config, reply, queue=None, motion=None):
        """queue: where mix changes go (set_mix), as Motion's: the planner or Transitions
        in front of it; the planner if None. motion: before_extrude is in its list of
        that name while a gradient is on (a call costs every extruding line about 15 us
        on the chips)."""
        self.motion = motion
        self._counted = [0] * settings["drives"]  # steps already added to the settings
        self.planner = planner
        self.queue = queue or planner
        self.settings = settings
        self.config = config
        self.reply = reply
        self.drives = settings["drives"]
        self.count = len(settings["tool_mixes"])
        self.collector = [0.0] * self.drives  # weights set by M163, stored by M164
        self.active = 0
        self.mix_id = 1
        self.mix = None
        self.palette = None  # Ovenbird's mixing matrix: rows of drive shares; None: identity
        self.gradient = None
        self.gradient_on = False
        # Printing extrusion since the gradient was set (ALONG_E), in integer nm: a sum
        # over a whole print, which 32-bit floats would let drift.
        self.extruded_nm = 0
        self.tool_flow_pct = [100] * self.count  # M221's, per tool (not saved, as in Marlin)
        self._activate(0)

    def filament_used_mm(self):
        """Per drive: the saved counter plus what the drive fed since it was updated."""
        self.planner.synchronize()
        spm = self.planner.drive_steps_per_mm
        used = list(self.settings["filament_used_mm"])
        mem = self.planner.mem
        for i in range(self.drives):
            steps = mem[S_DRIVE_POS + i]  # the step loop's: net steps since start-up
            used[i] += (steps - self._counted[i]) / spm[i]
            self._counted[i] = steps
        self.config.update([("filament_used_mm_%d" % i, used[i]) for i in range(self.drives)])
        return used

    # M167 [R]: filament fed by each drive, net of retractions, kept with the
    # configuration (M500 saves it). R clears the counters. Example: M167
    def m167(self, line):
        used = self.filament_used_mm()
        if line.has("R"):
            self.config.update([("filament_used_mm_%d" % i, 0.0) for i in range(self.drives)])
            used = [0.0] * self.drives
        self.reply("echo:filament used mm " + " ".join(
            "e%d:%.3f" % (i, used[i]) for i in range(self.drives)))

    def tool_mix(self, tool):
        return self.settings["tool_mixes"][tool]

    def _check_tool(self, tool):
        if not 0 <= tool < self.count:
            raise GcodeError("tool T%d out of range T0..T%d" % (tool, self.count - 1))
        return tool

    def _activate(self, tool):
        """Blocks queued from now on print with this tool's mix; queued ones keep theirs."""
        self.active = tool
        if self.motion:
            self.motion.set_flow(self.tool_flow_pct[tool])
        self.planner.set_advance(self.settings["tool_advance_k"][tool])
        mix = self.tool_mix(tool)
        if mix != self.mix:
            self.mix = mix
            self.mix_id += 1
            self.queue.set_mix(self.mix_id, mix, tool)

    def store(self, tool, weights, save=False):
        """Set a virtual tool's mix (normalised; an all-zero mix is refused)."""
        self.config.set("tool_mixes_%d" % tool, normalize(weights, self.drives))
        if tool == self.active:
            self._activate(tool)
        if save:
            self.config.save()
        else:
            self.reply("echo:T%d mix set; M500 keeps it after a restart" % tool)

    def before_extrude(self, z2_nm, e_nm):
        """Called by motion before each move that extrudes: a gradient sets the mix the
        move prints with, taken at the middle of the move. z2_nm: twice the middle's Z
        (an integer: the millimetres are worked out only for a Z gradient)."""
        g = self.gradient
        if g is None or not self.gradient_on or (g.alias >= 0 and g.alias != self.active):
            return
        if g.along == ALONG_Z:
            pos = z2_nm / (2 * NM_PER_MM)
        else:
            pos = (self.extruded_nm + max(e_nm, 0) // 2) / NM_PER_MM
            if e_nm > 0:
                self.extruded_nm += e_nm
        mix = g.weights_at(pos)
        if mix != self.mix:
            self.mix = mix
            self.mix_id += 1
            self.queue.set_mix(self.mix_id, mix)

    def _tool_shares(self, tool):
        return self.tool_mix(self._check_tool(tool))

    # M166 A<z0> Z<z1> I<tool0> J<tool1> [S0|S1] [T<alias>]: Marlin's Z gradient from
    # tool I at height A to tool J at height Z; T: only while that tool prints. No
    # words: report. Example: M166 A0 Z10 I0 J1 S1
    def m166(self, line):
        if not line.present:
            return self._report()
        if line.has("A") or line.has("Z") or line.has("I") or line.has("J"):
            for ch in "AZIJ":
                line.require(ch)
            stops = [(line.float("A"), self._tool_shares(line.int("I"))),
                     (line.float("Z"), self._tool_shares(line.int("J")))]
            alias = self._check_tool(line.int("T")) if line.has("T") else -1
            self.gradient = Gradient(stops, ALONG_Z, alias, self.drives)
            self.gradient_on = True
        if line.has("S"):
            if self.gradient is None:
                raise GcodeError("no gradient set (M166 A Z I J or M169)")
            self.gradient_on = line.int("S", lo=0, hi=1) == 1
        self._after_gradient_change()

    # M169 [T<alias>] Z<pos>:<tool>,<pos>:<tool>,... | E<mm>:<tool>,...: a gradient of
    # two or more stops along Z (mm) or along the filament extruded from now (mm).
    # M169 alone turns gradients off. Example: M169 T4 Z0:0,2:1,4:2,6:0
    def m169(self, line):
        words = line.args_text.split()
        if not words:
            self.gradient = None
            self.gradient_on = False
            self._after_gradient_change()
            return
        alias = -1
        along = stops = None
        for word in words:
            letter, value = word[0].upper(), word[1:]
            try:
                if letter == "T":
                    alias = self._check_tool(int(value))
                elif letter in "ZE":
                    along = ALONG_Z if letter == "Z" else ALONG_E
                    stops = []
                    for stop in value.split(","):
                        pos, tool = stop.split(":")
                        stops.append((float(pos), self._tool_shares(int(tool))))
                else:
                    raise GcodeError("M169 takes T<tool> and Z or E stops, not %s" % word)
            except ValueError as e:
                if isinstance(e, GcodeError):
                    raise
                raise GcodeError("malformed stop list %s: want <pos>:<tool>,..." % word)
        if stops is None:
            raise GcodeError("M169 needs stops: Z<pos>:<tool>,... or E<mm>:<tool>,...")
        self.gradient = Gradient(stops, along, alias, self.drives)
        self.gradient_on = True
        self.extruded_nm = 0
        self._after_gradient_change()

    def _after_gradient_change(self):
        hooks = self.motion.before_extrude if self.motion else []
        on = self.gradient is not None and self.gradient_on
        if on and self.before_extrude not in hooks:
            hooks.append(self.before_extrude)
        elif not on and self.before_extrude in hooks:
            hooks.remove(self.before_extrude)
        if not self.gradient_on:
            self.mix = None
            self._activate(self.active)
        self._report()

    def _report(self):
        g = self.gradient
        if g is None:
            self.reply("echo:no gradient")
            return
        self.reply("echo:gradient along %s %s%s: %s" % (
            "Z" if g.along == ALONG_Z else "E", "on" if self.gradient_on else "off",
            "" if g.alias < 0 else " for T%d" % g.alias,
            ", ".join("%g:%s" % (p, ":".join("%.4f" % x for x in m)) for p, m in g.stops)))

    def apply(self, settings):
        """M930: the active tool's mix may have changed through M926."""
        self._activate(self.active)

    # M163 S<drive> P<weight>: set one drive's weight in the mix being built.
    # Weights are any non-negative numbers; M164 normalises them. Example: M163 S0 P0.2
    def m163(self, line):
        line.require("S")
        line.require("P")
        drive = line.int("S", lo=0, hi=self.drives - 1)
        weight = line.float("P")
        if weight < 0:
            raise GcodeError("weight P must be >= 0, got %s" % weight)
        self.collector[drive] = weight

    # M164 [S<tool>] [P1]: store the M163 weights as a virtual tool, by default the
    # active one, which then prints with it. P1 also saves to flash, as in Repetier,
    # once the queued moves have run (as M500). An all-zero mix is refused.
    # Example: M164 S4 P1
    def m164(self, line):
        tool = self._check_tool(line.int("S", self.active))
        self.store(tool, self.collector, save=line.int("P", 0, lo=0, hi=1) == 1)

    # M165 A<w> B<w> C<w> D<w> H<w> I<w>: the active tool's whole mix at once (Marlin's
    # letters for drives 0..5). M165 R: print every tool as M567 lines that can be
    # pasted back. Example: M165 A0.25 B0.75
    def m165(self, line):
        if line.has("R"):
            for t in range(self.count):
                self.reply("M567 P%d E%s" % (t, ":".join("%d" % w for w in self.tool_mix(t))))
            return
        weights = [0.0] * self.drives
        given = False
        for i in range(self.drives):
            ch = _MARLIN_LETTERS[i]
            if line.has(ch):
                weights[i] = line.float(ch)
                given = True
        if not given:
            raise GcodeError("M165 needs drive weights A B C D H I, or R to report")
        self.store(self.active, weights)

    # M567 P<tool> E<w0>:<w1>:...: a tool's mix, as RepRapFirmware writes it. Or
    # U<u0>:<u1>:...: a mixture of the palette's mixtures (M168). Example: M567 P2 E1:2:3
    def m567(self, line):
        tool = None
        weights = None
        for word in line.args_text.split():
            letter, value = word[0].upper(), word[1:]
            try:
                if letter == "P":
                    tool = int(value)
                elif letter == "E":
                    weights = [float(w) for w in value.split(":")]
                elif letter == "U":
                    weights = self.mixture_of_mixtures([float(u) for u in value.split(":")])
                else:
                    raise GcodeError("M567 takes P<tool> E<w0>:<w1>:... or U<u0>:..., not %s"
                                     % word)
            except ValueError as e:
                if isinstance(e, GcodeError):
                    raise
                raise GcodeError("malformed number in %s" % word)
        if tool is None or weights is None:
            raise GcodeError("M567 needs P<tool> and E<w0>:<w1>:... or U<u0>:<u1>:...")
        self.store(self._check_tool(tool), weights)

    # M168 <row>,<row>,...: the palette, Ovenbird's mixing matrix: m mixtures over the
    # drives, one row of drive weights w0:w1:... each, rows normalised. M168 alone:
    # back to the identity (mixture k = drive k), and report. Example: M168 1:0,0:1,1:1
    def m168(self, line):
        text = line.args_text.strip()
        if not text:
            self.palette = None
        else:
            rows = []
            for row in text.split(","):
                try:
                    weights = [float(w) for w in row.split(":")]
                except ValueError:
                    raise GcodeError("malformed palette row %r: want w0:w1:..." % row)
                shares = normalize(weights, self.drives)
                rows.append([w / sum(shares) for w in shares])
            self.palette = rows
        for k, row in enumerate(self._palette_rows()):
            self.reply("echo:palette %d: %s" % (k, ":".join("%.4f" % w for w in row)))

    def _palette_rows(self):
        if self.palette is not None:
            return self.palette
        return [[1.0 if i == k else 0.0 for i in range(self.drives)] for k in range(self.drives)]

    def mixture_of_mixtures(self, amounts):
        """Drive weights of u . P: amounts of the palette's mixtures."""
        rows = self._palette_rows()
        if len(amounts) > len(rows):
            raise GcodeError("%d amounts for a palette of %d mixtures" % (len(amounts), len(rows)))
        total = [0.0] * self.drives
        for u, row in zip(amounts, rows):
            if u < 0:
                raise GcodeError("mixture amounts must be >= 0, got %s" % u)
            for i in range(self.drives):
                total[i] += u * row[i]
        return total

    # M221 [S<percent>] [T<tool>]: the flow of a virtual tool (without T the active
    # one), as a percentage of its moves' E (OctoPrint's flow slider): the filament of
    # the whole mix, which its drives share as before. No S: report, as Marlin's
    # "E0 Flow: 100%". Example: M221 S95
    def m221(self, line):
        tool = self._check_tool(line.int("T", self.active))
        if not line.has("S"):
            self.reply("echo:E%d Flow: %d%%" % (tool, self.tool_flow_pct[tool]))
            return
        self.tool_flow_pct[tool] = line.int("S", lo=1, hi=999)
        if tool == self.active:
            self._activate(tool)

    # M900 [K<s>] [T<tool>]: the pressure advance of a virtual tool (without T the
    # active one), Marlin's LIN_ADVANCE K: the filament is pushed ahead by K times its
    # speed, for the whole mix, which its drives share as before (stepper.py's
    # follower); from the next move queued. 0 turns it off. Kept by M500, as Marlin's
    # EEPROM keeps it. No K: report, as Marlin's "Advance K=0.05". Example: M900 K0.08
    def m900(self, line):
        tool = self._check_tool(line.int("T", self.active))
        if not line.has("K"):
            self.reply("echo:Advance K=%.3f" % self.settings["tool_advance_k"][tool])
            return
        k = line.float("K")
        if not 0 <= k <= 10:
            raise GcodeError("M900 K%s out of range 0..10 (s)" % k)
        self.config.set("tool_advance_k_%d" % tool, k)
        if tool == self.active:
            self._activate(tool)

    # T<n>: select virtual tool n. Example: T2
    def t(self, line):
        tool = self._check_tool(line.number)
        if tool != self.active:
            self._activate(tool)


RAW_COMMANDS = (("M", 567), ("M", 168), ("M", 169))


def register(printer, mixing):
    printer.add_command("M", 163, mixing.m163)  # set a drive's weight: S<drive> P<weight>
    # store the weights as virtual tool S<tool> [P1 save]
    printer.add_command("M", 164, mixing.m164)
    printer.add_command("M", 165, mixing.m165)  # whole mix A B C D H I; R reports every tool
    printer.add_command("M", 567, mixing.m567)  # a tool's mix: P<tool> E<w0>:<w1>:...
    printer.add_command("M", 167, mixing.m167)  # filament used per drive; R clears
    printer.add_command("M", 168, mixing.m168)  # palette: mixtures over the drives, w0:w1,...
    printer.add_command("M", 166, mixing.m166)  # Z gradient A<z0> Z<z1> I<tool0> J<tool1> S T
    printer.add_command("M", 169, mixing.m169)  # gradient of stops along Z or E
    printer.add_command("T", -1, mixing.t)  # select virtual tool
    printer.add_command("M", 221, mixing.m221)  # flow percentage S of tool T
    printer.add_command("M", 900, mixing.m900)  # pressure advance K of tool T
