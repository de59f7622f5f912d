"""Defects the hardening bench (benches/hardening.py) found, each pinned by its minimal case."""

from __future__ import annotations

import numpy as np
import pytest

import binpick


@pytest.mark.parametrize(
    "header",
    [
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (4k[0, 3), }",  # an unclosed bracket
        b"{'descr': '<f8', 'fortran_order': (False, 'shape': (40, 3), }",  # an unclosed parenthesis
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (-40, 3), }",  # mmap's OverflowError (file_fuzz.py)
    ],
)
def test_an_npy_scene_with_a_broken_header_is_a_mesh_file_error(tmp_path, header):
    """numpy tokenizes the header and raises tokenize.TokenError or SyntaxError, neither a ValueError;
    a negative shape passes numpy's header checks and mmap raises OverflowError."""
    path = tmp_path / "scene.npy"
    good = tmp_path / "good.npy"
    np.save(good, np.zeros((40, 3)))
    data = good.read_bytes()
    size = int.from_bytes(data[8:10], "little")
    body = header.ljust(size - 1) + b"\n"
    path.write_bytes(data[:10] + body + data[10 + size :])
    with pytest.raises(binpick.MeshFileError, match="NumPy"):
        binpick.read_scene(path)


V, F = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]], [[0, 1, 2]]


@pytest.mark.parametrize("spacing", [1e300, 1e-300])
def test_an_absurd_spacing_is_an_invalid_input_not_an_overflow(spacing):
    """area / spacing² raised OverflowError (1e300) and ZeroDivisionError (1e-300)."""
    with pytest.raises(binpick.InvalidInputError, match="spacing"):
        binpick.Model.from_arrays(V, F, spacing=spacing)


def test_ragged_faces_are_an_invalid_input():
    """np.asarray of ragged faces raised numpy's plain ValueError."""
    with pytest.raises(binpick.InvalidInputError, match="faces"):
        binpick.Model.from_arrays(V, [[0, 1, 2], [1, 2]])


def test_coordinates_whose_squares_overflow_are_refused_not_given_nan_normals():
    """estimate_normals returned all-NaN normals for points about 1e301 mm out."""
    pts = np.random.default_rng(0).normal(size=(50, 3)) * 1e301
    with pytest.raises(binpick.InvalidInputError, match="points"):
        binpick.estimate_normals(pts, k=3)


@pytest.mark.parametrize("value", ["0.05", (0.05,), 0.05j, [0.05], {}, b"0", True])
def test_ppf_sampling_ratio_of_the_wrong_type_is_an_invalid_type_error(value):
    """sampling_ratio raised a plain TypeError (and accepted True) where angle_bins was checked."""
    with pytest.raises(binpick.InvalidTypeError, match="sampling_ratio"):
        binpick.PpfParams(sampling_ratio=value)
    assert binpick.PpfParams(sampling_ratio=None).sampling_ratio == 0.05  # None takes the default


@pytest.mark.parametrize("value", [10**400, float("nan"), float("inf"), 2.0])
def test_ppf_sampling_ratio_out_of_range_is_refused_when_built(value):
    with pytest.raises(binpick.InvalidInputError, match="sampling_ratio"):
        binpick.PpfParams(sampling_ratio=value)
