"""README's "Commission a cell" commands, word for word, in a temporary folder: the digital twin
as its own process, the calibration captured through its ptys and camera socket and solved, the
solution against the twin's truth (issue 15's targets), three picks, and the twin's clean exit.
Also what ``binpick calibrate compare`` reports for a calibration known to be off."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess

import numpy as np
import pytest

from _readme import command_shim, readme_block
from binpick.calibration import CellCalibration
from binpick.calibration.compare import captured_angles, compare_calibrations
from binpick.transforms import rot_y, rotation_about, rotation_angle_deg

MARKER = "<!-- commission-commands -->"
#: The whole flow's longest run, s (about 2.5 min on a loaded 2-core machine).
TIMEOUT_S = 900


def _step_times(trace: str, end: float) -> list[tuple[str, float]]:
    """(command, seconds) of each traced top-level command, up to the next one (or ``end``)."""
    starts = [(float(t), cmd) for t, cmd in re.findall(r"^\+\++ @(\d+\.\d+) (.*)$", trace, re.M)]
    starts.sort()  # the background job's trace may be printed after the next command's
    steps: dict[str, float] = {}
    for i, (t, cmd) in enumerate(starts):
        seconds = (starts[i + 1][0] if i + 1 < len(starts) else end) - t
        if cmd.startswith(("'[' ", "sleep ")):  # the turns of the `until` loop, together
            cmd = "until [ -S twin/camera.sock ] … (the twin starting)"
        steps[cmd] = steps.get(cmd, 0.0) + seconds
    return list(steps.items())


@pytest.fixture(scope="module")
def commissioned(tmp_path_factory):
    """The README's commands run once with `bash -e` (the expensive part)."""
    import time

    work = tmp_path_factory.mktemp("commission")
    env = command_shim(work / ".bin")
    script = work / "commission.sh"
    script.write_text(readme_block(MARKER))
    t0 = time.time()
    proc = subprocess.Popen(
        # Each command traced with its start time (bash's xtrace; bash takes no PS4 from a root
        # environment), for the wall time of each step; the script is sourced by this shell.
        ["bash", "-e", "-c", f"PS4='+ @${{EPOCHREALTIME}} '; set -x; . {script.name}"],
        cwd=work,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # the twin runs in this group: on a failure it is stopped with it
    )
    try:
        out, _ = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
        pytest.fail(f"the commissioning commands did not finish in {TIMEOUT_S} s:\n{out[-4000:]}")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # anything left behind by a failed step
        except ProcessLookupError:
            pass
    end = time.time()
    steps = _step_times(out, end)
    print(f"\ncommissioning flow {end - t0:.1f} s")
    for cmd, seconds in steps:
        print(f"  {seconds:6.1f} s  {cmd}")
    assert proc.returncode == 0, out[-6000:]
    return work / "twin", out


def test_calibration_meets_the_targets_against_the_truth(commissioned):
    twin, out = commissioned
    solved = CellCalibration.load(twin / "calibration.toml")
    truth = CellCalibration.load(twin / "true_calibration.toml")
    X, X0 = solved.T_flange_camera, truth.T_flange_camera
    assert np.linalg.norm(X[:3, 3] - X0[:3, 3]) < 0.5
    assert rotation_angle_deg(X0[:3, :3].T @ X[:3, :3]) < 0.1
    for i in (0, 1):
        assert abs(solved.camera.K[i, i] / truth.camera.K[i, i] - 1) < 1e-3
    # Every motor angle the capture swept and the pick's scans reach (±17°), and beyond.
    manifest = json.loads((twin / "capture" / "manifest.json").read_text())
    swept = [f["angle"] for s in manifest["stations"] for f in s["laser_frames"]]
    assert len(swept) >= 30
    for angles in (swept, np.radians(np.arange(-25.0, 25.5, 0.5))):
        result = compare_calibrations(solved, truth, angles)
        assert max(result.laser_deg) < 0.1 and result.failures == []
    print("\n" + compare_calibrations(solved, truth, captured=captured_angles(twin / "calibration.toml")).table())
    assert "MISSED" not in out and out.count(" ok\n") >= 5  # `binpick calibrate compare` agreed
    per_angle = re.findall(r"^laser sheet at captured motor angle [+-]\d+\.\d°\s+0\.\d{4}°\s+0\.1°\s+ok$", out, re.M)
    assert len(per_angle) == len(captured_angles(twin / "calibration.toml")) >= 3


def test_three_parts_removed_in_three_attempts(commissioned):
    twin, out = commissioned
    world = json.loads((twin / "world.json").read_text())
    picks = json.loads((twin / "run" / "picks.json").read_text())
    assert len(picks["picks"]) == 3 and all(p["success"] for p in picks["picks"])
    assert len(world["removed"]) == 3 and len(set(world["removed"])) == 3
    assert world["held"] is None
    assert "3 of 3 picks succeeded" in out
    print(f"\nremoved {world['removed']}; {len(world['in_bin'])} left; collisions {world['collisions']}")


def test_the_twin_exited_cleanly(commissioned):
    twin, out = commissioned
    assert "stopped" in out and "parts removed" in out  # the twin's last line, after `kill %1`
    assert not (twin / "camera.sock").exists()
    assert "Traceback" not in out


def test_compare_reports_a_calibration_off_target(tmp_path, capsys):
    from binpick.cli import main
    from binpick.sim import Cell

    truth = Cell().calibration()
    off = truth.T_flange_camera.copy()
    off[:3, :3] = off[:3, :3] @ rotation_about([1.0, 0.0, 0.0], math.radians(0.2))
    off[:3, 3] += [0.3, 0.0, 0.0]
    K = truth.camera.K.copy()
    K[0, 0] *= 1.002
    from dataclasses import replace

    solved = replace(truth, T_flange_camera=off, camera=replace(truth.camera, K=K))
    result = compare_calibrations(solved, truth)
    assert result.hand_eye_mm == pytest.approx(0.3, abs=1e-9)
    assert result.hand_eye_deg == pytest.approx(0.2, abs=1e-9)
    assert result.fx_rel == pytest.approx(2e-3, rel=1e-9) and result.fy_rel == 0.0
    assert max(result.laser_deg) < 1e-9  # the laser is given in the camera frame: untouched
    assert [f.split(" is ")[0] for f in result.failures] == ["hand-eye rotation", "fx"]
    solved.save(tmp_path / "solved.toml")
    truth.save(tmp_path / "truth.toml")
    assert main(["calibrate", "compare", str(tmp_path / "solved.toml"), str(tmp_path / "truth.toml")]) == 1
    printed = capsys.readouterr()
    assert printed.out.count("MISSED") == 2 and "hand-eye rotation is 0.2000° off" in printed.err
    assert main(["calibrate", "compare", str(tmp_path / "truth.toml"), str(tmp_path / "truth.toml")]) == 0
    assert "(no captured motor angles: " in capsys.readouterr().out
    assert main(["calibrate", "compare", str(tmp_path / "truth.toml")]) == 2


def test_compare_prints_the_laser_sheet_error_at_each_captured_motor_angle(tmp_path, capsys):
    from dataclasses import replace

    from binpick.cli import main
    from binpick.sim import Cell

    # The laser sheet solved 0.05° turned about the camera's x axis: the error varies with the
    # motor angle. The solved file records the angles it was captured at, as `calibrate solve`
    # writes them ([residuals.laser] angles_rad).
    truth = Cell().calibration()
    turned = truth.T_camera_laser.copy()
    turned[:3, :3] = rotation_about([1.0, 0.0, 0.0], math.radians(0.05)) @ turned[:3, :3]
    solved = replace(truth, T_camera_laser=turned)
    captured = np.radians([-16.0, -12.0, -8.0, -4.0, 0.0, 4.0, 8.0, 12.0, 16.0])
    expected = compare_calibrations(solved, truth, captured=captured)
    assert len(set(np.round(expected.captured_deg, 6))) > 1 and max(expected.captured_deg) < 0.1
    table = "\n[residuals.laser]\nangles_rad = [" + ", ".join(repr(float(a)) for a in captured) + "]\n"
    (tmp_path / "solved.toml").write_text(solved.to_toml() + table)
    truth.save(tmp_path / "truth.toml")
    assert main(["calibrate", "compare", str(tmp_path / "solved.toml"), str(tmp_path / "truth.toml")]) == 0
    out = capsys.readouterr().out
    rows = re.findall(r"^laser sheet at captured motor angle ([+-]\d+\.\d)°\s+(\d\.\d{4})°\s+0\.1°\s+ok$", out, re.M)
    assert [float(a) for a, _ in rows] == [-16.0, -12.0, -8.0, -4.0, 0.0, 4.0, 8.0, 12.0, 16.0], out
    assert [float(e) for _, e in rows] == pytest.approx(expected.captured_deg, abs=6e-5)
    # The motor's zero 0.2° off (the sheet turned about the motor axis): every captured angle
    # misses by 0.2°, each line says so, and the command exits 1.
    off_zero = truth.T_camera_laser @ rot_y(math.radians(0.2))
    (tmp_path / "solved.toml").write_text(replace(truth, T_camera_laser=off_zero).to_toml() + table)
    assert main(["calibrate", "compare", str(tmp_path / "solved.toml"), str(tmp_path / "truth.toml")]) == 1
    printed = capsys.readouterr()
    missed = re.findall(r"^laser sheet at captured motor angle .*MISSED$", printed.out, re.M)
    assert len(missed) == len(captured), printed.out
    assert all(line.split()[-3] == "0.2000°" for line in missed)
    assert "the laser sheet is 0.2000° off" in printed.err
