"""The ``binpick`` command: demo end to end, usage errors, ``pick --dry-run`` against emulators."""

from __future__ import annotations

import numpy as np
import pytest
from _cell_helpers import emulated_cell_file, emulators

from binpick.cli import main

ESTIMATE_FLAGS = ["--d-star", "12", "--min-points", "500"]
ESTIMATE_TABLE = "[estimate]\nd_star = 12.0\nmin_points = 500"


def test_demo_picks_one_part_and_writes_the_pictures(tmp_path, capsys):
    # Two attempts on a pile of four (once the first lifted a part on a 180° flip, which did not
    # count; the trust stage now decides that pose): at least one succeeds.
    out = tmp_path / "demo"
    code = main(
        ["demo", "--picks", "2", "--count", "4", "--frames", "60", "--seed", "1", "--out", str(out), *ESTIMATE_FLAGS]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    for name in ("scan_contact_sheet.png", "cloud.png", "summary.png"):
        png = out / name
        assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert "picked" in text and " of 2 picks succeeded" in text and "0 of 2 picks succeeded" not in text


@pytest.mark.parametrize(
    "argv",
    [
        ["demo", "--picks", "many"],
        ["demo", "--picks", "0"],
        ["demo", "--part", "no-such-part.stl"],
        ["frobnicate"],
        [],
        ["pick"],
        ["estimate", "missing.ply", "tee"],
        ["calibrate", "/no/such/folder"],
    ],
)
def test_bad_arguments_exit_2(argv, capsys):
    assert main(argv) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_pick_example_prints_a_cell_file(capsys):
    assert main(["pick", "--example"]) == 0
    assert "[robot]" in capsys.readouterr().out


def test_pick_dry_run_against_emulators(tmp_path, capsys):
    with emulators() as (robot, motor, gripper):
        camera = 'source = "simulated"\ncount = 4\nseed = 1'
        cfg = emulated_cell_file(tmp_path, robot, motor, gripper, camera=camera, tail=ESTIMATE_TABLE)
        code = main(["pick", str(cfg), "--dry-run", "--out", str(tmp_path / "out")])
        captured = capsys.readouterr()
        assert code == 0, captured.err
        assert (tmp_path / "out" / "cloud.png").exists()
        assert np.allclose(robot.pose()[:3, 3], (400.0, 0.0, 620.0), atol=1.0)  # it went to the scan pose
        assert gripper.axis.position() == 0.0  # a dry run leaves the fingers open
        assert robot.failures == motor.failures == gripper.failures == []
    assert '"T_base_object"' in captured.out


def test_pick_with_a_drop_pose_outside_the_workspace_exits_1_before_sending(tmp_path, capsys):
    from binpick.devices.emulators import RobotEmulator
    from binpick.sim import Cell as Layout

    Layout().calibration().save(tmp_path / "calibration.toml")
    with RobotEmulator() as robot:
        cfg = tmp_path / "cell.toml"
        cfg.write_text(f"""
[robot]
port = "{robot.slave_path}"
[motor]
port = "{robot.slave_path}"
[gripper]
port = "{robot.slave_path}"
[part]
model = "tee"
[cell]
calibration = "calibration.toml"
bin_min_mm = [250.0, -100.0, 0.0]
bin_max_mm = [550.0, 100.0, 80.0]
scan_pose = [300.0, 0.0, 400.0, 180.0, 0.0, 0.0]
drop_pose = [2000.0, 0.0, 400.0, 180.0, 0.0, 0.0]
""")
        assert main(["pick", str(cfg)]) == 1
        assert "drop_pose" in capsys.readouterr().err
        assert robot.requests == []


def test_exit_codes_say_no_object_found_and_interrupted(tmp_path, capsys, monkeypatch):
    """3 when the scene holds no such part (not 1, as a fault), 130 on Ctrl-C (as a shell reports
    SIGINT), as the README lists them."""
    noise = tmp_path / "noise.npy"
    np.save(noise, np.random.default_rng(1).uniform([260.0, -90.0, 0.0], [540.0, 90.0, 80.0], (20000, 3)))
    assert main(["estimate", str(noise), "tee"]) == 3
    assert "NoObjectFound" in capsys.readouterr().err

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr("binpick.cli._estimate", interrupted)
    assert main(["estimate", str(noise), "tee"]) == 130
    assert "interrupted" in capsys.readouterr().err
