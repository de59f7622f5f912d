"""ICP through the public API: known seeded transforms recovered, robust options, bad input."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from _geometry import apply, random_rigid
from binpick.transforms import pose_error


@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_noiseless_transforms_recovered_to_1e6(tee_model, method):
    rng = np.random.default_rng(1)
    target = tee_model.points
    for _ in range(4):
        t_true = random_rigid(rng, np.radians(8), 5.0)
        source = apply(np.linalg.inv(t_true), target)
        res = binpick.icp(
            source,
            target,
            target_normals=tee_model.normals,
            method=method,
            max_correspondence_distance=15.0,
            max_iterations=300,
            rotation_tolerance=1e-11,
            translation_tolerance=1e-10,
        )
        rot, trans = pose_error(res.T_target_source, t_true)
        assert np.radians(rot) < 1e-6 and trans < 1e-6, (method, rot, trans, res)
        assert res.converged and res.fitness == 1.0 and res.rmse < 1e-5
        assert res.T_target_source.shape == (4, 4) and res.T_target_source.dtype == np.float64


@pytest.mark.parametrize("method", ["point_to_point", "point_to_plane"])
def test_noisy_independent_samplings_within_the_noise(method):
    rng = np.random.default_rng(2)
    target_model = binpick.parts.elbow(count=20000, seed=1)
    source_model = binpick.parts.elbow(count=6000, seed=2)
    target = target_model.points + rng.normal(0, 0.2, target_model.points.shape)
    for _ in range(3):
        t_true = random_rigid(rng, np.radians(6), 6.0)
        source = apply(np.linalg.inv(t_true), source_model.points + rng.normal(0, 0.2, source_model.points.shape))
        res = binpick.icp(source, target, method=method, max_correspondence_distance=12.0, max_iterations=300)
        rot, trans = pose_error(res.T_target_source, t_true)
        # Point-to-point keeps a small bias between independent samplings (pairs are not the
        # same surface points), mostly about the branch axes, which only the end faces pin.
        assert rot < (0.5 if method == "point_to_point" else 0.3) and trans < 0.2, (method, rot, trans)
        assert res.converged
        assert 0.2 < res.rmse < 0.6  # two independent 0.2 mm noises plus sampling


def test_init_is_used_and_threads_agree(tee_model):
    rng = np.random.default_rng(3)
    t_true = np.array(
        [[0.0, -1.0, 0.0, 30.0], [1.0, 0.0, 0.0, -20.0], [0.0, 0.0, 1.0, 40.0], [0, 0, 0, 1]]
    )  # 90° about z
    source = apply(np.linalg.inv(t_true), tee_model.points)
    far = binpick.icp(source, tee_model.points, method="point_to_point", max_correspondence_distance=5.0)
    assert pose_error(far.T_target_source, t_true)[0] > 10  # 90° away: no local convergence without init
    init = t_true @ random_rigid(rng, np.radians(3), 2.0)
    results = [
        binpick.icp(
            source,
            tee_model.points,
            init=init,
            method="point_to_point",
            max_correspondence_distance=10.0,
            max_iterations=200,
            num_threads=n,
        )
        for n in (1, 2)
    ]
    for res in results:
        rot, trans = pose_error(res.T_target_source, t_true)
        assert rot < 1e-4 and trans < 1e-4
    np.testing.assert_allclose(results[0].T_target_source, results[1].T_target_source, atol=1e-7)


@pytest.mark.parametrize(
    "options",
    [{"kernel": "tukey", "kernel_scale": 3.0}, {"trim_fraction": 0.35}, {"kernel": "cauchy", "kernel_scale": 1.0}],
)
def test_robust_options_resist_clutter(options):
    rng = np.random.default_rng(4)
    target_model = binpick.parts.tee(count=15000, seed=5, resolution=1.0)
    source = binpick.parts.tee(count=4000, seed=6, resolution=1.0).points.copy()
    source[:1200] += [0.0, 0.0, 7.0]  # 30 % clutter floating above the part
    t_true = random_rigid(rng, np.radians(5), 4.0)
    source = apply(np.linalg.inv(t_true), source)
    common = dict(target_normals=target_model.normals, max_correspondence_distance=12.0, max_iterations=100)
    plain = binpick.icp(source, target_model.points, **common)
    robust = binpick.icp(source, target_model.points, **common, **options)
    err_plain = pose_error(plain.T_target_source, t_true)
    err_robust = pose_error(robust.T_target_source, t_true)
    assert err_robust[0] < 0.3 and err_robust[1] < 0.3, err_robust
    assert err_robust[1] < err_plain[1]


def test_result_repr_and_fields(tee_model):
    res = binpick.icp(tee_model.points, tee_model.points, max_correspondence_distance=1.0)
    assert "IcpResult(converged=True" in repr(res)
    assert res.num_inliers == len(tee_model.points)
    np.testing.assert_allclose(res.T_target_source, np.eye(4), atol=1e-12)
