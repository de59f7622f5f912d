"""Corner order fixed by the board's colours: whatever order the detector returns the corners in,
``orient`` puts them in the board's own (so a board seen upside down keeps its frame)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from binpick.calibration import board_pose, find_checkerboard
from binpick.calibration.camera import _oriented
from binpick.sim import Camera, render_checkerboard
from binpick.transforms import rotation_about

PATTERN, SQUARE = (9, 6), 20.0


@pytest.mark.parametrize("roll_deg", [0.0, 92.0, 177.0, -133.0])
def test_oriented_corners_give_the_true_board_frame_at_any_roll(roll_deg):
    cam = Camera()
    T_cb = np.eye(4)
    T_cb[:3, :3] = rotation_about([0.0, 0.0, 1.0], np.radians(roll_deg)) @ rotation_about([1.0, 0.0, 0.0], 0.3)
    T_cb[:3, 3] = np.array([0.0, 0.0, 650.0]) - T_cb[:3, :3] @ np.array([80.0, 50.0, 0.0])  # grid centre on axis
    img = render_checkerboard(cam, T_cb, pattern=PATTERN, square=SQUARE, seed=1)[:, :, ::-1].copy()
    corners = find_checkerboard(img, PATTERN, orient=True)
    assert corners is not None
    found = board_pose(corners, cam, PATTERN, SQUARE)
    assert np.linalg.norm(found[:3, 3] - T_cb[:3, 3]) < 2.0
    # Handed the corners in the reverse order (as the detector may give a board turned by π), the
    # board's colours put them back.
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    assert np.array_equal(_oriented(grey, corners[::-1].copy(), PATTERN), corners)
    assert np.array_equal(_oriented(grey, corners, PATTERN), corners)
