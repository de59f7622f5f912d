"""`binpick pick` with a fixed 3-D camera (eye-to-hand): the twin with its structured-light camera
on a stand (`binpick emulate cell --camera fixed`, the MELFA arm), its true eye-to-hand pose, and
the pick loop unchanged above a depth shot per scan — every part picked, then the bin found empty
(the twin's ground truth says so: the run ends "bin empty: 3 of 3 removed", not failed)."""

from __future__ import annotations

import json
import time

from _twin import twin_process
from binpick.cli import main


def test_binpick_pick_empties_the_bin_with_a_fixed_camera(tmp_path, capsys):
    with twin_process(tmp_path / "twin", "--count", "3", "--camera", "fixed") as out:
        code = main(["pick", str(out / "cell.toml"), "--picks", "4", "--out", str(tmp_path / "run")])
        printed = capsys.readouterr()
        assert code == 0, printed.err[-3000:]
        assert "3 of 3 picks succeeded" in printed.out and "then bin empty: 3 of 3 removed" in printed.out
        picks = json.loads((tmp_path / "run" / "picks.json").read_text())["picks"]
        assert [p["success"] for p in picks] == [True, True, True, False]
        assert picks[3]["bin_empty"] and picks[3]["failure"] is None  # the bin emptied: not a failure
        time.sleep(0.5)  # the twin writes world.json on its next tick
        world = json.loads((out / "world.json").read_text())
        assert sorted(world["removed"]) == [0, 1, 2] and world["in_bin"] == []
