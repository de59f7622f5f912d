"""The laser motor as an AI motor on a pty (protocol as assumed in :mod:`binpick.devices.aimotor`).

Answers position send, status read and passive commands with ``load, position``; ignores
requests with a wrong checksum or another ID, as the motor does; moves at ``speed_units_s``.
The protocol has no checksum, device errors or other replies in its answers, so BAD_CRC,
UNKNOWN_REPLY and DEVICE_ERROR cannot be played.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from ..._validate import check_int, check_number
from ..aimotor import MODE_PASSIVE, MODE_STATUS
from ._pty import Fault, PtyEmulator
from .motor import LinearAxis

__all__ = ["AiMotorEmulatorConfig", "AiMotorEmulator"]


@dataclass(frozen=True)
class AiMotorEmulatorConfig:
    """Settings of an :class:`AiMotorEmulator`.

    Attributes:
        motor_id: the motor's ID, 0–30.
        start_position: position at start-up, units (0–254).
        speed_units_s: speed toward the goal, position units per second.
        load: the load byte reported.
    """

    motor_id: int = 0
    start_position: int = 127
    speed_units_s: float = 200.0
    load: int = 10

    def __post_init__(self) -> None:
        check_int(self.motor_id, "AiMotorEmulatorConfig.motor_id", 0, 30)
        check_int(self.start_position, "AiMotorEmulatorConfig.start_position", 0, 254)
        check_number(self.speed_units_s, "AiMotorEmulatorConfig.speed_units_s", low=1e-3)


class AiMotorEmulator(PtyEmulator):
    """An AI motor on a pty."""

    supported_faults = frozenset(Fault) - {Fault.BAD_CRC, Fault.UNKNOWN_REPLY, Fault.DEVICE_ERROR}
    device = "ai-motor"

    def __init__(self, *, config: AiMotorEmulatorConfig = AiMotorEmulatorConfig()) -> None:
        super().__init__()
        self.config = config
        self.axis = LinearAxis(config.start_position, config.speed_units_s)
        self.passive = True
        self.axis.enabled = False

    def present_position(self) -> float:
        """Present position, units."""
        with self._lock:
            return self.axis.position()

    def _take_requests(self, buf: bytearray) -> list[tuple[int, int]]:
        out = []
        while True:
            start = buf.find(b"\xff")
            if start < 0:
                buf.clear()
                return out
            del buf[:start]
            if len(buf) < 4:
                return out
            d1, d2, cs = buf[1], buf[2], buf[3]
            if cs == (d1 ^ d2) & 0x7F:
                out.append((d1, d2))
                del buf[:4]
            else:
                del buf[:1]  # not a request: resynchronise on the next FF

    def _handle(self, request: tuple[int, int]) -> Optional[bytes]:
        d1, d2 = request
        mode, motor_id = d1 >> 5, d1 & 0x1F
        if motor_id != self.config.motor_id:
            return None
        with self._lock:
            if mode <= 4:
                if d2 > 254:
                    return None
                self.axis.enabled, self.passive = True, False
                self.axis.set_goal(d2)
            elif mode == MODE_PASSIVE and d2 == 0x10:
                self.axis.set_goal(self.axis.position())
                self.axis.enabled, self.passive = False, True
            elif mode != MODE_STATUS:
                return None
            return bytes([self.config.load, int(round(self.axis.position()))])

    def _garble(self, reply: bytes) -> bytes:
        return b"\xff\xff"
