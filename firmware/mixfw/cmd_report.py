# Reports: M114 (position), M115 (firmware and capabilities).
from mixfw import stepper as st


# What hosts may rely on, in Marlin's M115 form.
CAPABILITIES = (
    ("SERIAL_XON_XOFF", 0), ("EEPROM", 1), ("VOLUMETRIC", 0), ("AUTOREPORT_TEMP", 0),
    ("PROGRESS", 0), ("PRINT_JOB", 1), ("AUTOLEVEL", 0), ("Z_PROBE", 0),
    ("LEVELING_DATA", 0), ("BUILD_PERCENT", 0), ("SOFTWARE_POWER", 0),
    ("TOGGLE_LIGHTS", 0), ("CASE_LIGHT_BRIGHTNESS", 0), ("EMERGENCY_PARSER", 1),
    ("HOST_ACTION_COMMANDS", 0), ("PROMPT_SUPPORT", 0), ("SDCARD", 1), ("AUTOREPORT_SD_STATUS", 0),
    ("THERMAL_PROTECTION", 1), ("MIXING_EXTRUDER", 1),
)


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

    # M115: firmware name and capabilities.
    def m115(self, line):
        self.printer.reply("FIRMWARE_NAME:mixstep 0.1 (MicroPython) PROTOCOL_VERSION:1.0 "
                           "MACHINE_TYPE:%s EXTRUDER_COUNT:1" % self.board_name)
        for cap in CAPABILITIES:
            self.printer.reply("Cap:%s:%d" % cap)


def register(printer, reports):
    printer.register("M114", reports.m114, "report position")
    printer.register("M115", reports.m115, "firmware info")
