# Lets the pure modules (gcode, mixer) import on CPython too, so host tools reuse them
# instead of carrying a second copy. On MicroPython the real decorators are used.
try:
    import micropython
    const = micropython.const
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

# Viper pointer annotations are names only CPython evaluates.
ptr32 = ptr8 = ptr16 = None
