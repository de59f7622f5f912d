"""Dynamixel Protocol 2.0: the packet codec, a bus driver and the laser-motor driver on top.

Packet (little-endian fields)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM… | CRC_L CRC_H

* LEN counts the bytes after itself: instruction, (stuffed) parameters and the 2 CRC bytes.
* Byte stuffing: wherever ``FF FF FD`` occurs in the instruction and parameters, an ``FD`` is
  inserted after it (``FF FF FD`` → ``FF FF FD FD``); LEN counts the stuffed bytes and the CRC
  is computed over them.
* CRC-16: polynomial 0x8005, initial value 0, no reflection, no final XOR (CRC-16/BUYPASS),
  over everything from the header to the last parameter byte.
* Status packet: INST = 0x55, then an ERROR byte (bit 7 = hardware alert; bits 0–6: 1 result
  fail, 2 instruction error, 3 CRC error, 4 data range, 5 data length, 6 data limit, 7 access),
  then the parameters. A PING status carries model number (2 bytes) and firmware version.

Instructions used: PING 0x01, READ 0x02 (address, length: 2 bytes each), WRITE 0x03 (address,
data). Control-table addresses are those of the X series: torque enable 64, profile velocity
112 (0.229 rpm units), goal position 116, moving 122, moving status 123 (bit 0 in position, bit 1
profile ongoing), present position 132 (4 bytes, 4096 ticks per revolution). Reads are retried
after a timeout or unusable status; writes are never sent twice: after a failed write the driver
reads the address back and accepts it only if it holds the written value. A move is reported
only once the motor's status says it has stopped, with the angle read after that.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Optional, Union

import serial

from .._validate import check_int, check_number
from ..errors import (
    ChecksumError,
    DeviceError,
    DeviceFault,
    DeviceTimeout,
    InvalidInputError,
    InvalidTypeError,
    ProtocolError,
    TruncatedReplyError,
    UnknownReplyError,
)
from ._link import SerialLink, SerialSettings, raise_after_stop, with_retries
from .motor import LaserMotor, MotorRange

__all__ = [
    "HEADER",
    "BROADCAST_ID",
    "INST_PING",
    "INST_READ",
    "INST_WRITE",
    "INST_STATUS",
    "ADDR_TORQUE_ENABLE",
    "ADDR_PROFILE_VELOCITY",
    "ADDR_GOAL_POSITION",
    "ADDR_MOVING",
    "ADDR_MOVING_STATUS",
    "MOVING_STATUS_IN_POSITION",
    "MOVING_STATUS_PROFILE_ONGOING",
    "ADDR_PRESENT_POSITION",
    "crc16",
    "stuff",
    "unstuff",
    "encode_packet",
    "encode_ping",
    "encode_read",
    "encode_write",
    "Packet",
    "StatusPacket",
    "decode_packet",
    "decode_status",
    "DynamixelBus",
    "DynamixelConfig",
    "DynamixelMotor",
]

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
INST_PING, INST_READ, INST_WRITE, INST_STATUS = 0x01, 0x02, 0x03, 0x55
ADDR_TORQUE_ENABLE = 64
ADDR_PROFILE_VELOCITY = 112
ADDR_GOAL_POSITION = 116
ADDR_MOVING = 122
ADDR_MOVING_STATUS = 123
MOVING_STATUS_IN_POSITION = 0x01
MOVING_STATUS_PROFILE_ONGOING = 0x02
ADDR_PRESENT_POSITION = 132
MAX_LENGTH = 1024  # longest LEN this driver accepts in a reply
_MAX_GARBAGE = 512  # bytes skipped while looking for a header before giving up

ERROR_NAMES = {
    1: "result fail",
    2: "instruction error",
    3: "CRC error",
    4: "data range error",
    5: "data length error",
    6: "data limit error",
    7: "access error",
}


def _crc_table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16 with polynomial 0x8005, initial value 0, unreflected, as Protocol 2.0 uses."""
    crc = 0
    for b in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(payload: bytes) -> bytes:
    """Inserts ``FD`` after every ``FF FF FD`` in ``payload``."""
    out = bytearray()
    for b in payload:
        out.append(b)
        if out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes) -> bytes:
    """Removes the ``FD`` that follows every ``FF FF FD`` in ``payload``."""
    out = bytearray()
    i = 0
    while i < len(payload):
        out.append(payload[i])
        if out[-3:] == b"\xff\xff\xfd" and i + 1 < len(payload) and payload[i + 1] == 0xFD:
            i += 1
        i += 1
    return bytes(out)


def encode_packet(motor_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete packet: header, ID, length, instruction, stuffed parameters, CRC."""
    check_int(motor_id, "motor_id", 0, 0xFE)
    check_int(instruction, "instruction", 0, 0xFF)
    if not isinstance(params, (bytes, bytearray)):  # bytes(n) of an int would be n zero bytes
        raise InvalidTypeError(f"params: expected bytes, got {type(params).__name__}")
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    if length > 0xFFFF:
        raise InvalidInputError(f"params: {len(params)} bytes do not fit a Protocol 2.0 packet")
    packet = HEADER + bytes([motor_id]) + struct.pack("<H", length) + body
    return packet + struct.pack("<H", crc16(packet))


def encode_ping(motor_id: int) -> bytes:
    """PING packet."""
    return encode_packet(motor_id, INST_PING)


def encode_read(motor_id: int, address: int, length: int) -> bytes:
    """READ packet for ``length`` bytes from ``address``."""
    check_int(address, "address", 0, 0xFFFF)
    check_int(length, "length", 1, 0xFFFF)
    return encode_packet(motor_id, INST_READ, struct.pack("<HH", address, length))


def encode_write(motor_id: int, address: int, data: bytes) -> bytes:
    """WRITE packet putting ``data`` at ``address``."""
    check_int(address, "address", 0, 0xFFFF)
    if not isinstance(data, (bytes, bytearray)):
        raise InvalidTypeError(f"data: expected bytes, got {type(data).__name__}")
    if not data:
        raise InvalidInputError("data: a WRITE needs at least one byte")
    return encode_packet(motor_id, INST_WRITE, struct.pack("<H", address) + bytes(data))


@dataclass(frozen=True)
class Packet:
    """A decoded packet.

    Attributes:
        motor_id: the ID byte.
        instruction: the instruction byte (0x55 for a status).
        params: the parameters, stuffing removed.
    """

    motor_id: int
    instruction: int
    params: bytes


@dataclass(frozen=True)
class StatusPacket:
    """A decoded status packet.

    Attributes:
        motor_id: the ID of the answering device.
        error: the ERROR byte (bit 7 hardware alert, bits 0–6 the error number).
        params: the parameters after the error byte.
    """

    motor_id: int
    error: int
    params: bytes

    @property
    def alert(self) -> bool:
        """Bit 7: the device has a hardware error (see its Hardware Error Status)."""
        return bool(self.error & 0x80)

    @property
    def error_code(self) -> int:
        """Bits 0–6: 0 when the instruction was carried out."""
        return self.error & 0x7F

    def describe_error(self) -> str:
        """Human-readable error byte."""
        parts = []
        if self.error_code:
            parts.append(ERROR_NAMES.get(self.error_code, f"error {self.error_code}"))
        if self.alert:
            parts.append("hardware alert (read Hardware Error Status at address 70, then reboot the motor)")
        return ", ".join(parts) or "no error"


def decode_packet(raw: bytes) -> Packet:
    """Decodes exactly one packet.

    Raises TruncatedReplyError when ``raw`` is shorter than its header or LEN say,
    ProtocolError for a bad header, impossible LEN or trailing bytes, and ChecksumError when the
    CRC does not match.
    """
    raw = bytes(raw)
    if len(raw) < 7:
        if HEADER.startswith(raw[:4]):
            raise TruncatedReplyError(f"dynamixel: packet of {len(raw)} bytes ends inside its header: {raw.hex(' ')}")
        raise ProtocolError(f"dynamixel: {raw.hex(' ')!r} is not a Protocol 2.0 packet")
    if raw[:4] != HEADER:
        raise ProtocolError(f"dynamixel: packet starts with {raw[:4].hex(' ')}, not the header FF FF FD 00")
    length = struct.unpack_from("<H", raw, 5)[0]
    if length < 3:
        raise ProtocolError(f"dynamixel: LEN {length} is too small (instruction and CRC need 3)")
    if len(raw) < 7 + length:
        raise TruncatedReplyError(f"dynamixel: packet says {length} bytes follow LEN but {len(raw) - 7} came")
    if len(raw) > 7 + length:
        raise ProtocolError(f"dynamixel: {len(raw) - 7 - length} unexpected bytes after the packet")
    got = struct.unpack_from("<H", raw, len(raw) - 2)[0]
    want = crc16(raw[:-2])
    if got != want:
        raise ChecksumError(
            f"dynamixel: CRC {got:04X} does not match the packet's {want:04X}; "
            "check for noise or a second master on the bus"
        )
    body = unstuff(raw[7:-2])
    return Packet(raw[4], body[0], body[1:])


def decode_status(raw: bytes) -> StatusPacket:
    """Decodes one status packet; UnknownReplyError when the packet is not a status (0x55)."""
    packet = decode_packet(raw)
    if packet.instruction != INST_STATUS:
        raise UnknownReplyError(
            f"dynamixel: expected a status packet (0x55), got instruction "
            f"0x{packet.instruction:02X} from ID {packet.motor_id}"
        )
    if not packet.params:
        raise ProtocolError(f"dynamixel: status packet from ID {packet.motor_id} lacks its error byte")
    return StatusPacket(packet.motor_id, packet.params[0], packet.params[1:])


# --------------------------------------------------------------------------- bus


class DynamixelBus:
    """Instruction → status transactions on one Protocol 2.0 bus.

    Args:
        port: serial device path, or an open ``serial.SerialBase``.
        settings: line settings; Dynamixel X motors default to 57600 baud, 8N1.
    """

    def __init__(
        self,
        port: Union[str, serial.SerialBase],
        *,
        settings: SerialSettings = SerialSettings(baudrate=57600, timeout_s=0.1),
    ) -> None:
        self.link = SerialLink(port, settings, device="dynamixel")

    def close(self) -> None:
        """Closes the port."""
        self.link.close()

    def _read_raw(self, deadline: float) -> bytes:
        window = bytearray()
        while not window.endswith(HEADER):
            if len(window) > _MAX_GARBAGE:
                raise ProtocolError(
                    f"dynamixel: {len(window)} bytes without a packet header; check baud rate and "
                    "that only one master drives the bus"
                )
            b = self.link.read_some(1, deadline)
            if not b:
                if window and not any(HEADER.startswith(window[-k:]) for k in range(1, 4)):
                    raise ProtocolError(
                        f"dynamixel: garbled reply, {len(window)} bytes without a packet header: "
                        f"{bytes(window[:32]).hex(' ')}"
                    )
                self.link.silence("status packet", bytes(window))
            window += b
        head = self.link.read_exact(3, deadline, what="status packet", got=HEADER)
        length = struct.unpack_from("<H", head, 1)[0]
        if not 3 <= length <= MAX_LENGTH:
            raise ProtocolError(f"dynamixel: status packet announces LEN {length}, outside 3–{MAX_LENGTH}")
        return HEADER + head + self.link.read_exact(length, deadline, what="status packet", got=HEADER + head)

    def transact(
        self, motor_id: int, instruction: int, params: bytes = b"", *, retry: bool, expect: Optional[int] = None
    ) -> StatusPacket:
        """Sends one instruction and returns the matching status; DeviceFault when its error byte is set.

        ``retry`` resends after a timeout or unusable status: only for instructions that change nothing.
        ``expect``: the status's parameter bytes. A status carries no instruction, so one of another
        length is a late answer to an earlier request (its timeout passed under load): unusable, and
        the request is sent again like any other unusable reply.
        """
        check_int(motor_id, "motor_id", 0, 0xFD)
        packet = encode_packet(motor_id, instruction, params)

        def once() -> StatusPacket:
            self.link.discard_input()
            self.link.write(packet)
            status = decode_status(self._read_raw(self.link.deadline()))
            if status.motor_id != motor_id:
                raise UnknownReplyError(f"dynamixel: asked ID {motor_id}, status came from ID {status.motor_id}")
            if expect is not None and len(status.params) != expect and not status.error:
                raise ProtocolError(
                    f"dynamixel: asked ID {motor_id} for {expect} bytes, got a status of {len(status.params)} "
                    "(a late answer to an earlier request)"
                )
            return status

        status = with_retries(self.link.settings.retries if retry else 0, once)
        if status.error:
            raise DeviceFault(
                f"dynamixel: motor {motor_id} refused instruction 0x{instruction:02X}: {status.describe_error()}"
            )
        return status

    def ping(self, motor_id: int) -> tuple[int, int]:
        """(model number, firmware version) of ``motor_id``."""
        st = self.transact(motor_id, INST_PING, retry=True)
        if len(st.params) != 3:
            raise ProtocolError(f"dynamixel: ping status of ID {motor_id} carries {len(st.params)} bytes, not 3")
        return struct.unpack_from("<H", st.params)[0], st.params[2]

    def read(self, motor_id: int, address: int, length: int) -> bytes:
        """``length`` bytes of ``motor_id``'s control table from ``address``."""
        check_int(address, "address", 0, 0xFFFF)
        check_int(length, "length", 1, MAX_LENGTH - 4)
        st = self.transact(motor_id, INST_READ, struct.pack("<HH", address, length), retry=True, expect=length)
        if len(st.params) != length:
            raise ProtocolError(f"dynamixel: asked {length} bytes at {address} of ID {motor_id}, got {len(st.params)}")
        return st.params

    def write(self, motor_id: int, address: int, data: bytes) -> None:
        """Writes ``data`` at ``address``; sent once, and after a lost or broken status read back to check."""
        check_int(address, "address", 0, 0xFFFF)
        try:
            self.transact(motor_id, INST_WRITE, struct.pack("<H", address) + bytes(data), retry=False)
        except (DeviceTimeout, ProtocolError) as exc:
            try:
                held = self.read(motor_id, address, len(data))
            except DeviceError as again:
                raise_after_stop(exc, f"reading address {address} back failed too ({again})")
            if held != bytes(data):
                raise_after_stop(
                    exc, f"address {address} holds {held.hex(' ')}, not the written {bytes(data).hex(' ')}"
                )


# --------------------------------------------------------------------------- motor


@dataclass(frozen=True)
class DynamixelConfig:
    """Settings of a :class:`DynamixelMotor`.

    Attributes:
        motor_id: the motor's ID on the bus, 0–252.
        serial: line settings (X series default: 57600 baud, 8N1).
        range: allowed angles, speed limit and arrival tolerance.
        ticks_per_revolution: position units per turn (4096 for the X series).
        zero_tick: the position value of angle 0 (the centre, 2048).
        velocity_unit_rpm: one profile-velocity unit, rpm (0.229 for the X series).
    """

    motor_id: int = 1
    serial: SerialSettings = SerialSettings(baudrate=57600, timeout_s=0.1)
    range: MotorRange = MotorRange()
    ticks_per_revolution: int = 4096
    zero_tick: int = 2048
    velocity_unit_rpm: float = 0.229

    def __post_init__(self) -> None:
        check_int(self.motor_id, "DynamixelConfig.motor_id", 0, 252)
        check_int(self.ticks_per_revolution, "DynamixelConfig.ticks_per_revolution", 2, 1 << 24)
        check_int(self.zero_tick, "DynamixelConfig.zero_tick", -(1 << 30), 1 << 30)
        check_number(self.velocity_unit_rpm, "DynamixelConfig.velocity_unit_rpm", low=1e-6, high=100.0, unit="rpm")
        if not isinstance(self.range, MotorRange) or not isinstance(self.serial, SerialSettings):
            raise InvalidInputError("DynamixelConfig: range must be a MotorRange and serial a SerialSettings")


class DynamixelMotor(LaserMotor):
    """The laser motor as a Dynamixel (X series, position mode) over Protocol 2.0.

    Args:
        port: serial device path, or an open ``serial.SerialBase``.
        config: ID, line settings, range and units.
    """

    def __init__(self, port: Union[str, serial.SerialBase], *, config: DynamixelConfig = DynamixelConfig()) -> None:
        super().__init__()
        if not isinstance(config, DynamixelConfig):
            raise InvalidInputError(f"config: expected DynamixelConfig, got {type(config).__name__}")
        self.config = config
        self.range = config.range
        self.bus = DynamixelBus(port, settings=config.serial)
        self._link = self.bus.link

    def _ticks(self, angle_rad: float) -> int:
        return self.config.zero_tick + int(round(angle_rad / (2 * math.pi) * self.config.ticks_per_revolution))

    def _angle(self, ticks: int) -> float:
        return (ticks - self.config.zero_tick) * 2 * math.pi / self.config.ticks_per_revolution

    def ping(self) -> int:
        """The model number (e.g. 1020 for an XM430-W350)."""
        return self.bus.ping(self.config.motor_id)[0]

    def enable(self) -> None:
        """Sets the speed limit (profile velocity) and turns torque on."""
        rpm = self.range.max_speed_rad_s * 60.0 / (2 * math.pi)
        units = max(1, int(rpm / self.config.velocity_unit_rpm))  # 0 would mean "no limit"
        self.bus.write(self.config.motor_id, ADDR_PROFILE_VELOCITY, struct.pack("<I", units))
        self.bus.write(self.config.motor_id, ADDR_TORQUE_ENABLE, b"\x01")

    def set_speed(self, speed_rad_s: float) -> float:
        """The profile velocity for the moves that follow (see :meth:`LaserMotor.set_speed`)."""
        v = check_number(speed_rad_s, "speed_rad_s", low=1e-6, high=self.range.max_speed_rad_s, unit="rad/s")
        units = max(1, round(v * 60.0 / (2 * math.pi) / self.config.velocity_unit_rpm))
        self.bus.write(self.config.motor_id, ADDR_PROFILE_VELOCITY, struct.pack("<I", units))
        return units * self.config.velocity_unit_rpm * 2 * math.pi / 60.0

    def disable(self) -> None:
        """Turns torque off."""
        self.bus.write(self.config.motor_id, ADDR_TORQUE_ENABLE, b"\x00")

    def present_angle(self) -> float:
        """Present position, radians."""
        raw = self.bus.read(self.config.motor_id, ADDR_PRESENT_POSITION, 4)
        return self._angle(struct.unpack("<i", raw)[0])

    def read_goal_angle(self) -> float:
        """The goal position the motor holds, radians."""
        raw = self.bus.read(self.config.motor_id, ADDR_GOAL_POSITION, 4)
        return self._angle(struct.unpack("<i", raw)[0])

    def is_moving(self) -> bool:
        """The motor's own status: Moving (address 122) set, or its motion profile still
        running (Moving Status, address 123, bit 1), read together."""
        moving, status = self.bus.read(self.config.motor_id, ADDR_MOVING, 2)
        return bool(moving) or bool(status & MOVING_STATUS_PROFILE_ONGOING)

    def _angle_at_rest(self) -> Optional[float]:
        """The present angle, read only once the motor's status says it has stopped."""
        return None if self.is_moving() else self.present_angle()

    def _send_goal(self, angle_rad: float) -> None:
        self.bus.write(self.config.motor_id, ADDR_GOAL_POSITION, struct.pack("<i", self._ticks(angle_rad)))
