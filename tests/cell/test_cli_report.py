"""What ``binpick demo`` prints about its picks: one line per skipped part, a picks table with
the part removed and the kind of failure per pick, and a line of totals."""

from __future__ import annotations

import json
import re

from binpick.cell import PickRecord, PoseTruth, RunReport
from binpick.cli import _print_table, main


def test_totals_line_counts_removed_parts_and_failures_by_kind(capsys):
    ok = PoseTruth(instance=3, rotation_error_deg=0.1, translation_error_mm=0.2)
    records = (
        PickRecord(index=1, success=True, picked_instance=3, truth=ok),
        PickRecord(index=2, success=False, held=False, error="the gripper closed on nothing", failure="empty grip"),
        PickRecord(index=3, success=False, picked_instance=5, error="part 5 left the bin", failure="wrong pose"),
        PickRecord(index=4, success=False, error="none of the grasps can be used", failure="no grasp"),
    )
    report = RunReport(records=records, stopped="pick 4: none of the grasps can be used")
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


def test_demo_prints_one_line_per_skipped_part(tmp_path, capsys):
    # In this pile the second scan finds first a cross lying flat against the bin's wall, its far
    # end hidden (the scan cannot rule out a slide along its arm: low confidence) or no grasp
    # keeping the palm inside the bin; the cell says so in one line and picks the next part found.
    out = tmp_path / "cross"
    argv = ["demo", "--part", "cross", "--picks", "2", "--count", "3", "--frames", "45", "--seed", "0"]
    code = main([*argv, "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    skips = [line for line in text.splitlines() if re.match(r"\[\s*[\d.]+ s\] skip ", line)]
    assert len(skips) >= 1, text
    for line in skips:
        at = r"skip\s+cross at \(-?[\d.]+, -?[\d.]+, -?[\d.]+\) mm: "
        assert re.search(at + r"(none of \d+ grasps usable \(|low confidence$)", line), line
        assert len(line) < 160, line
    assert "trying the next part" not in text and "declare more grasps" not in "\n".join(skips)
    records = json.loads((out / "picks.json").read_text())["picks"]
    assert [r["failure"] for r in records] == [None, None], text
    skipped = [k for r in records for k in r["skipped"]]
    assert len(skipped) == len(skips)
    assert all(
        (k["reason"].startswith("none of") and "bin" in k["reason"]) or k["reason"] == "low confidence" for k in skipped
    )
    removed = [r["picked_instance"] for r in records]
    assert f"removed 2 parts ({removed[0]}, {removed[1]}); failures: none" in text
    assert "2 of 2 picks succeeded" in text
