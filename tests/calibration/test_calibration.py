"""Calibration against a simulated cell of known geometry: intrinsics, the paper's projector
procedure, the general laser-plane fit and hand-eye."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_rig import PATTERN, SQUARE, Rig, rotation_angle_deg

from binpick.calibration import (
    HAND_EYE_METHODS,
    CellCalibration,
    LaserCalibration,
    axis_depth,
    board_pose,
    calibrate_camera,
    calibrate_hand_eye,
    calibrate_projector,
    find_checkerboard,
    laser_points_on_board,
)
from binpick.calibration._file import CameraIntrinsics
from binpick.errors import CalibrationError, InvalidInputError, SingularGeometryError
from binpick.vision import _synthetic as syn
from binpick.vision import extract_line


def test_camera_intrinsics_from_rendered_checkerboards(rig, board_views):
    _, images = board_views
    result = calibrate_camera(images, PATTERN, SQUARE)
    truth = rig.calibration.camera
    assert len(result.views) == len(images)
    assert result.rms < 0.1 and result.per_view_rms.max() < 0.15
    assert np.allclose(np.diag(result.camera.K)[:2], np.diag(truth.K)[:2], rtol=3e-3)
    assert np.allclose(result.camera.K[:2, 2], truth.K[:2, 2], atol=2.0)
    # The distortion is judged by what it does where the boards were seen: the rays through a
    # grid of pixels agree within 0.5 px (the image corners are extrapolation; a principal-point
    # shift traded against the board poses accounts for most of it).
    from binpick.vision import pixel_rays

    grid = np.stack(np.meshgrid(np.linspace(260, 780, 12), np.linspace(190, 590, 9)), -1).reshape(-1, 2)
    diff = (pixel_rays(grid, result.camera) - pixel_rays(grid, truth))[:, :2] * truth.K[0, 0]
    assert np.abs(diff).max() < 0.5


def test_hand_eye_within_half_a_millimetre_and_a_tenth_of_a_degree(rig, board_views):
    stations, images = board_views
    cam = rig.calibration.camera
    boards = [board_pose(find_checkerboard(im, PATTERN), cam, PATTERN, SQUARE) for im in images]
    result = calibrate_hand_eye(stations, boards)
    truth = rig.calibration.T_flange_camera
    assert set(result.residuals) == set(HAND_EYE_METHODS) and len(HAND_EYE_METHODS) == 5
    assert np.linalg.norm(result.T_flange_camera[:3, 3] - truth[:3, 3]) < 0.5
    assert rotation_angle_deg(result.T_flange_camera, truth) < 0.1
    t_res, r_res = result.residuals[result.method]
    assert t_res < 0.5 and r_res < 0.1
    with pytest.raises(CalibrationError, match="at least 3"):
        calibrate_hand_eye(stations[:2], boards[:2])
    with pytest.raises(InvalidInputError, match="method"):
        calibrate_hand_eye(stations, boards, method="magic")


def test_paper_projector_procedure_recovers_px_pz_within_0_1_mm():
    # Table 1 assumes the sheet is only turned about y and the laser sits in the camera's x-z plane.
    rig = Rig()
    truth = CellCalibration(rig.calibration.camera, syn.pose(t=(-150.0, 0.0, 5.0)), rig.calibration.T_flange_camera)
    rng = np.random.default_rng(2)
    depths, angles = [], []
    for i, distance in enumerate(np.linspace(320, 760, 8)):
        T = rig.looking_at_board(0.0, 0.0, 0.0, distance)
        corners = find_checkerboard(rig.image(T, seed=10 + i), PATTERN)
        d = axis_depth(board_pose(corners, truth.camera, PATTERN, SQUARE))
        T_camera_board = np.linalg.inv(T @ truth.T_flange_camera) @ rig.board.T_base_board
        true_d = axis_depth(T_camera_board)
        # The motor stops where the line crosses the principal point: p_z − p_x·cot θ = depth.
        theta = np.arctan(-150.0 / (5.0 - true_d)) + rng.normal(0, 2e-5)
        depths.append(d)
        angles.append(theta)
    result = calibrate_projector(depths, angles)
    assert abs(result.p_x - (-150.0)) < 0.1 and abs(result.p_z - 5.0) < 0.1
    assert result.rms < 0.2 and len(result.residuals) == 8
    with pytest.raises(InvalidInputError, match="radians"):
        calibrate_projector(depths, np.degrees(angles))
    with pytest.raises(SingularGeometryError, match="one distance"):
        calibrate_projector([500.0] * 4, [0.3, 0.31, 0.32, 0.33])


def test_laser_plane_fit_across_angles_predicts_the_sheet(rig):
    small = Rig(640, 482)
    cal = small.calibration
    rng = np.random.default_rng(4)
    stations = [small.looking_at_board(*rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.4, 0.4), d) for d in (430, 520, 600)]
    boards = [
        board_pose(find_checkerboard(small.image(T, seed=20 + i), PATTERN), cal.camera, PATTERN, SQUARE)
        for i, T in enumerate(stations)
    ]
    angles = [0.20, 0.27, 0.34, 0.41]
    points = []
    for k, a in enumerate(angles):
        lit = []
        for i, (T, T_cb) in enumerate(zip(stations, boards)):
            uv = extract_line(small.image(T, angle=a, seed=100 * k + i), threshold=15)
            # Keep the line on the board: the table around it is another plane.
            board_uv = uv[
                np.abs(
                    laser_points_on_board(uv, cal.camera, T_cb) @ np.linalg.inv(T_cb)[:3, :3].T
                    + np.linalg.inv(T_cb)[:3, 3]
                )[:, 2]
                < 100
            ]
            lit.append(laser_points_on_board(board_uv, cal.camera, T_cb))
        points.append(np.concatenate(lit))
    result = LaserCalibration.fit(angles, points)
    assert result.rms < 0.15
    # The fitted sheet at any angle in the sweep stays within 0.2 mm of the true one over the working volume.
    probe = np.stack(
        np.meshgrid(np.linspace(-120, 120, 5), np.linspace(-120, 120, 5), np.linspace(400, 620, 4)), -1
    ).reshape(-1, 3)
    for a in np.linspace(0.2, 0.41, 5):
        n_true = cal.T_camera_laser_at(a)[:3, 0]
        T_fit = result.T_camera_laser @ syn.pose(ry=a)
        n_fit = T_fit[:3, 0]
        # Project probe points onto the true sheet, measure their distance to the fitted one.
        on_true = probe - np.outer((probe - cal.T_camera_laser[:3, 3]) @ n_true, n_true)
        assert np.abs((on_true - T_fit[:3, 3]) @ n_fit).max() < 0.2
    with pytest.raises(CalibrationError, match="three distinct"):
        LaserCalibration.fit(angles[:2], points[:2])


def test_calibration_file_round_trip_and_errors(tmp_path, rig):
    path = rig.calibration.save(tmp_path / "calibration.toml")
    assert CellCalibration.load(path) == rig.calibration
    text = path.read_text()
    for broken, field in [
        (text.replace("version = 1", "version = 2"), "version"),
        (text.replace("dist = [", "dist = [0.0, "), "camera.dist"),
        (text.replace("width = 1032", ""), "camera.width"),
        (text.replace('axis = "y"', 'axis = "x"'), "laser.axis"),
        (text.replace("[hand_eye]\nT_flange_camera", "[hand_eye]\nT_flange_cam"), "hand_eye.T_flange_camera"),
        (text.replace("width = 1032", "width = 300"), "principal point"),
    ]:
        path.write_text(broken)
        with pytest.raises(CalibrationError, match=field):
            CellCalibration.load(path)
    T = rig.calibration.T_camera_laser.copy()
    T[0, 0] = 2.0
    with pytest.raises(CalibrationError, match="laser.T_camera_laser"):
        CellCalibration(rig.calibration.camera, T, np.eye(4))
    with pytest.raises(CalibrationError, match="camera.K"):
        CameraIntrinsics(10, 10, np.eye(3) * -1, np.zeros(5))
