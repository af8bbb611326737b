"""The simulated printer as a host sees it: a process that takes G-code lines and
answers them, here the firmware running on the MicroPython unix port."""
import json
import os
import subprocess

from mixstep import paths

SIM_MAIN = paths.BOARDS / "sim" / "sim_main.py"


def set_args(settings):
    """sim_main arguments that override board settings before the machine is built:
    {"pin_writer": "registers", "invert_dir": ("x",)} -> --set pin_writer=registers
    --set invert_dir=x, (a tuple keeps its trailing comma, even with one item)."""
    args = []
    for key, value in (settings or {}).items():
        if isinstance(value, (tuple, list)):
            value = ",".join(str(v) for v in value) + ","
        args += ["--set", "%s=%s" % (key, value)]
    return args


class SimPrinter:
    def __init__(self, edges_path=None, heap_lock=False, heap_size="2M", board="sim",
                 config_path=None, files_dir=None, settings=None, code_dir=None, jitter_us=0,
                 jitter_seed=1, console_log=None, clock_hz=None):
        """board: whose pin map and settings (the chip is simulated); settings: board
        settings to override, e.g. {"pin_writer": "registers"}; code_dir: a folder
        searched before the firmware's, e.g. with its modules compiled to .mpy;
        jitter_us: the step timer's callbacks run up to this late (pseudo-random from
        jitter_seed); console_log: write every console line in and out there, with
        the simulated time; clock_hz: the chip's system clock (machine.freq()), if not
        the one it boots with."""
        cmd = [paths.micropython(), "-X", "heapsize=" + heap_size, str(SIM_MAIN)]
        cmd += set_args(settings)
        if config_path:
            cmd += ["--config", str(config_path)]
        if files_dir:
            cmd += ["--files", str(files_dir)]
        if edges_path:
            cmd += ["--edges", str(edges_path)]
        if heap_lock:
            cmd.append("--heap-lock")
        if console_log:
            cmd += ["--console-log", str(console_log)]
        if clock_hz:
            cmd += ["--clock-hz", str(clock_hz)]
        if jitter_us:
            cmd += ["--jitter-us", str(jitter_us), "--jitter-seed", str(jitter_seed)]
        env = paths.micropython_env(board)
        if code_dir:
            env["MICROPYPATH"] = os.pathsep.join([str(code_dir), env["MICROPYPATH"]])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     env=env, bufsize=0)
        self.out = self.proc.stdout
        self.report = None
        banner = self._readline()
        if banner != "start":
            raise RuntimeError("firmware did not start: %r" % banner)
        self.boot_lines = []  # warnings the firmware printed at start

    def _readline(self):
        raw = self.out.readline()
        if not raw:
            code = self.proc.wait()
            raise RuntimeError("firmware exited (status %s) before answering" % code)
        return raw.decode("utf-8", "replace").rstrip("\r\n")

    def send(self, line):
        """Send one line (bytes as they are, or text as UTF-8); return the lines the
        firmware printed before its `ok`, and the `ok` line itself last."""
        if isinstance(line, str):
            line = line.encode()
        self.proc.stdin.write(line + b"\n")
        replies = []
        while True:
            text = self._readline()
            replies.append(text)
            if text == "ok" or text.startswith("ok "):
                return replies

    def finish(self):
        """Close the stream; the firmware drains its queue and reports."""
        self.proc.stdin.close()
        extra = []
        for raw in self.out:
            text = raw.decode("utf-8", "replace").rstrip("\r\n")
            if text.startswith("//sim "):
                self.report = json.loads(text[6:])
            else:
                extra.append(text)
        code = self.proc.wait()
        if code != 0 or self.report is None:
            raise RuntimeError("simulation failed (status %s): %s" % (code, extra))
        return self.report
