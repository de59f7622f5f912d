"""The paper's pose pipeline: segmentation, CCP + ICP, estimate_pose on views and on a physics
pile the test builds, grasp poses, and the bad inputs of a pose request."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from _geometry import pile_view, random_rotation
from binpick.transforms import pose_error, rotation_about

SYMMETRIES = {
    "tee": [np.eye(3)],
    "elbow": [np.eye(3), rotation_about([1, 1, 0], np.pi)],
    "cross": [rotation_about([0, 0, 1], k * np.pi / 2) for k in range(4)]
    + [rotation_about(a, np.pi) for a in ([1, 0, 0], [0, 1, 0], [1, 1, 0], [1, -1, 0])],
}


def symmetric_error(t_est, t_true, part) -> tuple[float, float]:
    errs = []
    for s in SYMMETRIES[part]:
        t = t_true.copy()
        t[:3, :3] = t_true[:3, :3] @ s
        errs.append(pose_error(t_est, t))
    return min(errs)


def partial_view(model, sampled, T, rng, noise=0.1):
    """What a sensor above (+z) sees of ``sampled`` (a second sampling of the part) posed at T."""
    pts = sampled.points @ T[:3, :3].T + T[:3, 3]
    nrm = sampled.normals @ T[:3, :3].T
    vis = nrm[:, 2] > 0.1
    return pts[vis] + rng.normal(0, noise, (int(vis.sum()), 3))


@pytest.mark.parametrize("part", ["tee", "elbow", "cross"])
def test_ccp_icp_recovers_random_poses_from_partial_noisy_views(part):
    rng = np.random.default_rng({"tee": 1, "elbow": 2, "cross": 3}[part])
    model = getattr(binpick.parts, part)(resolution=1.0)
    other = getattr(binpick.parts, part)(resolution=1.0, spacing=0.8, seed=9)
    ok = 0
    trials = 12
    for _ in range(trials):
        T = np.eye(4)
        T[:3, :3] = random_rotation(rng)
        T[:3, 3] = rng.uniform(-200, 200, 3)
        scene = partial_view(model, other, T, rng)
        try:
            res = binpick.estimate_pose(scene, model, method="ccp")
        except binpick.NoObjectFound:
            continue
        rot, trans = symmetric_error(res.T_scene_model, T, part)
        ok += rot < 5 and trans < 3
        assert res.score >= 0.6 and res.rmse < 1.0
    # Edge-on views (the branches' plane seen side-on) are the known weak case of CCP: allow
    # one miss per six views; a miss must still be a wrong pose flagged by a low score or
    # NoObjectFound, which the score assertion above checks for what is returned.
    assert ok >= trials - 2, f"{part}: {ok}/{trials} pick-grade"


def test_icp_alone_fails_where_ccp_succeeds():
    rng = np.random.default_rng(5)
    model = binpick.parts.tee(resolution=1.0)
    other = binpick.parts.tee(resolution=1.0, spacing=0.8, seed=4)
    T = np.eye(4)
    T[:3, :3] = rotation_about([0.3, 1, 0.2], np.radians(150))
    T[:3, 3] = [50, -20, 100]
    scene = partial_view(model, other, T, rng)
    good = binpick.estimate_pose(scene, model, method="ccp")
    assert max(pose_error(good.T_scene_model, T)) < 3
    # ICP alone from the centroids with the model's own orientation (the paper's baseline) falls
    # into a wrong basin.
    init = np.eye(4)
    init[:3, 3] = model.points.mean(axis=0) - scene.mean(axis=0)
    alone = binpick.icp(scene, model.points, init=init, max_correspondence_distance=10.0, target_normals=model.normals)
    assert pose_error(np.linalg.inv(alone.T_target_source), T)[0] > 20
    # The pipeline's centroid method passes the one judge and the near-symmetry check as every
    # method does: it says NoObjectFound, or its pose is right or flagged, never confidently wrong.
    try:
        bad = binpick.estimate_pose(scene, model, method="centroid")
    except binpick.NoObjectFound:
        return
    assert max(pose_error(bad.T_scene_model, T)) < 3 or bad.ambiguous or bad.confidence < 0.5


@pytest.fixture(scope="module")
def pile_scene():
    """A physics pile of five tees, seen by the simulated camera from the scan pose."""
    tee = binpick.parts.tee(resolution=1.0)
    return (tee, *pile_view(tee, 5, seed=11, step=3))


def test_segmentation_separates_touching_parts_in_a_pile(pile_scene):
    tee, cell, pile, scene, ids = pile_scene
    # Parts in this pile touch (the physics leaves no gap between resting parts).
    res = binpick.estimate_pose(scene, tee, bin=cell.bin.bounds)
    found = ids[res.indices]
    labels, counts = np.unique(found[found >= 0], return_counts=True)
    top = labels[np.argmax(counts)]
    # Where parts touch, a few points of the neighbour lie within the inlier distance of the posed
    # part; everything else belongs to one instance.
    assert counts.max() / len(found) > 0.95, dict(zip(labels.tolist(), counts.tolist()))
    # The object is one of the highest, and its pose is pick-grade against its ground truth.
    rot, trans = pose_error(res.T_scene_model, pile.pose(int(top)))
    assert rot < 5 and trans < 3, (rot, trans)
    assert (found == top).sum() >= 0.6 * (ids == top).sum()


def test_without_a_bin_box_the_support_planes_go_but_the_part_stays(pile_scene):
    tee, cell, pile, scene, ids = pile_scene
    res = binpick.estimate_pose(scene, tee)
    found = ids[res.indices]
    assert (found < 0).mean() < 0.02  # almost no floor or wall points in the object
    top = np.bincount(found[found >= 0]).argmax()
    assert (found == top).mean() > 0.9  # the rest: the touching neighbour
    # This top part stands on its run with the branch up; its position is found, while the turn
    # about the upright branch is only weakly seen (a known limit, checked in the bin-box test).
    assert pose_error(res.T_scene_model, pile.pose(int(top)))[1] < 3


def test_empty_bin_and_wrong_units_never_give_a_pose(pile_scene):
    tee, cell, pile, scene, ids = pile_scene
    bin_only = scene[ids < 0]
    with pytest.raises(binpick.NoObjectFound):
        binpick.estimate_pose(bin_only, tee, bin=cell.bin.bounds)
    with pytest.raises(binpick.NoObjectFound):
        binpick.estimate_pose(bin_only, tee)
    with pytest.raises(binpick.InvalidInputError, match="metres"):
        binpick.estimate_pose(scene / 1000.0, tee)
    with pytest.raises(binpick.InvalidInputError, match="bin"):
        binpick.estimate_pose(scene, tee, bin=[[0, 0, 0], [-1, 1, 1]])
    with pytest.raises(binpick.InvalidInputError, match="branches"):
        binpick.estimate_pose(scene, binpick.Model.from_arrays(tee.vertices, tee.faces, spacing=2.0), method="ccp")
    with pytest.raises(binpick.NonFiniteError):
        binpick.estimate_pose(np.full((100, 3), np.nan), tee)
    with pytest.raises(binpick.TooFewPointsError):
        binpick.estimate_pose(np.zeros((3, 3)), tee)


def test_grasp_pose_is_eq_30():
    rng = np.random.default_rng(2)
    T_base_object = np.eye(4)
    T_base_object[:3, :3] = random_rotation(rng)
    T_base_object[:3, 3] = [400, 20, 30]
    T_gripper_object = np.eye(4)
    T_gripper_object[:3, :3] = rotation_about([1, 0, 0], np.pi)
    T_gripper_object[:3, 3] = [0, 0, 120]
    T_base_gripper = binpick.grasp_pose(T_base_object, T_gripper_object)
    np.testing.assert_allclose(T_base_gripper @ T_gripper_object, T_base_object, atol=1e-12)
    tee = binpick.parts.tee(resolution=1.0)
    tee.add_grasp("top", T_gripper_object)
    np.testing.assert_array_equal(tee.grasps["top"], T_gripper_object)
    with pytest.raises(binpick.InvalidInputError):
        binpick.grasp_pose(T_base_object, np.eye(3))


def test_a_sparse_model_cloud_is_refined_on_its_mesh_to_the_paper_table_targets():
    """Table 3's setting: a 300-point model cloud of the tee's visible half, 100 data points of
    the same half with 0.3 mm noise, any pose. CCP works on the cloud; the refinement registers
    onto the tee's mesh surface, so the result meets the issue's 0.5 mm / 0.5° targets, which
    point-to-plane against 300 samples 5 mm apart does not."""
    rng = np.random.default_rng(21)
    mesh = binpick.parts.tee(resolution=1.0)
    dense_m = binpick.parts.tee(resolution=1.0, count=1200, seed=31)
    dense_d = binpick.parts.tee(resolution=1.0, count=400, seed=32)
    mi = np.flatnonzero(dense_m.normals[:, 2] > 0)[:300]
    di = np.flatnonzero(dense_d.normals[:, 2] > 0)[:100]
    model = binpick.Model(
        mesh.vertices.copy(),
        mesh.faces.copy(),
        dense_m.points[mi],
        dense_m.normals[mi],
        spacing=None,
        diameter=mesh.diameter,
        area=mesh.area,
        name="tee-300",
        branches=mesh.branches,
        special_direction=mesh.special_direction,
    )
    worst = (0.0, 0.0)
    for _ in range(6):
        T = np.eye(4)
        T[:3, :3] = random_rotation(rng)
        T[:3, 3] = rng.uniform(-200, 200, 3)
        data = dense_d.points[di] + rng.normal(0, 0.3, (len(di), 3))
        scene = data @ T[:3, :3].T + T[:3, 3]
        res = binpick.estimate_pose(scene, model, method="ccp", up=T[:3, :3] @ [0, 0, 1.0], min_fitness=0.5)
        rot, trans = pose_error(res.T_scene_model, T)
        worst = (max(worst[0], rot), max(worst[1], trans))
    assert worst[0] < 0.5 and worst[1] < 0.5, f"worst {worst[0]:.2f}°, {worst[1]:.2f} mm"
