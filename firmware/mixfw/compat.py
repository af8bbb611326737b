# The chips' small-int limit, and viper's int() of a pointer for CPython.
#
# MicroPython's compiler knows const(), the @micropython.viper/native decorators and
# viper's casts (ptr8/ptr16/ptr32) without any import, so the firmware's modules import
# none of them and keep no globals for them (each would cost RAM on the chips). On
# CPython, where host tools import the pure modules, importing cpython.py makes them
# builtins; the package's __init__ imports this module there first.
#
# Except where a module needs room in its globals: MicroPython's is an open-addressing
# hash table that grows only when it is full, and in a table nearly full a lookup
# walks most of it. lookahead's and ramp's viper code looks its helpers up by name
# on every line and every block, so those modules import names from here that they
# don't use, which make their tables grow to the next size.
try:
    import micropython  # noqa: F401
    int = int
except ImportError:
    from mixfw.cpython import int, micropython  # noqa: F401

# 2**30 - 1: the largest small int on the chips (31-bit, signed), so the mask of a
# counter that wraps at 2**30 and of a 30-bit limb. Viper folds only a module's own
# constants: a module that needs it keeps a copy, _MASK30, which
# host_tests/test_layouts.py checks against this one.
MASK30 = const(0x3FFFFFFF)
