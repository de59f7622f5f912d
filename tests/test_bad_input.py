"""Every kind of bad input gives a specific binpick exception with a useful message; no panic
or foreign exception escapes the native core."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import binpick
from binpick import errors


@pytest.fixture(scope="module")
def cloud():
    return binpick.parts.cross(count=600, seed=3).points


def icp(source, target, **kw):
    kw.setdefault("max_correspondence_distance", 5.0)
    return binpick.icp(source, target, **kw)


@pytest.mark.parametrize(
    "bad, exc, words",
    [
        (np.zeros((10, 2)), errors.ShapeError, "(N, 3)"),
        (np.zeros(30), errors.ShapeError, "(N, 3)"),
        (np.zeros((2, 3, 3)), errors.ShapeError, "(N, 3)"),
        (np.array([["a", "b", "c"]] * 10), errors.DTypeError, "dtype"),
        (np.zeros((10, 3), dtype=complex), errors.DTypeError, "dtype"),
        (np.array([[object()] * 3] * 10), errors.DTypeError, "dtype"),
        ([[1, 2, 3], [4, 5]], errors.DTypeError, "numeric"),
        (np.full((10, 3), np.nan), errors.NonFiniteError, "NaN"),
        (np.array([[0, 0, 0], [1, np.inf, 0], [0, 1, 0], [0, 0, 1]] * 3, dtype=float), errors.NonFiniteError, "(1, 1)"),
        (np.zeros((2, 3)), errors.TooFewPointsError, "at least"),
        (np.zeros((0, 3)), errors.TooFewPointsError, "at least"),
        (np.ones((50, 3)), errors.DegenerateCloudError, "equal"),
        (np.outer(np.arange(50.0), [1.0, 2.0, 3.0]), errors.DegenerateCloudError, "line"),
    ],
)
def test_bad_source_is_named(cloud, bad, exc, words):
    with pytest.raises(exc) as info:
        icp(bad, cloud, method="point_to_point")
    assert "source" in str(info.value) and words in str(info.value)
    assert isinstance(info.value, ValueError) and isinstance(info.value, binpick.BinpickError)


def test_bad_target_and_options(cloud):
    with pytest.raises(errors.DegenerateCloudError, match="target"):
        icp(cloud, np.outer(np.arange(50.0), [1.0, 0.0, 0.0]), method="point_to_point")
    with pytest.raises(errors.InvalidInputError, match="max_correspondence_distance"):
        icp(cloud, cloud, max_correspondence_distance=-1)
    with pytest.raises(errors.InvalidInputError, match="method"):
        icp(cloud, cloud, method="nearest")
    with pytest.raises(errors.InvalidInputError, match="kernel"):
        icp(cloud, cloud, kernel="gaussian")
    with pytest.raises(errors.InvalidInputError, match="trim_fraction"):
        icp(cloud, cloud, trim_fraction=0.95)
    with pytest.raises(errors.InvalidInputError, match="max_iterations"):
        icp(cloud, cloud, max_iterations=0)
    with pytest.raises(errors.ShapeError, match="init"):
        icp(cloud, cloud, init=np.eye(3))
    scaled = np.eye(4)
    scaled[0, 0] = 2.0
    with pytest.raises(errors.InvalidInputError, match="rotation"):
        icp(cloud, cloud, init=scaled)
    with pytest.raises(errors.InvalidInputError, match="target_normals"):
        icp(cloud, cloud, target_normals=np.zeros((3, 3)))


def test_no_panic_reaches_python():
    with pytest.raises(errors.InternalError, match="deliberate test panic"):
        binpick._core._panic_for_test()


def test_unknown_unit_and_mesh_errors(tmp_path):
    with pytest.raises(errors.UnknownUnitError, match="furlong"):
        binpick.Model.from_mesh(tmp_path / "x.stl", unit="furlong")
    with pytest.raises(errors.MeshFileNotFoundError):
        binpick.Model.from_mesh(tmp_path / "missing.stl")
    (tmp_path / "empty.stl").write_bytes(b"")
    with pytest.raises(errors.MeshFileError, match="empty"):
        binpick.Model.from_mesh(tmp_path / "empty.stl")
    (tmp_path / "junk.stl").write_bytes(bytes(range(256)) * 3)
    with pytest.raises(errors.MeshFileError, match="not a valid STL"):
        binpick.Model.from_mesh(tmp_path / "junk.stl")
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    with pytest.raises(errors.MeshFileError, match="refers to no vertex"):
        binpick.Model.from_mesh(tmp_path / "bad.obj")
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    with pytest.raises(errors.MeshFileError, match="non-zero area"):
        binpick.Model.from_mesh(tmp_path / "flat.obj")
    (tmp_path / "trunc.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty "
        b"float x\nproperty float y\nproperty float z\nend_header\n\x00\x00"
    )
    with pytest.raises(errors.MeshFileError, match="truncated"):
        binpick.read_ply(tmp_path / "trunc.ply")
    with pytest.raises(errors.MeshFileError, match="extension"):
        binpick.Model.from_mesh(tmp_path / "part.iges")


arrays = st.one_of(
    hnp.arrays(
        dtype=st.sampled_from([np.float64, np.float32, np.int32, np.uint8, np.complex64, np.bool_]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=12),
        elements=None,
    ),
    st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4), max_size=8),
)


@functools.cache
def _random_input_target() -> np.ndarray:
    """The target cloud of the random-input test, built once (not in each of its 150 examples)."""
    points = binpick.parts.cross(count=300, seed=1).points
    points.flags.writeable = False
    return points


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(source=arrays, method=st.sampled_from(["point_to_point", "point_to_plane"]))
def test_random_input_raises_only_binpick_errors(source, method):
    target = _random_input_target()
    try:
        res = binpick.icp(source, target, method=method, max_correspondence_distance=5.0, max_iterations=5)
    except binpick.BinpickError as exc:
        assert not isinstance(exc, errors.InternalError), exc
        assert str(exc)
    else:
        assert np.isfinite(res.T_target_source).all()
