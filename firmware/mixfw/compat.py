# The chips' small-int limit, and viper's int() of a pointer for CPython.
#
# MicroPython's compiler knows const(), the @micropython.viper/native decorators and
# viper's casts (ptr8/ptr16/ptr32) without any import, so the firmware's modules import
# none of them and keep no globals for them (each would cost RAM on the chips). On
# CPython, where host tools import the pure modules, the package's __init__ gives them
# as builtins (cpython.py).
try:
    import micropython  # noqa: F401
    int = int
except ImportError:
    from mixfw.cpython import int  # noqa: F401

# 2**30 - 1: the largest small int on the chips (31-bit, signed), so the mask of a
# counter that wraps at 2**30 and of a 30-bit limb. Viper folds only a module's own
# constants: a module that needs it keeps a copy, _MASK30, which
# host_tests/test_layouts.py checks against this one.
MASK30 = const(0x3FFFFFFF)
