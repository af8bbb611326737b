"""OctoPrint as a host client of the simulated printer, driven through its REST API.

OctoPrint (pinned, `make hosts` installs it into .venv-hosts/) runs headless on
127.0.0.1 with a base directory of its own: a config.yaml that skips the first-run
wizard, logs the serial traffic (logs/serial.log) and lists the pseudo-terminals as
serial ports; an admin user made with `octoprint user add`, whose API key the tests
set in users.yaml (the user API key OctoPrint's settings page would generate); and a
printer profile with three extruders sharing one nozzle, so that T1 and T2 are sent.

The simulated printer is `mixstep serve --pty`, started as a process of its own; the
first line it prints names the serial device."""
import http.client
import json
import os
import re
import secrets
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

from mixstep import paths
from net import free_port

HOSTS_VENV = paths.ROOT / ".venv-hosts"
OCTOPRINT = HOSTS_VENV / "bin" / "octoprint"
OCTOPRINT_VERSION = "1.11.8"
USER = "mixstep"
PROFILE = "mixstep3"

CONFIG = """\
server:
  firstRun: false
  onlineCheck:
    enabled: false
  pythonEolCheck:
    enabled: false
serial:
  log: true
  additionalPorts:
  - /dev/pts/*
  autoconnect: false
printerProfiles:
  default: {profile}
plugins:
  _disabled:
  - announcements
  - discovery
  - errortracking
  - health_check
  - pluginmanager
  - softwareupdate
  - tracking
"""

# Three extruders on one nozzle and one heater; no heated bed (the simulated printer
# has none). Coordinates as the slicer's: a 200 x 200 mm bed, origin at the corner.
PROFILE_YAML = """\
id: {profile}
name: mixstep simulated printer
model: mixstep (MicroPython) 3-in-1-out
color: default
heatedBed: false
heatedChamber: false
volume:
  width: 200
  depth: 200
  height: 200
  formFactor: rectangular
  origin: lowerleft
  custom_box: false
extruder:
  count: 3
  offsets:
  - [0.0, 0.0]
  - [0.0, 0.0]
  - [0.0, 0.0]
  nozzleDiameter: 0.4
  sharedNozzle: true
  defaultExtrusionLength: 5
axes:
  x: {{speed: 6000, inverted: false}}
  y: {{speed: 6000, inverted: false}}
  z: {{speed: 200, inverted: false}}
  e: {{speed: 300, inverted: false}}
"""


def mixstep_command():
    local = Path(sys.executable).parent / "mixstep"
    return str(local) if local.exists() else "mixstep"


def serve_supports(option):
    """Whether `mixstep serve` knows a command-line option (e.g. --console-log)."""
    out = subprocess.run([mixstep_command(), "serve", "--help"], capture_output=True,
                         text=True, timeout=60).stdout
    return option in out


def _stop(proc, first_signal, timeout_s=20):
    """Stop a process started in a session of its own: a signal it handles, then, if it
    is still there, SIGKILL to its process group (its own children)."""
    if proc.poll() is None:
        proc.send_signal(first_signal)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


class SimPrinter:
    """`mixstep serve --pty`: the simulated printer on a pseudo-terminal."""

    def __init__(self, realtime=0, console_log=None, stderr_path=None):
        cmd = [mixstep_command(), "serve", "--pty", "--realtime", str(realtime)]
        if console_log is not None:
            cmd += ["--console-log", str(console_log)]
        self.console_log = console_log
        self._stderr = open(stderr_path, "wb") if stderr_path else subprocess.DEVNULL
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._stderr,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        first = self.proc.stdout.readline().decode(errors="replace").strip()
        m = re.match(r"mixstep: simulated printer on serial device (\S+)$", first)
        if not m:
            self.stop()
            raise AssertionError("mixstep serve --pty did not name its device: %r" % first)
        self.path = m.group(1)
        # Keep reading, so that nothing it prints can ever block it.
        threading.Thread(target=self.proc.stdout.read, daemon=True).start()

    def stop(self):
        # SIGINT: `mixstep serve` closes the bridge and ends the firmware process.
        _stop(self.proc, signal.SIGINT)
        if self._stderr is not subprocess.DEVNULL:
            self._stderr.close()


class ApiError(AssertionError):
    pass


class OctoPrint:
    """One OctoPrint server with a base directory of its own, and its REST API."""

    def __init__(self, basedir):
        self.basedir = Path(basedir)
        self.basedir.mkdir(parents=True, exist_ok=True)
        (self.basedir / "config.yaml").write_text(CONFIG.format(profile=PROFILE))
        profiles = self.basedir / "printerProfiles"
        profiles.mkdir(exist_ok=True)
        (profiles / (PROFILE + ".profile")).write_text(PROFILE_YAML.format(profile=PROFILE))
        subprocess.run([str(OCTOPRINT), "--basedir", str(self.basedir), "user", "add", USER,
                        "--password", secrets.token_hex(12), "--admin"],
                       check=True, capture_output=True, timeout=120)
        self.apikey = secrets.token_hex(16).upper()
        users = self.basedir / "users.yaml"
        text = users.read_text()
        assert text.count("apikey: null") == 1, text
        users.write_text(text.replace("apikey: null", "apikey: " + self.apikey))
        self.port = free_port()
        self.url = "http://127.0.0.1:%d" % self.port
        self.logs = self.basedir / "logs"
        self._out = open(self.basedir / "server.out", "wb")
        cmd = [str(OCTOPRINT), "serve", "--basedir", str(self.basedir),
               "--host", "127.0.0.1", "--port", str(self.port)]
        if os.geteuid() == 0:  # CI containers run as root; OctoPrint refuses without this
            cmd.append("--iknowwhatimdoing")
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL, stdout=self._out, stderr=subprocess.STDOUT,
            start_new_session=True)
        self.started_s = self._wait_until_up()

    def _wait_until_up(self, timeout_s=120):
        t0 = time.time()
        while True:
            if self.proc.poll() is not None:
                raise AssertionError("OctoPrint exited (status %s):\n%s" % (
                    self.proc.returncode, (self.basedir / "server.out").read_text()[-3000:]))
            try:
                version = self.get("/api/version")
                assert version["server"] == OCTOPRINT_VERSION, version
                return time.time() - t0
            except (OSError, ApiError, http.client.HTTPException):
                # refused, or OctoPrint's intermediary server while it starts up
                assert time.time() - t0 < timeout_s, "OctoPrint did not answer in %d s" % timeout_s
                time.sleep(0.5)

    # -- REST API

    def request(self, method, path, body=None, content_type=None, timeout_s=30):
        headers = {"X-Api-Key": self.apikey}
        if body is not None and content_type is None:
            body = json.dumps(body).encode()
            content_type = "application/json"
        if content_type:
            headers["Content-Type"] = content_type
        req = urllib.request.Request(self.url + path, data=body, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req, timeout=timeout_s) as r:
                data = r.read()
        except urllib.error.HTTPError as e:
            raise ApiError("%s %s: HTTP %d %s" % (method, path, e.code, e.read()[:500]))
        return json.loads(data) if data.strip() else None

    def get(self, path):
        return self.request("GET", path)

    def post(self, path, body):
        return self.request("POST", path, body)

    def connect(self, port, timeout_s=60):
        self.post("/api/connection", {"command": "connect", "port": port, "baudrate": 115200,
                                      "printerProfile": PROFILE, "autoconnect": False})
        deadline = time.time() + timeout_s
        while True:
            current = self.get("/api/connection")["current"]
            if current["state"] == "Operational":
                return current
            assert "Error" not in current["state"], current
            assert time.time() < deadline, "not operational after %d s: %s" % (timeout_s, current)
            time.sleep(0.2)

    def disconnect(self):
        self.post("/api/connection", {"command": "disconnect"})

    def upload_and_print(self, path, name=None):
        """POST /api/files/local with select and print: the job starts at once."""
        name = name or Path(path).name
        boundary = uuid.uuid4().hex
        parts = []
        for field, value in (("select", "true"), ("print", "true")):
            parts.append(('--%s\r\nContent-Disposition: form-data; name="%s"\r\n\r\n%s\r\n'
                          % (boundary, field, value)).encode())
        parts.append(('--%s\r\nContent-Disposition: form-data; name="file"; filename="%s"\r\n'
                      'Content-Type: application/octet-stream\r\n\r\n' % (boundary, name)).encode()
                     + Path(path).read_bytes() + b"\r\n")
        parts.append(("--%s--\r\n" % boundary).encode())
        return self.request("POST", "/api/files/local", b"".join(parts),
                            "multipart/form-data; boundary=" + boundary, timeout_s=60)

    def command(self, *commands):
        self.post("/api/printer/command", {"commands": list(commands)})

    def state(self):
        return self.get("/api/connection")["current"]["state"]

    def stop(self):
        _stop(self.proc, signal.SIGTERM, timeout_s=30)
        self._out.close()

    # -- logs

    def log_text(self, name):
        path = self.logs / name
        return path.read_text(errors="replace") if path.exists() else ""


class Poller:
    """Polls GET /api/job and /api/printer in a thread, keeping every answer with its
    wall time: the states a job went through and the temperatures OctoPrint showed."""

    def __init__(self, octoprint, period_s=0.1):
        self.octoprint = octoprint
        self.period_s = period_s
        self.samples = []  # (wall s, job state, tool0 actual, tool0 target)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            try:
                job = self.octoprint.get("/api/job")
                try:
                    printer = self.octoprint.get("/api/printer?exclude=sd")
                    tool0 = printer.get("temperature", {}).get("tool0") or {}
                except ApiError:  # 409 while not operational
                    tool0 = {}
                self.samples.append((time.time(), job.get("state"),
                                     tool0.get("actual"), tool0.get("target")))
            except (OSError, ApiError, ValueError):
                pass
            self._stop.wait(self.period_s)

    def stop(self):
        self._stop.set()
        self._thread.join()


def read_console_log(path):
    """The simulated printer's console log: [(sim_us, '<' or '>', line)]."""
    entries = []
    for raw in Path(path).read_text(errors="replace").splitlines():
        m = re.match(r"(\d+) ([<>]) ?(.*)$", raw)
        if m:
            entries.append((int(m.group(1)), m.group(2), m.group(3)))
    return entries
