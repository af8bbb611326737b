# Reports and messages: M114 (position), M115 (firmware and capabilities), M117
# (message), M118 (echo to the host), M122 (diagnostics), M73 (the slicer's progress)
# and M27 (progress). M117 and M118 take free text.
import gc
from mixfw import stepper as st
from mixfw.gcode import GcodeError

# The text after these is the argument, whatever letters it holds.
RAW_COMMANDS = (("M", 117), ("M", 118))

# What hosts may rely on, in Marlin's M115 form. EEPROM and SDCARD depend on the
# printer (Reports): a simulation without storage says 0. HOST_ACTION_COMMANDS is
# left out: OctoPrint reads ":0" as "supported but disabled" and warns the user to
# turn on what this firmware doesn't have. Whole lines: a name on its own would be
# interned at load, and the chip holds interned names for good.
CAPABILITIES = (
    "Cap:SERIAL_XON_XOFF:0", "Cap:VOLUMETRIC:0", "Cap:AUTOREPORT_TEMP:1",
    "Cap:PROGRESS:1", "Cap:PRINT_JOB:1", "Cap:AUTOLEVEL:0", "Cap:Z_PROBE:0",
    "Cap:LEVELING_DATA:0", "Cap:BUILD_PERCENT:0", "Cap:SOFTWARE_POWER:0",
    "Cap:TOGGLE_LIGHTS:0", "Cap:CASE_LIGHT_BRIGHTNESS:0", "Cap:EMERGENCY_PARSER:1",
    "Cap:PROMPT_SUPPORT:1", "Cap:AUTOREPORT_SD_STATUS:0", "Cap:THERMAL_PROTECTION:1",
    "Cap:MIXING_EXTRUDER:1",
)


def m118_words(text):
    """M118's leading flags and its message: 'E1 A1 layer 3' -> ('E', 'A'), None
    or the port number, 'layer 3'. As Marlin: flags are A, E or P and one digit,
    each followed by a blank or the end."""
    flags = []
    port = None
    while len(text) >= 2 and text[0] in "AaEePp" and text[1] in "0123456789" and (
            len(text) == 2 or text[2] in " \t"):
        letter = text[0].upper()
        if letter == "P":
            port = int(text[1])
        elif text[1] != "0":
            flags.append(letter)
        text = text[2:].lstrip()
    return flags, port, text


class Reports:
    def __init__(self, printer, motion, planner, board_name, storage=True, files=True):
        """storage: M500 can save the configuration; files: M20-M32 can print from
        flash. M115 promises only what is there."""
        self.printer = printer
        self.motion = motion
        self.planner = planner
        self.board_name = board_name
        self.capabilities = CAPABILITIES + ("Cap:EEPROM:%d" % storage, "Cap:SDCARD:%d" % files)
        self.message = ""  # M117's text, for a display or a status report
        self.files = None  # the Files that M23-M32 print from flash, if any
        # M73's: percent done and minutes left, in normal and silent mode, and minutes
        # to the next colour change (C, D); None until given.
        self.progress = [None] * 6

    # M114: logical position and step counts, in Marlin's form.
    def m114(self, line):
        p = self.motion.pos_mm()
        mem = self.planner.mem
        self.printer.reply("X:%.2f Y:%.2f Z:%.2f E:%.2f Count X:%d Y:%d Z:%d" % (
            p[0], p[1], p[2], p[3], mem[st.S_POS], mem[st.S_POS + 1], mem[st.S_POS + 2]))

    # M115: firmware name and capabilities.
    def m115(self, line):
        self.printer.reply("FIRMWARE_NAME:mixstep 0.1 (MicroPython) PROTOCOL_VERSION:1.0 "
                           "MACHINE_TYPE:%s EXTRUDER_COUNT:1" % self.board_name)
        for cap in self.capabilities:
            self.printer.reply(cap)
        for text in self.printer.warnings:  # hosts ask M115 when they connect
            self.printer.reply(text)

    # M122: diagnostics, as RepRapFirmware's: the planner's underruns (the step loop
    # ran dry between two moves with no wait between them) and the free heap, as it is
    # and after a full collection (what the firmware really holds); with step_backend
    # pio_dma also the DMA refills that came late (the pins stalled). Example: M122
    def m122(self, line):
        free = gc.mem_free()
        gc.collect()
        mem = self.planner.mem
        late = ""
        if mem[st.S_PIO] == 2:
            late = " late_refills:%d dma_refills:%d" % (mem[st.R_LATE], mem[st.R_FIRED])
        self.printer.reply("echo:underruns:%d mem_free:%d mem_free_collected:%d%s" % (
            self.planner.underruns, free, gc.mem_free(), late))

    # M117 <text>: the status message, kept for a display or a report; M117 alone
    # clears it. Example: M117 Printing...
    def m117(self, line):
        self.message = line.args_text

    # M73 [P<percent>] [R<minutes>] [Q<percent>] [S<minutes>] [C<minutes>] [D<minutes>]:
    # the progress the slicer worked out (PrusaSlicer's remaining_times): done and time
    # left, Q and S in silent mode, C and D the time to the next colour change. M27
    # and a status report show it. Example: M73 P40 R12
    def m73(self, line):
        got = []  # all checked before any is kept
        for i, letter in enumerate("PRQSCD"):
            if line.has(letter):
                v = line.float(letter, -1.0)
                top = 100.0 if letter in "PQ" else 1e6
                if not 0 <= v <= top:
                    raise GcodeError("M73 %s%s out of range 0..%g" % (letter, v, top))
                got.append((i, v))
        for i, v in got:
            self.progress[i] = v

    def status(self):
        """The progress and message, as a display would show them: lines for a host."""
        p = self.progress
        out = []
        for mode, k in (("NORMAL", 0), ("SILENT", 2)):
            if p[k] is not None or p[k + 1] is not None:
                # Prusa's firmware words it so, and hosts' plugins read it.
                text = "%s MODE: Percent done: %d; print time remaining in mins: %d" % (
                    mode, -1 if p[k] is None else p[k], -1 if p[k + 1] is None else p[k + 1])
                if p[4 + k // 2] is not None:
                    text += "; Change in mins: %d" % p[4 + k // 2]
                out.append(text)
        if self.message:
            out.append("echo:status: " + self.message)
        return out

    # M27: the file printing from flash (bytes read of its size, paused or not), then
    # the progress (M73) and the message (M117).
    def m27(self, line):
        job = self.files.selected if self.files else None
        if job is None:
            self.printer.reply("Not SD printing")
        else:
            self.printer.reply("SD printing byte %d/%d" % (job.pos(), job.size))
        for text in self.status():
            self.printer.reply(text)

    # M118 [A1] [E1] [P<port>] <text>: send the text to the host, after "echo:" with
    # E1 and "//" (an action command) with A1; P0 to every host, otherwise to the one
    # that sent it. Example: M118 E1 layer 3
    def m118(self, line):
        flags, port, text = m118_words(line.args_text)
        if "A" in flags:
            text = "//" + text
        if "E" in flags:
            text = "echo:" + text
        if port == 0:
            self.printer.broadcast(text)
        else:
            self.printer.reply(text)


def register(printer, reports):
    printer.add_command("M", 114, reports.m114)  # report position
    printer.add_command("M", 115, reports.m115)  # firmware info
    printer.add_command("M", 122, reports.m122)  # diagnostics: underruns, free heap
    printer.add_command("M", 117, reports.m117)  # status message: M117 <text>
    # send text to the host: M118 [A1] [E1] [Pn] <text>
    printer.add_command("M", 118, reports.m118)
    printer.add_command("M", 73, reports.m73)  # progress P R (Q S, C D) from the slicer
    printer.add_command("M", 27, reports.m27)  # progress: file, M73, message
