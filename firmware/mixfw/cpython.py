# MicroPython's const, decorators and viper's casts for CPython, where host tools import
# the pure modules (see compat). The chips never import this.
import builtins


class _Micropython:
    @staticmethod
    def viper(f):
        return f

    native = viper

    @staticmethod
    def const(v):
        return v


micropython = _Micropython()
const = micropython.const


# Viper's pointer casts: on CPython the buffer itself indexes the same way.
def ptr32(buf):
    if isinstance(buf, builtins.int):  # an address int() gave: its buffer
        return _ADDRESSED[buf]
    # An array('f') is read as its bits, as viper reads it.
    if getattr(buf, "typecode", None) == "f":
        return memoryview(buf).cast("B").cast("I")
    return buf


ptr8 = ptr16 = ptr32

# Viper's int() of a pointer is its address, which ptr32() takes back (ramp.py's
# helpers take their array so): on CPython a key of the buffer's, a multiple of 4.
_ADDRESSED = {}


def int(x=0, *base):
    if base or isinstance(x, (builtins.int, float, str, bytes)):
        return builtins.int(x, *base)
    at = 4 * id(x)
    _ADDRESSED[at] = x
    return at


# The names MicroPython's compiler knows, for every module: as builtins.
for _name in ("micropython", "const", "ptr8", "ptr16", "ptr32"):
    setattr(builtins, _name, globals()[_name])
