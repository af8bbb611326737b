# The firmware's code on the heap, in two parts, on the unix port with the simulated
# chip as in the simulation. Prints one JSON line.
#   compiled_bytes: the modules' sources compiled (bytecode, constants) and kept, none
#     of it run; the names they intern are not counted (see below). A board with the
#     firmware frozen keeps all of this in flash.
#   module_body_bytes: what running the module bodies makes: globals, function and
#     class objects, module-level tables. A frozen board still makes these in RAM
#     when it imports the firmware.
# Every module is imported once first, so a body's imports are only look-ups and the
# names are interned already; importing costs about the sum of the two plus the names.
#   micropython -X heapsize=2M heap_code.py MODULE ...   (e.g. main mixfw.gcode), with
#   MICROPYPATH as for sim_main.py
import sys

# board.py must be the board's from MICROPYPATH, as in sim_main.py: look here last.
sys.path.append(sys.path.pop(0))
import gc
import json
import simmachine
import simtime

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime


def heap_bytes():
    gc.collect()
    return gc.mem_alloc()


def main(names):
    for name in names:
        __import__(name)
    kept = []
    compiled = 0
    bodies = 0
    for name in names:
        path = sys.modules[name].__file__
        before = heap_bytes()
        with open(path) as f:
            code = compile(f.read(), path, "exec")
        compiled += heap_bytes() - before
        # Its own name keeps main.py from starting the printer.
        globals_ = {"__name__": name, "__file__": path}
        before = heap_bytes()
        exec(code, globals_)
        bodies += heap_bytes() - before
        kept.append((code, globals_))
    print(json.dumps({"compiled_bytes": compiled, "module_body_bytes": bodies,
                      "modules": len(kept)}))


main(sys.argv[1:])
