"""Triangulation and the whole chain (scan folder → frames → line → points) against surfaces
of known geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from binpick.calibration import CameraIntrinsics, CellCalibration
from binpick.errors import (
    CalibrationError,
    InvalidInputError,
    NonFiniteError,
    ScanFormatError,
    ShapeError,
    SingularGeometryError,
)
from binpick.scan import load_scan, save_scan
from binpick.vision import _synthetic as syn
from binpick.vision import pixel_rays, reconstruct, triangulate


def test_scan_of_a_floor_and_cylinder_is_within_0_2_mm_rms(cell, tmp_path):
    surfaces = [cell.floor, cell.cylinder]
    rng = np.random.default_rng(11)
    angles = [cell.angle_for_column(u) for u in np.linspace(150, 900, 6)]
    frames = [
        syn.render(cell.calibration, surfaces, cell.T_base_flange, angle=a, rng=rng, noise=3.0, rays=cell.rays)
        for a in angles
    ]
    save_scan(
        tmp_path,
        frames,
        angles,
        [cell.T_base_flange] * len(angles),
        cell.calibration,
        ground_truth={"scene": "floor+cylinder"},
    )
    scan = load_scan(tmp_path)
    assert scan.ground_truth == {"scene": "floor+cylinder"} and scan.calibration == cell.calibration
    cloud = reconstruct(scan)
    assert len(cloud) > 0.9 * 778 * len(angles)
    dist = np.minimum(cell.floor.distance(cloud.points), cell.cylinder.distance(cloud.points))
    # Points within 3 px of a depth edge straddle two surfaces; the target is about the surfaces.
    assert np.mean(dist < 1.0) > 0.98
    inliers = dist[dist < 1.0]
    assert np.sqrt(np.mean(inliers**2)) < 0.2
    assert set(np.unique(cloud.frame)) == set(range(len(angles)))
    assert np.allclose(cloud.angle, np.asarray(angles)[cloud.frame])
    # Depth at the camera is about 500 mm (the target's range).
    T_base_camera = cell.T_base_flange @ cell.calibration.T_flange_camera
    depth = (cloud.points - T_base_camera[:3, 3]) @ T_base_camera[:3, 2]
    assert 380 < np.median(depth) < 520


def test_exact_pixels_triangulate_exactly_across_robot_poses(cell):
    cal = cell.calibration
    T_a = cell.T_base_flange
    T_b = T_a @ np.array(
        [[np.cos(0.2), -np.sin(0.2), 0, 15], [np.sin(0.2), np.cos(0.2), 0, -30], [0, 0, 1, 20], [0, 0, 0, 1.0]]
    )
    pixels, index, truth = [], [], []
    for f, (T, a) in enumerate([(T_a, 0.25), (T_b, 0.35)]):
        uv = syn.true_line_centres(cal, [cell.floor], T, a)[::40]
        pixels.append(uv)
        index.append(np.full(len(uv), f))
        T_base_camera = T @ cal.T_flange_camera
        dirs = syn.camera_rays(cal.camera, uv) @ T_base_camera[:3, :3].T
        truth.append(T_base_camera[:3, 3] + dirs * cell.floor.intersect(T_base_camera[:3, 3], dirs)[:, None])
    cloud = triangulate(np.concatenate(pixels), np.concatenate(index), [0.25, 0.35], [T_a, T_b], cal, num_threads=1)
    assert np.abs(cloud.points - np.concatenate(truth)).max() < 1e-5


def test_fast_undistortion_agrees_with_the_exact_one_over_the_whole_image():
    # A wide-angle lens (the image corners move by about 120 px); camera = flange = base frame.
    K = np.array([[900.0, 0, 530], [0, 905.0, 380], [0, 0, 1]])
    dist = np.array([-0.35, 0.2, 0.002, -0.0015, -0.05])
    cal = CellCalibration(CameraIntrinsics(1032, 778, K, dist), syn.pose(ry=0.9, t=(-150.0, 2.0, 5.0)), np.eye(4))
    u, v = np.meshgrid(np.r_[-0.5, np.arange(0.0, 1031.0, 3.7), 1031.5], np.r_[-0.5, np.arange(0.0, 777.0, 4.1), 777.5])
    pixels = np.column_stack([u.ravel(), v.ravel()])
    angles = [0.1, 0.3]
    frame = np.arange(len(pixels)) % 2
    cloud = triangulate(pixels, frame, angles, [np.eye(4)] * 2, cal, on_singular="raise", num_threads=1)
    assert len(cloud) == len(pixels)
    # OpenCV's forward model as the oracle: the points project back onto their pixels.
    back = cv2.projectPoints(cloud.points, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 2)
    assert np.abs(back - pixels).max() < 1e-4
    # And they are where the exact (Newton-to-convergence) rays meet the laser planes.
    rays = pixel_rays(pixels, cal.camera)
    for f, a in enumerate(angles):
        T = cal.T_camera_laser_at(a)
        n, p0 = T[:3, 0], T[:3, 3]
        exact = rays[frame == f] * ((p0 @ n) / (rays[frame == f] @ n))[:, None]
        assert np.abs(cloud.points[frame == f] - exact).max() < 1e-6


def test_singular_geometry_and_bad_input_are_named(cell):
    cal = cell.calibration
    # A laser plane through the optical centre: every ray lies in it or meets it at the camera.
    laser_through_camera = CellCalibration(cal.camera, np.eye(4), cal.T_flange_camera)
    K = cal.camera.K
    centre = np.array([[K[0, 2], 300.0]])
    with pytest.raises(SingularGeometryError, match="parallel|behind"):
        triangulate(centre, [0], [0.0], [np.eye(4)], laser_through_camera, on_singular="raise")
    assert len(triangulate(centre, [0], [0.0], [np.eye(4)], laser_through_camera)) == 0
    with pytest.raises(InvalidInputError, match="radians"):
        triangulate(centre, [0], [30.0], [np.eye(4)], cal)
    with pytest.raises(InvalidInputError, match="frame_index"):
        triangulate(centre, [1], [0.1], [np.eye(4)], cal)
    with pytest.raises(InvalidInputError, match="outside"):
        triangulate(np.array([[5000.0, 1.0]]), [0], [0.1], [np.eye(4)], cal)
    with pytest.raises(ShapeError, match="T_base_flanges"):
        triangulate(centre, [0], [0.1, 0.2], [np.eye(4)], cal)
    with pytest.raises(ShapeError, match="pixels"):
        pixel_rays(np.zeros((3, 3)), cal.camera)
    with pytest.raises(ShapeError, match="pixels"):
        triangulate(np.zeros((3, 3)), [0, 0, 0], [0.1], [np.eye(4)], cal)
    with pytest.raises(NonFiniteError, match="pixels"):
        triangulate(np.array([[10.0, 10.0], [np.nan, 1.0]]), [0, 0], [0.1], [np.eye(4)], cal)
    with pytest.raises(InvalidInputError, match="whole numbers"):
        triangulate(centre, [0.5], [0.1], [np.eye(4)], cal)
    with pytest.raises(InvalidInputError, match="frame_index"):
        triangulate(centre, np.array([-1]), [0.1], [np.eye(4)], cal)
    sheared = np.eye(4)
    sheared[0, 1] = 0.1
    with pytest.raises(InvalidInputError, match=r"T_base_flanges\[1\]"):
        triangulate(centre, [0], [0.1, 0.2], [np.eye(4), sheared], cal)
    # Dropped pixels take their frame, pixel and angle along; the kept ones keep theirs. The
    # sheet x = −150 mm (turned 0.1 rad in frame 1) is behind the camera for rays to the right.
    laser_left = CellCalibration(cal.camera, syn.pose(t=(-150.0, 0.0, 0.0)), cal.T_flange_camera)
    px = np.array([[300.0, 300.0], [700.0, 300.0], [200.0, 400.0], [800.0, 100.0]])
    cloud = triangulate(px, [0, 0, 1, 1], [0.0, 0.1], [np.eye(4)] * 2, laser_left)
    assert (
        np.array_equal(cloud.pixels, px[[0, 2]])
        and np.array_equal(cloud.frame, [0, 1])
        and np.array_equal(cloud.angle, [0.0, 0.1])
    )
    with pytest.raises(SingularGeometryError, match=r"row 1 \[700.0, 300.0\] in frame 0: .*behind"):
        triangulate(px, [0, 0, 1, 1], [0.0, 0.1], [np.eye(4)] * 2, laser_left, on_singular="raise")


def test_scan_folder_errors_are_clear(cell, tmp_path):
    img = np.zeros((778, 1032, 3), np.uint8)
    with pytest.raises(ShapeError, match="calibration says"):
        save_scan(tmp_path, [img[:100]], [0.1], [np.eye(4)], cell.calibration)
    with pytest.raises(InvalidInputError, match="np.radians"):
        save_scan(tmp_path, [img], [45.0], [np.eye(4)], cell.calibration)
    with pytest.raises(ScanFormatError, match="not a scan folder"):
        load_scan(tmp_path / "nowhere")
    save_scan(tmp_path, [img], [0.1], [np.eye(4)], cell.calibration)
    (tmp_path / "calibration.toml").write_text(
        (tmp_path / "calibration.toml").read_text().replace("[hand_eye]", "[hand_eyes]")
    )
    with pytest.raises(CalibrationError, match="hand_eye"):
        load_scan(tmp_path)
    (tmp_path / "scan.json").write_text('{"version": 2, "frames": []}')
    with pytest.raises(ScanFormatError, match="version"):
        load_scan(tmp_path)
