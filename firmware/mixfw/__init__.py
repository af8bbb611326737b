# mixstep firmware: one module per concern; assemble.py assembles them from the board's settings.
# Frozen into a MicroPython image, the package's path starts with this (inram.py).
FROZEN_PREFIX = ".frozen"
