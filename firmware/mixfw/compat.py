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
