"""Models from mesh files (STL binary/ASCII, PLY ASCII/binary, OBJ) in any unit, surface
sampling, PLY point clouds, normals and voxels."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from _geometry import box_mesh, write_obj, write_ply_mesh, write_stl_ascii, write_stl_binary

WRITERS = {
    "bin.stl": write_stl_binary,
    "ascii.stl": write_stl_ascii,
    "mesh.obj": write_obj,
    "ascii.ply": lambda p, v, f: write_ply_mesh(p, v, f, binary=False),
    "bin.ply": lambda p, v, f: write_ply_mesh(p, v, f, binary=True),
}


@pytest.mark.parametrize("name", sorted(WRITERS))
@pytest.mark.parametrize("unit, scale", [("m", 1000.0), ("mm", 1.0), ("in", 25.4), ("cm", 10.0)])
def test_every_format_and_unit_reads_to_millimetres(tmp_path, name, unit, scale):
    v, f = box_mesh((20.0, 30.0, 40.0))
    path = tmp_path / name
    WRITERS[name](path, v / scale, f)
    model = binpick.Model.from_mesh(path, unit=unit, spacing=2.0)
    assert len(model.faces) == 12 and len(model.vertices) == 8
    np.testing.assert_allclose(model.vertices.max(axis=0), [20, 30, 40], rtol=1e-6)
    assert model.area == pytest.approx(2 * (20 * 30 + 20 * 40 + 30 * 40), rel=1e-6)
    assert model.diameter == pytest.approx(np.sqrt(20**2 + 30**2 + 40**2), rel=1e-6)
    # One sample per ~4 mm², all on the surface, normals pointing out of the box.
    assert 0.85 < len(model.points) / (model.area / 4.0) < 1.15
    centre = np.array([10.0, 15.0, 20.0])
    assert (np.einsum("ij,ij->i", model.points - centre, model.normals) > 0).all()
    dist_to_faces = np.minimum.reduce(
        [np.abs(model.points[:, k] - b) for k, b in [(0, 0), (0, 20), (1, 0), (1, 30), (2, 0), (2, 40)]]
    )
    assert dist_to_faces.max() < 1e-6


def test_sampling_is_even_and_seeded():
    tee = binpick.parts.tee(spacing=1.5, seed=4, resolution=1.0)
    again = binpick.parts.tee(spacing=1.5, seed=4, resolution=1.0)
    np.testing.assert_array_equal(tee.points, again.points)
    # Even spacing: nearest-neighbour distances never below 0.75 × spacing, median near it.
    sub = tee.points[:: max(1, len(tee.points) // 400)]
    d = np.sqrt(((sub[:, None, :] - tee.points[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf
    nn = d.min(axis=1)
    assert nn.min() >= 0.75 * 1.5 - 1e-9 and 1.0 < np.median(nn) < 1.8
    assert len(binpick.parts.tee(count=1234, resolution=1.0).points) == 1234


def test_parts_have_their_documented_frame_and_size():
    tee = binpick.parts.tee(resolution=1.0)
    lo, hi = tee.vertices.min(axis=0), tee.vertices.max(axis=0)
    np.testing.assert_allclose(lo, [-40, -13, -13], atol=0.6)
    np.testing.assert_allclose(hi, [40, 40, 17], atol=0.6)
    assert [b.direction for b in tee.branches] == [(1, 0, 0), (-1, 0, 0), (0, 1, 0)]
    assert len(binpick.parts.elbow().branches) == 2 and len(binpick.parts.cross().branches) == 4
    with pytest.raises(binpick.InvalidInputError, match="outer_diameter"):
        binpick.parts.tee(outer_diameter=0)


def test_ply_point_cloud_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(500, 3)) * 100
    nrm = rng.normal(size=(500, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    for ascii_ in (False, True):
        path = tmp_path / f"c{ascii_}.ply"
        binpick.write_ply(path, pts, nrm, ascii=ascii_)
        back, back_n = binpick.read_ply(path)
        np.testing.assert_array_equal(back, pts)
        np.testing.assert_array_equal(back_n, nrm)
    binpick.write_ply(tmp_path / "plain.ply", pts)
    assert binpick.read_ply(tmp_path / "plain.ply")[1] is None
    assert (tmp_path / "plain.ply").read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")


def test_normals_face_the_viewpoint_and_voxels_average():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(3000, 3))
    sphere = 50.0 * d / np.linalg.norm(d, axis=1, keepdims=True)
    n_out = binpick.estimate_normals(sphere, k=15, viewpoint=[0, 0, 1000.0])
    radial = sphere / 50.0
    cos = np.einsum("ij,ij->i", n_out, radial)
    assert (np.abs(cos) > 0.99).all()
    up = sphere[:, 2] > 5
    assert (cos[up] > 0).all()
    n_in = binpick.estimate_normals(sphere, k=15, viewpoint=[0, 0, 0])
    assert (np.einsum("ij,ij->i", n_in, radial) < 0).all()
    grid = np.array([[x, y, 0.0] for x in np.arange(0.25, 10, 0.5) for y in np.arange(0.25, 10, 0.5)])
    pts, nrm, first = binpick.voxel_downsample(grid, 1.0, normals=np.tile([0.0, 0.0, 1.0], (len(grid), 1)))
    assert len(pts) == 100 and nrm.shape == (100, 3)
    np.testing.assert_allclose(np.sort(pts[:, 0])[::10], np.arange(0.5, 10, 1.0))
    assert first.dtype == np.int64 and len(first) == 100
