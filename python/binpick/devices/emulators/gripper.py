"""An electric parallel gripper with the Robotiq 2F register map, on Modbus RTU over a pty.

See :mod:`binpick.devices.gripper` for the frames. Activation takes ``activation_s``; the
fingers move toward the requested position at a speed set by the SPEED byte and stop early on
an object placed with :attr:`GripperEmulator.object_at` (a position, 0 open – 255 closed).
Wrong CRCs are ignored (a Modbus slave stays silent); unknown functions, addresses and values
get Modbus exception replies.

On a cell's :class:`~binpick.devices.emulators.clock.PhysicalClock` (``clock`` set) the fingers
move alongside the other devices, as a real gripper does: a command marks when they will arrive
(their travel at the SPEED byte's speed, from the clock's time at the command), and the first
status read that finds them stopped holds the cell until then. A driver that waits for the
fingers is charged the rest of their travel; one that moved the arm meanwhile, nothing more.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, Optional

from ..._validate import check_int, check_number
from ..gripper import (
    ACT,
    COMMAND_REGISTER,
    FC_READ_HOLDING,
    FC_READ_INPUT,
    FC_WRITE_MULTIPLE,
    GTO,
    STATUS_REGISTER,
    modbus_crc,
)
from ._pty import PtyEmulator, monotonic
from .motor import LinearAxis

__all__ = ["GripperEmulatorConfig", "GripperEmulator"]


@dataclass(frozen=True)
class GripperEmulatorConfig:
    """Settings of a :class:`GripperEmulator`.

    Attributes:
        slave: Modbus slave address.
        activation_s: time activation takes, seconds.
        min_speed_units_s: finger speed at SPEED 0, position units per second.
        max_speed_units_s: finger speed at SPEED 255, position units per second.
        device_exception: exception code sent for the DEVICE_ERROR fault.
        speed_scale: the fingers move this many times faster than their speed (> 1 makes a
            simulated cell quick); the time spent on the cell's clock is the speed's.
    """

    slave: int = 9
    activation_s: float = 0.05
    min_speed_units_s: float = 200.0
    max_speed_units_s: float = 2000.0
    device_exception: int = 4
    speed_scale: float = 1.0

    def __post_init__(self) -> None:
        check_int(self.slave, "GripperEmulatorConfig.slave", 1, 247)
        check_number(self.activation_s, "GripperEmulatorConfig.activation_s", low=0.0, unit="s")
        check_number(self.min_speed_units_s, "GripperEmulatorConfig.min_speed_units_s", low=1e-3)
        check_number(self.max_speed_units_s, "GripperEmulatorConfig.max_speed_units_s", low=1e-3)
        check_number(self.speed_scale, "GripperEmulatorConfig.speed_scale", low=1e-3, high=1e6)


class GripperEmulator(PtyEmulator):
    """A Modbus RTU gripper on a pty (see the module docstring)."""

    device = "gripper"

    def __init__(self, *, config: GripperEmulatorConfig = GripperEmulatorConfig()) -> None:
        super().__init__()
        self.config = config
        self.command = bytearray(6)
        self.axis = LinearAxis(0.0, config.min_speed_units_s)
        self._activated_at: Optional[float] = None
        #: position (0–255) where an object stops closing fingers; None for empty air
        self.object_at: Optional[int] = None
        #: when (on the clock) the fingers reach the goal of the last command
        self.arrives_at = 0.0

    # -- model
    def _activated(self) -> bool:
        return self._activated_at is not None and monotonic() >= self._activated_at

    def _status(self) -> bytes:
        action, request = self.command[0], self.command[3]
        pos = self.axis.position()
        going = bool(action & GTO) and self._activated()
        obj = 0
        if going and not self.axis.moving():
            blocked = abs(pos - request) > 0.5
            obj = (2 if request > pos else 1) if blocked else 3
        sta = 3 if self._activated() else (1 if action & ACT else 0)
        fault = 0x05 if action & GTO and not self._activated() else 0
        st = (action & ACT) | (GTO if going else 0) | (sta << 4) | (obj << 6)
        return bytes([st, 0, fault, request, int(round(pos)), 10 if going else 0])

    def _apply(self) -> None:
        action, request, speed = self.command[0], self.command[3], self.command[4]
        if not action & ACT:
            self._activated_at = None
        elif self._activated_at is None:
            self._activated_at = monotonic() + self.config.activation_s
            self._spend(self.config.activation_s)
        c = self.config
        physical = c.min_speed_units_s + (c.max_speed_units_s - c.min_speed_units_s) * speed / 255.0
        self.axis.speed = physical * c.speed_scale
        goal = float(request)
        if self.object_at is not None and goal > self.axis.position() >= 0 and goal > self.object_at:
            goal = float(max(self.object_at, self.axis.position()))
        if action & GTO and self._activated_at is not None:
            if goal != self.axis.goal and self.clock is not None:
                # The fingers' travel to the goal (or to the part they stop on) runs on the clock from now.
                self.arrives_at = self.clock.now() + abs(goal - self.axis.position()) / physical
            self.axis.set_goal(goal)

    # -- protocol
    def _take_requests(self, buf: bytearray) -> list[bytes]:
        out = []
        while len(buf) >= 8:
            need = 9 + buf[6] if buf[1] == FC_WRITE_MULTIPLE else 8
            if len(buf) < need:
                break
            frame = bytes(buf[:need])
            if struct.unpack_from("<H", frame, need - 2)[0] == modbus_crc(frame[:-2]):
                out.append(frame)
                del buf[:need]
            else:
                del buf[:1]  # lost sync (or a corrupted frame): a slave ignores it
        return out

    def _reply(self, body: bytes) -> bytes:
        return body + struct.pack("<H", modbus_crc(body))

    def _exception(self, function: int, code: int) -> bytes:
        return self._reply(bytes([self.config.slave, function | 0x80, code]))

    def _handle(self, frame: bytes) -> Optional[bytes]:
        slave, fc = frame[0], frame[1]
        if slave != self.config.slave:
            return None
        with self._lock:
            if fc in (FC_READ_INPUT, FC_READ_HOLDING):
                address, count = struct.unpack_from(">HH", frame, 2)
                if address != STATUS_REGISTER or not 1 <= count <= 3:
                    return self._exception(fc, 2)
                if self.clock is not None and not self.axis.moving():
                    self.clock.advance_to(self.arrives_at, self.device)  # seen stopped: they have arrived
                data = self._status()[: 2 * count]
                return self._reply(bytes([slave, fc, len(data)]) + data)
            if fc == FC_WRITE_MULTIPLE:
                address, count, nbytes = struct.unpack_from(">HHB", frame, 2)
                if address != COMMAND_REGISTER or not 1 <= count <= 3:
                    return self._exception(fc, 2)
                if nbytes != 2 * count:
                    return self._exception(fc, 3)
                self.command[: 2 * count] = frame[7 : 7 + nbytes]
                self._apply()
                return self._reply(frame[:6])
            return self._exception(fc, 1)

    # -- fault hooks
    def _garble(self, reply: bytes) -> bytes:
        return bytes([reply[0]]) + bytes(b ^ 0x5A for b in reply[1:])

    def _bad_crc(self, reply: bytes) -> bytes:
        return reply[:-1] + bytes([reply[-1] ^ 0xFF])

    def _unknown_reply(self, request: Any) -> bytes:
        return self._reply(bytes([self.config.slave, 0x2B, 0x0E, 0x01, 0x00, 0x00]))  # a well-formed MEI reply

    def _error_reply(self, request: Any) -> Optional[bytes]:
        return self._exception(request[1], self.config.device_exception)
