"""A device served on a pseudo-terminal: the base of every emulator, with fault injection.

The emulator opens a pty pair with :func:`os.openpty`, puts it in raw mode and serves the master
side from a background thread; a driver opens :attr:`PtyEmulator.slave_path` with pyserial like
any serial port, and may close and reopen it any number of times, as on a real serial line.
Faults armed with :meth:`PtyEmulator.inject` change the next matching replies.

Reopening: some kernels' ptys cannot hold a parity bit, and their ``tcsetattr`` fails with
EINVAL when parity is the only change asked for — which is what pyserial asks when a driver
reopens a port at the speed it last set (the MELFA line is 9600 8E2). A request that also changes
the speed is accepted. So the emulator keeps the line's stored speed at :data:`IDLE_BAUD`, a
speed no cell device uses, resetting it each time a driver has set another: every open then
changes the speed and succeeds. The speed of a pty carries no meaning for the bytes. The master
side runs in packet mode with the slave's EXTPROC flag set, so the kernel tells the emulator
(a TIOCPKT_IOCTL packet) each time a driver sets the line; the emulator resets the speed
:data:`REST_DELAY_S` later — not at once, which could land inside the driver's own
``tcsetattr`` and make it fail — and also checks it at every turn of its loop and after every
request. A driver that reopens the port within those few milliseconds of opening it can still
be refused.
"""

from __future__ import annotations

import enum
import fcntl
import os
import select
import termios
import threading
import time
import tty
from dataclasses import dataclass
from typing import Any, Callable, Optional

from ...errors import InvalidInputError
from .clock import PhysicalClock

__all__ = ["Fault", "PtyEmulator", "IDLE_BAUD", "REST_DELAY_S"]

#: The line speed the emulator's pty rests at between opens (see the module docstring).
IDLE_BAUD = termios.B50

#: Seconds between a driver's change of the line's settings and the emulator's reset of its speed.
REST_DELAY_S = 0.003

_EXTPROC = getattr(termios, "EXTPROC", 0o200000)  # Linux's value when the module lacks the name
_PKT_IOCTL = getattr(termios, "TIOCPKT_IOCTL", 0x40)


class Fault(enum.Enum):
    """A transport or device fault the emulator can play on its next replies.

    NO_REPLY: the request is carried out, the reply is lost.
    IGNORED: the request is lost on the way in: not carried out, no reply.
    DELAY: the reply comes ``delay_s`` late.
    PARTIAL: only the first half of the reply is sent.
    GARBLED: the reply's bytes are corrupted (framing or characters).
    BAD_CRC: the reply's checksum is wrong (protocols with a checksum only).
    UNKNOWN_REPLY: a well-formed reply the protocol does not define for the request.
    DEVICE_ERROR: the device refuses the request with an error of its own (not carried out).
    CLOSE_PORT: the port disappears: the pty is closed without a reply.
    """

    NO_REPLY = "no_reply"
    IGNORED = "ignored"
    DELAY = "delay"
    PARTIAL = "partial"
    GARBLED = "garbled"
    BAD_CRC = "bad_crc"
    UNKNOWN_REPLY = "unknown_reply"
    DEVICE_ERROR = "device_error"
    CLOSE_PORT = "close_port"


@dataclass
class _Armed:
    fault: Fault
    times: int
    when: Optional[Callable[[Any], bool]]
    delay_s: float


class PtyEmulator:
    """Base class: serves a protocol on a pty from a background thread.

    Subclasses implement :meth:`_take_requests` (cut complete requests off the input buffer),
    :meth:`_handle` (carry one out and return the reply bytes, or None for no reply) and the
    fault hooks :meth:`_garble`, :meth:`_bad_crc`, :meth:`_unknown_reply`, :meth:`_error_reply`.

    Use as a context manager, or call :meth:`start` and :meth:`close`.
    """

    #: faults this protocol can play; subclasses without a checksum drop BAD_CRC
    supported_faults = frozenset(Fault)
    #: the device's name in thread names and messages
    device = "device"
    #: seconds between a request and its reply: the device's return delay (0 = at once)
    reply_delay_s = 0.0

    def __init__(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self._master)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] |= _EXTPROC
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        fcntl.ioctl(self._master, termios.TIOCPKT, (1).to_bytes(4, "little"))
        self.slave_path = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self._faults: list[_Armed] = []
        self._requests: list[Any] = []
        self._closed = False
        #: exceptions raised while handling requests (an emulator bug); tests assert it stays empty
        self.failures: list[str] = []
        #: the cell's hardware time (a :class:`~binpick.devices.emulators.clock.PhysicalClock`
        #: shared with the cell's other emulators), or None: what each command takes is spent there
        self.clock: Optional[PhysicalClock] = None
        self._rest_line()
        self._thread = threading.Thread(target=self._serve, name=f"{self.device}-emulator", daemon=True)

    def _spend(self, seconds: float) -> None:
        """The device takes ``seconds`` of the cell's hardware time (kept when a clock is set)."""
        if self.clock is not None:
            self.clock.spend(seconds, self.device)

    # -- public
    def start(self) -> PtyEmulator:
        """Starts serving (returns self)."""
        if not self._thread.is_alive() and not self._closed:
            self._thread.start()
        return self

    def close(self) -> None:
        """Stops the thread and closes the pty; safe to call twice."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        self._close_fds()

    def __enter__(self) -> PtyEmulator:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def port_closed(self) -> bool:
        """Whether the pty has been closed (by :meth:`close` or a CLOSE_PORT fault)."""
        return self._closed

    @property
    def requests(self) -> list[Any]:
        """Every request received so far, in order (the protocol's own representation)."""
        with self._lock:
            return list(self._requests)

    def inject(
        self, fault: Fault, *, times: int = 1, when: Optional[Callable[[Any], bool]] = None, delay_s: float = 0.5
    ) -> None:
        """Plays ``fault`` on the next ``times`` requests for which ``when(request)`` is true (all if None)."""
        if not isinstance(fault, Fault):
            raise InvalidInputError(f"fault: expected a Fault, got {fault!r}")
        if fault not in self.supported_faults:
            raise InvalidInputError(f"fault: the {self.device} protocol cannot play {fault.name} (no checksum)")
        if not isinstance(times, int) or times < 1:
            raise InvalidInputError(f"times: must be a positive integer, got {times!r}")
        with self._lock:
            self._faults.append(_Armed(fault, times, when, float(delay_s)))

    def clear_faults(self) -> None:
        """Disarms every pending fault."""
        with self._lock:
            self._faults.clear()

    def send_raw(self, data: bytes) -> None:
        """Writes ``data`` to the driver as if the device had sent it (unsolicited bytes)."""
        os.write(self._master, bytes(data))

    # -- protocol hooks
    def _take_requests(self, buf: bytearray) -> list[Any]:
        raise NotImplementedError

    def _handle(self, request: Any) -> Optional[bytes]:
        raise NotImplementedError

    def _garble(self, reply: bytes) -> bytes:
        raise NotImplementedError

    def _bad_crc(self, reply: bytes) -> bytes:
        raise NotImplementedError

    def _unknown_reply(self, request: Any) -> bytes:
        raise NotImplementedError

    def _error_reply(self, request: Any) -> Optional[bytes]:
        raise NotImplementedError

    # -- machinery
    def _serve(self) -> None:
        buf = bytearray()
        rest_at: Optional[float] = None
        while not self._stop.is_set() and not self._closed:
            try:
                now = time.monotonic()
                if rest_at is None or now >= rest_at:
                    self._rest_line()
                    rest_at = None
                wait = 0.02 if rest_at is None else max(0.0, rest_at - now)
                ready, _, _ = select.select([self._master], [], [], wait)
                if not ready:
                    continue
                packet = os.read(self._master, 4097)
            except (OSError, ValueError):
                break
            if not packet or packet[0] != 0:  # a control packet, no data
                if packet and packet[0] & _PKT_IOCTL:
                    rest_at = time.monotonic() + REST_DELAY_S
                continue
            buf += packet[1:]
            for request in self._take_requests(buf):
                with self._lock:
                    self._requests.append(request)
                try:
                    self._dispatch(request)
                except Exception as exc:  # an emulator bug: keep serving, let the test see it
                    self.failures.append(f"{request!r}: {type(exc).__name__}: {exc}")
                if self._closed:
                    return
                self._rest_line()

    def _pop_fault(self, request: Any) -> Optional[_Armed]:
        with self._lock:
            for armed in self._faults:
                if armed.when is None or armed.when(request):
                    armed.times -= 1
                    if armed.times == 0:
                        self._faults.remove(armed)
                    return armed
        return None

    def _dispatch(self, request: Any) -> None:
        armed = self._pop_fault(request)
        fault = armed.fault if armed else None
        if fault is Fault.CLOSE_PORT:
            self._close_fds()
            return
        if fault is Fault.IGNORED:
            return
        reply = self._error_reply(request) if fault is Fault.DEVICE_ERROR else self._handle(request)
        if reply is None or fault is Fault.NO_REPLY:
            return
        if fault is Fault.DELAY:
            self._stop.wait(armed.delay_s)  # type: ignore[union-attr]
        elif fault is Fault.PARTIAL:
            reply = reply[: max(1, len(reply) // 2)]
        elif fault is Fault.GARBLED:
            reply = self._garble(reply)
        elif fault is Fault.BAD_CRC:
            reply = self._bad_crc(reply)
        elif fault is Fault.UNKNOWN_REPLY:
            reply = self._unknown_reply(request)
        if self.reply_delay_s:
            self._stop.wait(self.reply_delay_s)
        self._send_bytes(reply)

    def _rest_line(self) -> None:
        """Puts the line's stored speed back to :data:`IDLE_BAUD` once a driver has set another,
        so that the next open of the port changes the speed and is accepted (module docstring)."""
        if self._closed:
            return
        try:
            attrs = termios.tcgetattr(self._slave)
            if attrs[4] != IDLE_BAUD or attrs[5] != IDLE_BAUD:
                attrs[4] = attrs[5] = IDLE_BAUD
                termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        except termios.error as exc:  # keep serving: only the next reopen can suffer
            if not self._closed:
                self.failures.append(f"resting the line at {IDLE_BAUD} baud: {exc}")

    def _send_bytes(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except OSError:
            pass

    def _close_fds(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            for fd in (self._master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass


def monotonic() -> float:
    """The clock every emulator's motion model runs on."""
    return time.monotonic()
