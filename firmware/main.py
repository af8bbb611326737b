# Runs at boot, after boot.py turned the drivers off. MicroPython runs main.py only as
# source, compiling it on the chip, and the compiler's garbage would leave the heap in
# pieces too small for the step loop's arrays: the printer is assembled by a module
# compiled with mpy-cross.
from mixfw import assemble

if __name__ == "__main__" and not assemble.repl_boot():
    printer = assemble.start()
    # The code that built the printer is not needed again: off the heap, for printing.
    assemble.drop()
    del assemble
    from mixfw import safety
    safety.serve(printer)
