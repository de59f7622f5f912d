"""Each frame of a simulated scan is tagged with the angle the laser really was at when the
camera grabbed it: the motor driver reports a move only once the motor has stopped."""

import numpy as np

import binpick
from binpick.sim import SimulatedCell


def test_frames_are_tagged_with_the_angle_they_were_rendered_at():
    with SimulatedCell(binpick.parts.tee(), count=2, seed=0, frames=40) as sim:
        camera = sim.cell.camera
        rendered: list[float] = []
        grab = camera.grab

        def grab_and_note() -> np.ndarray:
            rendered.append(sim.laser_angle())
            return grab()

        camera.grab = grab_and_note
        scan = sim.cell.scan()
        assert sim.emulator_failures == []
    tagged = np.asarray(scan.angles)
    assert len(tagged) == len(rendered) == 40
    off = np.degrees(np.abs(tagged - np.asarray(rendered)))
    assert off.max() < 1e-9, f"{int((off > 1e-9).sum())} of 40 frames tagged up to {off.max():.3f}° off"
