"""Traces: the simulated chip's edge records -> VCD, and step counts from edges."""
import numpy as np
import vcd

from mixstep import paths


def read_edges(path):
    """(time, gpio, level) arrays from an edge file: the simulation's (time in us) or
    the emulated chip's (`mixstep emu`, time in ns)."""
    words = np.fromfile(path, dtype="<u8")
    return words >> 8, ((words >> 1) & 0x7F).astype(np.int64), (words & 1).astype(np.int8)


def signal_names(board="sim"):
    """gpio -> VCD signal name for every output of the board (STEP, DIR, ENABLE)."""
    pins = paths.load_board(board)["PINS"]
    return {gpio: name for name, gpio in pins.items()
            if name.endswith(("_step", "_dir", "_enable"))}


def write_vcd(edges_path, vcd_path, board="sim", timescale="1 us", date="mixstep simulation"):
    """timescale: the unit of the edge file's times."""
    times, gpios, levels = read_edges(edges_path)
    names = signal_names(board)
    order = sorted(names, key=lambda g: _name_order(names[g]))
    with open(vcd_path, "w") as f, vcd.VCDWriter(f, timescale=timescale, date=date,
                                                 version="mixstep") as w:
        first = {}
        for g in order:
            idx = np.nonzero(gpios == g)[0]
            first[g] = int(levels[idx[0]]) if len(idx) and times[idx[0]] == 0 else 0
        var = {g: w.register_var("mixstep", names[g], "wire", size=1, init=first[g]) for g in order}
        change = w.change
        for t, g, v in zip(times.tolist(), gpios.tolist(), levels.tolist()):
            if t == 0 or g not in var:
                continue
            change(var[g], t, v)


def _name_order(name):
    axis, kind = name.split("_")
    axes = ["x", "y", "z", "e0", "e1", "e2", "e3", "e4", "e5"]
    return (["step", "dir", "enable"].index(kind) // 2, axes.index(axis) if axis in axes else 99,
            kind)


def net_steps(edges_path, board="sim"):
    """Net steps per STEP signal, counted from rising edges and the DIR level then
    (DIR high is forward, low for the board's invert_dir motors)."""
    return net_steps_of(*read_edges(edges_path), board)


def net_steps_of(times, gpios, levels, board="sim"):
    """net_steps() of edges already read (read_edges' arrays, or a part of them from
    the start)."""
    pins = paths.load_board(board)["PINS"]
    result = {}
    for name in pins:
        if name.endswith("_step"):
            _, pos = positions_of(times, gpios, levels, board, name[:-5])
            result[name[:-5]] = int(pos[-1]) if len(pos) else 0
    return result


def positions_of(times, gpios, levels, board, axis):
    """The times of `axis`'s steps (rising STEP edges) and its position, in steps from
    where the trace starts, after each."""
    spec = paths.load_board(board)
    pins = spec["PINS"]
    gpio = pins[axis + "_step"]
    dir_gpio = pins[axis + "_dir"]
    sel = (gpios == gpio) | (gpios == dir_gpio)
    g = gpios[sel]
    lv = levels[sel]
    t = times[sel]
    is_dir = g == dir_gpio
    # DIR level in force at each record (records are in time order).
    dir_level = np.maximum.accumulate(np.where(is_dir, np.arange(len(g)), -1))
    level_at = np.where(dir_level >= 0, lv[np.maximum(dir_level, 0)], 0)
    rising = (~is_dir) & (lv == 1) & (t > 0)
    forward = 0 if axis in spec["SETTINGS"].get("invert_dir", ()) else 1
    return t[rising], np.cumsum(np.where(level_at[rising] == forward, 1, -1))
