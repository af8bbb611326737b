# mixstep firmware: one module per concern; assemble.py assembles them from the board's settings.
# Frozen into a MicroPython image, the package's path starts with this (inram.py).
FROZEN_PREFIX = ".frozen"

# On CPython (host tools reuse the pure modules) compat makes MicroPython's const,
# decorators and viper casts builtins; MicroPython's compiler needs no names for them.
try:
    import micropython  # noqa: F401
except ImportError:
    from mixfw import compat  # noqa: F401
