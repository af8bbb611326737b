# The web page's server: the page's files (gzipped on the flash), and a small JSON API
# over the printer the consoles see. Plain HTTP/1.0-style, one request a connection,
# read and answered a piece a turn of the main loop, so nothing here waits on the
# network; the step path never does.
#
# A page that has logged in (the password of the network console, netconsole.Gate,
# whose wait after a wrong one it shares) holds a session: a cookie and a channel of
# the printer of its own, as a host's, so its G-code runs and is answered as any
# host's. Limits, as the network console's: _MOST_CONNECTIONS at once (more turned
# away with 503), a request's head within _HEAD_BYTES and _HEAD_MS, a body sent at
# a byte a second or never given up at _BODY_MS of silence, _MOST_SESSIONS pages
# logged in (the oldest idle one makes room), G-code posts within _GCODE_BYTES.
# board_listeners sets up a board's network console and page: the one place that
# loads this module (and netconsole's), only on a board with a network.
import json
import os
import time

from mixfw.colours import drive_rgb, mix_rgb
from mixfw.netconsole import (Gate, TcpListener, is_loopback, listening_socket, turn_away,
                              _EAGAIN)
from mixfw.planner import waiting_blocks

_MOST_CONNECTIONS = const(4)
_HEAD_BYTES = const(1024)
_HEAD_MS = const(10000)
_BODY_MS = const(10000)
_MOST_SESSIONS = const(3)
_GCODE_BYTES = const(512)
_INBOX_BYTES = const(1024)
_OUTBOX_LINES = const(100)
_PIECE_BYTES = const(1024)  # read or sent a turn, per connection
_COOKIE = const("mixstep_session")
_TYPES = {"html": "text/html; charset=utf-8", "js": "application/javascript",
          "css": "text/css", "png": "image/png", "svg": "image/svg+xml"}
_REASONS = {200: "OK", 201: "Created", 400: "Bad Request", 401: "Unauthorized",
            403: "Forbidden", 404: "Not Found", 405: "Method Not Allowed",
            409: "Conflict", 411: "Length Required", 413: "Payload Too Large",
            429: "Too Many Requests", 431: "Request Header Fields Too Large",
            500: "Internal Server Error",
            503: "Service Unavailable", 507: "Insufficient Storage"}


class HttpError(Exception):
    def __init__(self, status, text):
        self.status = status
        self.text = text


class PageConsole:
    """A logged-in page's channel of the printer: its G-code in, the printer's lines
    out, kept until the page asks for them (the last _OUTBOX_LINES)."""

    def __init__(self, token):
        self.token = token
        self.inbox = b""
        self.outbox = []
        self.partial = ""
        self.closed = False
        self.seen_ms = time.ticks_ms()

    def readinto(self, mv, block=False):
        if self.closed:
            return -1
        n = min(len(mv), len(self.inbox))
        if n:
            mv[:n] = self.inbox[:n]
            self.inbox = self.inbox[n:]
        return n

    def write(self, text):
        if isinstance(text, bytes):
            text = text.decode()
        lines = (self.partial + text).split("\n")
        self.partial = lines.pop()
        self.outbox.extend(lines)
        if len(self.outbox) > _OUTBOX_LINES:
            del self.outbox[:len(self.outbox) - _OUTBOX_LINES]


class _Request:
    def __init__(self, sock, now_ms):
        self.sock = sock
        self.since_ms = now_ms
        self.heard_ms = now_ms
        self.head = bytearray()
        self.method = self.path = None
        self.length = -1
        self.cookie = None
        self.body = bytearray()
        self.upload = None  # the file name, while its body streams to flash
        self.got = 0  # body bytes read
        self.out = None  # the response's bytes not yet sent
        self.out_file = None  # a file to send after them
        self.new_cookie = None  # a session opened by this request


def _unquote(path):
    """A URL's path as text: %XX escapes decoded (a browser sends a file name's spaces
    and accents so), the bytes read as UTF-8."""
    if "%" not in path:
        return path
    raw = path.encode()
    out = bytearray()
    i = 0
    while i < len(raw):
        if raw[i] == 37 and i + 2 < len(raw):  # "%"
            try:
                out.append(int(raw[i + 1:i + 3], 16))
                i += 3
                continue
            except ValueError:
                pass
        out.append(raw[i])
        i += 1
    try:
        return out.decode()
    except UnicodeError:
        raise HttpError(400, "the path is not UTF-8")


def _flash_error(e, files):
    """The answer to a files.FileError of an upload or a deletion (M28's words, less
    its M29)."""
    text = str(e).replace("; M29 ends the upload", "")
    why = files.upload_failed  # str(OSError(ENOSPC)) on a port without errno's names, or with
    if why in ("28", "[Errno 28] ENOSPC"):
        return HttpError(507, text.replace(": " + why, ": the flash is full"))
    return HttpError(409, text)


def _end_upload(files):
    """End the page's upload: in place if all of it reached flash, else what did is
    removed (its space is the other files') and the error raised."""
    name = files.upload_name
    try:
        files.end_upload()
    except ValueError:
        try:
            files.storage.remove(files.path(name) + ".part")
        except OSError:
            pass
        raise


def _upload(files, data):
    """A page's upload as its bytes come: into the upload's chunk (files.py), which
    goes to flash a sector at a time, as M28's lines do."""
    chunk = files.chunk
    at = 0
    while at < len(data):
        if files.chunk_n == len(chunk):
            files._flush()
        n = min(len(data) - at, len(chunk) - files.chunk_n)
        chunk[files.chunk_n:files.chunk_n + n] = data[at:at + n]
        files.chunk_n += n
        at += n


def _token():
    try:
        raw = os.urandom(16)
    except (AttributeError, NotImplementedError):
        import random
        raw = bytes(random.getrandbits(8) for _ in range(16))
    return "".join("%02x" % b for b in raw)


class HttpListener:
    def __init__(self, host, port, printer, web_root, gate=None):
        """web_root: where the page's files are (each as <name>.gz). gate: the network
        console's, if it runs too (one wait after a wrong password for both)."""
        settings = printer.settings
        self.sock = listening_socket("web page", host, port, settings)
        self.printer = printer
        self.web_root = web_root.rstrip("/")
        self.gate = gate or Gate(settings, is_loopback(host))
        self.requests = []
        self.sessions = []
        self.new_console = None  # a session's channel for the printer to take
        self.busy = False  # in a request's step (a flash write waits for the moves,
        # and the printer's waits call accept: not into the same request again)

    # --- the printer's listener ---
    def accept(self, room):
        """Called every turn: take a connection, move each request on a piece, and
        hand the printer the channel of a page that has just logged in."""
        if self.busy:
            return None
        try:
            conn, _addr = self.sock.accept()
        except OSError:
            conn = None
        if conn is not None:
            if len(self.requests) >= _MOST_CONNECTIONS:
                turn_away(conn, "HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\n"
                          "Content-Length: 0\r\n\r\n")
            else:
                conn.setblocking(False)
                self.requests.append(_Request(conn, time.ticks_ms()))
                self._sweep_sessions()
        if self.requests:
            self.busy = True
            try:
                for r in self.requests[:]:
                    try:
                        self._step(r)
                    except HttpError as e:
                        self._abort_upload(r)
                        self._answer(r, e.status, {"error": e.text})
                    except OSError:
                        self._close(r)
            finally:
                self.busy = False
        console, self.new_console = self.new_console, None
        if console is not None and room <= 0:
            console.closed = True
            return None
        return console

    def _sweep_sessions(self):
        """Sessions idle for net_idle_timeout_s end. Looked at as a connection comes,
        not every turn: the main loop turns between G-code lines, and a session that
        outlives its time harms nothing until a page asks with it."""
        idle_s = self.printer.settings.get("net_idle_timeout_s", 0)
        now = time.ticks_ms()
        for s in self.sessions[:]:
            if s.closed or (idle_s and time.ticks_diff(now, s.seen_ms) > idle_s * 1000):
                s.closed = True  # the printer drops its channel at its next read
                self.sessions.remove(s)

    def _close(self, r):
        self._abort_upload(r)
        if r.out_file is not None:
            r.out_file.close()
        try:
            r.sock.close()
        except OSError:
            pass
        if r in self.requests:
            self.requests.remove(r)

    # --- a request, a piece at a time ---
    def _step(self, r):
        now = time.ticks_ms()
        if r.out is not None:
            return self._send(r)
        try:
            data = r.sock.read(_PIECE_BYTES)
        except OSError as e:
            if not (e.args and e.args[0] in _EAGAIN):
                raise
            data = None
        if data == b"":
            return self._close(r)
        if data:
            r.heard_ms = now
        if r.method is None:
            if data:
                r.head.extend(data)
            end = r.head.find(b"\r\n\r\n")
            if end < 0:
                if len(r.head) > _HEAD_BYTES:
                    raise HttpError(431, "request head over %d bytes" % _HEAD_BYTES)
                if time.ticks_diff(now, r.since_ms) > _HEAD_MS:
                    raise HttpError(400, "request head not sent within %d s" % (
                        _HEAD_MS // 1000))
                return
            if end > _HEAD_BYTES:
                raise HttpError(431, "request head over %d bytes" % _HEAD_BYTES)
            data = bytes(r.head[end + 4:])
            self._parse_head(r, bytes(r.head[:end]).decode())
            r.head = None
            self._begin(r)
            if r.out is not None:
                return
        if data:
            self._body(r, data)
        if r.out is None and r.got >= max(r.length, 0):
            self._finish(r)
        elif r.out is None and time.ticks_diff(now, r.heard_ms) > _BODY_MS:
            raise HttpError(400, "request body stopped for %d s" % (_BODY_MS // 1000))

    def _parse_head(self, r, head):
        lines = head.split("\r\n")
        words = lines[0].split(" ")
        if len(words) != 3 or not words[2].startswith("HTTP/"):
            raise HttpError(400, "bad request line")
        r.method, r.path = words[0], _unquote(words[1].split("?")[0])
        for line in lines[1:]:
            name, _, value = line.partition(":")
            name = name.strip().lower()
            value = value.strip()
            if name == "content-length":
                try:
                    r.length = int(value)
                except ValueError:
                    raise HttpError(400, "bad Content-Length")
            elif name == "cookie":
                for part in value.split(";"):
                    k, _, v = part.strip().partition("=")
                    if k == _COOKIE:
                        r.cookie = v

    def _session(self, r):
        for s in self.sessions:
            if r.cookie is not None and s.token == r.cookie and not s.closed:
                s.seen_ms = time.ticks_ms()
                return s
        return None

    def _begin(self, r):
        """What a request's head asks, checked before its body is read."""
        path = r.path
        if not path.startswith("/api/"):
            if r.method != "GET":
                raise HttpError(405, "only GET here")
            return self._static(r, path)
        if path in ("/api/login", "/api/session"):
            if path == "/api/login" and r.method == "POST" and r.length > 128:
                raise HttpError(413, "password too long")
            return
        if self._session(r) is None:
            if not self.gate.open():
                raise HttpError(401, "log in first")
            self._open_session(r)  # no password asked (loopback): a session at once
        if r.method == "PUT" and path.startswith("/api/files/"):
            if r.length < 0:
                raise HttpError(411, "Content-Length needed")
            files = self._files()
            name = path[len("/api/files/"):]
            if files.upload_name is not None:  # the files keep one upload at a time
                raise HttpError(409, "%s is being uploaded; try again after it"
                                % files.upload_name)
            sink = self.printer.sink
            try:
                files.begin_upload(name)
            except ValueError as e:  # files.FileError
                files.upload_name = None  # M28's would wait for its M29; none comes here
                raise HttpError(409 if "prints" in str(e) else 400,
                                str(e).replace("; the lines up to M29 are not run", ""))
            finally:
                self.printer.sink = sink  # the consoles' lines stay G-code: M28 takes them
            r.upload = name
        elif r.length > _GCODE_BYTES:
            raise HttpError(413, "request body over %d bytes" % _GCODE_BYTES)

    def _body(self, r, data):
        r.got += len(data)
        if r.length >= 0 and r.got > r.length:
            raise HttpError(400, "body longer than its Content-Length")
        if r.upload is not None:
            files = self._files()
            try:
                _upload(files, data)
            except ValueError as e:  # M28's words: the upload ends here, with no M29
                raise _flash_error(e, files)
        else:
            r.body.extend(data)

    def _abort_upload(self, r):
        if r.upload is not None:
            r.upload = None
            files = self._files()
            files.upload_failed = files.upload_failed or "the upload was cut short"
            try:
                _end_upload(files)
            except ValueError:
                pass  # not saved, as it should not be

    def _finish(self, r):
        method, path = r.method, r.path
        if path == "/api/session":
            return self._answer(r, 200, {"login_needed": not self.gate.open(),
                                         "logged_in": self._session(r) is not None})
        if path == "/api/login":
            if method != "POST":
                raise HttpError(405, "POST the password")
            why = self.gate.refusal(bytes(r.body).strip(), time.ticks_ms())
            if why is not None:
                raise HttpError(429 if "try again" in why else 403, why)
            self._open_session(r)
            return self._answer(r, 200, {"ok": True})
        session = self._session(r)
        if path == "/api/status" and method == "GET":
            return self._answer(r, 200, self.status())
        if path == "/api/console" and method == "GET":
            lines, session.outbox = session.outbox, []
            return self._answer(r, 200, {"lines": lines})
        if path == "/api/gcode" and method == "POST":
            text = bytes(r.body)
            if not text.endswith(b"\n"):
                text += b"\n"
            if len(session.inbox) + len(text) > _INBOX_BYTES:
                raise HttpError(503, "the printer has not yet taken the last lines; "
                                "try again")
            session.inbox += text
            return self._answer(r, 200, {"queued": text.count(b"\n")})
        if path == "/api/files" and method == "GET":
            return self._answer(r, 200, self._listing())
        if path.startswith("/api/files/"):
            name = path[len("/api/files/"):]
            files = self._files()
            try:
                if method == "PUT":
                    r.upload = None
                    _end_upload(files)
                    return self._answer(r, 201, {"name": name, "bytes": r.got})
                if method == "DELETE":
                    files.delete(name)
                    return self._answer(r, 200, {"ok": True})
            except ValueError as e:
                raise _flash_error(e, files)
        raise HttpError(404 if method in ("GET", "POST", "PUT", "DELETE") else 405,
                        "no %s %s" % (method, path))

    def _open_session(self, r):
        if len(self.sessions) >= _MOST_SESSIONS:
            oldest = self.sessions[0]
            for s in self.sessions:
                if time.ticks_diff(s.seen_ms, oldest.seen_ms) < 0:
                    oldest = s
            oldest.closed = True  # the printer drops its channel
            self.sessions.remove(oldest)
        token = _token()
        console = PageConsole(token)
        self.sessions.append(console)
        self.new_console = console
        r.cookie = r.new_cookie = token
        return token

    # --- answers ---
    def _answer(self, r, status, obj, extra=""):
        body = json.dumps(obj).encode()
        self._respond(r, status, "application/json", body, extra)

    def _respond(self, r, status, kind, body, extra="", length=None):
        if r.new_cookie is not None:
            extra += "Set-Cookie: %s=%s; Path=/; HttpOnly; SameSite=Strict\r\n" % (
                _COOKIE, r.new_cookie)
        head = "HTTP/1.1 %d %s\r\nContent-Type: %s\r\nContent-Length: %d\r\n" \
               "Cache-Control: no-store\r\nConnection: close\r\n%s\r\n" % (
                   status, _REASONS.get(status, ""), kind,
                   len(body) if length is None else length, extra)
        r.out = head.encode() + body
        self._send(r)

    def _send(self, r):
        if not r.out and r.out_file is not None:
            r.out = r.out_file.read(_PIECE_BYTES)
            if not r.out:
                return self._close(r)
        try:
            n = r.sock.write(r.out[:_PIECE_BYTES])
        except OSError as e:
            if not (e.args and e.args[0] in _EAGAIN):
                raise
            n = 0
        r.out = r.out[n or 0:]
        if n:
            r.heard_ms = time.ticks_ms()
        elif time.ticks_diff(time.ticks_ms(), r.heard_ms) > _BODY_MS:
            return self._close(r)  # a client that stopped reading
        if not r.out and r.out_file is None:
            self._close(r)

    def _static(self, r, path):
        name = "index.html" if path == "/" else path[1:]
        if "/" in name or name.startswith("."):
            raise HttpError(404, "no %s" % path)
        path = "%s/%s.gz" % (self.web_root, name)
        try:
            size = os.stat(path)[6]
            f = open(path, "rb")
        except OSError:
            raise HttpError(404, "no %s" % path)
        r.out_file = f
        self._respond(r, 200, _TYPES.get(name.rsplit(".", 1)[-1], "text/plain"), b"",
                      "Content-Encoding: gzip\r\n", size)

    # --- what the page shows ---
    def _files(self):
        files = self.printer.reports.files
        if files is None:
            raise HttpError(404, "this printer keeps no files")
        return files

    def _listing(self):
        files = self._files()
        try:
            st = os.statvfs(files.root or "/")
            free = st[1] * st[4]  # fragment size x fragments free to users
        except (AttributeError, OSError):
            free = None
        try:
            listing = files.listing()
        except OSError as e:
            raise HttpError(500, "cannot list the files: %s" % e)
        return {"files": [{"name": n, "bytes": b} for n, b in listing], "free_bytes": free}

    def status(self):
        p = self.printer
        s = p.settings
        pos = p.motion.pos_mm()
        p.thermal.refresh()
        heaters = [{"name": h.name, "c": round(h.temp_c, 1), "target_c": h.target_c}
                   for h in p.thermal.heaters]
        rgb = drive_rgb(s)
        tools = [{"mix": list(m), "rgb": "#%06x" % mix_rgb(m, rgb)} for m in s["tool_mixes"]]
        reports = p.reports
        files = reports.files
        job = files.selected if files is not None else None
        state = "idle"
        if job is not None:
            state = "paused" if job.paused or p.job is not job else "printing"
            if job.pos() >= job.size:
                state = "done"  # read to its end; M26 rewinds it
        progress = reports.progress
        return {
            "position_mm": {"x": pos[0], "y": pos[1], "z": pos[2], "e": pos[3]},
            "heaters": heaters,
            "fan": p.thermal.fan_duty,
            "tool": p.mixing.active, "drives": s["drives"], "tools": tools,
            "drive_rgb": ["#%06x" % c for c in rgb],
            "job": {"file": job.name if job else None, "state": state,
                    "bytes": job.pos() if job else 0, "size": job.size if job else 0},
            "progress_pct": progress[0], "left_min": progress[1],
            "message": reports.message,
            "queue_moves": waiting_blocks(p.mem),
            "halted": bool(p.halted),
        }


def board_listeners(printer, web_root, warnings):
    """A board's TCP console and web page, once it is on a network and a password is
    set; what stops them goes to warnings."""
    import network
    settings = printer.settings
    if not network.WLAN(network.STA_IF).isconnected():
        return []
    if not settings.get("net_password"):
        warnings.append("//network console and web page off: no password set "
                        "(M926 Inet_password V<8 to 64 characters>, M500, restart)")
        return []
    listeners = []
    gate = None
    if settings.get("tcp_port"):
        listeners.append(TcpListener("0.0.0.0", settings["tcp_port"], settings))
        gate = listeners[-1].gate
    if settings.get("web_page_port"):
        listeners.append(HttpListener("0.0.0.0", settings["web_page_port"], printer,
                                      web_root, gate))
    return listeners
