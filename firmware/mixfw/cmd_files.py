# Printing from flash, with Marlin's SD commands: M21 mount, M20 list, M23 select, M24
# start or resume, M25 pause, M26 rewind or set position, M32 select and start, M28/M29
# upload, M30 delete (M27's report is cmd_report's). File names are text, so these take raw arguments.
from mixfw.gcode import GcodeError

RAW_COMMANDS = (("M", 23), ("M", 28), ("M", 30), ("M", 32))


class FileCommands:
    def __init__(self, printer, files):
        self.printer = printer
        self.files = files

    # M21: mount the card. The files live on the board's flash, always there.
    def m21(self, line):
        self.printer.reply("echo:SD card ok")

    # M20: list the G-code files with their sizes.
    def m20(self, line):
        self.printer.reply("Begin file list")
        for name, size in self.files.listing():
            self.printer.reply("%s %d" % (name, size))
        self.printer.reply("End file list")

    # M23 <name>: select a file for printing. Example: M23 part.gcode
    def m23(self, line):
        job = self.files.select(line.args_text)
        self.printer.reply("File opened: %s Size: %d" % (job.name, job.size))
        self.printer.reply("File selected")

    # M24: start or resume printing the selected file.
    def m24(self, line):
        self.files.start()

    # M25: pause the file print; queued moves finish and the position is kept.
    def m25(self, line):
        self.files.pause()

    # M26 [S<byte>]: set the read position, or rewind without S. Example: M26 S0
    def m26(self, line):
        job = self.files.selected
        if job is None:
            raise GcodeError("no file selected (M23 <name>)")
        job.seek(line.int("S", 0, lo=0, hi=job.size))

    # M32 <name>: select a file and start printing it. Example: M32 part.gcode
    def m32(self, line):
        self.m23(line)
        self.files.start()

    # M28 <name>: write the following lines to a file until M29; they are kept in RAM
    # and written 4 KB at a time, each write after the queued moves have run (flash is
    # programmed with interrupts off). Refused while a file prints from flash: M25
    # pauses it. Example: M28 part.gcode
    def m28(self, line):
        self.files.begin_upload(line.args_text)
        self.printer.reply("Writing to file: %s" % line.args_text)

    # M29: write the rest of the upload and put the file in place, after the queued
    # moves have run. Example: M29
    def m29(self, line):
        self.files.end_upload()
        self.printer.reply("Done saving file.")

    # M524: stop printing the file from flash, as Marlin's; the moves already queued
    # run, the heaters stay as they are. Example: M524
    def m524(self, line):
        self.files.cancel()

    # M30 <name>: delete a file, after the queued moves have run; the file printing
    # from flash is refused (M25 pauses it). Example: M30 part.gcode
    def m30(self, line):
        self.files.delete(line.args_text)
        self.printer.reply("File deleted:%s" % line.args_text)


def register(printer, files):
    c = FileCommands(printer, files)
    for letter, number, fn in (
        ("M", 21, c.m21),  # mount the card (flash: always mounted)
        ("M", 20, c.m20),  # list files
        ("M", 23, c.m23),  # select a file
        ("M", 25, c.m25),  # pause the file print
        ("M", 26, c.m26),  # file position S<byte> (rewind without S)
        ("M", 28, c.m28),  # write lines to a file until M29
        ("M", 29, c.m29),  # end of upload
        ("M", 30, c.m30),  # delete a file
        ("M", 524, c.m524),  # stop the file print
    ):
        printer.add_command(letter, number, fn)
    printer.add_command("M", 24, c.m24, guarded=True)  # start or resume the file print
    printer.add_command("M", 32, c.m32, guarded=True)  # select a file and print it
    printer.on_halt.append(files.pause)
    return c
