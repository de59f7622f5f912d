"""The calibration board lying in the simulated cell: frames that do not see it are the pile's
frames bit for bit; where the board is seen it is drawn only where nearer than the scene."""

from __future__ import annotations

import math

import numpy as np
import pytest

from binpick import parts
from binpick.calibration import find_checkerboard
from binpick.sim import BIN_ID, Cell, RenderedCamera
from binpick.sim.camera import _BoardLayer
from binpick.sim.render import World
from binpick.transforms import looking_at


@pytest.fixture(scope="module")
def cameras():
    """The same pile seen by a layout with the board and one without."""
    with_board = RenderedCamera(parts.tee(), count=4, seed=5)
    without = RenderedCamera(parts.tee(), count=4, seed=5, layout=Cell(board=None))
    return with_board, without


def _grab(camera, T, angle=0.05):
    camera.begin(T)
    camera.laser_at(angle)
    return camera.grab()


def test_scan_pose_frames_are_unchanged(cameras):
    with_board, without = cameras
    T = with_board.layout.T_base_flange
    assert np.array_equal(_grab(with_board, T), _grab(without, T))
    assert with_board._board is None


def test_board_is_seen_and_hidden_behind_the_bin_where_the_bin_is_nearer(cameras):
    with_board, without = cameras
    layout = with_board.layout
    # From above the bin's far side, looking steeply across its wall at the board.
    target = layout.board.center + np.array([0.0, 40.0, 0.0])
    T_bc = looking_at(target, distance=560.0, tilt=math.radians(42.0), azimuth=math.radians(90.0))
    T = T_bc @ np.linalg.inv(layout.T_flange_camera)
    img, plain = _grab(with_board, T), _grab(without, T)
    view = World.of_pile(with_board.pile).view(layout, T)
    layer = _BoardLayer(layout, view, T)
    assert layer.mask.sum() > 10_000
    unoccluded = _BoardLayer(layout, World().view(layout, T), T).mask  # the board's outline, nothing in front
    hidden = unoccluded & ~layer.mask
    assert hidden.sum() > 1000 and (view.ids[hidden] == BIN_ID).all()  # the bin wall stands in front there
    assert np.array_equal(img[~layer.mask], plain[~layer.mask])
    assert not np.array_equal(img[layer.mask], plain[layer.mask])
    looking_down = _grab(
        with_board, looking_at(layout.board.center, distance=600.0) @ np.linalg.inv(layout.T_flange_camera)
    )
    assert find_checkerboard(looking_down, layout.board.pattern) is not None
