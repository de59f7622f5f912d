"""The core never trusts a count, a header or a coordinate (issue 16): through the public API."""

import time

import numpy as np
import pytest

import binpick
from _geometry import box_mesh, write_stl_ascii


def _ply(tmp_path, text: bytes, name="x.ply"):
    path = tmp_path / name
    path.write_bytes(text)
    return path


def test_a_huge_declared_count_fails_at_once_naming_the_element(tmp_path):
    head = b"ply\nformat binary_little_endian 1.0\nelement junk 18446744073709551615\nproperty uchar a\n"
    head += b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    path = _ply(tmp_path, head + bytes(12))
    start = time.perf_counter()
    for read in (binpick.read_ply, binpick.Model.from_mesh):
        with pytest.raises(binpick.BinpickError, match="element junk"):
            read(path)
    assert time.perf_counter() - start < 2.0


def test_a_negative_or_fractional_face_index_is_an_error(tmp_path):
    text = (
        b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 -1 2.9 3\n"
    )
    with pytest.raises(binpick.BinpickError, match="face row 0"):
        binpick.Model.from_mesh(_ply(tmp_path, text))


def test_non_finite_normals_name_the_row(tmp_path):
    text = (
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
        b"property float nx\nproperty float ny\nproperty float nz\nend_header\n0 0 0 0 0 1\n1 0 0 nan 0 1\n"
    )
    with pytest.raises(binpick.BinpickError, match="vertex row 1"):
        binpick.read_ply(_ply(tmp_path, text))


def test_write_ply_refuses_the_empty_cloud_read_ply_would_refuse(tmp_path):
    path = tmp_path / "empty.ply"
    with pytest.raises(ValueError, match="points"):
        binpick.write_ply(path, np.zeros((0, 3)))
    assert not path.exists()


def test_a_tee_too_fine_for_the_grid_ceiling_is_refused_at_once():
    start = time.perf_counter()
    with pytest.raises(binpick.InvalidInputError, match="resolution"):
        binpick.parts.tee(resolution=1e-6)
    assert time.perf_counter() - start < 2.0


def test_a_sample_count_over_the_ceiling_is_refused(tmp_path):
    path = tmp_path / "box.stl"
    write_stl_ascii(path, *box_mesh((40.0, 30.0, 20.0)))
    with pytest.raises(binpick.InvalidInputError, match="count"):
        binpick.Model.from_mesh(path, count=10**12)


def test_three_identical_branches_are_refused_naming_branches():
    tee = binpick.parts.tee()
    same = binpick.Branch(direction=(1.0, 0.0, 0.0), length=40.0, radius=13.0)
    tee.declare_branches([same, same, same], special_direction=(0.0, 0.0, 1.0))
    with pytest.raises(binpick.InvalidInputError, match="branches"):
        tee.prepared()


def test_voxelising_points_too_far_apart_is_refused_not_merged():
    far = np.array([[0.0, 0.0, 0.0], [2e19, 0.0, 0.0], [4e19, 0.0, 0.0]])
    with pytest.raises(binpick.InvalidInputError, match="points"):
        binpick.voxel_downsample(far, 1.0)


def test_a_scene_far_from_the_origin_ends_in_a_clear_error_not_a_panic():
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 400, 4000), rng.uniform(0, 300, 4000), rng.normal(0, 0.05, 4000)])
    top = np.column_stack([rng.uniform(100, 140, 1000), rng.uniform(100, 140, 1000), np.full(1000, 30.0)])
    scene = np.vstack([floor, top]) + 1e16
    with pytest.raises(binpick.BinpickError) as info:
        binpick.estimate_pose(scene, binpick.parts.tee())
    assert not isinstance(info.value, binpick.InternalError)
