# Lets the pure modules (gcode, mixer) import on CPython too, so host tools reuse them
# instead of carrying a second copy. On MicroPython the real decorators are used.
try:
    import micropython
    const = micropython.const
    # Inside viper functions these are the compiler's casts; the names only have to
    # exist for the modules' imports.
    ptr32 = ptr8 = ptr16 = None
except ImportError:
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
        # An array('f') is read as its bits, as viper reads it.
        if getattr(buf, "typecode", None) == "f":
            return memoryview(buf).cast("B").cast("I")
        return buf

    ptr8 = ptr16 = ptr32
