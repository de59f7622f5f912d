"""The paper's serial "AI motor" (Megarobotics AI-701/AI-1001 class) behind the laser-motor interface.

What is implemented, as far as the public AI-motor documentation describes it (check each point
against your unit's manual; the values are configurable where they are numbers):

* Line: 8 data bits, no parity, 1 stop bit; 57600 baud assumed as the default.
* Request: 4 bytes ``FF | D1 | D2 | CS`` with ``CS = (D1 XOR D2) AND 0x7F``.
* Position send: ``D1 = (torque level << 5) | ID`` with torque level 0 (strongest) to 4 and ID
  0–30, ``D2`` = goal position 0–254.
* Status read: ``D1 = (5 << 5) | ID``, ``D2 = 0``.
* Passive (torque off): ``D1 = (6 << 5) | ID``, ``D2 = 0x10``.
* Reply to each: 2 bytes, ``load`` then ``position`` (0–254); a reply byte of 0xFF is invalid.
* Position scale: 254 units over about 333°, unit 127 at the centre (``degrees_per_unit``,
  ``centre_unit``).

Limits of the protocol that the driver cannot paper over: replies carry no checksum and no
device error, so a corrupted but in-range reply cannot be told from a good one; there is no
goal read-back and no speed setting in the 4-byte commands used here (``MotorRange.max_speed_rad_s``
is not sent), and the 'moving' state is inferred from the position (stopped once it reads the same
for ``MotorRange.settle_s``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import serial

from .._validate import check_int, check_number
from ..errors import InvalidInputError, ProtocolError
from ._link import SerialLink, SerialSettings, with_retries
from .motor import LaserMotor, MotorRange

__all__ = ["MODE_STATUS", "MODE_PASSIVE", "encode_request", "decode_reply", "AiMotorConfig", "AiMotor"]

HEADER = 0xFF
MODE_STATUS = 5
MODE_PASSIVE = 6
MAX_POSITION = 254


def encode_request(d1: int, d2: int) -> bytes:
    """The 4-byte request ``FF D1 D2 CS``."""
    check_int(d1, "d1", 0, 0xFE)
    check_int(d2, "d2", 0, 0xFE)
    return bytes([HEADER, d1, d2, (d1 ^ d2) & 0x7F])


def encode_position(motor_id: int, position: int, *, torque_level: int = 2) -> bytes:
    """Position send: goal ``position`` (0–254) for ``motor_id`` (0–30) at ``torque_level`` (0–4)."""
    check_int(motor_id, "motor_id", 0, 30)
    check_int(torque_level, "torque_level", 0, 4)
    return encode_request((torque_level << 5) | motor_id, check_int(position, "position", 0, MAX_POSITION))


def decode_reply(raw: bytes) -> tuple[int, int]:
    """(load, position) from a 2-byte reply; ProtocolError for anything else."""
    raw = bytes(raw)
    if len(raw) != 2:
        raise ProtocolError(f"ai-motor: a reply has 2 bytes, got {len(raw)}: {raw[:8].hex(' ')}")
    load, position = raw
    if load == HEADER or position > MAX_POSITION:
        raise ProtocolError(f"ai-motor: garbled reply {raw.hex(' ')} (position must be 0–254, no byte may be FF)")
    return load, position


@dataclass(frozen=True)
class AiMotorConfig:
    """Settings of an :class:`AiMotor`.

    Attributes:
        motor_id: the motor's ID, 0–30.
        serial: line settings (57600 baud, 8N1 assumed).
        range: allowed angles, arrival tolerance and timing (its speed is not sent).
        torque_level: torque level of position commands, 0 (strongest) to 4.
        degrees_per_unit: angle of one position unit, degrees.
        centre_unit: position unit of angle 0.
    """

    motor_id: int = 0
    serial: SerialSettings = SerialSettings(baudrate=57600, timeout_s=0.1)
    range: MotorRange = MotorRange(tolerance_rad=math.radians(1.5))
    torque_level: int = 2
    degrees_per_unit: float = 333.0 / 254.0
    centre_unit: int = 127

    def __post_init__(self) -> None:
        check_int(self.motor_id, "AiMotorConfig.motor_id", 0, 30)
        check_int(self.torque_level, "AiMotorConfig.torque_level", 0, 4)
        check_number(self.degrees_per_unit, "AiMotorConfig.degrees_per_unit", low=1e-3, high=10, unit="deg")
        check_int(self.centre_unit, "AiMotorConfig.centre_unit", 0, MAX_POSITION)
        if not isinstance(self.range, MotorRange) or not isinstance(self.serial, SerialSettings):
            raise InvalidInputError("AiMotorConfig: range must be a MotorRange and serial a SerialSettings")


class AiMotor(LaserMotor):
    """The laser motor as an AI motor (see the module docstring for the protocol and its limits).

    Args:
        port: serial device path, or an open ``serial.SerialBase``.
        config: ID, line settings, range and scale.
    """

    def __init__(self, port: Union[str, serial.SerialBase], *, config: AiMotorConfig = AiMotorConfig()) -> None:
        super().__init__()
        if not isinstance(config, AiMotorConfig):
            raise InvalidInputError(f"config: expected AiMotorConfig, got {type(config).__name__}")
        self.config = config
        self.range = config.range
        self._link = SerialLink(port, config.serial, device="ai-motor")

    def _exchange(self, request: bytes, *, retry: bool) -> tuple[int, int]:
        def once() -> tuple[int, int]:
            self._link.discard_input()
            self._link.write(request)
            return decode_reply(self._link.read_exact(2, self._link.deadline(), what="reply"))

        return with_retries(self.config.serial.retries if retry else 0, once)

    def _unit(self, angle_rad: float) -> int:
        return self.config.centre_unit + int(round(math.degrees(angle_rad) / self.config.degrees_per_unit))

    def ping(self) -> int:
        """A status read; the protocol has no model number, so 0."""
        self.present_angle()
        return 0

    def present_angle(self) -> float:
        """Present position (status read), radians."""
        _, pos = self._exchange(encode_request((MODE_STATUS << 5) | self.config.motor_id, 0), retry=True)
        return math.radians((pos - self.config.centre_unit) * self.config.degrees_per_unit)

    def enable(self) -> None:
        """Holds the present position (the AI motor holds torque after a position command)."""
        self.move_to(self.present_angle(), wait=False)

    def disable(self) -> None:
        """Passive mode: torque off."""
        self._exchange(encode_request((MODE_PASSIVE << 5) | self.config.motor_id, 0x10), retry=True)

    def _send_goal(self, angle_rad: float) -> None:
        unit = self._unit(angle_rad)
        if not 0 <= unit <= MAX_POSITION:
            raise InvalidInputError(
                f"angle_rad: {math.degrees(angle_rad):.1f}° maps to position {unit}, outside 0–254; "
                "narrow MotorRange or fix AiMotorConfig.centre_unit"
            )
        self._exchange(encode_position(self.config.motor_id, unit, torque_level=self.config.torque_level), retry=False)
