"""The physical time a cell's hardware takes, kept by the emulators that play it.

An emulator runs in real time (the arm's sped up by its ``speed_scale``), and its wall clock
also holds what the hardware never waits for: a simulated camera's rendering, the pile's
physics, the drivers' polling of a busy machine. A :class:`PhysicalClock` shared by the
emulators of one cell holds instead what the hardware takes: each emulator spends on it the
time its motion model gives a command — the arm's move from its speed and acceleration limits
along the path it plans, the laser motor's turn at its speed, the gripper's fingers over their
travel, the camera's frame — when it starts carrying the command out. The cell reads the clock
at the edges of its stages (:attr:`binpick.cell.Cell.clock`); binpick's own compute is measured
apart, since the same CPU runs the simulator.
"""

from __future__ import annotations

import math
import threading

from ..._validate import non_negative

__all__ = ["PhysicalClock", "trapezoid_s"]


def trapezoid_s(distance: float, speed: float, ramp_s: float) -> float:
    """The time to travel ``distance`` from rest to rest at most at ``speed``, reaching it in
    ``ramp_s`` (constant acceleration ``speed / ramp_s``, and the same deceleration): ``d / v +
    ramp_s`` when the move reaches full speed (``d ≥ v·ramp_s``), else ``2·√(d·ramp_s / v)``."""
    d, v = abs(float(distance)), float(speed)
    if d == 0.0:
        return 0.0
    if ramp_s <= 0.0:
        return d / v
    return d / v + ramp_s if d >= v * ramp_s else 2.0 * math.sqrt(d * ramp_s / v)


class PhysicalClock:
    """Seconds of hardware time since the cell started (:meth:`now`), and how much of it each
    device took (:attr:`by_device`). Thread-safe: each emulator serves its port on a thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._t = 0.0
        self.by_device: dict[str, float] = {}

    def spend(self, seconds: float, device: str) -> None:
        """``device`` takes ``seconds`` (≥ 0) of the cell's time."""
        s = non_negative(seconds, "seconds", "s")
        with self._lock:
            self._t += s
            self.by_device[device] = self.by_device.get(device, 0.0) + s

    def advance_to(self, t: float, device: str) -> None:
        """``device`` holds the cell until ``t`` (s on this clock): the time up to it, if any, is
        spent (a wait for a motion that runs on the clock while other devices' time passes)."""
        with self._lock:
            dt = float(t) - self._t
            if dt > 0:
                self._t += dt
                self.by_device[device] = self.by_device.get(device, 0.0) + dt

    def now(self) -> float:
        """The hardware time spent so far, seconds."""
        with self._lock:
            return self._t

    def __call__(self) -> float:
        return self.now()
