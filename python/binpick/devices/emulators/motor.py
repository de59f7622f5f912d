"""The laser motor as a Dynamixel X-series servo speaking Protocol 2.0 on a pty.

It keeps a control table (model number 1020, the XM430-W350's), answers PING, READ and WRITE,
replies with CRC-error status to packets whose CRC is wrong, refuses what the servo refuses
(EEPROM writes with torque on, read-only addresses, goals outside the position limits, unknown
instructions) and, with torque on, moves the present position toward the goal at the profile
velocity (or ``max_speed_rad_s`` when that is 0).

On a cell's :class:`~binpick.devices.emulators.clock.PhysicalClock` (``clock`` set) the servo
turns in the cell's hardware time, not the wall clock's: it turns while the camera's frames
take their time (a continuous sweep), and a read of its moving status while it turns is a
driver waiting for it — each such poll takes :data:`STATUS_POLL_S` of the clock, at most until
the servo arrives.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, Optional, Union

from ..._validate import check_int, check_number
from ...errors import ChecksumError, ProtocolError
from ..dynamixel import (
    ADDR_GOAL_POSITION,
    ADDR_MOVING,
    ADDR_MOVING_STATUS,
    ADDR_PRESENT_POSITION,
    ADDR_PROFILE_VELOCITY,
    ADDR_TORQUE_ENABLE,
    BROADCAST_ID,
    HEADER,
    INST_PING,
    INST_READ,
    INST_STATUS,
    INST_WRITE,
    MOVING_STATUS_IN_POSITION,
    MOVING_STATUS_PROFILE_ONGOING,
    Packet,
    decode_packet,
    encode_packet,
)
from ._pty import PtyEmulator, monotonic

__all__ = ["LinearAxis", "DynamixelEmulatorConfig", "DynamixelEmulator", "CrcFailure", "STATUS_POLL_S"]

#: The time a read of the moving status takes on the bus, s: a 2-byte READ and its status
#: packet, 27 bytes at 57600 baud.
STATUS_POLL_S = 27 * 10 / 57600

ADDR_MAX_POSITION, ADDR_MIN_POSITION = 48, 52
TABLE_SIZE = 147
_ERR_INSTRUCTION, _ERR_CRC, _ERR_RANGE, _ERR_LENGTH, _ERR_LIMIT, _ERR_ACCESS = 2, 3, 4, 5, 6, 7


class LinearAxis:
    """A position that moves toward its goal at a constant speed (units per second), in the
    time ``now()`` gives (the wall clock's by default)."""

    def __init__(self, position: float, speed: float, now: Any = None) -> None:
        self.speed = speed
        self.now = now or monotonic
        self._pos = self.goal = float(position)
        self._t = self.now()
        self.enabled = True

    def arrival(self) -> float:
        """When the position reaches the goal (its time now when there)."""
        here = self.position()
        return self._t + (abs(self.goal - here) / self.speed if self.enabled else 0.0)

    def position(self) -> float:
        """The position now (advancing the model to this instant)."""
        now = self.now()
        if self.enabled:
            step = self.speed * max(0.0, now - self._t)  # 0 when the time source was changed
            delta = self.goal - self._pos
            self._pos = self.goal if abs(delta) <= step else self._pos + math.copysign(step, delta)
        self._t = now
        return self._pos

    def moving(self) -> bool:
        """Whether the position is still short of the goal."""
        return self.enabled and abs(self.position() - self.goal) > 1e-9

    def set_goal(self, goal: float) -> None:
        """A new goal, from where the axis is now."""
        self.position()
        self.goal = float(goal)


@dataclass(frozen=True)
class CrcFailure:
    """A request the emulator received with a wrong CRC (recorded in ``requests``)."""

    motor_id: int


@dataclass(frozen=True)
class DynamixelEmulatorConfig:
    """Settings of a :class:`DynamixelEmulator`.

    Attributes:
        motor_id: the servo's ID.
        model_number: value of address 0 (1020 = XM430-W350).
        firmware_version: value of address 6.
        start_position: present position at start-up, ticks.
        max_speed_rad_s: speed when profile velocity is 0, rad/s.
        min_position: Min Position Limit, ticks.
        max_position: Max Position Limit, ticks.
        device_error: ERROR byte sent for the DEVICE_ERROR fault (1 = result fail, 0x80 = alert).
        return_delay_s: time from a request to its status, s (the X series' default Return Delay
            Time of 250 × 2 µs); the motor keeps turning meanwhile.
    """

    motor_id: int = 1
    model_number: int = 1020
    firmware_version: int = 45
    start_position: int = 2048
    max_speed_rad_s: float = 2 * math.pi
    min_position: int = 0
    max_position: int = 4095
    device_error: int = 0x01
    return_delay_s: float = 500e-6

    def __post_init__(self) -> None:
        check_int(self.motor_id, "DynamixelEmulatorConfig.motor_id", 0, 252)
        check_number(self.max_speed_rad_s, "DynamixelEmulatorConfig.max_speed_rad_s", low=1e-6, unit="rad/s")
        check_number(self.return_delay_s, "DynamixelEmulatorConfig.return_delay_s", low=0.0, high=0.5, unit="s")


class DynamixelEmulator(PtyEmulator):
    """A Protocol 2.0 servo on a pty (see the module docstring)."""

    device = "dynamixel"

    def __init__(self, *, config: DynamixelEmulatorConfig = DynamixelEmulatorConfig()) -> None:
        super().__init__()
        self.config = config
        self.reply_delay_s = config.return_delay_s
        t = bytearray(TABLE_SIZE)
        struct.pack_into("<H", t, 0, config.model_number)
        t[6], t[7], t[8], t[11] = config.firmware_version, config.motor_id, 1, 3  # fw, ID, 57600 baud, position mode
        struct.pack_into("<i", t, ADDR_MAX_POSITION, config.max_position)
        struct.pack_into("<i", t, ADDR_MIN_POSITION, config.min_position)
        struct.pack_into("<i", t, ADDR_GOAL_POSITION, config.start_position)
        self.table = t
        self.axis = LinearAxis(config.start_position, config.max_speed_rad_s * 4096 / (2 * math.pi), self._now)
        self.axis.enabled = False

    def _now(self) -> float:
        """The servo's time: the cell's hardware clock when one is set, else the wall clock."""
        return monotonic() if self.clock is None else self.clock.now()

    # -- state for tests
    def present_position(self) -> float:
        """Present position, ticks."""
        with self._lock:
            return self.axis.position()

    @property
    def torque_enabled(self) -> bool:
        """Torque Enable (address 64)."""
        return bool(self.table[ADDR_TORQUE_ENABLE])

    # -- protocol
    def _take_requests(self, buf: bytearray) -> list[Union[Packet, CrcFailure]]:
        out: list[Union[Packet, CrcFailure]] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                del buf[: max(0, len(buf) - 3)]
                return out
            del buf[:start]
            if len(buf) < 7:
                return out
            end = 7 + struct.unpack_from("<H", buf, 5)[0]
            if end > 7 + 1024:  # no such request: this header was noise
                del buf[:1]
                continue
            if len(buf) < end:
                return out
            raw = bytes(buf[:end])
            del buf[:end]
            try:
                out.append(decode_packet(raw))
            except ChecksumError:
                out.append(CrcFailure(raw[4]))
            except ProtocolError:
                continue

    def _status(self, error: int, params: bytes = b"") -> bytes:
        return encode_packet(self.config.motor_id, INST_STATUS, bytes([error]) + params)

    def _refresh(self) -> None:
        pos = int(round(self.axis.position()))
        struct.pack_into("<i", self.table, ADDR_PRESENT_POSITION, pos)
        moving = self.axis.moving()
        self.table[ADDR_MOVING] = int(moving)
        self.table[ADDR_MOVING_STATUS] = MOVING_STATUS_PROFILE_ONGOING if moving else MOVING_STATUS_IN_POSITION

    def _handle(self, request: Any) -> Optional[bytes]:
        with self._lock:
            own = request.motor_id == self.config.motor_id
            if not own and request.motor_id != BROADCAST_ID:
                return None
            if isinstance(request, CrcFailure):
                return self._status(_ERR_CRC) if own else None
            if request.instruction == INST_PING:
                return self._status(0, self.table[0:2] + self.table[6:7])
            if not own:
                self._carry_out(request)  # broadcast instructions get no status
                return None
            return self._carry_out(request)

    def _carry_out(self, p: Packet) -> bytes:
        if p.instruction == INST_READ:
            if len(p.params) != 4:
                return self._status(_ERR_LENGTH)
            addr, n = struct.unpack("<HH", p.params)
            if addr + n > TABLE_SIZE:
                return self._status(_ERR_ACCESS)
            if self.clock is not None and addr <= ADDR_MOVING < addr + n and self.axis.moving():
                # A driver waiting for the servo: the poll takes its time on the bus, the servo turns on.
                self.clock.advance_to(min(self.clock.now() + STATUS_POLL_S, self.axis.arrival()), self.device)
            elif self.clock is not None and self.axis.moving():
                # A read while it turns takes its time on the bus; the position is the one at its middle.
                self.clock.advance_to(self.clock.now() + STATUS_POLL_S / 2, self.device)
                self._refresh()
                self.clock.advance_to(self.clock.now() + STATUS_POLL_S / 2, self.device)
                return self._status(0, bytes(self.table[addr : addr + n]))
            self._refresh()
            return self._status(0, bytes(self.table[addr : addr + n]))
        if p.instruction == INST_WRITE:
            if len(p.params) < 3:
                return self._status(_ERR_LENGTH)
            addr, data = struct.unpack_from("<H", p.params)[0], p.params[2:]
            return self._status(self._write(addr, data))
        return self._status(_ERR_INSTRUCTION)

    def _write(self, addr: int, data: bytes) -> int:
        end = addr + len(data)
        if addr < 7 or end > 120:
            return _ERR_ACCESS
        if addr < 64 and self.table[ADDR_TORQUE_ENABLE]:
            return _ERR_ACCESS  # EEPROM is locked while torque is on
        if addr <= ADDR_TORQUE_ENABLE < end and data[ADDR_TORQUE_ENABLE - addr] > 1:
            return _ERR_RANGE
        if addr <= ADDR_GOAL_POSITION and end >= ADDR_GOAL_POSITION + 4:
            goal = struct.unpack_from("<i", data, ADDR_GOAL_POSITION - addr)[0]
            lo, hi = (struct.unpack_from("<i", self.table, a)[0] for a in (ADDR_MIN_POSITION, ADDR_MAX_POSITION))
            if not lo <= goal <= hi:
                return _ERR_LIMIT
        self.table[addr:end] = data
        self._apply()
        return 0

    def _apply(self) -> None:
        self.axis.position()
        self.axis.enabled = bool(self.table[ADDR_TORQUE_ENABLE])
        velocity = struct.unpack_from("<I", self.table, ADDR_PROFILE_VELOCITY)[0]
        rpm_to_ticks = 4096 / 60.0
        self.axis.speed = (
            velocity * 0.229 * rpm_to_ticks if velocity else self.config.max_speed_rad_s * 4096 / (2 * math.pi)
        )
        self.axis.set_goal(struct.unpack_from("<i", self.table, ADDR_GOAL_POSITION)[0])

    # -- fault hooks
    def _garble(self, reply: bytes) -> bytes:
        return b"\xff\x00\xfd\xff" + reply[4:]

    def _bad_crc(self, reply: bytes) -> bytes:
        return reply[:-1] + bytes([reply[-1] ^ 0xFF])

    def _unknown_reply(self, request: Any) -> bytes:
        return encode_packet(self.config.motor_id, 0x77, b"\x00")

    def _error_reply(self, request: Any) -> Optional[bytes]:
        return self._status(self.config.device_error)
