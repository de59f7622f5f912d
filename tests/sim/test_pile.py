"""Physics piles: settled piles do not interpenetrate, rest inside the bin, repeat for a seed."""

import numpy as np
import pytest

import binpick
from _geometry import box_mesh
from binpick import sim


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee(resolution=1.0)


@pytest.fixture(scope="module")
def pile(tee):
    return sim.Pile(tee, 10, seed=3)


def _world_vertices(model, T):
    return model.vertices @ T[:3, :3].T + T[:3, 3]


def test_settled_pile_does_not_interpenetrate(pile):
    assert pile.last_settle.settled, pile.last_settle
    assert len(pile) == 10
    depth = pile.max_interpenetration(spacing=1.0)
    assert depth <= 0.5, f"parts overlap by {depth:.3f} mm"


def test_every_part_rests_inside_the_bin(pile, tee):
    (lo, hi) = pile.bin.bounds
    for T in pile.poses:
        v = _world_vertices(tee, T)
        assert (v[:, 0] >= lo[0] - 0.5).all() and (v[:, 0] <= hi[0] + 0.5).all()
        assert (v[:, 1] >= lo[1] - 0.5).all() and (v[:, 1] <= hi[1] + 0.5).all()
        assert (v[:, 2] >= lo[2] - 0.5).all(), v[:, 2].min()
        # Resting: nothing floats above the floor unsupported, the lowest part touches it.
    lowest = min(_world_vertices(tee, T)[:, 2].min() for T in pile.poses)
    assert lowest < lo[2] + 1.0


def test_interpenetration_check_sees_an_overlap(tee):
    T = np.eye(4)
    U = np.eye(4)
    U[0, 3] = 3.0  # 3 mm shift along the run: deep overlap
    assert sim.max_interpenetration(tee, np.stack([T, U])) > 2.0
    U[0, 3] = 200.0
    assert sim.max_interpenetration(tee, np.stack([T, U])) == 0.0


def test_same_seed_same_pile_other_seed_other_pile(tee):
    a = sim.Pile(tee, 4, seed=11)
    b = sim.Pile(tee, 4, seed=11)
    c = sim.Pile(tee, 4, seed=12)
    np.testing.assert_array_equal(a.poses, b.poses)
    assert np.abs(a.poses - c.poses).max() > 1.0


def test_picking_a_part_resettles_the_rest(tee):
    p = sim.Pile(tee, 5, seed=5)
    top = int(p.ids[np.argmax(p.poses[:, 2, 3])])
    report = p.remove(top)
    assert report.settled
    assert len(p) == 4 and top not in p.ids.tolist()
    assert p.max_interpenetration() <= 0.5
    with pytest.raises(binpick.InvalidInputError):
        p.remove(top)
    with pytest.raises(binpick.InvalidInputError):
        p.pose(top)


def test_collision_hulls_enclose_the_mesh(tee):
    hulls = sim.convex_decomposition(tee)
    assert len(hulls) >= 2
    # Outside distance of every mesh vertex from the nearest piece; the pile rounds pieces by a
    # 0.3 mm skin, so contacts stay off the real surface where the pieces fall short by less.
    outside = np.full(len(tee.vertices), np.inf)
    for v, f in hulls:
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        n = np.cross(b - a, c - a)
        area = np.linalg.norm(n, axis=1)
        keep = area > 1e-2  # sliver faces have no reliable normal
        n, a = n[keep] / area[keep, None], a[keep]
        n *= np.sign(np.einsum("ij,ij->i", n, a - v.mean(axis=0)))[:, None]
        d = np.einsum("ij,ij->i", n, a)
        outside = np.minimum(outside, (tee.vertices @ n.T - d).max(axis=1))
    assert (outside <= 0.3).mean() > 0.98, np.percentile(outside, [50, 99, 100])
    assert outside.max() < 1.0


@pytest.mark.parametrize(
    "kwargs",
    [dict(count_=0), dict(seed=-1), dict(friction=-1.0), dict(bin="big"), dict(time_step=0.0)],
)
def test_bad_input_is_rejected(tee, kwargs):
    args = dict(count_=3)
    args.update(kwargs)
    with pytest.raises(binpick.InvalidInputError):
        sim.Pile(tee, **args)


def test_bin_must_have_positive_size():
    with pytest.raises(binpick.InvalidInputError):
        sim.Bin(size=(100, -1, 50))


def test_a_low_poly_cad_part_falls_and_settles():
    """A box-like part whose mesh has only its 8 corners (as CAD exports flat parts) still gets
    solid collision pieces: the parts fall into the bin instead of hanging where they were dropped."""
    v, f = box_mesh((70.0, 40.0, 12.0))
    plate = binpick.Model.from_arrays(v, f, spacing=2.0)
    cell = sim.Cell()
    pile = sim.Pile(plate, 6, bin=cell.bin, seed=2)
    assert pile.last_settle.settled, pile.last_settle
    lo, hi = pile.bin.bounds
    tops = [_world_vertices(plate, T)[:, 2].max() for T in pile.poses]
    # Six 12 mm plates in a 300 × 200 mm bin lie at most a few deep, all below the rim.
    assert max(tops) < hi[2], tops
    assert min(_world_vertices(plate, T)[:, 2].min() for T in pile.poses) < lo[2] + 1.0
    assert pile.max_interpenetration(spacing=1.0) <= 0.5


def test_a_scene_placed_from_poses_settles_where_it_lies_and_can_be_set_back(pile, tee):
    placed = sim.Pile.placed(tee, pile.poses)  # a settled pile's poses: a scene at rest
    assert len(placed) == len(pile) and placed.last_settle.settled
    np.testing.assert_allclose(placed.poses[:, :3, 3], pile.poses[:, :3, 3], atol=1.0)
    # A part set in mid-air falls to the floor; set back, the scene is as placed.
    lifted = pile.poses.copy()
    lifted[0, 2, 3] += 60.0
    placed.set_poses(lifted)
    assert placed.poses[0, 2, 3] < lifted[0, 2, 3] - 30.0
    placed.set_poses(pile.poses)
    np.testing.assert_allclose(placed.poses[:, :3, 3], pile.poses[:, :3, 3], atol=1.0)


@pytest.mark.parametrize(
    "poses, match",
    [
        (np.zeros((0, 4, 4)), "poses"),
        (np.eye(4), "poses"),
        (np.full((1, 4, 4), np.nan), "poses"),
        (np.tile(np.eye(4), (501, 1, 1)), "poses"),
    ],
)
def test_bad_placed_poses_are_rejected(tee, poses, match):
    with pytest.raises(binpick.InvalidInputError, match=match):
        sim.Pile.placed(tee, poses)


def test_set_poses_needs_one_pose_per_part(pile, tee):
    placed = sim.Pile.placed(tee, pile.poses[:2])
    with pytest.raises(binpick.InvalidInputError, match="one per remaining part"):
        placed.set_poses(pile.poses[:1])
