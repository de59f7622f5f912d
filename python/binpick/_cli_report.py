"""What ``binpick demo`` and ``binpick pick`` report of a run: the table of picks with its line of
totals, the pictures and ``picks.json`` in the --out folder."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Optional

__all__ = ["_pictures", "_print_table", "_removed_text", "run_keeping_picks", "outcome_line", "interrupted"]


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'s' if n != 1 else ''}"


def _removed_text(report: Any) -> str:
    """What left the bin: the parts removed with ground truth; without it (real drivers) the
    count is not known, and the picks whose gripper reported holding a part (and those it could
    not tell) are named instead. A run that emptied the bin starts with :func:`bin_empty_text`."""
    removed = report.removed
    if removed is not None:
        listed = f" ({', '.join(map(str, removed))})" if removed else ""
        if report.bin_empty:
            return bin_empty_text(report) + listed
        return f"removed {_plural(len(removed), 'part')}{listed}"
    lifted = report.lifted
    head = bin_empty_text(report) if report.bin_empty else "removed: not known (no ground truth)"
    text = f"{head}; lifted a part: " + _plural(len(lifted), "pick")
    text += f" ({', '.join(map(str, lifted))})" if lifted else ""
    unsure = [r.index for r in report.records if r.success and r.held is None]
    if unsure:
        text += f", the gripper could not tell: {_plural(len(unsure), 'pick')} ({', '.join(map(str, unsure))})"
    return text


def bin_empty_text(report: Any) -> str:
    """How a run that found the bin empty ends: with ground truth, every part left the bin
    (``bin empty: N of N removed``); without it, the scan held nothing above the bin's floor and
    the picks that succeeded are what left it."""
    if report.removed is not None:
        n = len(report.removed)
        return f"bin empty: {n} of {n} removed"
    return f"bin empty (nothing found above the floor): {report.successes} removed"


def _removed_cell(report: Any, r: Any) -> str:
    """A pick's "removed" column: the part (ground truth), "?" where something may have left the
    bin but nothing tells which part, "-" where nothing did."""
    if r.picked_instance is not None:
        return f"part {r.picked_instance}"
    return "?" if not report.ground_truth and r.success else "-"


_TABLE_HEADER = tuple(
    "pick|result|removed|failure|score|confidence|orientation|rmse mm|rot err °|pos err mm|grasp|time s".split("|")
)


def _print_table(report: Any, out: Any = None) -> None:
    """The picks as a table (one row each: result, part removed, kind of failure, pose quality),
    a line of totals (parts removed, failures by kind) and one line per failed pick."""
    out = out or sys.stdout
    rows = [_TABLE_HEADER]
    for r in report.records:
        rows.append(
            (
                str(r.index),
                "picked" if r.success else "bin empty" if r.bin_empty else "failed",
                _removed_cell(report, r),
                r.failure or "-",
                "-" if r.score is None else f"{r.score:.2f}",
                _confidence_cell(r),
                "-" if r.orientation_decided is None else ("decided" if r.orientation_decided else "open"),
                "-" if r.rmse is None else f"{r.rmse:.2f}",
                "-" if r.truth is None else f"{r.truth.rotation_error_deg:.2f}",
                "-" if r.truth is None else f"{r.truth.translation_error_mm:.2f}",
                r.grasp or "-",
                f"{r.cycle_time_s if r.cycle_time_s is not None else r.timings.get('total', 0.0) / 1e3:.1f}",
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        print("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip(), file=out)
        if k == 0:
            print("  ".join("-" * w for w in widths), file=out)
    failures = report.failures_by_kind()
    print(
        _removed_text(report)
        + "; failures: "
        + (", ".join(f"{n} {kind}" for kind, n in failures.items()) if failures else "none"),
        file=out,
    )
    cycle = _cycle_line(report)
    if cycle:
        print(cycle, file=out)
    for r in report.records:
        if r.error:
            print(f"pick {r.index}: {r.error}", file=out)


def _cycle_line(report: Any) -> Optional[str]:
    """The physical cycle time and picks per hour of a cell that keeps a hardware clock (a
    simulated cell, the twin): its mean stages; None for a real cell (its time column is the wall clock's)."""
    from .cell.records import CYCLE_STAGES, cycle_stages_s, picks_per_hour
    from .sim.validate_report import stage_text

    cycles = [r for r in report.records if not r.bin_empty and r.cycle_time_s is not None]
    if not cycles:
        return None
    stages = [cycle_stages_s(r.timings) or {} for r in cycles]
    mean = {k: sum(st.get(k, 0.0) for st in stages) / len(stages) for k in CYCLE_STAGES}
    times = [r.cycle_time_s for r in cycles]
    rate = picks_per_hour(sum(r.success for r in cycles), times)
    return (
        f"cycle time (the cell's hardware clock, and binpick's compute): mean {sum(times) / len(times):.1f} s — "
        + stage_text(mean)
        + ("" if rate is None else f"; {rate:.0f} picks per hour")
    )


def _confidence_cell(r: Any) -> str:
    """The pose's confidence, and with open alternatives the confidence that one of them is right."""
    if r.confidence is None:
        return "-"
    extra = f" (any {r.confidence_any:.2f})" if r.orientation_decided is False and r.confidence_any else ""
    return f"{r.confidence:.2f}{extra}"


def _failure_pictures(out: Path, report: Any, model: Any, bin_bounds: Any) -> list[Path]:
    """A picture per failed pick: its last scan, the parts passed over and why, the part it went for."""
    from . import viz

    written = []
    for r in report.records:
        if r.success or r.bin_empty or r.scan is None or not len(r.scan.points):
            continue
        title = f"pick {r.index}: {r.failure} — {r.error or ''}"
        written.append(
            viz.save_record_failure(
                out / f"failure_pick{r.index}.png", r, model=model, bin_bounds=bin_bounds, title=title
            )
        )
    return written


def _pictures(out: Path, report: Any, model: Any, bin_bounds: Any) -> list[Path]:
    from . import viz

    written: list[Path] = []
    scan = report.last_scan
    if scan is not None and scan.frames:
        numbers = sorted(scan.frames)
        written.append(
            viz.save_contact_sheet(out / "scan_contact_sheet.png", [scan.frames[k] for k in numbers], numbers=numbers)
        )
    loc = report.last_located
    if loc is not None:
        scan = loc.scan  # the picture shows the last part found, over the scan it was found in
    if scan is not None and len(scan.points):
        if loc is not None:
            title = f"{len(scan.points)} points; {model.name} found with score {loc.result.score:.2f}"
            if loc.truth is not None:
                title += (
                    f", {loc.truth.rotation_error_deg:.2f}° / {loc.truth.translation_error_mm:.2f} mm from the truth"
                )
            written.append(
                viz.save_cloud(
                    out / "cloud.png",
                    scan.points,
                    model=model,
                    T_base_object=loc.T_base_object,
                    highlight=loc.indices,
                    bin_bounds=bin_bounds,
                    title=title,
                )
            )
        else:
            written.append(
                viz.save_cloud(
                    out / "cloud.png", scan.points, bin_bounds=bin_bounds, title=f"{len(scan.points)} points"
                )
            )
    if report.records:
        title = f"{_succeeded(report)}; {_removed_text(report)}"
        written.append(viz.save_pick_summary(out / "summary.png", report.records, title=title))
    written += _failure_pictures(out, report, model, bin_bounds)
    (out / "picks.json").write_text(
        json.dumps(
            {
                "picks": [r.as_dict() for r in report.records],
                "stopped": report.stopped,
                "removed": None if report.removed is None else list(report.removed),
                "lifted": list(report.lifted),
            },
            indent=1,
        )
    )
    written.append(out / "picks.json")
    return written


def _succeeded(report: Any) -> str:
    """``K of N picks succeeded``: the attempt that found the bin empty is not counted a pick."""
    picks = sum(not r.bin_empty for r in report.records)
    return f"{report.successes} of {picks} picks succeeded"


def outcome_line(report: Any, seconds: float) -> str:
    """The last line of a run: the picks that succeeded, and how the run ended (the bin emptied,
    or where and why it stopped)."""
    text = f"{_succeeded(report)} in {seconds:.1f} s"
    if report.bin_empty:
        return f"{text}; then {bin_empty_text(report)}"
    if report.stopped and report.records:
        last = report.records[-1]
        text += f"; stopped at pick {last.index} ({last.failure or 'see above'})"
    return text


def run_keeping_picks(cell: Any, picks: int) -> tuple[Any, bool]:
    """``cell.run(picks)``'s report, and whether Ctrl-C cut the run short: then the report holds
    the picks finished before it (:class:`binpick.RunInterrupted`), for the caller to write."""
    from .errors import RunInterrupted

    try:
        return cell.run(picks), False
    except RunInterrupted as stop:
        return stop.report, True


def interrupted(command: str, report: Any, out: Path) -> int:
    """Says that Ctrl-C stopped ``binpick COMMAND`` and where the picks finished were written;
    returns 130, the exit status of a command Ctrl-C stopped."""
    print(
        f"binpick {command}: interrupted (Ctrl-C) after {_plural(len(report.records), 'finished pick')}; "
        f"their records are in {out / 'picks.json'}",
        file=sys.stderr,
    )
    return 130
