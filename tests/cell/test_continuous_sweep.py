"""The continuous laser sweep on the simulated cell: the motor turns while the camera streams,
and each frame's angle comes from the motor's readings, fitted to the frame's time."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import binpick
from binpick.cell import CellConfig
from binpick.cell.frames import FrameSource
from binpick.cell.sweeps import fitted_angles
from binpick.errors import InvalidInputError
from binpick.sim import SimulatedCell

FRAMES = 40


def _scan(sweep: str):
    """A scan of the same pile swept ``sweep``; the angles the renderer drew each frame at."""
    with SimulatedCell(binpick.parts.tee(), count=3, seed=2, frames=FRAMES, num_threads=2, sweep=sweep) as sim:
        drawn: list[float] = []
        real = sim.laser_angle

        def laser_angle() -> float:
            drawn.append(real())
            return drawn[-1]

        sim.laser_angle = laser_angle  # the camera asks it once a frame, at the middle of the exposure
        scan = sim.cell.scan()
        assert sim.emulator_failures == []
    return scan, np.array(drawn)


@pytest.fixture(scope="module")
def scans():
    return _scan("steps"), _scan("continuous")


def test_each_frame_is_tagged_with_the_angle_it_was_drawn_at(scans):
    (steps, drawn_steps), (cont, drawn) = scans
    np.testing.assert_allclose(steps.angles, drawn_steps, atol=1e-12)  # at rest: the angle read there
    # Streaming: the motor's whole-tick readings, four a frame, fitted to the frame's time: within
    # 0.01°, 0.004° on average (a tick is 0.088°; the line's depth error is about 4× its angle's here).
    assert len(cont.angles) == len(drawn) and abs(len(cont.angles) - FRAMES) <= 2
    err = np.degrees(np.abs(cont.angles - drawn))
    assert err.max() < 0.01 and err.mean() < 0.004, (err.max(), err.mean())
    # The frames cover the same sweep, evenly.
    span = np.ptp(steps.angles)
    assert np.ptp(cont.angles) == pytest.approx(span, rel=0.05)
    assert np.diff(np.sort(cont.angles)).std() < 0.05 * span / FRAMES


def test_a_continuous_sweep_takes_its_frames_time_and_gives_the_same_cloud(scans):
    (steps, _), (cont, _) = scans
    frame = 1 / 15.0
    # Streaming: the frames' time, and the motor's short turn to the sweep's start.
    assert cont.timings["phys.sweep"] / 1e3 == pytest.approx(len(cont.angles) * frame, abs=0.2)
    # In steps each frame also waits for the motor's step.
    assert steps.timings["phys.sweep"] / 1e3 > FRAMES * frame
    assert len(cont.cloud) == pytest.approx(len(steps.cloud), rel=0.1)


def test_the_fit_averages_the_encoder_ticks_down():
    tick, fps, speed = 2 * math.pi / 4096, 15.0, math.radians(9.0)
    t_read = np.arange(41) / fps
    readings = np.c_[t_read, np.round((0.1 + speed * t_read) / tick) * tick]
    t_frames = t_read[:-1] + 0.5 / fps
    truth = 0.1 + speed * t_frames
    assert np.abs(fitted_angles(t_frames, readings) - truth).max() < tick / 4
    # Two readings alone are the line through them; one time alone is its reading.
    np.testing.assert_allclose(fitted_angles(np.array([0.5]), np.array([[0.0, 1.0], [1.0, 3.0]])), [2.0])
    np.testing.assert_allclose(fitted_angles(np.array([0.5]), np.array([[1.0, 2.0], [1.0, 2.0]])), [2.0])


def test_an_unknown_sweep_is_refused_by_name():
    with SimulatedCell(binpick.parts.tee(), count=1, seed=0, frames=4) as sim:
        with pytest.raises(InvalidInputError, match="sweep: 'spiral' is not one of 'steps', 'continuous'"):
            replace(sim.config, sweep="spiral")
        with pytest.raises(InvalidInputError, match="frames: a continuous sweep takes at least 2"):
            CellConfig(**{**sim.config.__dict__, "frames": 1, "sweep": "continuous"})


class _Untimed(FrameSource):
    """A camera that neither streams at a known rate nor times its frames."""

    def __init__(self, inner):
        self.inner = inner

    def begin(self, T):
        self.inner.begin(T)

    def grab(self):
        return self.inner.grab()


def test_a_camera_that_does_not_time_its_frames_cannot_sweep_continuously():
    with SimulatedCell(binpick.parts.tee(), count=1, seed=0, frames=4, sweep="continuous") as sim:
        sim.cell.camera = _Untimed(sim.cell.camera)
        with pytest.raises(InvalidInputError, match=r"sweep: a continuous sweep needs a camera .*_Untimed.*steps"):
            sim.cell.scan()
