"""The pictures of a run: a contact sheet whose laser line survives the shrink and whose tiles carry
the scan's frame numbers, and a picture per failed pick."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import binpick
from binpick import viz
from binpick.cell.records import Skipped
from binpick.errors import InvalidInputError


def test_the_laser_line_stays_bright_in_the_contact_sheet(tmp_path):
    frame = np.zeros((480, 1280, 3), dtype=np.uint8)
    frame[:, 700, 2] = 255  # a one-pixel red line, as the camera sees the laser
    path = viz.save_contact_sheet(tmp_path / "sheet.png", [frame, frame], numbers=[12, 44], columns=2, width=800)
    sheet = cv2.imread(str(path))
    assert sheet.shape == (150, 800, 3)
    # Shrunk 3.2 times, a plain area average would leave the line at about a third of full red.
    tile = sheet[40:, :400, 2]
    assert tile.max(axis=1).min() >= 240
    with pytest.raises(InvalidInputError, match="numbers"):
        viz.save_contact_sheet(tmp_path / "bad.png", [frame, frame], numbers=[1])


def test_a_failure_picture_shows_the_parts_passed_over_and_the_refused_grasps(tmp_path):
    tee = binpick.parts.tee()
    T = np.eye(4)
    T[:3, 3] = (400.0, 0.0, 13.0)
    pts = np.asarray(tee.points) + T[:3, 3]
    refused = {"tilt": np.stack([T, T]), "bin": T[None]}
    skipped = [Skipped(T, "none of 4320 grasps usable (3336 tilt, 966 bin)", refused=refused)]
    path = viz.save_failure(
        tmp_path / "failure.png",
        pts,
        model=tee,
        skipped=skipped,
        located=T,
        bin_bounds=((250.0, -100.0, 0.0), (550.0, 100.0, 80.0)),
        title="pick 3: no grasp",
    )
    image = cv2.imread(str(path))
    assert image is not None and image.shape[0] > 400 and image.shape[1] > 1000
    # The refused grasps' colours (tab:red, tab:purple) are drawn.
    rgb = image[:, :, ::-1].reshape(-1, 3).astype(int)
    for color in ((214, 39, 40), (148, 103, 189)):
        assert (np.abs(rgb - color).sum(axis=1) < 30).any(), color


def test_a_collision_is_drawn_at_its_pose_as_the_records_round_it(tmp_path):
    # The twin records a collision's gripper pose to 6 decimals: a tilted one is then a rotation
    # only to about 1e-6 (this one to 1.05e-6), which the pose checks refuse; the picture draws it.
    from binpick.transforms import rotation_about

    R = rotation_about((0.3, -0.8, 0.52), 0.9)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (400.0, 10.0, 40.0)
    rounded = np.round(T, 6)
    assert np.abs(rounded[:3, :3].T @ rounded[:3, :3] - np.eye(3)).max() > 1e-6
    touch = {"with": "part 2", "points": 5, "T_base_gripper": rounded.tolist()}
    tee = binpick.parts.tee()
    path = viz.save_failure(
        tmp_path / "c.png", np.asarray(tee.points) + (400.0, 0.0, 13.0), model=tee, collisions=[touch]
    )
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(InvalidInputError, match="collisions.T_base_gripper"):  # far from a rotation: still refused
        viz.save_failure(
            tmp_path / "d.png",
            np.asarray(tee.points),
            model=tee,
            collisions=[{**touch, "T_base_gripper": (2 * T).tolist()}],
        )
