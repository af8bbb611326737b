# Reports and settings: M114 (position), M92 (steps per mm), M115 (firmware).
from mixfw.gcode import GcodeError
from mixfw import stepper as st


class Reports:
    def __init__(self, printer, motion, planner, board_name):
        self.printer = printer
        self.motion = motion
        self.planner = planner
        self.board_name = board_name

    # M114: logical position and step counts, in Marlin's form.
    def m114(self, line):
        p = self.motion.pos_mm
        mem = self.planner.mem
        self.printer.reply("X:%.2f Y:%.2f Z:%.2f E:%.2f Count X:%d Y:%d Z:%d" % (
            p[0], p[1], p[2], p[3], mem[st.S_POS], mem[st.S_POS + 1], mem[st.S_POS + 2]))

    # M92 [X Y Z E]: steps per mm; E sets every mixing drive. Example: M92 E415
    def m92(self, line):
        planner = self.planner
        values = []
        for i, ch in enumerate("XYZE"):
            if line.has(ch):
                v = line.float(ch)
                if not 0 < v <= 100000:
                    raise GcodeError("steps per mm %s%s out of range (0, 100000]" % (ch, v))
                values.append((i, v))
        if not values:
            spm = planner.steps_per_mm
            self.printer.reply("echo:M92 X%.3f Y%.3f Z%.3f E%.3f" % tuple(spm))
            return
        planner.synchronize()
        for i, v in values:
            planner.steps_per_mm[i] = v
        planner.set_position_steps(self.motion.machine_steps())

    # M115: firmware name and capabilities.
    def m115(self, line):
        self.printer.reply("FIRMWARE_NAME:mixstep MACHINE_TYPE:%s EXTRUDER_COUNT:1"
                           % self.board_name)
        self.printer.reply("Cap:MIXING_EXTRUDER:1")


def register(printer, reports):
    printer.register("M114", reports.m114, "report position")
    printer.register("M92", reports.m92, "steps per mm")
    printer.register("M115", reports.m115, "firmware info")
