"""How a run of ``binpick demo`` / ``binpick pick`` ends: Ctrl-C keeps the picks finished (their
records in picks.json, exit 130), and a run that empties the bin ends "bin empty", not failed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading

import binpick.cell
from _readme import command_shim
from binpick.cell import PickRecord, RunReport
from binpick.cli import _print_table, main

#: A small demo: two tees, the estimator's options the other demo tests use.
DEMO = ["demo", "--count", "2", "--frames", "45", "--seed", "1", "--d-star", "12", "--min-points", "500"]


def test_ctrl_c_in_the_demo_writes_the_finished_picks_and_exits_130(tmp_path, monkeypatch, capsys):
    # Ctrl-C as the second pick starts: the first pick's record is kept.
    class CtrlCAtPick2(binpick.cell.ProgressPrinter):
        def __call__(self, stage, message):
            super().__call__(stage, message)
            if message.startswith("— pick 2 of"):
                raise KeyboardInterrupt

    monkeypatch.setattr(binpick.cell, "ProgressPrinter", CtrlCAtPick2)
    out = tmp_path / "run"
    assert main([*DEMO, "--picks", "3", "--out", str(out)]) == 130
    printed = capsys.readouterr()
    saved = json.loads((out / "picks.json").read_text())
    assert [p["success"] for p in saved["picks"]] == [True], printed.out
    assert saved["stopped"] == "interrupted (Ctrl-C) in pick 2"
    assert "interrupted (Ctrl-C) after 1 finished pick" in printed.err and str(out / "picks.json") in printed.err
    assert (out / "summary.png").exists()
    assert "1     picked  part" in printed.out  # the table of the picks finished


def test_sigint_to_the_demo_process_keeps_the_first_pick(tmp_path):
    """End to end: a real SIGINT to `binpick demo` once its second pick has started."""
    out = tmp_path / "run"
    env = command_shim(tmp_path / ".bin")
    proc = subprocess.Popen(
        [sys.executable, "-m", "binpick", *DEMO, "--picks", "3", "--out", str(out)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    watchdog = threading.Timer(90.0, proc.kill)
    watchdog.start()
    try:
        seen = []
        for line in proc.stdout:
            seen.append(line)
            if "— pick 2 of 3 —" in line:
                os.kill(proc.pid, signal.SIGINT)
                break
        rest, err = proc.communicate(timeout=60)
    finally:
        watchdog.cancel()
    assert proc.returncode == 130, "".join(seen)[-2000:] + rest[-2000:] + err[-2000:]
    picks = json.loads((out / "picks.json").read_text())["picks"]
    assert len(picks) == 1 and picks[0]["success"] and picks[0]["index"] == 1
    assert "interrupted (Ctrl-C) after 1 finished pick" in err


def test_a_demo_that_empties_the_bin_ends_bin_empty_not_failed(tmp_path, capsys):
    # One tee: the first pick removes it, the second attempt finds the bin empty.
    out = tmp_path / "run"
    code = main([*DEMO, "--count", "1", "--picks", "2", "--frames", "30", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    table = text[text.index("pick  result") :].splitlines()
    assert table[3].split()[:2] == ["2", "bin"] and table[3].split()[2:4] == ["empty", "-"], text
    assert table[4].startswith("bin empty: 1 of 1 removed (0); failures: none"), text
    assert "1 of 1 picks succeeded in" in text and "then bin empty: 1 of 1 removed" in text
    assert "nothing found" not in text
    saved = json.loads((out / "picks.json").read_text())["picks"]
    assert [(p["success"], p["failure"], p["bin_empty"]) for p in saved] == [(True, None, False), (False, None, True)]
    assert not (out / "failure_pick2.png").exists()  # not a failure: no failure picture


def test_without_ground_truth_an_emptied_bin_counts_the_picks(capsys):
    # Real drivers: nothing tells which part left; the scan held nothing above the floor.
    records = (
        PickRecord(index=1, success=True, held=True),
        PickRecord(index=2, success=True, held=True),
        PickRecord(index=3, success=False, bin_empty=True),
    )
    report = RunReport(records=records, stopped="pick 3: the bin is empty")
    assert report.bin_empty and report.failures_by_kind() == {}
    _print_table(report)
    lines = capsys.readouterr().out.splitlines()
    assert lines[4].split()[:4] == ["3", "bin", "empty", "-"]
    assert (
        lines[5]
        == "bin empty (nothing found above the floor): 2 removed; lifted a part: 2 picks (1, 2); failures: none"
    )
