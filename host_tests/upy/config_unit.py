"""The configuration's test doubles for scripts on the unix port: Commands, a printer
that dispatches M-codes through the real parser and cmd_config, and Flash, a file
system that can lose power at any step; sweep(), a save interrupted at every step;
boot_each(), the boot of each of a run of files. For test_config.py's snippets
(run_unit) and its config_*.py scripts."""
import json

import board
from mixfw import cmd_config
from mixfw.config import Config
from mixfw.gcode import Parser


class Commands:
    def __init__(self, config):
        self.handlers = {}
        self.lines = []
        self.parser = Parser(cmd_config.RAW_COMMANDS)
        cmd_config.register(self, config)

    def add_command(self, letter, number, fn):
        self.handlers[letter + str(number)] = fn

    def reply(self, text):
        self.lines.append(text)

    def send(self, text):
        if text.startswith(";"):
            return  # a comment, which the printer's intake drops (M503's password line)
        b = text.encode()
        line = self.parser.parse(b, len(b))
        self.handlers["%s%d" % (line.letter, line.number)](line)


class PowerLoss(Exception):
    pass


class Flash:
    # Loses power before step number `budget`: each open-for-write, close, rename,
    # remove and each byte written is one step, and what reached flash stays there.
    # fat=True renames as MicroPython's FAT driver does: remove the target, then rename.
    def __init__(self, files=None, fat=False):
        self.files = dict(files or {})
        self.fat = fat
        self.budget = -1
        self.steps = 0

    def step(self, n=1):
        room = n if self.budget < 0 else min(n, self.budget - self.steps)
        self.steps += room
        return room

    def lose_power_unless(self, n=1):
        if self.step(n) < n:
            raise PowerLoss()

    def stat(self, path):
        if path not in self.files:
            raise OSError(2)
        return (0x8000, 0, 0, 0, 0, 0, len(self.files[path]), 0, 0, 0)

    def open(self, path, mode):
        if "w" in mode:
            self.lose_power_unless()
            self.files[path] = b""
            return Writer(self, path)
        if path not in self.files:
            raise OSError(2)
        return Reader(self.files[path])

    def rename(self, old, new):
        if self.fat and new in self.files:
            self.remove(new)
        self.lose_power_unless()
        self.files[new] = self.files.pop(old)

    def remove(self, path):
        self.lose_power_unless()
        del self.files[path]


class Writer:
    def __init__(self, fs, path):
        self.fs = fs
        self.path = path

    def write(self, data):
        room = self.fs.step(len(data))
        self.fs.files[self.path] += bytes(data[:room])
        if room < len(data):
            raise PowerLoss()
        return room

    def close(self):
        self.fs.lose_power_unless()


class Reader:
    def __init__(self, data):
        self.data = data

    def read(self):
        return self.data

    def close(self):
        pass


PATH = "/mixstep.cfg"


def boot_each(files):
    """For each file's bytes: whether a boot from it gives the defaults, and the warnings
    it printed; a line of JSON each."""
    defaults = Config(board.SETTINGS, PATH, Flash()).settings
    for data in files:
        warnings = []
        c = Config(board.SETTINGS, PATH, Flash({PATH: data}), warnings.append)
        c.boot()
        print(json.dumps((c.settings == defaults, warnings)))


def sweep(old_pairs, new_pairs, fat, start, every_byte=True):
    # every_byte=False: only around the file-system operations (open, first byte, last
    # bytes, close, remove, rename), where a stale .tmp can make a difference.
    old = Config(board.SETTINGS, PATH, Flash())
    old.update(old_pairs)
    new = Config(board.SETTINGS, PATH, Flash())
    new.update(new_pairs)
    files = {}
    if start == "no file":
        old = Config(board.SETTINGS, PATH, Flash())  # nothing saved: the defaults
    else:
        files[PATH] = old.text()
    if start == "stale partial tmp":
        files[PATH + ".tmp"] = new.text()[:100]
    if start == "stale complete tmp":
        files[PATH + ".tmp"] = Config(board.SETTINGS, PATH, Flash()).text()
    # A complete save, to count its steps.
    flash = Flash(files, fat)
    new.storage = flash
    new.save()
    total = flash.steps
    tried = 0
    got = {"old": 0, "new": 0}
    budgets = range(total + 1) if every_byte else sorted(set(
        b for b in (0, 1, 2, total - 3, total - 2, total - 1, total) if b >= 0))
    for budget in budgets:
        flash = Flash(files, fat)
        flash.budget = budget
        new.storage = flash
        try:
            new.save()
            assert budget == total
        except PowerLoss:
            pass
        after_loss = flash.files
        # The boot after the loss may itself lose power (it finishes an interrupted
        # FAT save by a rename): try that at each of its steps, then boot for good.
        boot_budget = 0
        while True:
            flash = Flash(after_loss, fat)
            flash.budget = boot_budget
            c = Config(board.SETTINGS, PATH, flash)
            try:
                c.boot()
                break
            except PowerLoss:
                boot_budget += 1
                flash.budget = -1
                c = Config(board.SETTINGS, PATH, flash)
                c.boot()
            tried += 1
            assert c.settings == new.settings or c.settings == old.settings
        tried += 1
        if c.settings == new.settings:
            got["new"] += 1
        elif c.settings == old.settings:
            got["old"] += 1
        else:
            raise AssertionError("power lost at step %d: neither old nor new" % budget)
        # The next save after the interrupted one completes and loads.
        flash.budget = -1
        c.update(new_pairs)
        c.update((("steps_per_mm_z", 123.0),))
        c.save()
        d = Config(board.SETTINGS, PATH, flash)
        d.boot()
        assert d.settings == c.settings, "save after one interrupted at step %d" % budget
    return {"save_steps": total, "file_bytes": len(new.text()), "tried": tried,
            "old": got["old"], "new": got["new"]}
