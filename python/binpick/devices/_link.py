"""The serial transport every driver shares (its input checks are in :mod:`binpick._validate`).

A :class:`SerialLink` owns one pyserial port and reads against absolute deadlines, so no read
can wait longer than the configured reply timeout. pyserial and OS errors become
:class:`~binpick.errors.PortClosedError`; silence becomes :class:`~binpick.errors.DeviceTimeout`;
a reply that stops part-way becomes :class:`~binpick.errors.TruncatedReplyError`.
"""

from __future__ import annotations

import errno
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Optional, TypeVar, Union

import serial

try:
    import termios

    _PORT_ERRORS: tuple = (serial.SerialException, OSError, termios.error)
    _SETTINGS_REFUSED: tuple = (termios.error,)
    _INTERRUPTED: tuple = (termios.error, InterruptedError)
except ImportError:  # pragma: no cover - not POSIX
    _PORT_ERRORS = (serial.SerialException, OSError)
    _SETTINGS_REFUSED = ()
    _INTERRUPTED = (InterruptedError,)

from .._validate import check_int, check_number
from ..errors import (
    BinpickError,
    DeviceError,
    DeviceTimeout,
    InvalidInputError,
    PortClosedError,
    ProtocolError,
    TruncatedReplyError,
)

__all__ = ["SerialSettings", "SerialLink"]

T = TypeVar("T")
E = TypeVar("E", bound=BaseException)

_SLICE_S = 0.01  # the port's read timeout: reads return at least this often to check their deadline
#: Opens of a port whose line settings are refused, and the pause between them (see SerialLink._open).
_OPEN_ATTEMPTS = 5
_OPEN_RETRY_S = 0.02
#: Waits for a write to drain made when signals keep interrupting them (see SerialLink._drain).
_DRAIN_ATTEMPTS = 5

_PARITIES = {
    "N": serial.PARITY_NONE,
    "E": serial.PARITY_EVEN,
    "O": serial.PARITY_ODD,
    "M": serial.PARITY_MARK,
    "S": serial.PARITY_SPACE,
}


@dataclass(frozen=True)
class SerialSettings:
    """How a driver opens and talks over its serial port.

    Attributes:
        baudrate: line speed, bits per second.
        bytesize: data bits, 5 to 8.
        parity: ``"N"`` none, ``"E"`` even, ``"O"`` odd, ``"M"`` mark or ``"S"`` space.
        stopbits: 1, 1.5 or 2.
        timeout_s: longest wait for one complete reply, seconds.
        write_timeout_s: longest wait for a write to leave the port, seconds.
        retries: how many more times a *query* is sent after a timeout or an unusable reply.
            Commands that move something are never sent twice.
    """

    baudrate: int = 9600
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1
    timeout_s: float = 1.0
    write_timeout_s: float = 1.0
    retries: int = 2

    def __post_init__(self) -> None:
        check_int(self.baudrate, "SerialSettings.baudrate", 50, 20_000_000)
        check_int(self.bytesize, "SerialSettings.bytesize", 5, 8)
        if not isinstance(self.parity, str) or self.parity not in _PARITIES:
            raise InvalidInputError(f"SerialSettings.parity: {self.parity!r} is not one of {sorted(_PARITIES)}")
        stopbits = self.stopbits
        if isinstance(stopbits, bool) or not isinstance(stopbits, (int, float)) or stopbits not in (1, 1.5, 2):
            raise InvalidInputError(f"SerialSettings.stopbits: {self.stopbits!r} must be 1, 1.5 or 2")
        check_number(self.timeout_s, "SerialSettings.timeout_s", low=0.001, high=3600, unit="s")
        check_number(self.write_timeout_s, "SerialSettings.write_timeout_s", low=0.001, high=3600, unit="s")
        check_int(self.retries, "SerialSettings.retries", 0, 10)


# --------------------------------------------------------------------------- link


class SerialLink:
    """One open serial port read against deadlines.

    Args:
        port: a device path such as ``/dev/ttyUSB0`` (or a pty slave path), or an already open
            ``serial.SerialBase`` that the link then owns.
        settings: line settings, timeouts and retries.
        device: a short name of the device used in error messages ("robot", "laser motor").
    """

    def __init__(self, port: Union[str, serial.SerialBase], settings: SerialSettings, *, device: str) -> None:
        self.settings = settings
        self.device = device
        if isinstance(port, serial.SerialBase):
            self._ser = port
            self.port_name = str(port.port)
            try:
                port.timeout = _SLICE_S
            except (*_PORT_ERRORS, ValueError) as exc:
                raise PortClosedError(
                    f"{device}: cannot set the read timeout of {self.port_name} ({exc}); "
                    "pass a port path instead and let the driver open it"
                ) from None
            return
        if not isinstance(port, str) or not port:
            raise InvalidInputError(f"{device}: port must be a device path such as '/dev/ttyUSB0', got {port!r}")
        self.port_name = port
        self._ser = self._open(port, settings, device)

    @staticmethod
    def _open(port: str, settings: SerialSettings, device: str) -> serial.Serial:
        """Opens ``port`` with ``settings``. A port whose line settings are refused is tried again
        for a short while: a pty emulator resets its stored speed a few milliseconds after each
        open (see ``devices.emulators._pty``), and a driver that reopens within them is refused
        once; a real port that refuses them still fails, after :data:`_OPEN_ATTEMPTS` tries."""
        for attempt in range(_OPEN_ATTEMPTS):
            try:
                return serial.Serial(
                    port,
                    baudrate=settings.baudrate,
                    bytesize=settings.bytesize,
                    parity=_PARITIES[settings.parity],
                    stopbits=settings.stopbits,
                    timeout=_SLICE_S,
                    write_timeout=settings.write_timeout_s,
                )
            except _SETTINGS_REFUSED as exc:
                if attempt + 1 < _OPEN_ATTEMPTS:
                    time.sleep(_OPEN_RETRY_S)
                    continue
                raise PortClosedError(
                    f"{device}: serial port {port!r} refuses the line settings {settings.baudrate} baud "
                    f"{settings.bytesize}{settings.parity}{settings.stopbits:g} ({exc}); check the port "
                    "supports them (SerialSettings)"
                ) from None
            except (serial.SerialException, OSError, ValueError) as exc:
                raise PortClosedError(
                    f"{device}: cannot open serial port {port!r} ({exc}); check that the device is plugged in, "
                    "the path is right and you may read and write it"
                ) from None
        raise AssertionError("unreachable: the last attempt returns or raises")

    # -- housekeeping
    @property
    def is_open(self) -> bool:
        """Whether the port is still open."""
        return bool(self._ser.is_open)

    def close(self) -> None:
        """Closes the port; closing twice is harmless."""
        try:
            self._ser.close()
        except (serial.SerialException, OSError):
            pass

    def deadline(self, timeout_s: Optional[float] = None) -> float:
        """The monotonic time by which a reply must be complete."""
        return time.monotonic() + (self.settings.timeout_s if timeout_s is None else timeout_s)

    @contextmanager
    def _io(self) -> Iterator[None]:
        if not self._ser.is_open:
            raise PortClosedError(f"{self.device}: serial port {self.port_name} is closed; open a new driver")
        try:
            yield
        except BinpickError:
            raise
        except _PORT_ERRORS as exc:
            raise PortClosedError(
                f"{self.device}: serial port {self.port_name} failed ({exc}); the device or adapter disappeared — "
                "check the cable and power, then open a new driver"
            ) from None

    # -- bytes
    def discard_input(self) -> None:
        """Drops whatever stale bytes wait in the input buffer."""
        with self._io():
            self._ser.reset_input_buffer()

    def write(self, data: bytes) -> None:
        """Writes all of ``data`` or raises PortClosedError / DeviceTimeout."""
        with self._io():
            try:
                self._ser.write(data)
                self._drain()
            except serial.SerialTimeoutException:
                raise DeviceTimeout(
                    f"{self.device}: writing to {self.port_name} did not finish in "
                    f"{self.settings.write_timeout_s} s; check the line and flow control"
                ) from None

    def _drain(self) -> None:
        """Waits until the written bytes have left (``tcdrain``). A signal to this process
        (a child exiting, a profiler attaching) interrupts the wait with EINTR, which Python does
        not retry for ``termios`` calls: the bytes are written, so the wait is made again."""
        for _ in range(_DRAIN_ATTEMPTS - 1):
            try:
                self._ser.flush()
                return
            except _INTERRUPTED as exc:
                if exc.args[:1] != (errno.EINTR,):
                    raise
        self._ser.flush()

    def read_some(self, n: int, deadline: float) -> bytes:
        """Up to ``n`` bytes: whatever arrives first, or b'' once the deadline has passed.

        The port's own timeout is a short slice set once at opening (changing it later would
        reprogram the line each time), so the deadline is kept here.
        """
        with self._io():
            while time.monotonic() < deadline:
                data = self._ser.read(n)
                if data:
                    return bytes(data)
        return b""

    def read_exact(self, n: int, deadline: float, *, what: str, got: bytes = b"") -> bytes:
        """Exactly ``n`` bytes by ``deadline``; ``got`` are the reply's bytes already read (for the message)."""
        buf = bytearray()
        while len(buf) < n:
            chunk = self.read_some(n - len(buf), deadline)
            if not chunk:
                self.silence(what, got + bytes(buf))
            buf += chunk
        return bytes(buf)

    def read_until(self, terminator: bytes, deadline: float, *, what: str, max_bytes: int = 4096) -> bytes:
        """Bytes up to and including ``terminator``; ProtocolError past ``max_bytes`` without one."""
        buf = bytearray()
        while not buf.endswith(terminator):
            if len(buf) >= max_bytes:
                raise ProtocolError(
                    f"{self.device}: {what} ran past {max_bytes} bytes without its terminator "
                    f"{terminator!r}: {bytes(buf[:40])!r}…"
                )
            chunk = self.read_some(1, deadline)
            if not chunk:
                self.silence(what, bytes(buf))
            buf += chunk
        return bytes(buf)

    def silence(self, what: str, got: bytes) -> None:
        """Raises for a reply that did not (fully) come: DeviceTimeout when ``got`` is empty, else
        TruncatedReplyError."""
        t = self.settings.timeout_s
        if got:
            raise TruncatedReplyError(
                f"{self.device}: {what} stopped after {len(got)} bytes ({got[:40]!r}) and "
                f"the rest did not come within {t} s; check the cable and line settings"
            )
        raise DeviceTimeout(
            f"{self.device}: no {what} on {self.port_name} within {t} s; check power, cable, "
            "baud rate and the device's address"
        )


def with_retries(attempts: int, action: Callable[[], T]) -> T:
    """Runs ``action`` up to ``1 + attempts`` times while it fails with a timeout or an unusable reply.

    Only for requests that change nothing (queries) or whose repetition is harmless; the last
    failure is raised again with the number of attempts in its message.
    """
    for attempt in range(attempts + 1):
        try:
            return action()
        except (DeviceTimeout, ProtocolError) as exc:
            if attempt == attempts:
                if attempts == 0:
                    raise
                raise restate(exc, f"{exc} (gave up after {attempts + 1} attempts)") from exc
    raise AssertionError("unreachable")  # pragma: no cover


def restate(exc: E, message: str) -> E:
    """A new exception of ``exc``'s class with ``message`` and ``exc``'s attributes (e.g. error_number)."""
    new = type(exc)(message)
    new.__dict__.update(exc.__dict__)
    return new


def raise_after_stop(exc: DeviceError, note: str) -> None:
    """Raises ``exc``'s class again with ``note`` appended, chained to ``exc``."""
    raise restate(exc, f"{exc} — {note}") from exc
