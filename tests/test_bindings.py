"""The native module's surface: frozen, keyword-only config classes that carry the core's
defaults (the public signatures show the same values), and every error variant of the core
arriving as its class of binpick.errors."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import numpy as np
import pytest

import binpick
from binpick import _core, errors

CONFIGS = [_core.PoseConfig, _core.IcpConfig, _core.PpfParams]


@pytest.mark.parametrize("cls", CONFIGS)
def test_configs_are_keyword_only_and_frozen(cls):
    params = inspect.signature(cls).parameters.values()
    assert params and all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in params)
    with pytest.raises(TypeError):
        cls(1.0)
    config = cls()
    name = next(iter(inspect.signature(cls).parameters))
    with pytest.raises(AttributeError):
        setattr(config, name, getattr(config, name))
    assert repr(config).startswith(f"{cls.__name__}(")


def test_configs_carry_the_core_defaults():
    pose = _core.PoseConfig()
    assert (pose.method, pose.up, pose.min_fitness, pose.min_coverage) == ("auto", None, 0.6, 0.8)
    assert (pose.noise_mm, pose.noise_per_m2) == (None, 0.0)
    assert pose.max_normal_angle == pytest.approx(np.radians(70.0), abs=1e-15)
    assert (pose.reference_fraction, pose.max_hypotheses, pose.max_instances, pose.num_threads) == (0.1, 16, 1, 0)
    assert pose.search_instances == 5
    assert pose.bin is None and pose.viewpoint is None and pose.d_star is None and pose.ccp_tau is None
    icp = _core.IcpConfig()
    assert (icp.method, icp.max_iterations, icp.kernel, icp.kernel_scale) == ("point_to_plane", 50, "none", None)
    assert (icp.rotation_tolerance, icp.translation_tolerance, icp.trim_fraction) == (1e-6, 1e-4, 0.0)
    ppf = binpick.PpfParams()
    assert (ppf.sampling_ratio, ppf.angle_bins, ppf.rotation_bins) == (0.05, 30, 30)
    assert binpick.PpfParams is _core.PpfParams
    assert ppf == binpick.PpfParams(angle_bins=30) and hash(ppf) == hash(binpick.PpfParams())
    assert ppf != binpick.PpfParams(sampling_ratio=0.06)


@pytest.mark.parametrize(
    "public, cls",
    [
        (binpick.estimate_poses, _core.PoseConfig),
        (binpick.estimate_pose, _core.PoseConfig),
        (binpick.icp, _core.IcpConfig),
    ],
)
def test_public_defaults_are_the_cores(public, cls):
    core = cls()
    for name, p in inspect.signature(public).parameters.items():
        if p.default is not inspect.Parameter.empty and p.default is not None and hasattr(core, name):
            if name != "max_instances":  # estimate_poses ranks five by default, the core one
                assert p.default == getattr(core, name), name


def test_given_values_are_kept_and_names_resolved():
    c = _core.PoseConfig(method="PPF", bin=np.array([[0.0, 0, 0], [1, 2, 3]]), min_fitness=0.5, reference_fraction=0.2)
    assert c.method == "ppf" and c.min_fitness == 0.5 and c.reference_fraction == 0.2
    np.testing.assert_array_equal(c.bin, [[0, 0, 0], [1, 2, 3]])
    k = _core.IcpConfig(kernel="Tukey", max_correspondence_distance=9.0)
    assert k.kernel == "tukey" and k.kernel_scale == 3.0  # a third of the correspondence distance
    with pytest.raises(errors.InvalidInputError, match="method"):
        _core.PoseConfig(method="fpfh")
    with pytest.raises(errors.InvalidInputError, match="kernel"):
        _core.IcpConfig(kernel="gaussian")


def test_values_are_checked_by_the_core_and_types_named(tee_model):
    scene = np.random.default_rng(0).uniform(0, 100, (500, 3))
    for option in ("min_fitness", "min_coverage", "max_normal_angle", "d_star"):
        with pytest.raises(errors.InvalidInputError, match=option):
            binpick.estimate_poses(scene, tee_model, **{option: -1.0})
    with pytest.raises(errors.InvalidInputError, match="rotation_tolerance"):
        binpick.icp(scene, scene, max_correspondence_distance=5.0, rotation_tolerance=-1.0)
    with pytest.raises(errors.InvalidInputError, match="max_iterations"):
        binpick.icp(scene, scene, max_correspondence_distance=5.0, max_iterations=-1)
    with pytest.raises(errors.InvalidInputError, match="num_threads"):
        binpick.estimate_poses(scene, tee_model, num_threads="all")


def _write_into_missing_folder(tmp_path):
    binpick.write_ply(tmp_path / "missing" / "x.ply", np.zeros((4, 3)))


def _empty_mesh(tmp_path):
    (tmp_path / "empty.stl").write_bytes(b"")
    binpick.Model.from_mesh(tmp_path / "empty.stl")


CORE_ERRORS = {
    # each variant of binpick_core::Error, raised by the core (not by a Python check)
    "InvalidInput": (
        errors.InvalidInputError,
        lambda m, p: binpick.icp(np.eye(3) * 9, np.eye(3) * 9, method="point_to_point", max_correspondence_distance=-1),
    ),
    "NonFinite": (
        errors.NonFiniteError,
        lambda m, p: _core.estimate_normals(np.full((5, 3), np.nan), 3, None, None, 0),
    ),
    "TooFewPoints": (
        errors.TooFewPointsError,
        lambda m, p: _core.estimate_poses(np.zeros((3, 3)), m.prepared(), _core.PoseConfig()),
    ),
    "Degenerate": (
        errors.DegenerateCloudError,
        lambda m, p: binpick.icp(
            np.outer(np.arange(50.0), [1.0, 0, 0]), m.points, method="point_to_point", max_correspondence_distance=5
        ),
    ),
    "UnknownUnit": (errors.UnknownUnitError, lambda m, p: _core.read_mesh(str(p / "x.stl"), "furlong")),
    "FileNotFound": (errors.MeshFileNotFoundError, lambda m, p: binpick.Model.from_mesh(p / "missing.stl")),
    "BadFile": (errors.MeshFileError, lambda m, p: _empty_mesh(p)),
    "WriteFailed": (errors.FileWriteError, lambda m, p: _write_into_missing_folder(p)),
    "NoObjectFound": (
        errors.NoObjectFound,
        lambda m, p: binpick.estimate_pose(
            np.random.default_rng(1).uniform(0, 100, (500, 3)), m, bin=((500, 500, 500), (600, 600, 600))
        ),
    ),
    "panic": (errors.InternalError, lambda m, p: _core._panic_for_test()),
}


@pytest.mark.parametrize("variant", sorted(CORE_ERRORS))
def test_every_core_error_variant_maps_to_its_class(variant, tee_model, tmp_path):
    cls, trigger = CORE_ERRORS[variant]
    with pytest.raises(cls) as info:
        trigger(tee_model, tmp_path)
    assert type(info.value) is cls and str(info.value)


def test_the_error_table_lists_every_core_variant():
    source = (Path(__file__).parents[1] / "rust" / "core" / "src" / "error.rs").read_text(encoding="utf-8")
    enum = source[source.index("pub enum Error {") : source.index("\nimpl Error")]
    assert set(re.findall(r"^    ([A-Z]\w*) \{", enum, flags=re.M)) == set(CORE_ERRORS) - {"panic"}
