"""Calibration from the cell: the plan driven through the simulated cell's real drivers (the
robot, motor and gripper emulators on ptys) with SimCamera looking at the board lying beside the
bin, solved, and compared with the twin's exact calibration (issue 15 item 2's targets)."""

from __future__ import annotations

import json
import shutil
import time
from contextlib import ExitStack

import numpy as np
import pytest

from binpick._validate import parse_toml
from binpick.calibration import CellCalibration
from binpick.calibration.capture import calibration_plan, capture
from binpick.calibration.solve import load_capture, solve
from binpick.devices import CellLimits
from binpick.errors import CalibrationError, SafetyError
from binpick.sim import simulated_cell
from binpick.transforms import rotation_angle_deg
from binpick.vision import pixel_rays


@pytest.fixture(scope="module")
def captured(tmp_path_factory):
    """One capture through the simulated cell (the expensive part, done once), its solution and the truth."""
    out = tmp_path_factory.mktemp("capture")
    t0 = time.perf_counter()
    with simulated_cell(count=6, seed=2, speed_scale=50.0) as sim:
        layout = sim.layout
        plan = calibration_plan(layout.board.center, T_flange_camera=layout.T_flange_camera)
        cell = sim.cell
        capture(cell.robot, cell.motor, cell.camera, plan, out)
        assert sim.emulator_failures == []
    t1 = time.perf_counter()
    solution = solve(out)
    t2 = time.perf_counter()
    print(f"\ncapture {t1 - t0:.1f} s, solve {t2 - t1:.1f} s")
    return out, plan, solution, layout.calibration()


def test_intrinsics_within_a_tenth_of_a_percent(captured):
    _, _, solution, truth = captured
    K, K0 = solution.calibration.camera.K, truth.camera.K
    for i in (0, 1):
        assert abs(K[i, i] / K0[i, i] - 1) < 1e-3, (K[i, i], K0[i, i])
    assert solution.camera.rms < 0.3


def test_hand_eye_within_half_a_millimetre_and_a_tenth_of_a_degree(captured):
    _, _, solution, truth = captured
    X, X0 = solution.calibration.T_flange_camera, truth.T_flange_camera
    assert np.linalg.norm(X[:3, 3] - X0[:3, 3]) < 0.5
    assert rotation_angle_deg(X0[:3, :3].T @ X[:3, :3]) < 0.1
    assert set(solution.hand_eye.residuals) == {"tsai", "park", "horaud", "andreff", "daniilidis"}
    kept = solution.hand_eye.residuals[solution.hand_eye.method]
    assert all(kept[0] <= mm for mm, _ in solution.hand_eye.residuals.values())
    # What the file holds is the kept method refined with the intrinsics (bundle adjustment): the
    # chain through the robot's poses reprojects the corners nearly as well as free board poses.
    assert np.array_equal(X, solution.refined.T_flange_camera)
    assert solution.refined.rms < solution.camera.rms * 1.2


def test_laser_plane_within_a_tenth_of_a_degree_at_every_angle(captured):
    _, plan, solution, truth = captured
    cal = solution.calibration
    angles = sorted({a for s in plan.laser_stations for a in s.laser_angles})
    v, u = np.mgrid[0:778:20, 0:1032:20]
    grid = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    assert len(solution.laser.angles) >= len(angles) - 2
    for a in angles:
        n, n0 = cal.T_camera_laser_at(a)[:3, 0], truth.T_camera_laser_at(a)[:3, 0]
        assert np.degrees(np.arccos(min(1.0, abs(n @ n0)))) < 0.1, np.degrees(a)
        # The sheets agree where the camera measures: points of the true sheet seen at 450–650 mm
        # lie within 0.3 mm of the solved one.
        ray = pixel_rays(grid, truth.camera)
        T0, T = truth.T_camera_laser_at(a), cal.T_camera_laser_at(a)
        p = ray * ((n0 @ T0[:3, 3]) / (ray @ n0))[:, None]
        p = p[(p[:, 2] > 450) & (p[:, 2] < 650)]
        assert len(p) > 100
        assert np.abs((p - T[:3, 3]) @ n).max() < 0.3, np.degrees(a)


def test_table1_procedure_is_reported(captured):
    _, _, solution, truth = captured
    p = solution.projector
    assert p is not None
    assert abs(p.p_x - truth.T_camera_laser[0, 3]) < 2.0
    assert abs(p.p_z - truth.T_camera_laser[2, 3]) < 5.0


def test_saved_calibration_loads_and_has_residuals(captured, tmp_path):
    _, _, solution, _ = captured
    path = solution.save(tmp_path / "calibration.toml")
    assert CellCalibration.load(path) == solution.calibration
    text = path.read_text()
    for table in ("[residuals.camera]", "[residuals.hand_eye]", "[residuals.laser]"):
        assert table in text
    # How far the intrinsics can be trusted, with the limits they were judged by: the plan's 32
    # board frames (28 board views, 4 laser stations) pass the default limits with room to spare.
    quality = parse_toml(text, str(path), CalibrationError)["quality"]["camera"]
    assert quality["trusted"] is True and quality["warnings"] == [] and quality["views"] == quality["images"] == 32
    assert quality["coverage"] > 0.4 and quality["tilt_spread_deg"] > 40 and quality["focal_sigma_pct"] < 0.1
    assert quality["limits"]["min_views"] == 8 and quality["limits"]["max_rms_px"] == 0.5
    assert "focal 1-sigma" in solution.summary() and "trusted" in solution.summary()
    assert (tmp_path / "calibration_residuals.png").stat().st_size > 10_000
    assert "daniilidis" in solution.summary()


def test_plan_leaving_the_limits_is_refused_before_anything_moves(tmp_path):
    with simulated_cell(count=4, seed=3, speed_scale=50.0) as sim:
        layout, cell = sim.layout, sim.cell
        plan = calibration_plan(layout.board.center, T_flange_camera=layout.T_flange_camera)
        before = sim.robot_emulator.pose()
        tight = CellLimits(workspace_min_mm=(100.0, -200.0, 60.0), workspace_max_mm=(650.0, 350.0, 700.0))
        with pytest.raises(
            SafetyError, match=r"calibration station 'board\d\d': y = -\d+\.\d mm is outside the cell's workspace"
        ):
            capture(cell.robot, cell.motor, cell.camera, plan, tmp_path / "c", limits=tight)
        assert np.array_equal(sim.robot_emulator.pose(), before)
        assert not (tmp_path / "c").exists()


def test_corrupt_or_incomplete_capture_gives_a_clear_error(captured, tmp_path):
    out = captured[0]
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    manifest = bad / "manifest.json"
    manifest.write_text(manifest.read_text()[:500])
    with pytest.raises(CalibrationError, match="manifest.json: not a readable JSON manifest"):
        load_capture(bad)
    doc = json.loads((out / "manifest.json").read_text())
    doc["stations"][3].pop("T_base_flange")
    manifest.write_text(json.dumps(doc))
    with pytest.raises(CalibrationError, match=r"stations\[3\]\.T_base_flange is missing"):
        solve(bad)
    doc = json.loads((out / "manifest.json").read_text())
    manifest.write_text(json.dumps(doc))
    (bad / doc["stations"][0]["board_frame"]["file"]).unlink()
    with pytest.raises(CalibrationError, match="board_frame.file frames/board00_00.png is missing"):
        solve(bad)
    with pytest.raises(CalibrationError, match="manifest is missing"):
        solve(tmp_path)


def test_cli_solve_prints_the_table_and_writes_the_files(captured, tmp_path, capsys):
    from binpick.cli import main

    out = tmp_path / "calibration.toml"
    code = main(["calibrate", "solve", str(captured[0]), "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    loaded, solved = CellCalibration.load(out), captured[2].calibration  # a second solve: same to rounding
    assert np.allclose(loaded.camera.K, solved.camera.K, rtol=1e-6)
    assert np.allclose(loaded.T_flange_camera, solved.T_flange_camera, atol=1e-4)
    assert (tmp_path / "calibration_residuals.png").exists()
    for word in ("fx", "tsai", "park", "horaud", "andreff", "daniilidis", "laser", "table 1"):
        assert word in printed.out


def test_cli_solve_refuses_untrusted_intrinsics_and_keeps_them_on_request(captured, tmp_path, capsys):
    """The capture's 32 views judged against a limit they miss (33 views): refused, exit 2 and
    nothing written; with --accept-untrusted solved, the warning on stderr and in the file."""
    from binpick.cli import main

    out = tmp_path / "calibration.toml"
    args = ["calibrate", "solve", str(captured[0]), "--out", str(out), "--min-views", "33"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "found in only 32 views; at least 33 are needed" in err and "--accept-untrusted" in err
    assert not out.exists()
    assert main([*args, "--accept-untrusted"]) == 0
    printed = capsys.readouterr()
    assert "WARNING: this camera calibration CANNOT BE TRUSTED" in printed.err and "NOT TRUSTED" in printed.out
    quality = parse_toml(out.read_text(), str(out), CalibrationError)["quality"]["camera"]
    assert quality["trusted"] is False and quality["limits"]["min_views"] == 33
    assert len(quality["warnings"]) == 1 and "at least 33 are needed" in quality["warnings"][0]
    assert CellCalibration.load(out).camera.width == captured[3].camera.width


def test_cli_capture_refuses_a_plan_outside_the_cell_file_limits(tmp_path, capsys):
    from binpick.cli import main
    from binpick.devices.emulators import DynamixelEmulator, GripperEmulator, RobotEmulator, RobotEmulatorConfig
    from binpick.sim import SIM_ARM

    with ExitStack() as stack:
        robot, motor, gripper = (
            stack.enter_context(e)
            for e in (RobotEmulator(config=RobotEmulatorConfig(arm=SIM_ARM)), DynamixelEmulator(), GripperEmulator())
        )
        ports = "".join(
            f'[{n}]\nport = "{e.slave_path}"\n' for n, e in zip(("robot", "motor", "gripper"), (robot, motor, gripper))
        )
        cfg = tmp_path / "cell.toml"
        cfg.write_text(
            ports
            + """
[camera]
source = "simulated"
[part]
model = "tee"
[cell]
calibration = "not_yet.toml"
bin_min_mm = [250.0, -100.0, 0.0]
bin_max_mm = [550.0, 100.0, 80.0]
scan_pose = [400.0, 0.0, 620.0, 180.0, 0.0, 0.0]
drop_pose = [400.0, -250.0, 350.0, 180.0, 0.0, 0.0]
[calibration_board]
pattern = [9, 6]
square_mm = 20.0
center_mm = [400.0, -250.0, -5.0]
[limits]
workspace_min_mm = [100.0, -200.0, 60.0]
workspace_max_mm = [650.0, 350.0, 700.0]
approach_height_mm = 270.0
"""
        )
        before = robot.pose()
        code = main(["calibrate", "capture", str(cfg), "--out", str(tmp_path / "cap")])
        err = capsys.readouterr().err
        assert code == 1, err
        assert "SafetyError: calibration station" in err and "nothing was sent" in err
        assert np.array_equal(robot.pose(), before)
        assert motor.failures == robot.failures == []
    assert not (tmp_path / "cap").exists()
    assert main(["calibrate", "capture", str(cfg)]) == 2  # --out is required


def test_cli_folder_of_images_still_gives_the_intrinsics(captured, tmp_path, capsys):
    from binpick.cli import main

    folder = tmp_path / "boards"
    folder.mkdir()
    for png in sorted((captured[0] / "frames").glob("board*_00.png")):
        shutil.copy(png, folder / png.name)
    code = main(["calibrate", str(folder), "--pattern", "9x6", "--square", "20"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    doc = json.loads(printed.out)
    assert abs(doc["K"][0][0] / captured[3].camera.K[0, 0] - 1) < 1e-3
    assert len(doc["views"]) == len(list(folder.iterdir()))
    assert main(["calibrate", str(folder), "--out", "x.toml"]) == 2
