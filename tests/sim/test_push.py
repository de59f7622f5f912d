"""Pushing a pile with a kinematic tool: what it sweeps through moves, what it misses does not."""

import numpy as np
import pytest

import binpick
from binpick import sim

BLOCK = [((10.0, 10.0, 20.0), np.eye(4))]


def _at(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee(resolution=2.0)


def test_a_sweep_through_a_part_moves_it_inside_the_bin(tee):
    p = sim.Pile(tee, 1, seed=4)
    before = p.poses[0].copy()
    c = before[:3, :3] @ tee.vertices.mean(axis=0) + before[:3, 3]
    report = p.push(BLOCK, [_at(c[0] - 80, c[1], 28), _at(c[0] + 40, c[1], 28)], speed=60)
    assert report.moved == [0]
    assert report.settle.settled
    after = p.poses[0]
    assert after[0, 3] - before[0, 3] > 10.0
    world = tee.vertices @ after[:3, :3].T + after[:3, 3]
    half = np.asarray(p.bin.size[:2]) / 2
    centre = np.asarray(p.bin.center)
    assert world[:, 2].min() > p.bin.floor_z - 1.0
    assert (np.abs(world[:, :2] - centre) < half + 1.0).all()


def test_a_sweep_above_the_pile_moves_nothing(tee):
    p = sim.Pile(tee, 3, seed=2)
    before = p.poses.copy()
    report = p.push(BLOCK, [_at(350, 0, 200), _at(450, 0, 200)], speed=200)
    assert report.moved == []
    assert np.abs(p.poses[:, :3, 3] - before[:, :3, 3]).max() < 0.5


@pytest.mark.parametrize(
    "boxes, path, speed",
    [
        ([], [_at(0, 0, 200), _at(1, 0, 200)], 10),
        (BLOCK, [_at(0, 0, 200)], 10),
        (BLOCK, [_at(0, 0, 200), _at(1, 0, 200)], 0),
        ([((-1, 1, 1), np.eye(4))], [_at(0, 0, 200), _at(1, 0, 200)], 10),
        (BLOCK, [_at(0, 0, 200), np.full((4, 4), np.nan)], 10),
        (BLOCK, [_at(0, 0, 200), _at(1e6, 0, 200)], 1),
        ("box", [_at(0, 0, 200), _at(1, 0, 200)], 10),
    ],
)
def test_bad_pushes_are_refused(tee, boxes, path, speed):
    p = sim.Pile(tee, 1, seed=1)
    with pytest.raises(binpick.InvalidInputError):
        p.push(boxes, path, speed)
    assert len(p) == 1
