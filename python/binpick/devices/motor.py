"""The interface every laser-motor driver offers, and the range and timing it is held to.

The laser projector turns on one motor; scanning needs only: is it there, hold torque or not,
go to an angle (radians, 0 at the motor's mechanical centre), where is it now, has it stopped there.
:class:`LaserMotor` implements the waiting and the range check once; drivers supply the bytes.
"""

from __future__ import annotations

import abc
import math
import time
from dataclasses import dataclass
from typing import Any, Optional

from .._validate import check_number, flag
from ..errors import DeviceTimeout, InvalidInputError, SafetyError
from ._link import SerialLink

__all__ = ["MotorRange", "LaserMotor"]


@dataclass(frozen=True)
class MotorRange:
    """Where and how fast the laser motor may turn, and how arrival is judged.

    Attributes:
        min_angle_rad: smallest goal angle accepted, radians (0 = mechanical centre).
        max_angle_rad: largest goal angle accepted, radians.
        max_speed_rad_s: speed the motor is limited to where its protocol allows, rad/s.
        tolerance_rad: a goal counts as reached within this angle, radians.
        move_timeout_s: longest wait for one move, seconds.
        poll_interval_s: pause between two position reads while waiting, seconds.
        settle_s: for a motor whose protocol reports no motion, how long its position must
            read the same before it counts as stopped, seconds.
    """

    min_angle_rad: float = -math.pi / 2
    max_angle_rad: float = math.pi / 2
    max_speed_rad_s: float = math.pi
    tolerance_rad: float = math.radians(0.5)
    move_timeout_s: float = 10.0
    poll_interval_s: float = 0.02
    settle_s: float = 0.03

    def __post_init__(self) -> None:
        lo = check_number(self.min_angle_rad, "MotorRange.min_angle_rad", low=-math.pi, high=math.pi, unit="rad")
        hi = check_number(self.max_angle_rad, "MotorRange.max_angle_rad", low=-math.pi, high=math.pi, unit="rad")
        if hi <= lo:
            raise InvalidInputError(f"MotorRange: max_angle_rad {hi} must exceed min_angle_rad {lo}")
        check_number(self.max_speed_rad_s, "MotorRange.max_speed_rad_s", low=1e-6, unit="rad/s")
        check_number(self.tolerance_rad, "MotorRange.tolerance_rad", low=0.0, high=math.pi, unit="rad")
        check_number(self.move_timeout_s, "MotorRange.move_timeout_s", low=1e-3, unit="s")
        check_number(self.poll_interval_s, "MotorRange.poll_interval_s", low=1e-4, unit="s")
        check_number(self.settle_s, "MotorRange.settle_s", low=0.0, unit="s")


class LaserMotor(abc.ABC):
    """A rotary axis turning the laser projector; angles in radians.

    Subclasses implement :meth:`ping`, :meth:`enable`, :meth:`disable`, :meth:`present_angle`
    and :meth:`_send_goal`; they override :meth:`is_moving` and :meth:`_angle_at_rest` when the
    device reports whether it moves.
    """

    range: MotorRange
    _link: SerialLink

    def __init__(self) -> None:
        self._goal: Optional[float] = None

    @abc.abstractmethod
    def ping(self) -> int:
        """Checks that the motor answers; returns its model number (0 when the protocol has none)."""

    @abc.abstractmethod
    def enable(self) -> None:
        """Turns holding torque on."""

    @abc.abstractmethod
    def disable(self) -> None:
        """Turns holding torque off (the axis turns freely)."""

    @abc.abstractmethod
    def present_angle(self) -> float:
        """The angle the motor is at now, radians."""

    @abc.abstractmethod
    def _send_goal(self, angle_rad: float) -> None:
        """Sends the goal (already checked against the range) to the motor."""

    def set_speed(self, speed_rad_s: float) -> float:
        """Turns the moves that follow at ``speed_rad_s`` (at most ``range.max_speed_rad_s``; a
        continuous sweep turns at a set speed); returns the speed the motor was set to, as its
        protocol's units round it. InvalidInputError where the protocol sends no speed."""
        raise InvalidInputError(
            f"laser motor: the {type(self).__name__} protocol sets no speed, which a continuous sweep needs; "
            'sweep the laser in steps (the cell file\'s [cell] sweep = "steps")'
        )

    @property
    def goal_angle(self) -> Optional[float]:
        """The last goal sent, radians (None before the first)."""
        return self._goal

    def is_moving(self) -> bool:
        """Whether the motor is turning now: the protocol's moving status where it has one (see
        :meth:`_angle_at_rest`), else whether the position is away from the goal."""
        return self._goal is not None and abs(self.present_angle() - self._goal) > self.range.tolerance_rad

    def move_to(self, angle_rad: float, *, wait: bool = True) -> float:
        """Sends goal ``angle_rad`` and (with ``wait``) returns the angle the motor came to rest at.

        SafetyError, with nothing sent, when the angle is outside ``range``.
        """
        a, wait = check_number(angle_rad, "angle_rad", unit="rad"), flag(wait, "wait")
        r = self.range
        if not r.min_angle_rad <= a <= r.max_angle_rad:
            raise SafetyError(
                f"laser motor: goal {math.degrees(a):.2f}° is outside the allowed range "
                f"[{math.degrees(r.min_angle_rad):.2f}°, {math.degrees(r.max_angle_rad):.2f}°]; "
                "nothing was sent — choose an angle inside MotorRange"
            )
        self._send_goal(a)
        self._goal = a
        return self.wait_until_reached() if wait else a

    def wait_until_reached(self, timeout_s: Optional[float] = None) -> float:
        """Waits until the motor has stopped within the tolerance of its goal, then returns the
        angle read at rest (the angle a frame is tagged with). DeviceTimeout past the timeout.

        The stop is judged first and the angle read after it: an angle read while the motor still
        turns is not where it stays.
        """
        if self._goal is None:
            raise InvalidInputError("laser motor: no goal has been sent yet; call move_to first")
        limit = self.range.move_timeout_s if timeout_s is None else check_number(timeout_s, "timeout_s", low=0)
        deadline = time.monotonic() + limit
        while True:
            angle = self._angle_at_rest()
            if angle is not None and abs(angle - self._goal) <= self.range.tolerance_rad:
                return angle
            if time.monotonic() > deadline:
                here = self.present_angle()
                raise DeviceTimeout(
                    f"laser motor: still at {math.degrees(here):.2f}° "
                    f"({'at rest' if angle is not None else 'moving'}) {limit} s after the goal "
                    f"{math.degrees(self._goal):.2f}° was sent; check torque, load and the speed limit"
                )
            time.sleep(self.range.poll_interval_s)

    def _angle_at_rest(self) -> Optional[float]:
        """The present angle if the motor has stopped, else None.

        This default is for protocols without a moving status: the motor counts as stopped when
        its position reads the same for ``range.settle_s``. Drivers whose protocol reports
        motion override it to ask that status first and read the angle after.
        """
        first = self.present_angle()
        end = time.monotonic() + self.range.settle_s
        while time.monotonic() < end:
            time.sleep(self.range.poll_interval_s)
            if self.present_angle() != first:
                return None
        return first

    def close(self) -> None:
        """Closes the serial port."""
        self._link.close()

    def __enter__(self) -> LaserMotor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
