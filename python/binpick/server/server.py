"""The vision server's sockets: :class:`VisionServer` listens on TCP, serves one robot program
at a time, and hands each request line to a :class:`~binpick.server.service.VisionService`.

* One connection is served at a time; another one meanwhile gets a BUSY reply and is closed
  (after a second's grace, for a program that closed and reconnected at once). A robot
  controller that drops the connection (a program restart) reconnects and goes on: the service
  keeps its state between connections. One that vanished without closing (a power cut) holds
  its connection until ``idle_timeout_s``.
* A connection silent for ``idle_timeout_s`` is closed; so is one whose line grows past
  :data:`~binpick.server.protocol.MAX_LINE_BYTES` without a line end (after a TOO_LONG reply).
* Every other fault of a request is an error reply; the server keeps serving.
"""

from __future__ import annotations

import re
import socket
import threading
from typing import Any, Callable, Optional

from ..cell.loop import quiet
from ..errors import InvalidInputError
from .protocol import MAX_LINE_BYTES, Code, encode_reply
from .service import VisionService

__all__ = ["VisionServer", "DEFAULT_PORT"]

#: How long a new connection waits for the one being served to end before it is refused, s.
_HANDOVER_S = 1.0
#: A request's end: LF, CR or CR LF (an empty line between a CR and an LF is ignored).
_LINE_END = re.compile(rb"\r\n?|\n")

#: The port the server listens on unless the cell file or the command line names another.
DEFAULT_PORT = 50100


class VisionServer:
    """A TCP server for one :class:`VisionService`.

    Args:
        service: what answers each request.
        host: the address to listen on (loopback by default: a cell network is opened on purpose).
        port: the TCP port; 0 picks a free one (see :attr:`address`).
        idle_timeout_s: a connection silent this long is closed.
        progress: called with (stage, message).
    """

    def __init__(
        self,
        service: VisionService,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        idle_timeout_s: float = 60.0,
        progress: Optional[Callable[[str, str], None]] = None,
    ) -> None:
        if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
            raise InvalidInputError(f"port: {port!r:.20} is not a TCP port; use 0..65535 (0: any free port)")
        if not (isinstance(idle_timeout_s, (int, float)) and 0 < idle_timeout_s < 86400):
            raise InvalidInputError(f"idle_timeout_s: {idle_timeout_s!r:.20}; use a time in seconds, under a day")
        self.service = service
        self.idle_timeout_s = float(idle_timeout_s)
        self.progress = progress or quiet
        try:
            self._listener = socket.create_server((host, port), reuse_port=False)
        except OSError as exc:
            raise InvalidInputError(f"port: cannot listen on {host}:{port} ({exc}); choose another port") from None
        self._listener.settimeout(0.2)
        self._stop = threading.Event()
        self._busy = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._accepting: Optional[threading.Thread] = None
        self.connections = 0

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the server listens on."""
        host, port = self._listener.getsockname()[:2]
        return host, port

    def start(self) -> VisionServer:
        """Starts accepting connections in a background thread."""
        self._accepting = threading.Thread(target=self._accept, name="binpick-serve", daemon=True)
        self._accepting.start()
        return self

    def close(self) -> None:
        """Stops accepting, closes the connections' sockets and the listener."""
        self._stop.set()
        if self._accepting is not None:
            self._accepting.join(timeout=5.0)
        for t in self._threads:
            t.join(timeout=5.0)
        self._listener.close()

    def __enter__(self) -> VisionServer:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, peer = self._listener.accept()
            except (socket.timeout, TimeoutError):
                continue
            except OSError:
                return
            # A program that closed and reconnects at once may find its old connection not yet
            # wound up: it is given a moment before being refused as a second program.
            if not self._busy.acquire(timeout=_HANDOVER_S):
                self._refuse(conn, peer)
                continue
            self.connections += 1
            self._threads = [t for t in self._threads if t.is_alive()]
            t = threading.Thread(target=self._serve, args=(conn, peer), name="binpick-serve-conn", daemon=True)
            self._threads.append(t)
            t.start()

    def _refuse(self, conn: socket.socket, peer: Any) -> None:
        self.progress("serve", f"{peer[0]}:{peer[1]} refused: another robot program is connected")
        try:
            conn.settimeout(1.0)
            conn.sendall(encode_reply(Code.BUSY, size=1, text="busy: another robot program is connected"))
        except OSError:
            pass
        finally:
            conn.close()

    def _serve(self, conn: socket.socket, peer: Any) -> None:
        self.progress("serve", f"robot program connected from {peer[0]}:{peer[1]}")
        why = "closed by the robot program"
        try:
            why = self._conversation(conn)
        except (socket.timeout, TimeoutError):
            why = f"silent for {self.idle_timeout_s:g} s, closed"
        except OSError as exc:
            why = f"connection lost ({exc})"
        finally:
            self._busy.release()  # before the close the program sees: its reconnect is never refused as busy
            conn.close()
            self.progress("serve", f"robot program {peer[0]}:{peer[1]}: {why}")

    def _conversation(self, conn: socket.socket) -> str:
        conn.settimeout(self.idle_timeout_s)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        pending = b""
        while not self._stop.is_set():
            chunk = conn.recv(4096)
            if not chunk:
                return "closed by the robot program"
            pending += chunk
            while True:
                end = _LINE_END.search(pending)
                if end is None:
                    break
                line, pending = pending[: end.start()], pending[end.end() :]
                reply = self.service.handle_line(line)
                if reply:
                    conn.sendall(reply)
                if line.strip().upper() == b"BYE":
                    return "said BYE"
            if len(pending) >= MAX_LINE_BYTES:
                text = f"a message is at most {MAX_LINE_BYTES - 1} bytes before its line end; closing"
                conn.sendall(encode_reply(Code.TOO_LONG, size=1, text=text))
                _drain(conn)
                return "sent a line too long, closed"
        return "the server stopped"


#: What is read and dropped of a connection closed for a line too long, bytes and seconds.
_DRAIN_BYTES, _DRAIN_S = 1 << 20, 0.5


def _drain(conn: socket.socket) -> None:
    """Ends the sending side, then drops what the peer still sends (a bounded amount, briefly):
    closing with unread bytes would reset the connection and lose the reply already sent."""
    try:
        conn.shutdown(socket.SHUT_WR)
        conn.settimeout(_DRAIN_S)
        dropped = 0
        while dropped < _DRAIN_BYTES:
            chunk = conn.recv(65536)
            if not chunk:
                return
            dropped += len(chunk)
    except OSError:
        pass
