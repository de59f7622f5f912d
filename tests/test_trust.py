"""Poses you can trust (issue 13): one judge for every method, near-symmetric parts recovered
where the feature shows and flagged where it does not, a calibrated confidence, and
``estimate_pose`` exactly the first of ``estimate_poses`` — on scenes the tests make."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from _geometry import camera_cloud, extruded_mesh, pile_view, rendered_view, rot
from binpick import sim

METHODS = ("auto", "ppf", "ccp", "centroid")
VIEWPOINT = sim.Cell().T_base_camera[:3, 3]


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


@pytest.fixture(scope="module")
def plain_tee(tee):
    """The paper's tee read as a plain mesh: no branches declared, only its geometry."""
    return binpick.Model.from_arrays(tee.vertices, tee.faces, unit="mm", name="plain-tee")


def pick_grade(model, T, truth) -> bool:
    rot_err, trans_err = model.pose_error(T, truth)
    return rot_err < 5 and trans_err < 3


def lying(yaw: float, boss_up: bool, xy=(400.0, 0.0)) -> np.ndarray:
    """The tee lying in the bin (its boss along +z in the model frame) turned by ``yaw``."""
    T = np.eye(4)
    T[:3, :3] = rot((0, 0, 1), yaw) @ (np.eye(3) if boss_up else rot((1, 0, 0), np.pi))
    T[:3, 3] = [xy[0], xy[1], 40.0]
    return T


def test_the_tee_has_one_near_symmetry_broken_at_its_boss(plain_tee):
    near = plain_tee.near_symmetries
    assert plain_tee.symmetries.is_trivial
    assert len(near) == 1
    n = near[0]
    assert n.angle is not None and abs(n.angle - np.pi) < np.radians(2)
    assert 0.85 <= n.agreement < 0.98
    # The feature is the boss (it stands out along +z) and the place the flip moves it to: far
    # from the run's mid-plane, but for a few samples at sampling gaps.
    assert (np.abs(n.feature[:, 2] - n.center[2]) > 5).mean() > 0.9
    T = n.transform
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)


def test_a_boss_in_view_decides_the_flip_and_a_hidden_one_is_flagged(plain_tee):
    rng = np.random.default_rng(13)
    for yaw in (0.4, 2.2, -1.6):
        truth = lying(yaw, boss_up=True)
        res = binpick.estimate_pose(rendered_view(plain_tee, truth, rng), plain_tee, num_threads=1)
        assert pick_grade(plain_tee, res.T_scene_model, truth), f"yaw {yaw}"
        assert not res.ambiguous and res.confidence >= 0.9
        truth = lying(yaw, boss_up=False)
        res = binpick.estimate_pose(rendered_view(plain_tee, truth, rng), plain_tee, num_threads=1)
        poses = [res.T_scene_model] + [a.T_scene_model for a in res.alternatives]
        # Never confident-wrong: right, or flagged with the truth among the alternatives.
        assert pick_grade(plain_tee, res.T_scene_model, truth) or (
            res.ambiguous and any(pick_grade(plain_tee, T, truth) for T in poses)
        ), f"yaw {yaw}"
        if res.ambiguous:
            assert res.confidence <= 0.5
            assert all(set(a.evidence) >= {"fits", "misfits", "seen_through", "score"} for a in res.alternatives)


@pytest.fixture(scope="module")
def flange():
    return binpick.parts.flange()


def test_a_small_feature_decides_where_the_feature_region_is_wide(flange):
    """The flange turns onto itself about its axis but for six bolt holes (every 60°) and a
    3 × 10 mm notch in the rim (once): the region where its features can lie is its whole face,
    thousands of scan points that every turn fits alike. Where the notch shows, the few points
    that fit one turn and not another decide — not a share of the thousands (the margin was once
    10 % of them, and such views came back with a free axis at confidence 0.03)."""
    rng = np.random.default_rng(17)
    for yaw in (0.3, 1.9, -2.4):
        truth = np.eye(4)
        truth[:3, :3] = rot((0, 0, 1), yaw)
        truth[:3, 3] = [400.0, 0.0, 40.0]
        res = binpick.estimate_pose(rendered_view(flange, truth, rng), flange, num_threads=1)
        assert pick_grade(flange, res.T_scene_model, truth), f"yaw {yaw}"
        # Decided: a lead of well over one margin (0.7; each probe seen through is one observation
        # however many points it stands for, so the margin is not the points' alone).
        assert not res.ambiguous and res.confidence >= 0.7, (yaw, res.confidence, res.free_axis)


def test_a_feature_too_small_for_the_agreement_still_makes_the_part_near_symmetric():
    """A 100 mm plate with one corner cut 2.5 mm deep: the cut is 0.3 % of the surface, which an
    agreement of 98 % alone took for noise — the square's eight turns were reported as proper
    symmetries, and every pose came back "pick-grade" at 0.99 whichever corner it put the cut at
    (14 confident-wrong of 20 on a bench of such plates). The turns that move the cut are
    near-symmetries: a view is right or says it cannot tell, never confidently wrong."""
    plate = binpick.parts.cut_plate(side=100.0, thickness=6.0, cut=3.5)
    assert len(plate.symmetries.rotations) == 2, plate.symmetries
    quarter_turns = [n for n in plate.near_symmetries if n.agreement >= 0.98]
    assert len(quarter_turns) == 3, plate.near_symmetries
    rng = np.random.default_rng(31)
    decided = 0
    for yaw in (0.3, 1.9, -2.4):
        for tilt in (0.0, 0.35):
            truth = np.eye(4)
            truth[:3, :3] = rot((0, 0, 1), yaw) @ rot((1, -1, 0), tilt)
            truth[:3, 3] = [400.0, 0.0, 40.0]
            res = binpick.estimate_pose(rendered_view(plate, truth, rng), plate, num_threads=1)
            right = pick_grade(plate, res.T_scene_model, truth)
            poses = [res.T_scene_model] + [a.T_scene_model for a in res.alternatives]
            assert right or (res.ambiguous and any(pick_grade(plate, T, truth) for T in poses)), (yaw, tilt)
            decided += right and not res.ambiguous
    # Tilted towards the camera the cut shows well enough to decide.
    assert decided >= 3


_FLIP_X = np.eye(4)
_FLIP_X[:3, :3] = rot((1, 0, 0), np.pi)


def _right_or_flagged(model, rng: np.random.Generator, views: int) -> int:
    """Poses ``model`` (an extruded part whose one symmetry is the flip about x) in ``views``
    random orientations before the simulated camera; asserts each pose is pick-grade or flagged
    ambiguous and returns how many were decided right."""
    decided = 0
    for k in range(views):
        truth = np.eye(4)
        truth[:3, :3] = rot(rng.normal(size=3), rng.uniform(0, np.pi))
        truth[:3, 3] = [400 + rng.uniform(-30, 30), rng.uniform(-30, 30), 60.0]
        res = binpick.estimate_pose(rendered_view(model, truth, rng), model, num_threads=1)
        rot_err, trans_err = binpick.transforms.pose_error(res.T_scene_model, truth, [_FLIP_X])
        right = rot_err < 5 and trans_err < 3
        assert right or res.ambiguous, (k, rot_err, res.confidence)
        decided += right and not res.ambiguous
    return decided


def test_a_small_slot_decides_the_turn_of_a_disc_to_within_pick_grade():
    """A 50 × 8 mm disc with one 3 × 4 mm slot in its rim (a part no bench has): the turns about
    its axis lie 15° apart, and the slot pulled the nearest one too weakly to bring it onto the
    slot — views came back 6–8° off, decided, at 0.53–0.63. The best turn is tried at finer
    steps too; every view is right or flagged."""
    t0 = np.arcsin(1.5 / 25)
    a = np.linspace(t0, 2 * np.pi - t0, 120)
    v, f = extruded_mesh(np.r_[np.c_[25 * np.cos(a), 25 * np.sin(a)], [[21.0, -1.5], [21.0, 1.5]]], 8.0)
    v[:, 2] -= 4.0
    disc = binpick.Model.from_arrays(v, f, unit="mm", name="slotted-disc")
    assert _right_or_flagged(disc, np.random.default_rng(1), 12) >= 5


def test_a_flat_on_a_shaft_is_no_symmetry_at_the_default_samples():
    """A 60 mm D-shaft (radius 6 mm, a flat 1 mm deep along it) at the default samples: a half
    turn about the axis, about a centre the flat itself displaced, put the flat half a
    millimetre from the round side, within the tolerance, and the part passed for one with four
    symmetries — 6 views in 14 had no pose. Its only symmetry is the flip about the flat's
    normal; every view is right or flagged."""
    a = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    outline = np.c_[np.minimum(6 * np.cos(a), 5.0), 6 * np.sin(a)]
    outline = outline[np.r_[True, np.abs(np.diff(outline, axis=0)).sum(axis=1) > 1e-9]]
    v, f = extruded_mesh(outline, 60.0)
    v[:, 2] -= 30.0
    shaft = binpick.Model.from_arrays(v, f, unit="mm", name="d-shaft")
    assert len(shaft.symmetries.rotations) == 2, shaft.symmetries
    assert np.allclose(np.abs(shaft.symmetries.rotations[1]), np.abs(_FLIP_X[:3, :3]), atol=0.02)
    assert _right_or_flagged(shaft, np.random.default_rng(11), 8) >= 2


def test_confidence_is_calibrated_on_a_seeded_set(plain_tee):
    """Of the poses reported at confidence >= c, at least a fraction c are pick-grade."""
    rng = np.random.default_rng(29)
    reported = []
    for k in range(12):
        truth = lying(rng.uniform(-np.pi, np.pi), boss_up=bool(k % 2), xy=(rng.uniform(340, 460), rng.uniform(-40, 40)))
        tilt = np.eye(4)
        tilt[:3, :3] = rot(rng.normal(size=3), rng.uniform(0, np.radians(35)))
        truth = truth @ tilt
        try:
            res = binpick.estimate_pose(rendered_view(plain_tee, truth, rng), plain_tee, num_threads=1)
        except binpick.NoObjectFound:
            continue
        reported.append((res.confidence, pick_grade(plain_tee, res.T_scene_model, truth)))
    conf = np.array([c for c, _ in reported])
    good = np.array([g for _, g in reported])
    assert len(reported) >= 10
    assert (conf >= 0.9).sum() >= 4, "the confidence must also say when a pose is sure"
    for c in (0.5, 0.7, 0.9):
        sel = conf >= c
        if sel.any():
            assert good[sel].mean() >= c, f"confidence >= {c}: {good[sel].mean():.2f} pick-grade"


def test_a_right_pose_fits_at_the_scans_noise(tee):
    """PoseResult.fit: the residuals of a right pose are at the noise the scan itself shows (read
    without the model), so the fit costs it no confidence. (A pose off the surface by more than
    the noise, and the turns a scan cannot see, are tested in the core's pose tests.)"""
    rng = np.random.default_rng(41)
    for noise in (0.1, 0.25):
        truth = lying(0.7, boss_up=True)
        res = binpick.estimate_pose(rendered_view(tee, truth, rng, noise=noise), tee, num_threads=1)
        assert pick_grade(tee, res.T_scene_model, truth)
        fit = res.fit
        assert fit is not None and fit["factor"] == 1.0 and fit["ratio"] < 2.0, fit
        # The floor is the scan's noise along the view (or the judge's finest, 0.1 mm).
        assert max(0.1, 0.6 * noise) < fit["noise_floor_mm"] < 1.6 * noise + 0.05, fit
        assert fit["residual_sigma_mm"] < 2.0 * noise + 0.05, fit


def test_a_part_unlike_its_model_is_no_object_and_the_error_names_the_fit():
    """A pose whose points sit more than 2.5 times the scan's own noise off the model is not
    reported: an elbow 1.5 mm fatter all round than its CAD model lies mostly within the judge's
    tolerance but far beyond the scan's 0.1 mm noise, for every method. The elbow of the right
    size, in the same place, is found."""
    model = binpick.parts.elbow()
    fat = binpick.parts.elbow(outer_diameter=29.0)
    truth = np.eye(4)
    truth[:3, :3] = rot((0, 0, 1), 0.6)
    truth[:3, 3] = [400.0, 0.0, 40.0]
    rng = np.random.default_rng(47)
    right = binpick.estimate_pose(rendered_view(model, truth, rng, noise=0.1), model, num_threads=1)
    assert pick_grade(model, right.T_scene_model, truth) and right.fit["ratio"] < 2.0, right.fit
    wrong = rendered_view(fat, truth, rng, noise=0.1)
    for method in METHODS:
        with pytest.raises(binpick.NoObjectFound) as err:
            binpick.estimate_pose(wrong, model, method=method, num_threads=1)
        if method in ("ppf", "ccp"):
            assert "noise floors off the model" in str(err.value), str(err.value)


def uniform_noise(seed: int) -> np.ndarray:
    lo, hi = np.array([260.0, -90.0, 0.0]), np.array([540.0, 90.0, 80.0])
    return np.random.default_rng(seed).uniform(lo, hi, (20000, 3))


def empty_bin() -> np.ndarray:
    cell = sim.Cell()
    world = sim.World()
    world.add_bin(cell.bin)
    return camera_cloud(world.view(cell), cell, step=2)[0]


@pytest.fixture(scope="module")
def bracket_pile():
    """Six L-brackets in the bin: a pile of another part. (Not the elbow: it is the tee less one
    branch, so two thirds of a tee fit it exactly — see the closing note of issue 13.)"""
    v, f = extruded_mesh([(0, 0), (80, 0), (80, 12), (12, 12), (12, 50), (0, 50)], 30.0)
    return pile_view(binpick.Model.from_arrays(v, f, spacing=1.0, name="bracket"), 6, seed=3, step=2)[2]


@pytest.mark.parametrize("scene_kind", ["noise", "empty bin", "other part"])
def test_scenes_without_the_part_give_no_pose_for_every_method(tee, bracket_pile, scene_kind):
    scenes = {"noise": lambda: uniform_noise(1), "empty bin": empty_bin, "other part": lambda: bracket_pile}
    scene = scenes[scene_kind]()
    for method in METHODS:
        for box in (sim.Cell().bin.bounds, None):
            with pytest.raises(binpick.NoObjectFound):
                binpick.estimate_poses(scene, tee, bin=box, method=method, num_threads=1)


@pytest.fixture(scope="module")
def tee_piles(tee):
    """Four piles of eight tees (seeds 8-11), seen by the cell's camera."""
    return {seed: pile_view(tee, 8, seed=seed, step=2) for seed in (8, 9, 10, 11)}


def test_a_plate_is_not_read_on_a_pile_of_tees(tee_piles):
    """The cut plate asked for on a pile of tees: before the judge's continuation test its face
    was confirmed on a tee of this pile (confidence 0.98 without the bin box), while the scan ran
    on past the plate in its face's plane (measured: 14 of 28 such calls on 7 piles gave a plate,
    4 do now, at confidence 0.02 and 0.32)."""
    cell, _, scene, _ = tee_piles[11]
    plate = binpick.parts.cut_plate()
    for box in (cell.bin.bounds, None):
        for method in ("auto", "ppf"):
            with pytest.raises(binpick.NoObjectFound):
                binpick.estimate_poses(scene, plate, bin=box, method=method, num_threads=1)


def test_an_elbow_is_seldom_read_on_a_pile_of_tees_and_always_on_a_pile_of_elbows(tee_piles):
    """Every face of an elbow is a tee's: before the extension test (a branch's cylinder carried
    on past its end) every one of the five instances asked for on each of these four piles was an
    elbow read on a tee, at confidence 0.99. Now the tee's run going on past the elbow's corner
    refuses it where the scan shows it: 4 of 20 are left (seeds 8-11: 0, 2, 1, 1), those whose
    run past the corner is covered or turned away. Real elbows keep every instance."""
    elbow = binpick.parts.elbow()
    found = 0
    for cell, _, scene, _ in tee_piles.values():
        try:
            found += len(binpick.estimate_poses(scene, elbow, bin=cell.bin.bounds, num_threads=1, max_instances=5))
        except binpick.NoObjectFound:
            pass
    assert found <= 6, f"{found} elbows read on 4 piles of tees (measured 4; 20 without the extension test)"
    for seed in (8, 9):
        cell, pile, scene, _ = pile_view(elbow, 8, seed=seed, step=2)
        found = binpick.estimate_poses(scene, elbow, bin=cell.bin.bounds, num_threads=1, max_instances=5)
        assert len(found) == 5, f"seed {seed}: {len(found)} elbows"
        for r in found:
            assert any(pick_grade(elbow, r.T_scene_model, T) for T in pile.poses), f"seed {seed}: {r}"


@pytest.fixture(scope="module")
def tee_pile(tee):
    return pile_view(tee, 6, seed=8, step=2)


@pytest.mark.parametrize("method", ["auto", "ppf"])
def test_estimate_pose_is_exactly_the_first_of_estimate_poses(tee, tee_pile, method):
    cell, pile, scene, _ = tee_pile
    for box in (cell.bin.bounds, None):
        one = binpick.estimate_pose(scene, tee, bin=box, method=method, num_threads=1)
        first = binpick.estimate_poses(scene, tee, bin=box, method=method, num_threads=1)[0]
        np.testing.assert_array_equal(one.T_scene_model, first.T_scene_model)
        assert (one.score, one.confidence, one.ambiguous) == (first.score, first.confidence, first.ambiguous)
        np.testing.assert_array_equal(one.indices, first.indices)


def test_fewer_instances_of_a_wider_search_are_the_first_of_its_answer(tee):
    cell, _, scene, _ = pile_view(tee, 14, seed=2, step=2)
    box = cell.bin.bounds
    wide = binpick.estimate_poses(scene, tee, bin=box, max_instances=8, num_threads=1)
    few = binpick.estimate_poses(scene, tee, bin=box, max_instances=2, search_instances=8, num_threads=1)
    assert len(wide) > 2 and len(few) == 2
    for a, b in zip(few, wide):
        np.testing.assert_array_equal(a.T_scene_model, b.T_scene_model)
        assert (a.score, a.confidence, a.ambiguous, len(a.alternatives)) == (
            b.score,
            b.confidence,
            b.ambiguous,
            len(b.alternatives),
        )
    # The narrower search of the default (sized for 5) answers differently on this pile: the
    # width is what makes the two agree.
    narrow = binpick.estimate_poses(scene, tee, bin=box, max_instances=2, num_threads=1)
    assert not all(np.array_equal(a.T_scene_model, b.T_scene_model) for a, b in zip(narrow, wide))
    with pytest.raises(binpick.InvalidInputError, match="search_instances"):
        binpick.estimate_poses(scene, tee, search_instances=0)


def test_in_a_pile_an_uncovered_instance_comes_first(tee, tee_pile):
    cell, pile, scene, _ = tee_pile
    found = binpick.estimate_poses(scene, tee, bin=cell.bin.bounds, max_instances=5, num_threads=1)
    uncovered = [r.occluded_fraction <= 0.1 for r in found]
    assert any(uncovered)
    assert uncovered[0], [round(r.occluded_fraction, 2) for r in found]
    for r in found:
        assert any(pick_grade(tee, r.T_scene_model, T) for T in pile.poses)


def test_a_pinned_flange_pin_up_is_not_taken_for_its_flip_at_another_turn():
    """Piles of pinned flanges (a continuous near axis and a flip): the truth may be the flip at
    any turn about the axis, and the trust stage tries the flip at every turn it tries. Tried only
    at the pose's own turn, these three piles gave 7 poses whose truth was neither the pose nor
    one of its alternatives (two of them decided, 26° and 80° off at 0.73 and 0.62); now at most
    one, and no decided one."""
    from binpick.cell.symmetry import continuous_near_axis

    flange = binpick.parts.pinned_flange()
    axis = continuous_near_axis(flange)
    outside = []
    for seed in (3, 4, 5):
        cell, pile, scene, _ = pile_view(flange, 8, seed=seed, step=2)
        for r in binpick.estimate_poses(scene, flange, bin=cell.bin.bounds, max_instances=8, num_threads=1):
            errors = [flange.pose_error(r.T_scene_model, T) for T in pile.poses]
            T = pile.poses[int(np.argmin([mm for _, mm in errors]))]
            about = axis if r.free_axis is not None else None
            poses = [r.T_scene_model, *(a.T_scene_model for a in r.alternatives)]
            if not any(
                deg < 5.0 and mm < 3.0 for deg, mm in (flange.pose_error(P, T, turn_about=about) for P in poses)
            ):
                outside.append((seed, r.ambiguous, round(r.confidence, 2)))
    assert len(outside) <= 1, outside
    assert all(ambiguous for _, ambiguous, _ in outside), outside


def _first_scan_has_every_truth_open(model, count: int, seed: int):
    """The three poses found on the simulated cell's first scan of a pile (``count`` parts,
    ``seed``), each asserted to have its truth among itself, its alternatives and its free turns
    (pick-grade: 5°, 3 mm), or to be no surer of that than even odds; with the pile's poses."""
    from binpick.cell.symmetry import continuous_near_axis
    from binpick.sim import SimulatedCell

    axis = continuous_near_axis(model)
    with SimulatedCell(model, count=count, seed=seed, num_threads=1) as cell:
        scan = cell.cell.scan()
        options = cell.cell.pose_options(scan)
        results = binpick.estimate_poses(scan.points, model, bin=cell.config.bin_bounds, max_instances=3, **options)
        poses = cell.pile.poses
    assert len(results) == 3
    for r in results:
        T = poses[int(np.argmin([model.pose_error(r.T_scene_model, P)[1] for P in poses]))]
        about = axis if r.free_axis is not None else None
        found = [r.T_scene_model, *(a.T_scene_model for a in r.alternatives)]
        errors = [model.pose_error(P, T, turn_about=about) for P in found]
        assert any(deg < 5.0 and mm < 3.0 for deg, mm in errors) or r.confidence_any <= 0.5, (errors, r.confidence_any)
    return results, poses


def test_a_pinned_flange_whose_pin_the_scan_shows_is_not_located_face_down():
    """The simulated cell's laser scan of a pile of ten pinned flanges (seed 2): the top flange
    lies pin up and the scan shows its pin (some 30 points on it), yet it was located face down
    at confidence_any 0.76 and lifted as a wrong pose. Its flip at the pin's turn fitted fewer
    of the trust stage's quick look than three turns of the wrong face, and refined from the
    coarse turn the pin drifted 8 mm off; now the best turn of each side is compared, refined
    from its quick look. Every pose found has its truth among itself and its alternatives."""
    flange = binpick.parts.pinned_flange()
    results, poses = _first_scan_has_every_truth_open(flange, count=10, seed=2)
    top = results[0]
    assert (
        flange.pose_error(
            top.T_scene_model, poses[np.argmin(np.linalg.norm(poses[:, :3, 3] - top.T_scene_model[:3, 3], axis=1))]
        )[0]
        < 5.0
    )


@pytest.mark.parametrize(("part", "seed"), [("bossed_rod", 1), ("bossed_rod", 13), ("keyed_shaft", 19)])
def test_a_turn_the_quick_look_or_the_judge_cannot_rule_out_keeps_the_truth_open(part, seed):
    """The simulated cell's first scan of a pile of bossed rods or keyed shafts. Bossed rods,
    seed 1: the trust stage's quick look fitted most of the 24 turns about the rod's axis within
    a few glance points and compared only the three it ranked first; those lost to the pose on
    the depth test, the truth's turn was never compared, and a rod 72° off had confidence_any
    0.99. Seed 13: the rod's own pose, a turn of the one kept, was left open as a plain
    alternative rather than a free turn, and a rod 65° off had confidence_any 0.99. Keyed
    shafts, seed 19: every turn but the one kept had a few more probes seen through than the
    judge allows, none was counted, and a shaft 24° off was decided at 0.99. Every pose found
    has its truth among itself, its alternatives and its free turns, or is no surer of that than
    even odds."""
    _first_scan_has_every_truth_open(binpick.parts.built_in(part), count=8 + seed % 5, seed=seed)
