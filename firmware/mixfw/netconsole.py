# A G-code console over TCP, several connections at once (as APrinter's): each
# accepted connection becomes one more channel of the printer.
import socket
import select

_EAGAIN = (11, 115, 119)  # EAGAIN, EINPROGRESS/EWOULDBLOCK on the ports we run on


class SocketConsole:
    def __init__(self, sock):
        self.sock = sock
        sock.setblocking(False)
        self.poller = select.poll()
        self.poller.register(sock, select.POLLOUT)
        self.closed = False

    def readinto(self, mv, block=False):
        if self.closed:
            return -1
        try:
            n = self.sock.readinto(mv)
        except OSError as e:
            if e.args and e.args[0] in _EAGAIN:
                return 0
            self.close()
            return -1
        if n is None:
            return 0
        if n == 0:
            self.close()
            return -1
        return n

    def write(self, text):
        if self.closed:
            return
        data = text.encode() if isinstance(text, str) else text
        sent = 0
        tries = 0
        while sent < len(data):
            try:
                n = self.sock.write(data[sent:])
            except OSError as e:
                if not (e.args and e.args[0] in _EAGAIN):
                    self.close()
                    return
                n = 0
            if not n:
                tries += 1
                if tries > 500:  # a host that never reads: give it up, not the printer
                    self.close()
                    return
                self.poller.poll(10)
            sent += n or 0

    def close(self):
        if not self.closed:
            self.closed = True
            try:
                self.sock.close()
            except OSError:
                pass


class TcpListener:
    def __init__(self, host, port, backlog=4):
        addr = socket.getaddrinfo(host, port)[0][-1]
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(addr)
        s.listen(backlog)
        s.setblocking(False)
        self.sock = s

    def accept(self):
        try:
            conn, _addr = self.sock.accept()
        except OSError:
            return None
        return SocketConsole(conn)  # Printer.add_channel says `start`
