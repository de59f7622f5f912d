"""A scan that gives no points says what its camera saw (issue 38: a scan with no laser line in
it said only 'is the laser on and the bin in view?')."""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
import pytest

import binpick
from binpick.cell.records import ScanResult
from binpick.errors import NoObjectFound
from binpick.sim import SimulatedCell
from binpick.vision import Cloud, describe_frames, extract_line

RNG = np.random.default_rng(7)


def _scene(level=110):
    """A grey, textured scene: no red in it."""
    g = np.clip(RNG.normal(level, 20, (120, 160)), 0, 255).astype(np.uint8)
    return np.dstack([g, g, g])


def test_dark_frames_say_dark():
    assert "dark" in describe_frames([np.zeros((120, 160, 3), np.uint8)] * 3)


def test_overexposed_frames_say_saturated():
    assert "saturated" in describe_frames([np.full((120, 160, 3), 255, np.uint8)] * 3)


def test_a_scene_without_red_says_no_line_is_there():
    text = describe_frames([_scene() for _ in range(3)])
    assert "no pixel is red enough" in text and "is the laser on" in text, text


def test_red_specks_that_are_no_line_say_so():
    frames = []
    for _ in range(3):
        img = _scene()
        ys, xs = RNG.integers(0, 120, 40), RNG.integers(0, 160, 40)
        img[ys, xs] = (0, 0, 255)  # scattered red pixels (BGR)
        frames.append(img)
    assert all(len(extract_line(f)) < 60 for f in frames)
    text = describe_frames(frames)
    assert "red enough for the line, but none could be followed" in text, text


def test_a_scan_without_points_names_what_the_camera_saw():
    with SimulatedCell(binpick.parts.tee(resolution=2.0), count=1, seed=0, frames=4) as sim:
        empty = Cloud(points=np.zeros((0, 3)), frame=np.zeros(0, np.int64), pixels=np.zeros((0, 2)), angle=np.zeros(0))
        scan = ScanResult(
            cloud=empty,
            angles=np.zeros(1),
            T_base_flanges=sim.layout.T_base_flange[None],
            frames=MappingProxyType({0: np.zeros((120, 160, 3), np.uint8)}),
            timings=MappingProxyType({}),
        )
        with pytest.raises(NoObjectFound, match=r"0 usable points \(1 frames kept: .*dark.*scan_contact_sheet\.png"):
            sim.cell.locate_all(scan)
