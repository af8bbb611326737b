# Lets the pure modules (gcode, mixer) import on CPython too, so host tools reuse them
# instead of carrying a second copy. On MicroPython the real decorators are used; the
# CPython stand-ins are a module of their own (cpython), whose code the chips never load.
try:
    import micropython
    const = micropython.const
    # Inside viper functions these are the compiler's casts; the names only have to
    # exist for the modules' imports.
    ptr32 = ptr8 = ptr16 = None
    int = int
except ImportError:
    from mixfw.cpython import micropython, const, ptr32, ptr8, ptr16, int  # noqa: F401

# 2**30 - 1: the largest small int on the chips (31-bit, signed), so the mask of a
# counter that wraps at 2**30 and of a 30-bit limb. Viper folds only a module's own
# constants: a module that needs it keeps a copy, _MASK30, which
# host_tests/test_layouts.py checks against this one.
MASK30 = const(0x3FFFFFFF)
