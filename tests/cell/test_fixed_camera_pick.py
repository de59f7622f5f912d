"""`binpick pick` with a fixed 3-D camera (eye-to-hand): the twin with its structured-light camera
on a stand (`binpick emulate cell --camera fixed`, the MELFA arm), its true eye-to-hand pose, and
the pick loop unchanged above a depth shot per scan — every part picked, then the bin found empty."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

from binpick.cli import main


def test_binpick_pick_empties_the_bin_with_a_fixed_camera(tmp_path, capsys):
    out = tmp_path / "twin"
    proc = subprocess.Popen(
        [sys.executable, "-m", "binpick", "emulate", "cell", "--out", str(out), "--count", "3", "--camera", "fixed"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out / "camera.sock").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "the twin did not start"
            time.sleep(0.2)
        shutil.copy(out / "true_calibration.toml", out / "calibration.toml")
        shutil.copy(out / "true_eye_to_hand.toml", out / "eye_to_hand.toml")
        code = main(["pick", str(out / "cell.toml"), "--picks", "4", "--out", str(tmp_path / "run")])
        printed = capsys.readouterr()
        assert code == 0, printed.err[-3000:]
        assert "3 of 4 picks succeeded" in printed.out + printed.err
        picks = json.loads((tmp_path / "run" / "picks.json").read_text())["picks"]
        assert [p["success"] for p in picks] == [True, True, True, False] and picks[3]["failure"] == "nothing found"
        time.sleep(0.5)  # the twin writes world.json on its next tick
        world = json.loads((out / "world.json").read_text())
        assert sorted(world["removed"]) == [0, 1, 2] and world["in_bin"] == []
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)
