"""The laser's sweep across the bin from one scan pose, a frame per line into a
:class:`~binpick.cell.frames.Sweep`: in steps (the motor stops at each angle, the frame is taken
at rest and tagged with the angle read there) or continuous, as the paper does it (the motor
turns at a set speed while the camera streams; each frame's angle is the motor's reported
position interpolated to the middle of the frame's exposure, both on the cell's clock).

Interpolating a continuous sweep: the motor reports whole encoder ticks (a Dynamixel's 4096 a
turn: 0.088°), and a laser line's depth error is its angle's error times about the distance over
the baseline (×4 in the paper's cell: 0.04° is 1.5 mm). So the motor is read
:data:`READS_PER_FRAME` times a frame (each read timed at its middle on the bus, the camera
free-running meanwhile), and each frame's angle is not read off the two nearest readings but from
a straight line fitted to the :data:`FIT_READINGS` readings nearest its time: the motor turns at
a steady speed over them, and the fit averages the ticks' rounding down — read once a frame, the
readings fall at a near-periodic phase against the ticks and leave a bias of up to 1/8 tick.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..errors import DeviceTimeout, InvalidInputError
from ..vision import LaserWindow
from .frames import Sweep

__all__ = ["sweep_laser"]

#: Position readings of a continuous sweep a frame's angle is fitted to (those nearest its time).
FIT_READINGS = 40
#: Position readings taken after each frame of a continuous sweep, one after another on the bus:
#: at several phases against the encoder's ticks, so that the fit averages the ticks' rounding.
READS_PER_FRAME = 4

#: A continuous sweep stops grabbing when the motor has not reached the sweep's end after this
#: many times the frames it was set up for (a motor that stalls or turns slower than it was set).
STREAM_SLACK = 1.5


def sweep_laser(cell: Any, sweep: Sweep, wanted: np.ndarray, T_bf: np.ndarray) -> tuple[float, float]:
    """Turns the laser through the angles ``wanted`` at flange pose ``T_bf`` (as
    ``cell.config.sweep`` says), a frame per line into ``sweep``; returns the seconds (wall
    clock, and this thread's CPU) spent extracting lines."""
    cell.camera.begin(T_bf)
    window = LaserWindow(cell.config.calibration, T_bf, cell.config.scan_volume)
    readings: list[tuple[float, float]] = []  # a continuous sweep's (time, angle) readings
    times: list[float] = []  # and its frames' times
    continuous = cell.config.sweep == "continuous"
    frames = _continuous(cell, wanted, readings, times) if continuous else _steps(cell, wanted)
    first = len(sweep.angles)
    n_keep = min(cell.config.keep_frames, len(wanted))
    keep = set(np.linspace(0, len(wanted) - 1, n_keep).round().astype(int).tolist())
    extract_s = extract_cpu = 0.0
    for k, (angle, img) in enumerate(frames):
        te, ce = time.perf_counter(), time.thread_time()
        uv = window.extract(img, angle)
        extract_s += time.perf_counter() - te
        extract_cpu += time.thread_time() - ce
        sweep.add(uv, angle, T_bf, img if k in keep else None)
    if continuous:  # the angles fitted to every reading (a frame was extracted with its nearest ones')
        sweep.angles[first:] = fitted_angles(np.array(times), np.array(readings)).tolist()
    return extract_s, extract_cpu


def _steps(cell: Any, wanted: np.ndarray):
    """Stop and go: the motor to each angle, a frame at rest, tagged with the angle read there."""
    for a in wanted:
        reached = float(cell.motor.move_to(float(a), wait=True))
        cell.camera.laser_at(reached)
        yield reached, cell.camera.grab()


def _continuous(cell: Any, wanted: np.ndarray, readings: list, times: list):
    """The motor turns from the nearer end of ``wanted`` to the other at the speed that puts one
    frame per ``len(wanted)``-th of the sweep at the camera's rate, while the camera streams;
    each frame is tagged with the motor's angle at the middle of its exposure, interpolated
    between the positions read before and after it (:func:`fitted_angles` refines it after the
    sweep). The frames come until the motor has reached the far end; ``readings`` and ``times``
    get the motor's (time, angle) readings and the frames' times."""
    camera, motor, clock = cell.camera, cell.motor, cell.clock
    fps = camera.fps
    if fps is None or clock is None:
        raise InvalidInputError(
            f"sweep: a continuous sweep needs a camera that streams at a known rate and times each frame on the "
            f"cell's clock; the {type(camera).__name__} does not; sweep in steps (CellConfig(sweep='steps'), the "
            'cell file\'s [cell] sweep = "steps")'
        )
    here = motor.present_angle()
    a0, a1 = (float(wanted[0]), float(wanted[-1]))
    if abs(here - a1) < abs(here - a0):  # start from the nearer end: no return stroke
        a0, a1 = a1, a0
    motor.move_to(a0, wait=True)
    full = motor.range.max_speed_rad_s
    speed = motor.set_speed(abs(a1 - a0) / len(wanted) * fps)
    try:
        camera.streaming(True)
        motor.move_to(a1, wait=False)
        before = _read(clock, motor)
        readings.append(before)
        limit = math.ceil(STREAM_SLACK * len(wanted)) + 1
        for _ in range(limit):
            img = camera.grab()
            t = camera.frame_time_s
            for _ in range(READS_PER_FRAME - 1):
                readings.append(_read(clock, motor))
            after = _read(clock, motor)
            if t is None:
                raise InvalidInputError(
                    f"sweep: the {type(camera).__name__} did not time its frame; a continuous sweep needs each "
                    "frame's time on the cell's clock; sweep in steps"
                )
            times.append(t)
            yield _at(t, before, after), img
            before = after
            if abs(after[1] - a1) <= motor.range.tolerance_rad:
                # Arrived: the readings after the first at the end are of a motor at rest, off the line.
                arrived = next(
                    (k for k, (_, a) in enumerate(readings) if abs(a - a1) <= motor.range.tolerance_rad), None
                )
                del readings[len(readings) if arrived is None else arrived + 1 :]
                if arrived is None:
                    readings.append(after)
                break
            readings.append(after)
        else:
            raise DeviceTimeout(
                f"laser motor: a continuous sweep set to {math.degrees(speed):.2f}°/s was at "
                f"{math.degrees(before[1]):.2f}°, short of {math.degrees(a1):.2f}°, after {limit} frames at "
                f"{fps:g} fps; check the motor's load and speed limit"
            )
        motor.wait_until_reached()
    finally:
        camera.streaming(False)
        motor.set_speed(full)


def fitted_angles(times: np.ndarray, readings: np.ndarray, n: int = FIT_READINGS) -> np.ndarray:
    """The angle at each of ``times`` from a straight line fitted (least squares) to the ``n``
    (time, angle) ``readings`` nearest it — fewer when there are fewer; a single reading's angle
    when they all share one time."""
    t_r, a_r = readings[:, 0], readings[:, 1]
    out = np.empty(len(times))
    for k, t in enumerate(times):
        near = np.argsort(np.abs(t_r - t), kind="stable")[: max(2, n)]
        tt, aa = t_r[near], a_r[near]
        dt = tt - tt.mean()
        var = float(dt @ dt)
        slope = float(dt @ (aa - aa.mean())) / var if var > 0 else 0.0
        out[k] = aa.mean() + slope * (t - tt.mean())
    return out


def _read(clock: Any, motor: Any) -> tuple[float, float]:
    """The motor's angle and the time it was read at: the middle of the read's time on the bus."""
    t0 = clock()
    angle = motor.present_angle()
    return (t0 + clock()) / 2, angle


def _at(t: float, before: tuple[float, float], after: tuple[float, float]) -> float:
    """The angle at time ``t`` between two (time, angle) readings (the nearer one outside them)."""
    (t0, a0), (t1, a1) = before, after
    if t1 <= t0:
        return a1
    s = min(1.0, max(0.0, (t - t0) / (t1 - t0)))
    return a0 + s * (a1 - a0)
