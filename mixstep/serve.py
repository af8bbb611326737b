"""`mixstep serve`: the simulated printer as a network or serial printer, for hosts
such as Pronterface/printcore and OctoPrint.

--tcp HOST:PORT  the firmware's own TCP console (several connections at once);
--pty            a pseudo-terminal, bridged to the firmware's serial console; the
                 device path is printed, and hosts open it like a USB printer.
--set KEY=VALUE  a board setting for this run, e.g. trace_records=60000 for a step
                 capture (M7300) longer than the default ring."""
import os
import selectors
import subprocess
import sys
import threading
import time
import tty

from mixstep import paths
from mixstep.simprinter import SIM_MAIN, set_args


def _command(tcp, realtime, stdio, edges=None, settings=None):
    cmd = [paths.micropython(), "-X", "heapsize=2M", str(SIM_MAIN),
           "--realtime", str(realtime)] + set_args(settings)
    if tcp:
        cmd += ["--tcp", tcp]
    if not stdio:
        cmd.append("--no-stdio")
    if edges:
        cmd += ["--edges", str(edges)]
    return cmd


def serve_tcp(address, realtime=1.0, announce=print, settings=None):
    proc = subprocess.Popen(_command(address, realtime, stdio=False, settings=settings),
                            stdin=subprocess.DEVNULL, env=paths.micropython_env())
    announce("mixstep: simulated printer on tcp %s" % address)
    return proc


class PtyBridge:
    """A pseudo-terminal whose far end is the firmware's stdio console."""

    def __init__(self, realtime=1.0, settings=None):
        self._lock = threading.Lock()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # a serial line: no echo, no line editing
        self.path = os.ttyname(self.slave)
        self.proc = subprocess.Popen(_command(None, realtime, stdio=True, settings=settings),
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     env=paths.micropython_env(), bufsize=0)

    def run(self):
        """Copy bytes both ways until the firmware exits."""
        sel = selectors.DefaultSelector()
        sel.register(self.master, selectors.EVENT_READ, "host")
        sel.register(self.proc.stdout, selectors.EVENT_READ, "firmware")
        try:
            while self.proc.poll() is None:
                for key, _ in sel.select(timeout=0.5):
                    if key.data == "host":
                        with self._lock:
                            if self.master is None:
                                return
                            try:
                                data = os.read(self.master, 4096)
                            except OSError:  # no host has the device open just now
                                data = None
                        if data is None:
                            time.sleep(0.05)
                            continue
                        if data:
                            self.proc.stdin.write(data)
                    else:
                        data = self.proc.stdout.read1(4096) if hasattr(
                            self.proc.stdout, "read1") else os.read(self.proc.stdout.fileno(), 4096)
                        if not data:
                            return
                        with self._lock:
                            if self.master is None:
                                return
                            os.write(self.master, data)
        finally:
            self.close()

    def close(self):
        """Idempotent: the bridge thread and its owner may both call it, and closing an
        fd number twice could close a file someone else has opened since."""
        with self._lock:
            if self.master is None:
                return
            if self.proc.poll() is None:
                self.proc.terminate()
                self.proc.wait()
            for fd in (self.master, self.slave):
                os.close(fd)
            self.master = self.slave = None


def main(tcp=None, pty=False, realtime=1.0, settings=None):
    """settings: board settings to override, {key: value text}."""
    if bool(tcp) == bool(pty):
        raise SystemExit("mixstep serve: give either --tcp HOST:PORT or --pty")
    if tcp:
        proc = serve_tcp(tcp, realtime, announce=lambda s: print(s, flush=True),
                         settings=settings)
        try:
            return proc.wait()
        except KeyboardInterrupt:
            proc.terminate()
            return 0
    bridge = PtyBridge(realtime, settings)
    print("mixstep: simulated printer on serial device %s" % bridge.path, flush=True)
    try:
        bridge.run()
    except KeyboardInterrupt:
        bridge.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
