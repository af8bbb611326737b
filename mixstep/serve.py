"""`mixstep serve`: the simulated printer as a network or serial printer, for hosts
such as Pronterface/printcore and OctoPrint.

--tcp HOST:PORT     the firmware's own TCP console (several connections at once); on
                    an address beyond this machine only with a password
                    (--set net_password=...), which a loopback address goes without
                    unless one is set;
--http HOST:PORT    the firmware's web page (the same password rule), its files
                    gzipped from firmware/web/ into the flash's web/ folder;
--pty               a pseudo-terminal, bridged to the firmware's serial console; the
                    device path is printed, and hosts open it like a USB printer.
--config FILE       the simulated flash's configuration file (M500/M501);
--files DIR         the simulated flash's G-code folder (M20-M32);
                    both default to out/printer/ under the current directory.
--set KEY=VALUE     a board setting for this run, e.g. trace_records=60000 for a step
                    capture (M7300) longer than the default ring.
--console-log FILE  every console line in and out, stamped with the simulated time.

The firmware runs in a child process. However serve ends (its host closing, Ctrl-C,
SIGTERM, or the parent dying), the child ends with it, so its TCP port is free again."""
import ctypes
import os
import selectors
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

from mixstep import paths, webfiles
from mixstep.simprinter import SIM_MAIN, set_args

# The simulated printer's flash, relative to where mixstep runs (as `make` does).
DEFAULT_FLASH = Path("out") / "printer"
_PR_SET_PDEATHSIG = 1


def default_flash(config=None, files=None):
    """config file and files folder, out/printer/ where not given; made if missing."""
    config = Path(config) if config else DEFAULT_FLASH / "mixstep.cfg"
    files = Path(files) if files else DEFAULT_FLASH / "files"
    config.parent.mkdir(parents=True, exist_ok=True)
    files.mkdir(parents=True, exist_ok=True)
    return config, files


def _command(tcp, realtime, stdio, edges=None, settings=None, config=None, files=None,
             console_log=None, http=None, web=None):
    cmd = [paths.micropython(), "-X", "heapsize=2M", str(SIM_MAIN),
           "--realtime", str(realtime)] + set_args(settings)
    if tcp:
        cmd += ["--tcp", tcp]
    if http:
        cmd += ["--http", http, "--web", str(web)]
    if not stdio:
        cmd.append("--no-stdio")
    if edges:
        cmd += ["--edges", str(edges)]
    for flag, value in (("--config", config), ("--files", files),
                        ("--console-log", console_log)):
        if value:
            cmd += [flag, str(value)]
    return cmd


def _die_with_parent():
    """In the child before exec: the kernel sends SIGTERM when serve dies, even by
    SIGKILL, so no firmware is left holding the port."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass  # not Linux: the handlers in main() still end it


def _start(cmd, **kw):
    # A session of its own: Ctrl-C in the terminal reaches serve only, which then
    # ends the firmware itself (no traceback from the child).
    return subprocess.Popen(cmd, env=paths.micropython_env(), start_new_session=True,
                            preexec_fn=_die_with_parent if sys.platform == "linux" else None,
                            **kw)


def stop(proc, timeout_s=5):
    """End the firmware process: SIGTERM, then SIGKILL if it lingers."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _check_free(address):
    """OSError (EADDRINUSE, or an address this machine doesn't have) before the
    firmware starts, so that nothing is announced that won't listen."""
    host, _, port = address.rpartition(":")
    try:
        port = int(port)
    except ValueError:
        raise ValueError("--tcp wants HOST:PORT, got %r" % address)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host or "0.0.0.0", port))
        except OSError as err:
            raise OSError(err.errno, "can't listen on %s: %s" % (address, err.strerror))


def serve_tcp(address, realtime=1.0, announce=print, settings=None, config=None, files=None,
              console_log=None, http=None):
    """address: the TCP console's HOST:PORT (None: none); http: the web page's."""
    web = None
    for where in (address, http):
        if where:
            _check_free(where)
    if http:
        web = Path(config or default_flash()[0]).parent / "web"
        webfiles.build(web)
    proc = _start(_command(address, realtime, stdio=False, settings=settings, config=config,
                           files=files, console_log=console_log, http=http, web=web),
                  stdin=subprocess.DEVNULL)
    if address:
        announce("mixstep: simulated printer on tcp %s" % address)
    if http:
        announce("mixstep: its web page on http://%s/" % http)
    return proc


class PtyBridge:
    """A pseudo-terminal whose far end is the firmware's stdio console."""

    def __init__(self, realtime=1.0, settings=None, config=None, files=None, console_log=None):
        self._lock = threading.Lock()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # a serial line: no echo, no line editing
        self.path = os.ttyname(self.slave)
        self.proc = _start(_command(None, realtime, stdio=True, settings=settings,
                                    config=config, files=files, console_log=console_log),
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0)

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
        except BrokenPipeError:
            return  # the firmware ended
        finally:
            self.close()

    def close(self):
        """Idempotent: the bridge thread and its owner may both call it, and closing an
        fd number twice could close a file someone else has opened since."""
        with self._lock:
            if self.master is None:
                return
            stop(self.proc)
            for fd in (self.master, self.slave):
                os.close(fd)
            self.master = self.slave = None


class _Terminated(Exception):
    pass


def _sources(config, files, settings):
    """Where the settings come from, in their order: the board's, the saved file, --set."""
    return "mixstep: the board's settings, then configuration %s, then --set %s; files in %s" % (
        config, " ".join("%s=%s" % (k, "(not shown)" if k == "net_password" else v)
                         for k, v in (settings or {}).items()) or "(none)", files)


def _on_sigterm(signum, frame):
    raise _Terminated()


def main(tcp=None, pty=False, realtime=1.0, settings=None, config=None, files=None,
         console_log=None, http=None):
    """settings: board settings to override, {key: value text}. Returns the exit
    status: 0 when stopped by Ctrl-C or SIGTERM, else the firmware's."""
    if bool(tcp or http) == bool(pty):
        raise SystemExit("mixstep serve: give --tcp HOST:PORT and/or --http HOST:PORT, "
                         "or --pty")
    config, files = default_flash(config, files)
    flash = dict(config=config, files=files, console_log=console_log)
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main_thread else None
    proc = bridge = None
    try:
        if tcp or http:
            proc = serve_tcp(tcp, realtime, announce=lambda s: print(s, flush=True),
                             settings=settings, http=http, **flash)
            print(_sources(config, files, settings), flush=True)
            return proc.wait()
        bridge = PtyBridge(realtime, settings, **flash)
        print("mixstep: simulated printer on serial device %s" % bridge.path, flush=True)
        print(_sources(config, files, settings), flush=True)
        bridge.run()
        return 0
    except (KeyboardInterrupt, _Terminated):
        print("mixstep: stopped", flush=True)
        return 0
    finally:
        if bridge is not None:
            bridge.close()
        if proc is not None:
            stop(proc)
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
