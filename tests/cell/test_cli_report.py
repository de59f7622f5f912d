"""What ``binpick demo`` prints about its picks: one line per skipped part, a picks table with
the part removed and the kind of failure per pick, and a line of totals; and what ``binpick
pick`` prints on real drivers, where nothing tells which part left the bin."""

from __future__ import annotations

import json
import re

import binpick
from binpick.cell import PickRecord, PoseTruth, RunReport
from binpick.cli import _pictures, _print_table, main


def test_totals_line_counts_removed_parts_and_failures_by_kind(capsys):
    ok = PoseTruth(instance=3, rotation_error_deg=0.1, translation_error_mm=0.2)
    records = (
        PickRecord(index=1, success=True, picked_instance=3, truth=ok),
        PickRecord(index=2, success=False, held=False, error="the gripper closed on nothing", failure="empty grip"),
        PickRecord(index=3, success=False, picked_instance=5, error="part 5 left the bin", failure="wrong pose"),
        PickRecord(index=4, success=False, error="none of the grasps can be used", failure="no grasp"),
    )
    report = RunReport(records=records, stopped="pick 4: none of the grasps can be used", ground_truth=True)
    assert report.removed == (3, 5)
    assert report.failures_by_kind() == {"no grasp": 1, "empty grip": 1, "wrong pose": 1}
    _print_table(report)
    lines = capsys.readouterr().out.splitlines()
    header = lines[0].split()
    assert header[:4] == ["pick", "result", "removed", "failure"]
    assert lines[2].split()[:4] == ["1", "picked", "part", "3"]
    assert "empty grip" in lines[3] and "wrong pose" in lines[4] and "no grasp" in lines[5]
    assert lines[6] == "removed 2 parts (3, 5); failures: 1 no grasp, 1 empty grip, 1 wrong pose"
    assert lines[7:] == [
        "pick 2: the gripper closed on nothing",
        "pick 3: part 5 left the bin",
        "pick 4: none of the grasps can be used",
    ]


def test_without_ground_truth_the_removed_count_is_not_known_and_the_lifts_are_named(tmp_path, capsys):
    # Real drivers: three picks the gripper reported holding, one it closed on nothing, one
    # whose gripper cannot tell (the robot's hand outputs). No record knows which part left.
    records = (
        PickRecord(index=1, success=True, held=True, grasp="b0"),
        PickRecord(index=2, success=False, held=False, error="the gripper closed on nothing", failure="empty grip"),
        PickRecord(index=3, success=True, held=True, grasp="b1"),
        PickRecord(index=4, success=True, held=True, grasp="b2"),
        PickRecord(index=5, success=True, held=None, grasp="b0"),
    )
    report = RunReport(records=records, stopped=None)
    assert report.removed is None and report.lifted == (1, 3, 4)
    _print_table(report)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[:3] for line in lines[2:7]] == [
        ["1", "picked", "?"],
        ["2", "failed", "-"],
        ["3", "picked", "?"],
        ["4", "picked", "?"],
        ["5", "picked", "?"],
    ]
    assert lines[7] == (
        "removed: not known (no ground truth); lifted a part: 3 picks (1, 3, 4), "
        "the gripper could not tell: 1 pick (5); failures: 1 empty grip"
    )
    assert not any(line.startswith("removed 0") for line in lines)
    _pictures(tmp_path, report, binpick.parts.tee(), None)
    saved = json.loads((tmp_path / "picks.json").read_text())
    assert saved["removed"] is None and saved["lifted"] == [1, 3, 4]
    assert (tmp_path / "summary.png").read_bytes()[:4] == b"\x89PNG"


def test_demo_prints_one_line_per_skipped_part(tmp_path, capsys):
    # In this pile a scan finds first a tee whose every grasp would take the palm into the bin's
    # wall or beyond the tilt limit; the cell says so in one line and picks the next part found.
    out = tmp_path / "tee"
    argv = ["demo", "--part", "tee", "--picks", "3", "--count", "6", "--frames", "45", "--seed", "2"]
    code = main([*argv, "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    skips = [line for line in text.splitlines() if re.match(r"\[\s*[\d.]+ s\] skip ", line)]
    assert len(skips) >= 1, text
    for line in skips:
        at = r"skip\s+tee at \(-?[\d.]+, -?[\d.]+, -?[\d.]+\) mm: "
        assert re.search(at + r"(none of \d+ grasps usable \(|low confidence$)", line), line
        assert len(line) < 160, line
    assert "trying the next part" not in text and "declare more grasps" not in "\n".join(skips)
    records = json.loads((out / "picks.json").read_text())["picks"]
    assert [r["failure"] for r in records] == [None, None, None], text
    skipped = [k for r in records for k in r["skipped"]]
    assert len(skipped) == len(skips)
    assert all(
        (k["reason"].startswith("none of") and "bin" in k["reason"]) or k["reason"] == "low confidence" for k in skipped
    )
    removed = [r["picked_instance"] for r in records]
    assert f"removed 3 parts ({removed[0]}, {removed[1]}, {removed[2]}); failures: none" in text
    assert "3 of 3 picks succeeded" in text
