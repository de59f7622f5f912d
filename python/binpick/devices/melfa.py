"""Driver for Mitsubishi MELFA controllers (CR1/CR2 class, e.g. the RV-1A's) over the R3 protocol.

Wire format implemented here (RS-232C, default 9600 baud, 8 data bits, even parity, 2 stop bits):

* Request: ``<robot>;<slot>;<COMMAND>`` + CR, ASCII, e.g. ``1;1;OPEN=NARCUSR\\r``.
* Reply: one CR-terminated line starting with a status:

  ======  ===================================================================
  QoK…    accepted, controller has no alarm; the rest of the line is the data
  Qok…    accepted, but the controller has an alarm active
  QeR…    refused; the digits that follow are the error number
  Qer…    refused while an alarm is active; digits as for QeR
  ======  ===================================================================

Commands used and the replies parsed (angles on the wire in degrees, lengths in mm):

* ``OPEN=<client>`` / ``CLOSE`` — start and end the session; ``CNTLON`` / ``CNTLOFF`` — take and
  give back operation rights; ``SRVON`` / ``SRVOFF`` — servo power; ``RSTALRM`` — reset alarm;
  ``STOP`` — stop the running motion.
* ``OVRD=<percent>`` — speed override; ``EXECSPD <mm/s>`` — straight-line speed.
* ``EXECP<n>=(X,Y,Z,A,B,C)(FL1,FL2)`` — define position variable P<n> (2 decimals), then
  ``EXECMOV P<n>`` (joint interpolation) or ``EXECMVS P<n>`` (straight line).
* ``PPOSF`` → ``QoKX;<x>;Y;<y>;Z;<z>;A;<a>;B;<b>;C;<c>;;<FL1>,<FL2>;…`` (fields after the flags
  are ignored; extra axes such as ``L1;<v>`` before the empty field are skipped).
* ``JPOSF`` → ``QoKJ1;<j1>;J2;<j2>;…;J6;<j6>;;****,****;…``.
* ``HNDON<n>`` opens hand n, ``HNDOFF<n>`` closes it.
* ``ERRORMES<error number>`` → ``QoK<message text>``.
* ``DSTATE`` → ``QoK<SS><EEEE>…`` where SS are two hex digits of status bits (0x80 operation
  rights held, 0x40 program/motion running, 0x20 servo on) and EEEE the active alarm's number
  (``0000`` when none); whatever follows is ignored. This is the subset of the controller's
  status reply the driver relies on; check it against your controller's manual.

FL1 is the posture flag (bit 2 right/left, bit 1 above/below, bit 0 non-flip/flip; 7 = R, A, N).
Conversion between transforms and (X, Y, Z, A, B, C) lives in :mod:`binpick.devices.xyzabc`.

Queries (PPOSF, JPOSF, DSTATE, ERRORMES, STOP, position definitions) and the session commands
are retried after a timeout or an unusable reply; motion commands are never sent twice. The raw
:meth:`MelfaRobot.command` sends only the queries and session commands of :data:`SAFE_COMMANDS`:
every motion, speed, override, program, jog or hand command goes through a checked method.
When anything fails after a motion has been commanded the driver sends STOP and raises the
failure with what it did.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Callable, Optional, Union

import numpy as np
import serial

from .._validate import check_int, check_number, flag
from ..errors import (
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    InvalidInputError,
    ProtocolError,
    SafetyError,
    UnknownReplyError,
)
from ._link import SerialLink, SerialSettings, raise_after_stop, restate, with_retries
from .robot import Robot
from .safety import CellLimits, check_linear_speed, check_move, check_override, check_pose, check_sequence
from .xyzabc import _as_xyzabc, transform_from_xyzabc, xyzabc_from_transform, xyzabc_from_wire, xyzabc_to_wire

__all__ = [
    "R3Reply",
    "RobotState",
    "MelfaConfig",
    "MelfaRobot",
    "encode_command",
    "parse_reply",
    "format_position",
    "posture_flags",
    "parse_position",
    "parse_joints",
    "parse_state",
    "SAFE_COMMANDS",
]

_STATUSES = {"QoK": (True, False), "Qok": (True, True), "QeR": (False, False), "Qer": (False, True)}
#: What :meth:`MelfaRobot.command` lets through, each matched against the whole command as
#: written (no leading blanks, no lower case, nothing after it): name → (pattern, what it does).
SAFE_COMMANDS: dict[str, tuple[str, str]] = {
    "PPOSF": ("PPOSF", "read the flange position"),
    "JPOSF": ("JPOSF", "read the joint angles"),
    "DSTATE": ("DSTATE", "read the controller's state bits and alarm number"),
    "ERRORMES<n>": (r"ERRORMES\d{1,5}", "read the text of an error number"),
    "OPEN=<client>": ("OPEN=[A-Za-z0-9_]{1,32}", "open the session"),
    "CLOSE": ("CLOSE", "close the session"),
    "CNTLON": ("CNTLON", "take operation rights"),
    "CNTLOFF": ("CNTLOFF", "give operation rights back"),
    "SRVON": ("SRVON", "servo power on (the arm holds where it is)"),
    "SRVOFF": ("SRVOFF", "servo power off (stops any motion)"),
    "RSTALRM": ("RSTALRM", "reset the alarm"),
    "STOP": ("STOP", "stop the running motion"),
}
_SAFE_COMMAND = re.compile("|".join(f"(?:{pattern})" for pattern, _ in SAFE_COMMANDS.values()))
_COMMAND_OK = re.compile(r"^[\x20-\x7e]{1,250}$")
_POSE_NAMES = ("X", "Y", "Z", "A", "B", "C")
_JOINT_NAMES = ("J1", "J2", "J3", "J4", "J5", "J6")

BIT_CONTROL = 0x80
BIT_RUNNING = 0x40
BIT_SERVO = 0x20


# --------------------------------------------------------------------------- codec


@dataclass(frozen=True)
class R3Reply:
    """One parsed reply line.

    Attributes:
        status: the three-letter status, ``QoK``, ``Qok``, ``QeR`` or ``Qer``.
        ok: the command was accepted (QoK, Qok).
        alarm: the controller has an alarm active (Qok, Qer).
        data: the text after the status (for QeR/Qer the error number and anything after it).
        error_number: for QeR/Qer, the controller's error number; None otherwise.
    """

    status: str
    ok: bool
    alarm: bool
    data: str
    error_number: Optional[int] = None


@dataclass(frozen=True)
class RobotState:
    """The controller's state from ``DSTATE``.

    Attributes:
        control_on: operation rights are held (CNTLON).
        moving: a motion or program is running.
        servo_on: servo power is on.
        error_number: number of the active alarm, 0 when none.
    """

    control_on: bool
    moving: bool
    servo_on: bool
    error_number: int


def encode_command(command: str, *, robot: int = 1, slot: int = 1) -> bytes:
    """``<robot>;<slot>;<command>`` + CR as ASCII bytes.

    Raises InvalidInputError for an empty command, non-printable or non-ASCII characters, or
    robot/slot numbers outside 0–99.
    """
    check_int(robot, "robot", 0, 99)
    check_int(slot, "slot", 0, 99)
    if not isinstance(command, str) or not _COMMAND_OK.match(command):
        raise InvalidInputError(f"command: {command!r} must be 1–250 printable ASCII characters without CR or LF")
    return f"{robot};{slot};{command}\r".encode("ascii")


def parse_reply(raw: bytes) -> R3Reply:
    """Parses one reply line (with or without its trailing CR).

    Raises ProtocolError for bytes that are not printable ASCII or a line too short to hold a
    status, UnknownReplyError for printable text whose status is none of QoK/Qok/QeR/Qer, and
    ProtocolError for a QeR/Qer without an error number.
    """
    if not isinstance(raw, (bytes, bytearray)):
        raise InvalidInputError(f"raw: expected bytes, got {type(raw).__name__}")
    body = bytes(raw[:-1] if raw.endswith(b"\r") else raw)
    if any(b < 0x20 or b > 0x7E for b in body):
        raise ProtocolError(
            f"robot: garbled reply {bytes(raw[:60])!r} (bytes outside printable ASCII); "
            "check baud rate, parity (even) and stop bits (2)"
        )
    text = body.decode("ascii")
    if len(text) < 3:
        raise ProtocolError(f"robot: reply {text!r} is too short to hold a status (QoK/QeR…)")
    status = text[:3]
    if status not in _STATUSES:
        raise UnknownReplyError(f"robot: unknown reply {text[:60]!r}; the R3 protocol answers QoK, Qok, QeR or Qer")
    ok, alarm = _STATUSES[status]
    data = text[3:]
    if ok:
        return R3Reply(status, ok, alarm, data)
    digits = re.match(r"\d+", data)
    if not digits:
        raise ProtocolError(f"robot: error reply {text[:60]!r} lacks its error number")
    return R3Reply(status, ok, alarm, data, int(digits.group()))


def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ProtocolError(f"robot: {what} {text!r} is not a number") from None
    if not math.isfinite(v):
        raise ProtocolError(f"robot: {what} {text!r} is not finite")
    return v


def _named_values(data: str, names: tuple[str, ...], what: str) -> tuple[np.ndarray, list]:
    """Values of ``name;value;`` pairs up to the first empty field, then the remaining fields."""
    fields = data.split(";")
    values = {}
    i = 0
    while i < len(fields) and fields[i] != "":
        if i + 1 >= len(fields):
            raise ProtocolError(f"robot: {what} reply {data[:80]!r} ends inside a name;value pair")
        values[fields[i]] = _number(fields[i + 1], f"{what} value of {fields[i]}")
        i += 2
    missing = [n for n in names if n not in values]
    if missing:
        raise ProtocolError(f"robot: {what} reply {data[:80]!r} lacks {', '.join(missing)}")
    return np.array([values[n] for n in names]), fields[i + 1 :]


def parse_position(data: str) -> tuple[np.ndarray, tuple[int, int]]:
    """(X, Y, Z, A, B, C) in mm and degrees and the flags (FL1, FL2) from a PPOSF reply's data."""
    xyzabc, rest = _named_values(data, _POSE_NAMES, "PPOSF")
    m = re.fullmatch(r"(\d+),(-?\d+)", rest[0]) if rest else None
    if not m:
        raise ProtocolError(f"robot: PPOSF reply {data[:80]!r} lacks the posture flags 'FL1,FL2'")
    return xyzabc, (int(m.group(1)), int(m.group(2)))


def parse_joints(data: str) -> np.ndarray:
    """Joint angles J1..J6 in degrees from a JPOSF reply's data."""
    return _named_values(data, _JOINT_NAMES, "JPOSF")[0]


def parse_state(data: str) -> RobotState:
    """The state bits and alarm number from a DSTATE reply's data (see the module docstring)."""
    m = re.match(r"([0-9A-Fa-f]{2})(\d{4})?", data)
    if not m:
        raise ProtocolError(f"robot: DSTATE reply {data[:40]!r} does not start with two hex status digits")
    bits = int(m.group(1), 16)
    return RobotState(bool(bits & BIT_CONTROL), bool(bits & BIT_RUNNING), bool(bits & BIT_SERVO), int(m.group(2) or 0))


def format_position(number: int, xyzabc_deg: Any, flags: tuple[int, int]) -> str:
    """``P<n>=(X,Y,Z,A,B,C)(FL1,FL2)`` with two decimals, the body of an EXECP command."""
    check_int(number, "position number", 1, 999)
    v = [check_number(x, "xyzabc_deg", low=-99999.0, high=99999.0) for x in _as_xyzabc(xyzabc_deg, "xyzabc_deg")]
    fl1, fl2 = posture_flags(flags, "flags")
    return f"P{number}=(" + ",".join(f"{x:.2f}" for x in v) + f")({fl1},{fl2})"


def posture_flags(flags: Any, name: str) -> tuple[int, int]:
    """``(FL1, FL2)`` checked: FL1 0–7, FL2 a 32-bit integer, or InvalidInputError naming ``name``."""
    if not isinstance(flags, (tuple, list)) or len(flags) != 2:
        raise InvalidInputError(f"{name}: expected the posture flags (FL1, FL2), got {flags!r:.60}")
    return check_int(flags[0], f"{name}[0] (FL1)", 0, 7), check_int(flags[1], f"{name}[1] (FL2)", -(2**31), 2**31 - 1)


# --------------------------------------------------------------------------- driver


@dataclass(frozen=True)
class MelfaConfig:
    """Settings of a :class:`MelfaRobot`.

    Attributes:
        serial: line settings; R3 over RS-232C defaults to 9600 baud, 8E2, 2 s per reply.
        robot_number: the ``<robot>`` field of every request.
        slot: the ``<slot>`` field of every request.
        client_name: the name sent with ``OPEN=``.
        position_variable: number n of the position variable P<n> used for moves.
        default_flags: (FL1, FL2) used when the arm's current flags cannot be read.
        initial_override_percent: override set when the session opens, percent.
        initial_linear_speed_mm_s: straight-line speed set when the session opens, mm/s.
        servo_on_timeout_s: longest wait for servo power after SRVON, seconds.
        motion_timeout_s: longest wait for one motion to finish, seconds.
        poll_interval_s: pause between two DSTATE polls while waiting, seconds.
        arrival_tolerance_mm: largest distance between target and reached position, mm.
    """

    serial: SerialSettings = SerialSettings(baudrate=9600, bytesize=8, parity="E", stopbits=2, timeout_s=2.0)
    robot_number: int = 1
    slot: int = 1
    client_name: str = "NARCUSR"
    position_variable: int = 1
    default_flags: tuple[int, int] = (7, 0)
    initial_override_percent: float = 10.0
    initial_linear_speed_mm_s: float = 50.0
    servo_on_timeout_s: float = 5.0
    motion_timeout_s: float = 60.0
    poll_interval_s: float = 0.05
    arrival_tolerance_mm: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.serial, SerialSettings):
            raise InvalidInputError(f"MelfaConfig.serial: expected SerialSettings, got {type(self.serial).__name__}")
        check_int(self.robot_number, "MelfaConfig.robot_number", 0, 99)
        check_int(self.slot, "MelfaConfig.slot", 0, 99)
        if not re.fullmatch(r"[A-Za-z0-9_]{1,32}", str(self.client_name)):
            raise InvalidInputError(f"MelfaConfig.client_name: {self.client_name!r} must be 1–32 letters/digits")
        check_int(self.position_variable, "MelfaConfig.position_variable", 1, 999)
        posture_flags(self.default_flags, "MelfaConfig.default_flags")
        check_number(self.initial_override_percent, "MelfaConfig.initial_override_percent", low=1, high=100, unit="%")
        check_number(self.initial_linear_speed_mm_s, "MelfaConfig.initial_linear_speed_mm_s", low=0.001, unit="mm/s")
        for name in ("servo_on_timeout_s", "motion_timeout_s", "poll_interval_s"):
            check_number(getattr(self, name), f"MelfaConfig.{name}", low=0.001, high=86400, unit="s")
        check_number(self.arrival_tolerance_mm, "MelfaConfig.arrival_tolerance_mm", low=0.0, unit="mm")


class MelfaRobot(Robot):
    """A MELFA arm driven over R3; every motion is checked against ``limits`` before it is sent.

    Use as a context manager to open and close the session::

        with MelfaRobot("/dev/ttyUSB0", limits=CellLimits()) as robot:
            robot.move_to(T_base_flange, linear=True)

    Args:
        port: serial device path, or an open ``serial.SerialBase``.
        config: protocol and timing settings.
        limits: the cell's workspace, approach and speed rules.
    """

    def __init__(
        self,
        port: Union[str, serial.SerialBase],
        *,
        config: MelfaConfig = MelfaConfig(),
        limits: CellLimits = CellLimits(),
    ) -> None:
        if not isinstance(config, MelfaConfig):
            raise InvalidInputError(f"config: expected MelfaConfig, got {type(config).__name__}")
        if not isinstance(limits, CellLimits):
            raise InvalidInputError(f"limits: expected CellLimits, got {type(limits).__name__}")
        self.config = config
        self.limits = limits
        self.alarm_active = False
        self._link = SerialLink(port, config.serial, device="robot")

    # -- life cycle
    def __enter__(self) -> MelfaRobot:
        try:
            self.open_session()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        try:
            if self._link.is_open:
                self.close_session()
        except DeviceError:
            if exc_type is None:
                raise  # otherwise the failure that ended the block is the one to see
        finally:
            self.close()

    def close(self) -> None:
        """Closes the serial port (the session should be closed first)."""
        self._link.close()

    def open_session(self) -> None:
        """OPEN, CNTLON, SRVON (waiting for servo power), then the initial override and speed.

        Each is harmless to repeat, so a lost or unusable reply is retried (``serial.retries``
        times) before DeviceTimeout or ProtocolError is raised.
        """
        cfg = self.config
        self._send(f"OPEN={cfg.client_name}", retry=True)
        self._send("CNTLON", retry=True)
        self._send("SRVON", retry=True)
        deadline = time.monotonic() + cfg.servo_on_timeout_s
        while not self.state().servo_on:
            if time.monotonic() > deadline:
                raise DeviceTimeout(
                    f"robot: servo power not on {cfg.servo_on_timeout_s} s after SRVON; check the "
                    "emergency stop, the door switch and the controller's display"
                )
            time.sleep(cfg.poll_interval_s)
        self.set_override(cfg.initial_override_percent)
        self.set_linear_speed(cfg.initial_linear_speed_mm_s)

    def close_session(self) -> None:
        """SRVOFF, CNTLOFF and CLOSE, each retried like :meth:`open_session`'s; all three are
        tried, the first failure is raised after."""
        first: Optional[DeviceError] = None
        for cmd in ("SRVOFF", "CNTLOFF", "CLOSE"):
            try:
                self._send(cmd, retry=True)
            except DeviceError as exc:
                first = first or exc
        if first is not None:
            raise first

    # -- transactions
    def command(self, command: str, *, retry: bool = False) -> R3Reply:
        """Sends one raw R3 command from an allowlist and returns the accepted reply.

        Only queries and session commands pass (:data:`SAFE_COMMANDS`): ``PPOSF``, ``JPOSF``,
        ``DSTATE``, ``ERRORMES<n>``, ``OPEN=<client>``, ``CLOSE``, ``CNTLON``, ``CNTLOFF``,
        ``SRVON``, ``SRVOFF``, ``RSTALRM`` and ``STOP``, each matched whole and case as written.
        Everything else is refused with SafetyError before a byte is sent: anything that moves the
        arm (``EXEC…`` statements such as ``EXECMOV``, ``EXECMVS``, ``EXECP<n>=``), starts or
        selects a program (``RUN…``, ``PRGLOAD…``), jogs (``JOG…``), changes speed or override
        (``OVRD``, ``EXECSPD``), or opens or closes the hand. An allowlist, not a list of what to
        refuse, because the controller's command set is large and any ``EXEC`` prefix runs a
        MELFA-BASIC statement: the checked methods (:meth:`move_to`, :meth:`move_sequence`,
        :meth:`set_override`, :meth:`set_linear_speed`, :meth:`open_hand`, :meth:`close_hand`)
        are the only way to move anything. ``retry`` resends after a timeout or an unusable reply
        (every allowed command is harmless to repeat). A refusal (QeR/Qer) raises DeviceFault
        carrying the controller's error number and its ERRORMES text.
        """
        if not isinstance(command, str):
            raise InvalidInputError(f"command: expected a string such as 'PPOSF', got {type(command).__name__}")
        if not _SAFE_COMMAND.fullmatch(command):
            raise SafetyError(
                f"command: {command[:60]!r} is not one of the queries and session commands command() allows "
                f"({', '.join(SAFE_COMMANDS)}); "
                "nothing was sent — move with move_to or move_sequence, set speeds with set_override or "
                "set_linear_speed, drive the hand with open_hand or close_hand"
            )
        return self._send(command, retry=retry)

    def _send(self, command: str, *, retry: bool = False, parse: Optional[Callable[[str], Any]] = None) -> Any:
        """One transaction; returns the reply, or ``parse(reply.data)`` when ``parse`` is given.

        With ``parse``, an accepted reply whose data does not parse is taken for a late answer
        to an earlier request and skipped while the deadline allows.
        """
        frame = encode_command(command, robot=self.config.robot_number, slot=self.config.slot)
        what = f"reply to {command!r}"

        def once() -> tuple[R3Reply, Any]:
            self._link.discard_input()
            self._link.write(frame)
            deadline = self._link.deadline()
            stale: Optional[ProtocolError] = None
            while True:
                try:
                    reply = parse_reply(self._link.read_until(b"\r", deadline, what=what))
                except DeviceTimeout:
                    if stale is None:
                        raise
                    raise ProtocolError(f"{stale} (no fitting reply followed)") from None
                if parse is None or not reply.ok:
                    return reply, None
                try:
                    return reply, parse(reply.data)
                except ProtocolError as exc:
                    stale = exc

        reply, parsed = with_retries(self.config.serial.retries if retry else 0, once)
        self.alarm_active = reply.alarm
        if not reply.ok:
            self._refused(command, reply)
        return reply if parse is None else parsed

    def _refused(self, command: str, reply: R3Reply) -> None:
        if command.startswith("ERRORMES"):  # no text to fetch for the text request itself
            err = DeviceFault(f"robot: the controller refused {command!r} with error {reply.error_number}")
            err.error_number = reply.error_number  # type: ignore[attr-defined]
            raise err
        raise self._fault(int(reply.error_number or 0), f"the controller refused {command!r} with")

    def _fault(self, number: int, what: str) -> DeviceFault:
        try:
            text = self.error_message(number)
        except DeviceError as exc:
            text = f"(its text could not be read: {exc})"
        err = DeviceFault(f"robot: {what} error {number}: {text}")
        err.error_number = number  # type: ignore[attr-defined]
        return err

    def error_message(self, error_number: int) -> str:
        """The controller's text for ``error_number`` (ERRORMES)."""
        check_int(error_number, "error_number", 0, 99999)
        reply = self._send(f"ERRORMES{error_number}", retry=True)
        return reply.data.strip()

    # -- queries
    def state(self) -> RobotState:
        """Operation rights, servo power, running and alarm number (DSTATE)."""
        return self._send("DSTATE", retry=True, parse=parse_state)

    def read_xyzabc(self) -> tuple[np.ndarray, tuple[int, int]]:
        """The flange pose as (X, Y, Z, A, B, C) in mm and radians, and the posture flags (PPOSF)."""
        deg, flags = self._send("PPOSF", retry=True, parse=parse_position)
        return xyzabc_from_wire(deg), flags

    def read_pose(self) -> np.ndarray:
        """The flange pose ``T_base_flange`` (4×4, mm)."""
        return transform_from_xyzabc(self.read_xyzabc()[0])

    def read_joints(self) -> np.ndarray:
        """Joint angles J1..J6 in radians (JPOSF)."""
        return np.radians(self._send("JPOSF", retry=True, parse=parse_joints))

    # -- settings
    def set_override(self, percent: float) -> None:
        """Speed override in percent, refused above ``limits.max_override_percent``."""
        v = check_override(percent, self.limits)
        self._send(f"OVRD={int(round(v))}", retry=True)

    def set_linear_speed(self, speed_mm_s: float) -> None:
        """Straight-line speed in mm/s, refused above ``limits.max_linear_speed_mm_s``."""
        v = check_linear_speed(speed_mm_s, self.limits)
        self._send(f"EXECSPD {v:.2f}", retry=True)

    def reset_alarm(self) -> None:
        """Resets the controller's alarm (RSTALRM)."""
        self._send("RSTALRM", retry=True)

    # -- hand
    def open_hand(self, hand: int = 1) -> None:
        """Opens hand ``hand`` (HNDON<n>)."""
        self._send(f"HNDON{check_int(hand, 'hand', 1, 8)}")

    def close_hand(self, hand: int = 1) -> None:
        """Closes hand ``hand`` (HNDOFF<n>)."""
        self._send(f"HNDOFF{check_int(hand, 'hand', 1, 8)}")

    # -- motion
    def stop(self) -> None:
        """Stops the arm (STOP); harmless to repeat, so it is retried."""
        self._send("STOP", retry=True)

    def wait_until_idle(self, timeout_s: Optional[float] = None) -> None:
        """Polls DSTATE until nothing runs; DeviceFault if an alarm appears, DeviceTimeout past the timeout."""
        limit = self.config.motion_timeout_s if timeout_s is None else check_number(timeout_s, "timeout_s", low=0)
        deadline = time.monotonic() + limit
        while True:
            st = self.state()
            if st.error_number:
                raise self._fault(st.error_number, "alarm during motion:")
            if not st.moving:
                return
            if time.monotonic() > deadline:
                raise DeviceTimeout(f"robot: the motion did not finish within {limit} s")
            time.sleep(self.config.poll_interval_s)

    def move_to(
        self, T_base_flange: Any, *, linear: bool = False, flags: Optional[tuple[int, int]] = None, wait: bool = True
    ) -> None:
        """Moves the flange to ``T_base_flange`` (MOV, or MVS when ``linear``).

        The target is checked against the cell's limits (SafetyError, nothing sent), then the
        move from the current pose is checked against the approach rules. ``flags`` default to
        the arm's current posture flags. With ``wait`` the call returns when the arm has arrived.
        """
        linear, wait = flag(linear, "linear"), flag(wait, "wait")
        target = check_pose(T_base_flange, self.limits)
        start_xyzabc, start_flags = self.read_xyzabc()
        check_move(transform_from_xyzabc(start_xyzabc), target, linear=linear, limits=self.limits)
        self._execute(target, linear, start_flags if flags is None else flags, wait)

    def move_sequence(self, targets: Sequence[Any], *, linear: Union[bool, Sequence[bool]] = False) -> None:
        """Moves through ``targets`` in order, each step waited for.

        The whole sequence is checked before the first byte of it is sent. If a step fails,
        the arm is stopped, later steps are not sent, and the failure is raised naming the step.
        """
        targets = list(targets)
        if isinstance(linear, (list, tuple, np.ndarray)):
            lin = [flag(v, f"linear[{i}]") for i, v in enumerate(linear)]
        else:
            lin = [flag(linear, "linear")] * len(targets)
        for i, T in enumerate(targets):
            check_pose(T, self.limits, name=f"targets[{i}]")
        start_xyzabc, flags = self.read_xyzabc()
        checked = check_sequence(transform_from_xyzabc(start_xyzabc), targets, lin, self.limits)
        for i, (T, is_linear) in enumerate(zip(checked, lin)):
            try:
                self._execute(T, is_linear, flags, True)
            except DeviceError as exc:
                raise restate(exc, f"step {i + 1} of {len(checked)} failed, later steps were not sent: {exc}") from exc

    def _execute(self, target: np.ndarray, linear: bool, flags: tuple[int, int], wait: bool) -> None:
        n = self.config.position_variable
        self._send("EXEC" + format_position(n, xyzabc_to_wire(xyzabc_from_transform(target)), flags), retry=True)
        verb = "MVS" if linear else "MOV"
        try:
            self._send(f"EXEC{verb} P{n}")
            if wait:
                self.wait_until_idle()
                reached = self.read_pose()
                miss = float(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
                if miss > self.config.arrival_tolerance_mm:
                    raise DeviceFault(
                        f"robot: the arm stopped {miss:.2f} mm from the target (tolerance "
                        f"{self.config.arrival_tolerance_mm} mm)"
                    )
        except DeviceError as exc:
            raise_after_stop(exc, self._stop_after_fault())

    def _stop_after_fault(self) -> str:
        try:
            self.stop()
        except DeviceError as exc:
            return f"STOP could not be sent ({exc}); stop the arm by hand"
        return "the arm was stopped (STOP sent)"
