# The step path's code in RAM, in every deployment.
#
# Frozen into a MicroPython image, a module's code stays in the chip's flash, which the
# CPU reads through a small cache (16 KB on the RP2040, in 8-byte lines): a miss stalls
# it for tens of cycles, printing from a file and every flash write (M500, an upload)
# evict or flush that cache, and the step loop's viper code alone is several KB. The
# step loop's timing is measured with its code in RAM, so in a frozen image the step
# path's modules also live as .mpy files in RAM_DIR on the board's filesystem, from
# which MicroPython loads their machine code into the heap (`mixstep deploy --frozen`
# puts them there). Deployed as .mpy files (`mixstep deploy`), every module loads into
# RAM anyway, and the firmware does not import this module.
import mixfw

# What the interrupts run, in import order: the step loop (stepper; mixer's pick and
# ramp's schedule, which it calls), and for step_backend pio_dma the DMA refill
# (piodma) with what it imports that is not loaded before (pio).
STEP_LOOP = ("ramp", "mixer", "stepper")
DMA_FEED = ("pio", "piodma")
STEP_PATH = STEP_LOOP + DMA_FEED
RAM_DIR = "/mixfw_ram"


def load(settings, package=mixfw):
    """In a frozen image (mixfw.FROZEN_PREFIX), import the step path's modules for
    these settings from RAM_DIR, before anything else imports them."""
    names = STEP_PATH if settings.get("step_backend") == "pio_dma" else STEP_LOOP
    import sys
    # ramp takes viper's int() from compat, which the interrupts don't run: the image's.
    __import__("mixfw.compat")
    here = package.__path__
    ram_dir = RAM_DIR
    package.__path__ = ram_dir
    try:
        for name in names:
            full = "mixfw." + name
            if full in sys.modules:
                continue
            try:
                __import__(full)
            except ImportError as e:
                raise ImportError(
                    "this MicroPython image has mixstep frozen in, but %s is not in %s "
                    "on the board's flash, so the step loop would run from flash: "
                    "run `mixstep deploy --frozen` for this board (%s)" % (full, ram_dir, e))
    finally:
        package.__path__ = here
