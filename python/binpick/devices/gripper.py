"""Grippers: the common interface, the robot's own hand, and an electric gripper on Modbus RTU.

:class:`MelfaHandGripper` drives the hand outputs of the MELFA controller (a pneumatic gripper
on the arm's hand interface, as in the paper's cell). :class:`ModbusGripper` drives an electric
parallel gripper with the Robotiq 2F register map over Modbus RTU:

* Frame: ``slave | function | data… | CRC_L CRC_H``; CRC-16/MODBUS (reflected polynomial 0xA001,
  initial 0xFFFF), low byte first. Default line: 115200 baud, 8N1, slave 9.
* Command: function 0x10 (write multiple registers) of 3 registers at 0x03E8 holding the bytes
  ``ACTION, 0, 0, POSITION, SPEED, FORCE``; ACTION bits: 0 rACT activate, 3 rGTO go to
  position. Reply: ``slave 10 03 E8 00 03`` + CRC.
* Status: function 0x04 (read input registers) of 3 registers at 0x07D0, answered with 6 bytes
  ``STATUS, 0, FAULT, POSITION REQUEST ECHO, POSITION, CURRENT``; STATUS bits: 0 gACT,
  3 gGTO, 4–5 gSTA (3 = activated), 6–7 gOBJ (0 moving, 1 object met opening, 2 object met
  closing, 3 arrived without object).
* Exception reply: ``slave | function|0x80 | code`` + CRC (1 illegal function, 2 illegal
  address, 3 illegal value, 4 device failure).

Position 0 is fully open and 255 fully closed; widths in mm map linearly over ``stroke_mm``.
Status reads are retried; a command is sent once, and if its reply is lost or broken the status
is read to see whether the gripper took it.
"""

from __future__ import annotations

import abc
import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Optional, Union

import serial

from .._validate import check_int, check_number
from ..errors import (
    ChecksumError,
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    InvalidInputError,
    ProtocolError,
    SafetyError,
    TruncatedReplyError,
    UnknownReplyError,
)
from ._link import SerialLink, SerialSettings, raise_after_stop, with_retries

__all__ = [
    "Gripper",
    "MelfaHandGripper",
    "modbus_crc",
    "encode_write_registers",
    "encode_read_input_registers",
    "decode_response",
    "GripperStatus",
    "GripperConfig",
    "ModbusGripper",
    "COMMAND_REGISTER",
    "STATUS_REGISTER",
]

FC_READ_HOLDING, FC_READ_INPUT, FC_WRITE_MULTIPLE = 0x03, 0x04, 0x10
COMMAND_REGISTER = 0x03E8
STATUS_REGISTER = 0x07D0
ACT, GTO = 0x01, 0x08
EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "slave device failure",
    5: "acknowledge",
    6: "slave device busy",
}
FAULT_NAMES = {
    0x05: "action delayed: activation must complete first",
    0x07: "activation bit not set",
    0x08: "temperature too high",
    0x0A: "supply voltage too low",
    0x0B: "automatic release in progress",
    0x0C: "internal fault",
    0x0D: "activation fault",
    0x0E: "overcurrent",
    0x0F: "automatic release done",
}


class Gripper(abc.ABC):
    """What the pick sequence needs of a gripper: :meth:`open` and :meth:`close`, and
    :meth:`activate`, :meth:`open_for_grasp` and :meth:`close_port` where the device has them
    (their defaults do nothing, or open fully)."""

    sets_width: bool = False
    """Whether :meth:`open_for_grasp` opens the fingers to the width asked for (then the cell
    opens each grasp only as wide as the part needs); False: it opens them fully."""

    def activate(self) -> Any:
        """Makes the gripper ready to move (a reset and activation where the device needs one); nothing by default."""

    def open_for_grasp(self, width_mm: float, *, wait: bool = True) -> None:
        """Opens the fingers at least ``width_mm`` apart for a grasp; fully by default. Without
        ``wait`` it returns once the command is sent (:meth:`settle` waits for the fingers)."""
        self.open(wait=wait)

    def release(self, width_mm: float) -> None:
        """Lets go of a held part by opening the fingers to ``width_mm``, the opening they had
        around it on the way in (so it is free of them), where the gripper sets widths; fully
        by default. Waits for the fingers."""
        self.open()

    def settle(self) -> None:
        """Waits until the fingers have done what the last command sent without waiting asked
        (nothing by default: such a gripper's commands wait)."""

    def close_port(self) -> None:
        """Releases the gripper's own connection, if it has one; nothing by default."""

    @abc.abstractmethod
    def open(self, *, wait: bool = True) -> None:
        """Opens the fingers."""

    @abc.abstractmethod
    def close(self, *, wait: bool = True) -> Optional[bool]:
        """Closes the fingers; returns whether an object is held, or None when the gripper cannot tell."""


class MelfaHandGripper(Gripper):
    """The gripper on the robot's hand outputs (HNDON/HNDOFF through a :class:`~binpick.devices.melfa.MelfaRobot`).

    Args:
        robot: the connected robot driver.
        hand: hand number, 1–8.
        settle_s: time the (pneumatic) fingers take to open or close, seconds.
    """

    def __init__(self, robot: Any, *, hand: int = 1, settle_s: float = 0.3) -> None:
        self.robot = robot
        self.hand = check_int(hand, "hand", 1, 8)
        self.settle_s = check_number(settle_s, "settle_s", low=0.0, high=60.0, unit="s")

    _settled_at = 0.0

    def open(self, *, wait: bool = True) -> None:
        """HNDON<hand>, then (with ``wait``) the settle time."""
        self.robot.open_hand(self.hand)
        self._after_command(wait)

    def close(self, *, wait: bool = True) -> Optional[bool]:
        """HNDOFF<hand>; the hand outputs carry no sensing, so None."""
        self.robot.close_hand(self.hand)
        self._after_command(wait)
        return None

    def settle(self) -> None:
        """Sleeps out what is left of the settle time of a command sent without waiting."""
        left = self._settled_at - time.monotonic()
        if left > 0:
            time.sleep(left)

    def _after_command(self, wait: bool) -> None:
        self._settled_at = time.monotonic() + self.settle_s
        if wait:
            self.settle()


# --------------------------------------------------------------------------- Modbus RTU codec


def _crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def modbus_crc(data: bytes) -> int:
    """CRC-16/MODBUS of ``data`` (send it low byte first)."""
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return crc


def _frame(body: bytes) -> bytes:
    return body + struct.pack("<H", modbus_crc(body))


def encode_write_registers(slave: int, address: int, values: Sequence[int]) -> bytes:
    """Function 0x10: write ``values`` (16-bit each) from register ``address``."""
    check_int(slave, "slave", 1, 247)
    check_int(address, "address", 0, 0xFFFF)
    if not 1 <= len(values) <= 123:
        raise InvalidInputError(f"values: 1–123 registers per write, got {len(values)}")
    regs = [check_int(v, "register value", 0, 0xFFFF) for v in values]
    return _frame(
        struct.pack(">BBHHB", slave, FC_WRITE_MULTIPLE, address, len(regs), 2 * len(regs))
        + struct.pack(f">{len(regs)}H", *regs)
    )


def encode_read_input_registers(slave: int, address: int, count: int) -> bytes:
    """Function 0x04: read ``count`` input registers from ``address``."""
    check_int(slave, "slave", 1, 247)
    check_int(address, "address", 0, 0xFFFF)
    check_int(count, "count", 1, 125)
    return _frame(struct.pack(">BBHH", slave, FC_READ_INPUT, address, count))


def response_length(head: bytes, function: int) -> int:
    """Total length of a response from its first 3 bytes (slave, function, byte count or address high)."""
    if head[1] & 0x80:
        return 5
    if head[1] in (FC_READ_HOLDING, FC_READ_INPUT):
        return 5 + head[2]
    return 8  # write replies echo address and quantity


def decode_response(raw: bytes, *, slave: int, function: int) -> bytes:
    """The data of one response to ``function`` from ``slave``.

    For reads the register bytes, for writes the echoed address and quantity. Raises
    TruncatedReplyError (too short), ChecksumError (CRC), DeviceFault (exception reply),
    UnknownReplyError (another slave or function) and ProtocolError (impossible lengths).
    """
    raw = bytes(raw)
    if len(raw) < 5:
        raise TruncatedReplyError(f"gripper: {len(raw)}-byte reply is shorter than any Modbus response")
    want = response_length(raw[:3], function)
    if len(raw) < want:
        raise TruncatedReplyError(f"gripper: reply has {len(raw)} of its {want} bytes")
    if len(raw) > want:
        raise ProtocolError(f"gripper: {len(raw) - want} unexpected bytes after the reply")
    if struct.unpack_from("<H", raw, len(raw) - 2)[0] != modbus_crc(raw[:-2]):
        raise ChecksumError(f"gripper: CRC of reply {raw[:12].hex(' ')} does not match; check for noise on the line")
    if raw[0] != slave:
        raise UnknownReplyError(f"gripper: asked slave {slave}, slave {raw[0]} answered")
    if raw[1] == function | 0x80:
        code = raw[2]
        raise DeviceFault(
            f"gripper: refused function 0x{function:02X}: exception {code} ({EXCEPTION_NAMES.get(code, 'unknown')})"
        )
    if raw[1] != function:
        raise UnknownReplyError(f"gripper: asked function 0x{function:02X}, the reply is function 0x{raw[1]:02X}")
    return raw[3:-2] if function in (FC_READ_HOLDING, FC_READ_INPUT) else raw[2:-2]


# --------------------------------------------------------------------------- driver


@dataclass(frozen=True)
class GripperStatus:
    """The gripper's status registers.

    Attributes:
        activated: gSTA = 3, activation complete.
        going: gGTO, a position command is active.
        object_state: gOBJ — 0 moving, 1 object met while opening, 2 object met while closing,
            3 arrived at the requested position without meeting an object.
        fault: fault code, 0 when none.
        position_request: echo of the requested position, 0–255.
        position: present position, 0 (open) – 255 (closed).
        current: motor current, units of about 10 mA.
    """

    activated: bool
    going: bool
    object_state: int
    fault: int
    position_request: int
    position: int
    current: int

    @classmethod
    def from_bytes(cls, data: bytes) -> GripperStatus:
        """Parses the 6 status bytes; ProtocolError for another length."""
        if len(data) != 6:
            raise ProtocolError(f"gripper: status has 6 bytes, got {len(data)}")
        st = data[0]
        return cls(((st >> 4) & 3) == 3, bool(st & GTO), st >> 6, data[2], data[3], data[4], data[5])

    @property
    def moving(self) -> bool:
        """Going and not yet stopped."""
        return self.going and self.object_state == 0

    @property
    def holding(self) -> bool:
        """Stopped by an object."""
        return self.object_state in (1, 2)


@dataclass(frozen=True)
class GripperConfig:
    """Settings of a :class:`ModbusGripper`.

    Attributes:
        slave: Modbus slave address (9 for Robotiq grippers).
        serial: line settings (115200 baud, 8N1).
        stroke_mm: finger opening at position 0, mm (fully closed at 255).
        speed: finger speed sent with each command, 0–255.
        force: grip force sent with each command, 0–255.
        max_speed: largest speed ever sent, 0–255 (the cell's limit).
        max_force: largest force ever sent, 0–255 (the cell's limit).
        activation_timeout_s: longest wait for activation, seconds.
        move_timeout_s: longest wait for a finger motion, seconds.
        poll_interval_s: pause between two status reads while waiting, seconds.
    """

    slave: int = 9
    serial: SerialSettings = SerialSettings(baudrate=115200, timeout_s=0.2)
    stroke_mm: float = 85.0
    speed: int = 128
    force: int = 100
    max_speed: int = 255
    max_force: int = 200
    activation_timeout_s: float = 5.0
    move_timeout_s: float = 5.0
    poll_interval_s: float = 0.02

    def __post_init__(self) -> None:
        check_int(self.slave, "GripperConfig.slave", 1, 247)
        if not isinstance(self.serial, SerialSettings):
            raise InvalidInputError(f"GripperConfig.serial: expected SerialSettings, got {type(self.serial).__name__}")
        check_number(self.stroke_mm, "GripperConfig.stroke_mm", low=0.1, unit="mm")
        for name in ("speed", "force", "max_speed", "max_force"):
            check_int(getattr(self, name), f"GripperConfig.{name}", 0, 255)
        if self.speed > self.max_speed or self.force > self.max_force:
            raise InvalidInputError("GripperConfig: speed and force must not exceed max_speed and max_force")
        for name in ("activation_timeout_s", "move_timeout_s", "poll_interval_s"):
            check_number(getattr(self, name), f"GripperConfig.{name}", low=1e-4, unit="s")


class ModbusGripper(Gripper):
    """An electric parallel gripper with the Robotiq 2F register map on Modbus RTU.

    Args:
        port: serial device path, or an open ``serial.SerialBase``.
        config: slave address, line settings, stroke, speed and force.
    """

    sets_width = True

    def __init__(self, port: Union[str, serial.SerialBase], *, config: GripperConfig = GripperConfig()) -> None:
        if not isinstance(config, GripperConfig):
            raise InvalidInputError(f"config: expected GripperConfig, got {type(config).__name__}")
        self.config = config
        self._link = SerialLink(port, config.serial, device="gripper")
        self._requested: Optional[int] = None  # the position of the last motion command

    def close_port(self) -> None:
        """Closes the serial port."""
        self._link.close()

    def __enter__(self) -> ModbusGripper:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close_port()

    def _exchange(self, request: bytes, function: int, *, retry: bool) -> bytes:
        def once() -> bytes:
            self._link.discard_input()
            self._link.write(request)
            deadline = self._link.deadline()
            head = self._link.read_exact(3, deadline, what="Modbus reply")
            rest = self._link.read_exact(response_length(head, function) - 3, deadline, what="Modbus reply", got=head)
            return decode_response(head + rest, slave=self.config.slave, function=function)

        return with_retries(self.config.serial.retries if retry else 0, once)

    def status(self) -> GripperStatus:
        """Reads the status registers."""
        request = encode_read_input_registers(self.config.slave, STATUS_REGISTER, 3)
        return GripperStatus.from_bytes(self._exchange(request, FC_READ_INPUT, retry=True))

    def _command(self, action: int, position: int, speed: int, force: int) -> None:
        request = encode_write_registers(
            self.config.slave, COMMAND_REGISTER, [action << 8, position, (speed << 8) | force]
        )
        try:
            self._exchange(request, FC_WRITE_MULTIPLE, retry=False)
        except (DeviceTimeout, ProtocolError) as exc:
            try:
                st = self.status()
            except DeviceError as again:
                raise_after_stop(exc, f"reading the status back failed too ({again})")
            took = st.going == bool(action & GTO) and (not action & GTO or st.position_request == position)
            if not took:
                raise_after_stop(exc, "the status shows the command was not taken")

    def activate(self) -> GripperStatus:
        """Resets and activates the gripper, waiting until activation completes."""
        self._command(0, 0, 0, 0)
        self._command(ACT, 0, 0, 0)
        return self._wait(lambda st: st.activated, self.config.activation_timeout_s, "activation")

    def move_to_width(
        self, width_mm: float, *, speed: Optional[int] = None, force: Optional[int] = None, wait: bool = True
    ) -> Optional[GripperStatus]:
        """Moves the fingers to ``width_mm`` apart; with ``wait`` returns the status once they
        stop, else None as soon as the command is sent (:meth:`settle` waits for them)."""
        cfg = self.config
        w = check_number(width_mm, "width_mm", low=0.0, high=cfg.stroke_mm, unit="mm")
        sp = cfg.speed if speed is None else check_int(speed, "speed", 0, 255)
        fo = cfg.force if force is None else check_int(force, "force", 0, 255)
        if sp > cfg.max_speed or fo > cfg.max_force:
            raise SafetyError(
                f"gripper: speed {sp} / force {fo} exceed the limits {cfg.max_speed} / {cfg.max_force}; "
                "nothing was sent — lower them or raise GripperConfig.max_speed/max_force"
            )
        position = int(round((1.0 - w / cfg.stroke_mm) * 255))
        self._command(ACT | GTO, position, sp, fo)
        self._requested = position
        if not wait:
            return None
        return self.settle()

    def settle(self) -> GripperStatus:
        """Waits until the fingers have stopped at (or on the way to) the last position asked
        for; returns the status."""
        asked = self._requested
        return self._wait(
            lambda st: (asked is None or st.position_request == asked) and not st.moving,
            self.config.move_timeout_s,
            "motion",
        )

    def open(self, *, wait: bool = True) -> None:
        """Opens fully."""
        self.move_to_width(self.config.stroke_mm, wait=wait)

    def open_for_grasp(self, width_mm: float, *, wait: bool = True) -> None:
        """Opens to ``width_mm`` (at most the stroke)."""
        self.move_to_width(min(float(width_mm), float(self.config.stroke_mm)), wait=wait)

    def release(self, width_mm: float) -> None:
        """Opens to ``width_mm`` (at most the stroke): the part held is let go."""
        self.move_to_width(min(float(width_mm), float(self.config.stroke_mm)))

    def close(self, *, wait: bool = True) -> Optional[bool]:
        """Closes fully; with ``wait`` returns whether an object stopped the fingers."""
        st = self.move_to_width(0.0, wait=wait)
        return None if st is None else st.holding

    def _wait(self, done: Any, timeout_s: float, what: str) -> GripperStatus:
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if st.fault:
                raise DeviceFault(
                    f"gripper: fault 0x{st.fault:02X} ({FAULT_NAMES.get(st.fault, 'unknown')}) during {what}"
                )
            if done(st):
                return st
            if time.monotonic() > deadline:
                raise DeviceTimeout(f"gripper: {what} did not finish within {timeout_s} s")
            time.sleep(self.config.poll_interval_s)
