# The network console: G-code over TCP, several connections at once (as APrinter's).
# A connection becomes one more channel of the printer only once it has sent the
# password (net_password) as its first line, as RepRapFirmware's Telnet asks for it;
# until then none of its bytes reach the printer. With no password set the console is
# off, but on a loopback address, which only this machine reaches (the simulation's
# `mixstep serve --tcp 127.0.0.1:PORT`, as Moonraker trusts localhost).
#
# What keeps the printer printing while someone misbehaves on the network: one new
# connection taken a turn, at most _LOGINS_AT_ONCE logging in, each given _LOGIN_MS
# and _PASSWORD_BYTES; connections beyond tcp_max_clients turned away at once (not
# left in the backlog); a wait after each wrong password, doubling to
# _LOCKOUT_MOST_MS, for every connection (a guesser opens a new one per guess); a
# connection that sends no whole line for net_idle_timeout_s closed (one gone quiet,
# or a sender of a byte a second); a host that stops reading given up after
# _WRITE_WAIT_MS. All of it runs in the main loop between lines: the step path never
# waits on the network.
import socket
import select
import time

_EAGAIN = (11, 115, 119)  # EAGAIN, EINPROGRESS/EWOULDBLOCK on the ports we run on
_LOGIN_MS = const(10000)
_PASSWORD_BYTES = const(80)
_LOGINS_AT_ONCE = const(2)
_LOCKOUT_FIRST_MS = const(1000)
_LOCKOUT_MOST_MS = const(60000)
_LINE_MOST_BYTES = const(256)  # more than any line: a newline has passed among them
_WRITE_WAIT_MS = const(200)
_PROMPT = b"password:\n"


def same_secret(given, secret):
    """given == secret (bytes), in a time that depends on secret's length alone, so
    the time of an answer tells a guesser nothing of how much of a guess was right."""
    diff = len(given) ^ len(secret)
    n = len(given)
    for i in range(len(secret)):
        diff |= secret[i] ^ (given[i] if i < n else 0)
    return diff == 0


def is_loopback(host):
    return host.startswith("127.") or host in ("localhost", "::1")


class Gate:
    """Who may in: the password (read from the settings at each try, so M926 changes
    it at once), and the wait after wrong ones."""

    def __init__(self, settings, loopback):
        self.settings = settings
        self.loopback = loopback
        self.failures = 0
        self.wait_until_ms = 0

    def open(self):
        """No password asked: none is set, on a loopback address."""
        return self.loopback and not self.settings.get("net_password")

    def refusal(self, given, now_ms):
        """None if given (bytes) is the password; else why not, as the client hears."""
        if self.failures:
            wait_ms = time.ticks_diff(self.wait_until_ms, now_ms)
            if wait_ms > 0:
                return "too many wrong passwords: try again in %d s" % ((wait_ms + 999) // 1000)
        secret = self.settings.get("net_password")
        if secret and same_secret(given, secret.encode()):
            self.failures = 0
            return None
        self.failures += 1
        self.wait_until_ms = time.ticks_add(now_ms, min(
            _LOCKOUT_FIRST_MS << min(self.failures - 1, 6), _LOCKOUT_MOST_MS))
        if not secret:
            return "network console off: no password set (net_password)"
        return "wrong password"


class SocketConsole:
    def __init__(self, sock, settings):
        self.sock = sock
        self.settings = settings
        sock.setblocking(False)
        self.poller = select.poll()
        self.poller.register(sock, select.POLLOUT)
        self.closed = False
        self.heard_ms = time.ticks_ms()  # when the last whole line had come in
        self.line_bytes = 0  # bytes since then
        self.early = b""  # what came in behind the password line

    def readinto(self, mv, block=False):
        if self.closed:
            return -1
        if self.early:
            n = min(len(mv), len(self.early))
            mv[:n] = self.early[:n]
            self.early = self.early[n:]
            return n
        try:
            n = self.sock.readinto(mv)
        except OSError as e:
            if not (e.args and e.args[0] in _EAGAIN):
                self.close()
                return -1
            n = None
        now = time.ticks_ms()
        if n:
            # A read that ends a line, or more bytes than a line holds: a line has come
            # (looking for its newline in every byte would cost the chip more).
            self.line_bytes += n
            if mv[n - 1] == 10 or self.line_bytes > _LINE_MOST_BYTES:
                self.heard_ms = now
                self.line_bytes = 0
            return n
        if n == 0:
            self.close()
            return -1
        idle_s = self.settings.get("net_idle_timeout_s", 0)
        if idle_s and time.ticks_diff(now, self.heard_ms) > idle_s * 1000:
            return self._drop("closed: no whole line for %d s (net_idle_timeout_s)" % idle_s)
        return 0

    def _drop(self, why):
        self.write("Error:%s\n" % why)
        self.close()
        return -1

    def write(self, text):
        if self.closed:
            return
        data = text.encode() if isinstance(text, str) else text
        sent = 0
        waited_ms = 0
        while sent < len(data):
            try:
                n = self.sock.write(data[sent:])
            except OSError as e:
                if not (e.args and e.args[0] in _EAGAIN):
                    self.close()
                    return
                n = 0
            if not n:
                if waited_ms >= _WRITE_WAIT_MS:  # a host that stops reading: give it up
                    self.close()
                    return
                self.poller.poll(10)
                waited_ms += 10
            sent += n or 0

    def close(self):
        if not self.closed:
            self.closed = True
            try:
                self.sock.close()
            except OSError:
                pass


class _Login:
    """A connection that has not yet sent the password: its bytes so far."""

    def __init__(self, sock, now_ms):
        self.sock = sock
        self.since_ms = now_ms
        self.buf = bytearray(_PASSWORD_BYTES)
        self.n = 0


def turn_away(sock, text):
    try:
        # What it sent and was not read, read first: a socket closed with unread
        # bytes resets the connection, and the client would not see why.
        sock.setblocking(False)
        sock.read(_LINE_MOST_BYTES)
    except OSError:
        pass
    try:
        sock.write(text.encode())
    except OSError:
        pass
    try:
        sock.close()
    except OSError:
        pass


def listening_socket(what, host, port, settings):
    """A socket listening on host:port, taking connections without waiting. Raises
    ValueError on an address beyond this machine with no password set."""
    if not is_loopback(host) and not settings.get("net_password"):
        raise ValueError(
            "the %s on %s needs a password first: set net_password "
            "(M926 Inet_password V<8 to 64 characters>, then M500)" % (what, host))
    addr = socket.getaddrinfo(host, port)[0][-1]
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(addr)
    s.listen(4)
    s.setblocking(False)
    return s


class TcpListener:
    def __init__(self, host, port, settings):
        """settings: the printer's (net_password, net_idle_timeout_s)."""
        self.sock = listening_socket("network console", host, port, settings)
        self.settings = settings
        self.gate = Gate(settings, is_loopback(host))
        self.logins = []

    def accept(self, room):
        """A console that has given the password, or None. room: channels the printer
        still takes; a connection beyond it is turned away."""
        try:
            conn, _addr = self.sock.accept()
        except OSError:
            conn = None
        if conn is not None:
            if room - len(self.logins) <= 0:
                turn_away(conn, "Error:too many connections (tcp_max_clients)\n")
            elif self.gate.open():
                return SocketConsole(conn, self.settings)  # Printer.add_channel says `start`
            elif len(self.logins) >= _LOGINS_AT_ONCE:
                turn_away(conn, "Error:too many connections logging in; try again\n")
            else:
                conn.setblocking(False)
                try:
                    conn.write(_PROMPT)
                except OSError:
                    pass
                self.logins.append(_Login(conn, time.ticks_ms()))
        for login in self.logins:
            console = self._log_in(login)
            if console is not False:
                self.logins.remove(login)
                return console
        return None

    def _log_in(self, login):
        """The console once login's password line is in and right; None when it is
        turned away or gone; False while it is still coming."""
        sock = login.sock
        now = time.ticks_ms()
        try:
            n = sock.readinto(memoryview(login.buf)[login.n:])
        except OSError as e:
            if not (e.args and e.args[0] in _EAGAIN):
                sock.close()
                return None
            n = None
        if n == 0:
            sock.close()
            return None
        if n:
            login.n += n
        end = login.buf.find(b"\n", 0, login.n)
        if end < 0:
            if login.n >= _PASSWORD_BYTES:
                turn_away(sock, "Error:password line too long\n")
                return None
            if time.ticks_diff(now, login.since_ms) > _LOGIN_MS:
                turn_away(sock, "Error:no password within %d s\n" % (_LOGIN_MS // 1000))
                return None
            return False
        given = bytes(login.buf[:end]).strip()
        why = self.gate.refusal(given, now)
        if why is not None:
            turn_away(sock, "Error:%s\n" % why)
            return None
        console = SocketConsole(sock, self.settings)
        console.early = bytes(login.buf[end + 1:login.n])
        return console

