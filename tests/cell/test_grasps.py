"""Grasp derivation and the grasp matching of the simulated gripper, checked against direct computation."""

from __future__ import annotations

import math

import numpy as np
import pytest

import binpick
from binpick.cell.grasp import GraspMatcher, branch_grasps
from binpick.poses import grasp_pose
from binpick.transforms import pose_error, rotation_about


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


def _tilt_deg(T_base_gripper):
    return math.degrees(math.acos(max(-1.0, min(1.0, -float(T_base_gripper[2, 2])))))


@pytest.mark.parametrize("pitch_deg", [0.0, 30.0])
@pytest.mark.parametrize("elevation_deg", [0.0, 20.0, 40.0, 44.0])
def test_a_tilted_branch_has_a_grasp_within_half_a_step_of_its_elevation(tee, elevation_deg, pitch_deg):
    # The most vertical approach square to a branch tilted e from horizontal is tilted e itself;
    # pitched by q along the branch it is tilted |e - q|, least over the pitches. The grasps must come
    # within half a step (2.5°) of it for every branch.
    grasps = branch_grasps(tee, pitches_deg=(-pitch_deg, 0.0, pitch_deg) if pitch_deg else (0.0,), end_pitches_deg=())
    rng = np.random.default_rng(3)
    for _ in range(5):
        R = rotation_about(np.array([0.0, 0.0, 1.0]), rng.uniform(0, 2 * math.pi))
        for b_index, b in enumerate(tee.branches):
            d = np.asarray(b.direction, dtype=float)
            # turn the part so that branch b points elevation_deg below the horizontal
            h = np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            T = np.eye(4)
            T[:3, :3] = R @ rotation_about(h, math.radians(elevation_deg))
            elev = math.degrees(math.asin(abs((T[:3, :3] @ d)[2])))
            assert elev == pytest.approx(elevation_deg, abs=1e-6)
            best = min(
                _tilt_deg(grasp_pose(T, G)) for name, G in grasps.items() if name.startswith(f"branch{b_index}/")
            )
            lowest = min(abs(elev - q) for q in (0.0, pitch_deg))
            assert lowest - 1e-6 <= best <= lowest + 2.5 + 1e-6


@pytest.mark.parametrize("elevation_deg", [50.0, 70.0, 90.0])
def test_a_branch_standing_up_is_gripped_from_its_end_nearly_upright(tee, elevation_deg):
    # Square approaches to a branch standing e above the horizontal tilt at least e - 30° (the
    # largest pitch); from the end at q from square, the approach tilts |q - e|. With q in 60, 75
    # and 90 a standing branch has an end grasp within 15° (+ half a step) of vertical, the
    # fingertips a finger's width in from the end face, closing square to the axis.
    grasps = branch_grasps(tee)
    rng = np.random.default_rng(5)
    for b_index, b in enumerate(tee.branches):
        d = np.asarray(b.direction, dtype=float)
        for _ in range(3):
            # turn the part so that branch b points elevation_deg above the horizontal, any heading
            up = np.array([0.0, 0.0, 1.0])
            h = np.cross(d, up) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            T = np.eye(4)
            T[:3, :3] = rotation_about(up, rng.uniform(0, 2 * math.pi)) @ rotation_about(h, math.radians(elevation_deg))
            assert math.degrees(math.asin((T[:3, :3] @ d)[2])) == pytest.approx(elevation_deg, abs=1e-6)
            ends = {n: G for n, G in grasps.items() if n.startswith(f"branch{b_index}/") and "/end" in n}
            tilts = {n: _tilt_deg(grasp_pose(T, G)) for n, G in ends.items()}
            best = min(tilts, key=tilts.get)
            lowest = min(abs(q - elevation_deg) for q in (60.0, 75.0, 90.0))
            assert lowest - 1e-6 <= tilts[best] <= lowest + 2.5 + 1e-6
            # square to the axis, tips on the axis 20 mm in from the end face (or mid-branch)
            T_og = np.linalg.inv(ends[best])
            assert abs(T_og[:3, 0] @ d) < 1e-9
            tip = T_og[:3, 3] + 10.0 * T_og[:3, 2]  # the default tip depth
            lift = 5.0 if best.endswith("/raised5mm") else 0.0  # raised: half the tip depth back along the approach
            assert np.allclose(tip, max(b.length - 20.0, b.length / 2) * d - lift * T_og[:3, 2], atol=1e-6)


def test_vectorised_grasp_matching_equals_pose_error_over_every_grasp(tee):
    S = np.eye(4)
    S[:3, :3] = rotation_about(np.array([0.0, 1.0, 0.0]), math.pi)
    every = branch_grasps(tee, pitches_deg=(0.0,))  # 864 grasps; every fourth: pose_error over each is slow
    grasps = {name: G for k, (name, G) in enumerate(every.items()) if k % 4 == 0}
    matcher = GraspMatcher(grasps, (S,), tolerance_deg=12.0, tolerance_mm=6.0)
    values = list(grasps.values())
    rng = np.random.default_rng(0)
    for k in range(40):
        T = values[rng.integers(len(values))].copy()
        T[:3, :3] = rotation_about(rng.normal(size=3), rng.uniform(0, 0.4 if k < 20 else 3.0)) @ T[:3, :3]
        T[:3, 3] += rng.normal(size=3) * (3.0 if k < 20 else 30.0)
        expected = min((pose_error(T, G, (S,)) for G in values), key=lambda e: e[0] / 12.0 + e[1] / 6.0)
        assert matcher.error(T) == pytest.approx(expected, abs=1e-6)


def _random_grasps(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` grasps at random turns, their TCPs about 20 mm from the object's origin."""
    grasps = []
    for _ in range(n):
        G = np.eye(4)
        G[:3, :3] = rotation_about(rng.normal(size=3), rng.uniform(0.0, math.pi))
        G[:3, 3] = rng.normal(size=3) * 20.0
        grasps.append(G)
    return grasps


def test_the_matcher_allows_any_turn_about_a_continuous_symmetry_axis():
    # A shaft's pose about its own axis is arbitrary: a grip of the shaft turned by any angle about
    # its axis (through a centre off the object origin) is the same grip, and the matcher finds the
    # turn in closed form; a turn about another axis or a shift along the axis is still an error.
    rng = np.random.default_rng(3)
    centre, axis = np.array([2.0, -1.0, 5.0]), np.array([0.0, 0.0, 1.0])
    grasps = _random_grasps(rng, 5)
    plain = GraspMatcher(grasps, tolerance_deg=12.0, tolerance_mm=6.0)
    shaft = GraspMatcher(grasps, tolerance_deg=12.0, tolerance_mm=6.0, continuous=(centre, axis * 3.0))
    for angle in (0.3, 1.7, -2.9):
        turn = np.eye(4)
        turn[:3, :3] = rotation_about(axis, angle)
        turn[:3, 3] = centre - turn[:3, :3] @ centre
        T = grasps[2] @ turn
        deg, mm = shaft.error(T)
        assert deg < 1e-6 and mm < 1e-6
        assert plain.error(T)[0] > 15.0
        tipped = T.copy()
        tipped[:3, :3] = T[:3, :3] @ rotation_about(np.array([1.0, 0.0, 0.0]), math.radians(20.0))
        assert shaft.error(tipped)[0] == pytest.approx(20.0, abs=1e-6)
        slid = T.copy()
        slid[:3, 3] += T[:3, :3] @ axis * 8.0
        assert shaft.error(slid)[1] == pytest.approx(8.0, abs=1e-6)
    with pytest.raises(binpick.InvalidInputError, match="continuous"):
        GraspMatcher(grasps, tolerance_deg=12.0, tolerance_mm=6.0, continuous=(centre, np.zeros(3)))


def test_the_matcher_weighs_a_stack_of_poses_as_it_weighs_each_and_names_a_bad_one():
    # A planner weighs a batch of grasps against each alternative of an undecided pose at once:
    # errors() of a stack is error() of each (a flip symmetry and a continuous axis off the
    # origin), and a stack with a bad pose is refused naming it.
    rng = np.random.default_rng(5)
    centre, axis = np.array([1.0, 4.0, -3.0]), np.array([0.0, 0.6, 0.8])
    flip = np.eye(4)
    flip[:3, :3] = rotation_about(np.array([1.0, 0.0, 0.0]), math.pi)
    flip[:3, 3] = centre - flip[:3, :3] @ centre
    grasps = _random_grasps(rng, 40)
    matcher = GraspMatcher(grasps, (flip,), tolerance_deg=12.0, tolerance_mm=6.0, continuous=(centre, axis))
    poses = []
    for k in range(50):
        T = grasps[rng.integers(len(grasps))].copy()
        T[:3, :3] = rotation_about(rng.normal(size=3), rng.uniform(0, 0.15 if k < 25 else 3.0)) @ T[:3, :3]
        T[:3, 3] += rng.normal(size=3) * (1.0 if k < 25 else 40.0)
        poses.append(T)
    deg, mm = matcher.errors(np.stack(poses))
    assert deg.shape == mm.shape == (50,)
    for T, d, m in zip(poses, deg, mm):
        assert (d, m) == pytest.approx(matcher.error(T), abs=1e-9)
    assert sum(matcher.within(e) for e in zip(deg, mm)) >= 20  # the near ones match a grasp
    bad = np.stack(poses[:3])
    bad[1, :3, :3] *= 1.1
    with pytest.raises(binpick.InvalidInputError, match=r"T_gripper_objects\[1\]"):
        matcher.errors(bad)
    with pytest.raises(binpick.ShapeError, match="T_gripper_objects"):
        matcher.errors(np.eye(4))
    assert [len(e) for e in matcher.errors(np.zeros((0, 4, 4)))] == [0, 0]
    nan = np.stack(poses[:2])
    nan[0, 0, 3] = np.nan
    with pytest.raises(binpick.NonFiniteError, match="T_gripper_objects"):
        matcher.errors(nan)


def test_matches_says_whether_any_grasp_is_within_tolerance_as_each_grasp_alone_says():
    # matches() weighs only the grasps near in translation (the swing of a turn about an axis
    # off the origin included): for every pose it must say what asking each grasp alone says.
    rng = np.random.default_rng(8)
    centre, axis = np.array([6.0, -4.0, 2.0]), np.array([0.0, 0.6, 0.8])  # 7 mm off the origin
    flip = np.eye(4)
    flip[:3, :3] = rotation_about(np.array([1.0, 0.0, 0.0]), math.pi)
    flip[:3, 3] = centre - flip[:3, :3] @ centre
    grasps = _random_grasps(rng, 30)
    kw = dict(tolerance_deg=12.0, tolerance_mm=6.0)
    for continuous in (None, (centre, axis)):
        matcher = GraspMatcher(grasps, (flip,), continuous=continuous, **kw)
        alone = [GraspMatcher([G], (flip,), continuous=continuous, **kw) for G in grasps]
        poses = []
        for k in range(300):
            T = grasps[rng.integers(len(grasps))].copy()
            if continuous is not None and k % 2:  # turned about the axis: the origin swings up to 14 mm
                turn = np.eye(4)
                turn[:3, :3] = rotation_about(axis, rng.uniform(-math.pi, math.pi))
                turn[:3, 3] = centre - turn[:3, :3] @ centre
                T = T @ turn
            T[:3, :3] = rotation_about(rng.normal(size=3), rng.uniform(0, 0.3)) @ T[:3, :3]
            T[:3, 3] += rng.normal(size=3) * 4.0
            poses.append(T)
        poses = np.stack(poses)
        expected = np.zeros(len(poses), dtype=bool)
        for m in alone:
            deg, mm = m.errors(poses)
            expected |= (deg <= 12.0) & (mm <= 6.0)
        got = matcher.matches(poses)
        assert got.tolist() == expected.tolist()
        assert 50 < got.sum() < 290  # both answers occur
        assert matcher.matches(np.zeros((0, 4, 4))).shape == (0,)
    bad = poses[:3].copy()
    bad[2, :3, :3] *= 1.1
    with pytest.raises(binpick.InvalidInputError, match=r"T_gripper_objects\[2\]"):
        matcher.matches(bad)


def test_nearest_distances_are_the_brute_force_distances():
    from binpick.models import nearest_distances

    rng = np.random.default_rng(2)
    points, reference = rng.normal(size=(400, 3)) * 30.0, rng.normal(size=(700, 3)) * 30.0
    brute = np.sqrt(((points[:, None, :] - reference[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    assert nearest_distances(points, reference) == pytest.approx(brute, abs=1e-9)
    assert np.isinf(nearest_distances(points[:2], np.zeros((0, 3)))).all()
    assert nearest_distances(np.zeros((0, 3)), reference).shape == (0,)
    with pytest.raises(binpick.NonFiniteError, match="reference"):
        nearest_distances(points, np.full((2, 3), np.nan))
    with pytest.raises(binpick.ShapeError, match="points"):
        nearest_distances(points[:, :2], reference)


def _occupied_by_hand(g, p, gap, margin, grow):
    """The gripper's volume written out: two finger boxes and the body's cylinder above them."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    side = margin - grow
    top = g.tip_depth_mm - g.finger_length_mm
    offset, half = gap / 2 + g.finger_thickness_mm / 2, g.finger_thickness_mm / 2 - side
    finger = (
        (z <= g.tip_depth_mm - margin)
        & (z >= top + side)
        & (np.abs(y) <= g.finger_width_mm / 2 - side)
        & ((np.abs(x - offset) <= half) | (np.abs(x + offset) <= half))
    )
    body = (z < top - side) & (z >= top - g.body_length_mm + side) & (np.hypot(x, y) <= g.body_radius_mm - side)
    return finger | body


def test_the_gripper_volume_and_its_counts_at_many_poses_are_the_pieces_written_out():
    from binpick.cell import GripperGeometry
    from binpick.cell.grasp import points_in_gripper

    g = GripperGeometry(open_width_mm=60.0, finger_length_mm=40.0, body_radius_mm=30.0)
    rng = np.random.default_rng(4)
    local = rng.uniform((-45, -25, -110), (45, 25, 20), size=(6, 4000, 3))
    gaps = rng.uniform(0.0, 60.0, size=(6, 1))
    for margin, grow in ((0.0, 0.0), (1.0, 0.0), (0.0, 3.0)):
        expected = _occupied_by_hand(g, local, gaps, margin, grow)
        assert g.occupied(local, gaps, margin, grow).tolist() == expected.tolist()
        assert 500 < expected.sum() < 20000
    assert g.occupied(local[0, :5]).tolist() == _occupied_by_hand(g, local[0, :5], 60.0, 0.0, 0.0).tolist()
    # Counted at poses in the base frame: the same points, each pose's own.
    poses = []
    for _ in range(6):
        T = np.eye(4)
        T[:3, :3] = rotation_about(rng.normal(size=3), rng.uniform(0, math.pi))
        T[:3, 3] = rng.normal(size=3) * 100.0
        poses.append(T)
    poses = np.stack(poses)
    base = np.concatenate([local[k] @ poses[k, :3, :3].T + poses[k, :3, 3] for k in range(6)])
    counts = g.hits(base, poses, gaps[:, 0], 0.0, 2.0)
    for k in range(6):
        back = (base - poses[k, :3, 3]) @ poses[k, :3, :3]
        assert counts[k] == _occupied_by_hand(g, back, gaps[k, 0], 0.0, 2.0).sum()
        assert points_in_gripper(g, base, poses[k], gaps[k, 0]) == _occupied_by_hand(g, back, gaps[k, 0], 0, 0).sum()
    with pytest.raises(binpick.InvalidInputError, match="T_base_gripper"):
        g.hits(base, poses * 1.1, gaps[:, 0])
    # The points bucketed once count the same, plain and swept.
    scene = g.scene(base)
    assert len(scene) == len(base)
    assert g.hits(scene, poses, gaps[:, 0], 0.0, 2.0).tolist() == counts.tolist()
    swept = dict(back_mm=30.0, floor_z_mm=float(base[:, 2].min()) - 1.0)
    along = g.hits(base, poses, gaps[:, 0], 0.0, 2.0, **swept)
    assert g.hits(scene, poses, gaps[:, 0], 0.0, 2.0, **swept).tolist() == along.tolist()
    # Swept, every point in the gripper still counts, and more do (the approach, the columns),
    # as a sampling of the motion finds them: the gripper slid back along its axis, each point
    # pushed down its column (300 of the points, 1 mm steps).
    assert (along >= counts).all() and (along > counts).any()
    few = base[rng.choice(len(base), 300, replace=False)]
    depths = np.arange(0.0, few[:, 2].max() - swept["floor_z_mm"] + 1.0, 1.0)
    for k in range(6):
        exact = int(g.hits(few, poses[k][None], gaps[k], 0.0, 2.0, **swept)[0])
        column = few[None, :, :] - depths[:, None, None] * np.array([0.0, 0.0, 1.0])
        above = column[..., 2] >= swept["floor_z_mm"]
        local = (column - poses[k, :3, 3]) @ poses[k, :3, :3]
        met = np.zeros(len(few), dtype=bool)
        for slide in np.arange(0.0, 30.01, 1.0):
            met |= (g.occupied(local + [0.0, 0.0, slide], gaps[k, 0], 0.0, 2.0) & above).any(axis=0)
        assert abs(int(met.sum()) - exact) <= 2, (k, int(met.sum()), exact)
    # Closing from their opening to a narrower width, the fingers meet what a sampling of the
    # widths between meets (at the pose; the approach is made open; the clearance grows each
    # finger but for the face that closes onto the part), and counts stop at at_most.
    shut = gaps[:, 0] * rng.uniform(0.2, 0.9, size=6)
    closing = g.hits(base, poses, gaps[:, 0], 0.0, 2.0, closing_mm=shut)
    assert (closing >= counts).all() and (closing > counts).any()
    for k in range(6):
        back = (base - poses[k, :3, 3]) @ poses[k, :3, :3]
        met = np.zeros(len(base), dtype=bool)
        for w in np.linspace(shut[k], gaps[k, 0], 200):
            met |= g.occupied(back, min(w + 2 * 2.0, gaps[k, 0]), 0.0, 2.0)
        assert abs(int(met.sum()) - int(closing[k])) <= 2, (k, int(met.sum()), int(closing[k]))
    capped = g.hits(scene, poses, gaps[:, 0], 0.0, 2.0, closing_mm=shut, at_most=5)
    assert capped.tolist() == np.minimum(closing, 5).tolist()
    for bad, match in (
        (dict(back_mm=-1.0), "back_mm"),
        (dict(floor_z_mm=float("nan")), "floor_z_mm"),
        (dict(closing_mm=gaps[:, 0] + 1.0), "closing_mm"),
        (dict(closing_mm=np.full(6, np.nan)), "closing_mm"),
        (dict(closing_mm=np.ones(4)), "closing_mm"),
        (dict(at_most=0), "at_most"),
    ):
        with pytest.raises(binpick.InvalidInputError, match=match):
            g.hits(base, poses, gaps[:, 0], **bad)
