"""The figures of a validation run (:func:`binpick.validate`) from its cycle and pile records,
how they are defined, the table the command prints, ``report.json`` and ``summary.png``.

Definitions (over the run's cycles: pick attempts; the look that finds a bin empty is none):

* success rate — cycles whose outcome is ``picked`` (the part lifted out, the located one, its
  pose pick-grade or the grasp one of the cell's on the part as it truly lay, nothing touched on
  the way) over all cycles, with the Wilson score interval at 95 % (:func:`wilson`);
* picked off pose — picks whose located pose was not pick-grade, but off by a turn or a slide
  the grasp does not care about (:func:`binpick.cell.records.grasp_fits_truth`);
* bins emptied — piles whose every part was picked out of the bin (a part a push threw out of it,
  ``parts_lost``, is neither removed nor does its bin count as emptied);
* looks and nudges per cycle — the scans and the pushes of the closed gripper a cycle took, on average;
* failures by kind — the cycles of each :data:`binpick.cell.FAILURE_KINDS`;
* cycle time — each cycle's physical ``cycle_time_s`` (:func:`binpick.cell.records.cycle_stages_s`:
  the hardware's time on the simulated cell's clock and binpick's compute): mean, median, 90th
  percentile, and each stage's mean;
* picks per hour — :func:`binpick.cell.records.picks_per_hour`: 3600 × picked cycles / the sum of
  every cycle's time, failed ones included: the rate parts come out of the bin;
* CPU per cycle — the workers' CPU time per cycle (``cpu_s``; binpick's own: ``binpick_cpu_s``);
* cycles per core-hour — cycles / the workers' whole CPU time (each pile's, setup and last
  look included) × 3600.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .._validate import write_atomic
from ..errors import InvalidInputError

__all__ = ["Z95", "ValidationReport", "stage_text", "summarize", "table", "wilson"]

#: The standard normal quantile of a two-sided 95 % interval.
Z95 = 1.959963984540054


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate ``successes / n`` (``z`` = 1.96: 95 %); (0, 1) for n = 0."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # All or none: the bound is 0 or 1 exactly (the formula's, but for rounding).
    return 0.0 if successes == 0 else centre - half, 1.0 if successes == n else centre + half


def stage_text(stages: Mapping[str, float]) -> str:
    """A cycle's stages as a line: ``scan move 0.5 s, sweep 2.4 s, compute 0.3 s, …``."""
    names = {"scan.move": "scan move", "scan.sweep": "sweep", "motion": "pick motion"}
    return ", ".join(f"{names.get(k, k)} {v:.2f} s" for k, v in stages.items() if v > 0.0005)


def summarize(
    records: Sequence[Mapping[str, Any]],
    piles: Sequence[Mapping[str, Any]],
    settings: Optional[Mapping[str, Any]] = None,
    pictures: Optional[Mapping[str, Mapping[str, Any]]] = None,
    run: Optional[Mapping[str, Any]] = None,
) -> dict:
    """The report's figures (``report.json``; definitions in the module docstring)."""
    from ..cell.records import CYCLE_STAGES, FAILURE_KINDS, picks_per_hour

    n = len(records)
    picked = sum(r["outcome"] == "picked" for r in records)
    lo, hi = wilson(picked, n)
    times = np.array([r["cycle_time_s"] for r in records if r.get("cycle_time_s") is not None], dtype=np.float64)
    pile_cpu = sum(float(p["cpu_s"]) for p in piles)
    kinds = [k for k in FAILURE_KINDS if any(r["outcome"] == k for r in records)]
    kinds += sorted({r["outcome"] for r in records} - set(FAILURE_KINDS) - {"picked"})
    return {
        "part": None if settings is None else settings.get("part"),
        "piles": len(piles),
        "cycles": n,
        "picked": picked,
        "success_rate": picked / n if n else None,
        "success_rate_95": [lo, hi],
        "interval": "Wilson score, 95 %",
        "bins_emptied": sum(bool(p["emptied"]) for p in piles),
        "parts_dropped": sum(int(p["dropped"]) for p in piles),
        "parts_removed": sum(int(p["removed"]) for p in piles),
        "parts_lost": sum(int(p.get("lost", 0)) for p in piles),
        "looks_per_cycle": _mean_of(records, "looks"),
        "nudges_per_cycle": _mean_of(records, "nudges"),
        "failures": {k: sum(r["outcome"] == k for r in records) for k in kinds},
        # Picks whose located pose was off the truth (not pick-grade) by a turn or a slide the grasp
        # does not care about: the grasp, on the part as it lay, is one of the cell's.
        "picked_off_pose": sum(r["outcome"] == "picked" and r.get("pick_grade") is False for r in records),
        "failure_pictures": dict(pictures or {}),
        "cycle_time_s": None
        if not len(times)
        else {
            "mean": float(times.mean()),
            "median": float(np.median(times)),
            "p90": float(np.percentile(times, 90)),
            "min": float(times.min()),
            "max": float(times.max()),
        },
        "stage_s_mean": {
            k: float(np.mean([r["stage_s"].get(k, 0.0) for r in records if r.get("stage_s")])) for k in CYCLE_STAGES
        }
        if any(r.get("stage_s") for r in records)
        else None,
        "picks_per_hour": picks_per_hour(picked, times.tolist()),
        "cpu_s_per_cycle": _mean_of(records, "cpu_s"),
        "binpick_cpu_s_per_cycle": _mean_of(records, "binpick_cpu_s"),
        "cpu_s_total": pile_cpu,
        "cycles_per_core_hour": 3600.0 * n / pile_cpu if pile_cpu > 0 else None,
        "emulator_failures": [f for p in piles for f in p.get("emulator_failures", [])],
        "picture_errors": [f for p in piles for f in p.get("picture_errors", [])],
        "measured": "the CPU figures are measurements (they vary with the machine and its load); cycle_time_s and "
        "picks_per_hour are the hardware's time on the simulated cell's clock (decided by the seed) and binpick's "
        "compute as measured (binpick.cell.records.cycle_stages_s)",
        "settings": dict(settings or {}),
        "run": dict(run or {}),
    }


def _mean_of(records: Sequence[Mapping[str, Any]], key: str) -> Optional[float]:
    """The mean of ``key`` over the records that have it, or None."""
    values = [float(r[key]) for r in records if r.get(key) is not None]
    return float(np.mean(values)) if values else None


def table(summary: Mapping[str, Any]) -> str:
    """The short table ``binpick validate`` prints."""
    s = summary
    lines = [f"part {s['part']}: {s['cycles']} cycles over {s['piles']} piles"]
    if s["cycles"]:
        lo, hi = s["success_rate_95"]
        lines.append(
            f"  success rate      {s['success_rate']:.1%} ({s['picked']} of {s['cycles']}; "
            f"95 % interval {lo:.1%}-{hi:.1%})"
        )
    lost = f"; {s['parts_lost']} thrown out of the bin by a push" if s.get("parts_lost") else ""
    lines.append(
        f"  bins emptied      {s['bins_emptied']} of {s['piles']} "
        f"({s['parts_removed']} of {s['parts_dropped']} parts removed{lost})"
    )
    if s.get("looks_per_cycle") is not None and s.get("nudges_per_cycle") is not None:
        lines.append(f"  per cycle         {s['looks_per_cycle']:.2f} looks, {s['nudges_per_cycle']:.2f} nudges")
    if s.get("picked_off_pose"):
        lines.append(
            f"  picked off pose   {s['picked_off_pose']} (not pick-grade; the grasp one of the cell's on the truth)"
        )
    for kind, k in s["failures"].items():
        pic = s["failure_pictures"].get(kind)
        where = f"  (picture: {pic['file']}, seed {pic['seed']} cycle {pic['cycle']})" if pic else ""
        lines.append(f"  {kind:<17} {k} ({k / s['cycles']:.1%}){where}")
    if s["cycle_time_s"]:
        c = s["cycle_time_s"]
        lines.append(f"  cycle time        median {c['median']:.1f} s, p90 {c['p90']:.1f} s, mean {c['mean']:.1f} s")
        if s.get("stage_s_mean"):
            lines.append("    of which         " + stage_text(s["stage_s_mean"]))
    if s["picks_per_hour"] is not None:
        lines.append(f"  picks per hour    {s['picks_per_hour']:.0f}")
    if s["cpu_s_per_cycle"] is not None:
        lines.append(
            f"  CPU per cycle     {s['cpu_s_per_cycle']:.2f} s (binpick's own {s['binpick_cpu_s_per_cycle']:.2f} s); "
            f"{s['cycles_per_core_hour']:.0f} cycles per core-hour"
        )
    run = s.get("run") or {}
    if run.get("cycles_run"):
        rate = 3600.0 * run["cycles_run"] / run["wall_s"] if run.get("wall_s") else 0.0
        here = run.get("cpu_s_here")
        lines.append(
            f"  this run          {run['cycles_run']} cycles in {run['wall_s']:.0f} s on {run['backend']} "
            f"({rate:.0f} cycles/h"
            + ("" if not here else f"; {3600.0 * run['cycles_run'] / here:.0f} cycles per core-hour, start-up included")
            + ")"
        )
    return "\n".join(lines)


@dataclass(frozen=True)
class ValidationReport:
    """What :func:`binpick.validate` found: the cycle records (``records``: dicts as in
    ``records.jsonl``), the pile records, the figures (``summary``: as in ``report.json``) and the
    files written (name → path)."""

    records: tuple[dict, ...]
    piles: tuple[dict, ...]
    summary: dict
    files: dict = field(default_factory=dict)

    @property
    def success_rate(self) -> Optional[float]:
        """Picked cycles over cycles (None without cycles)."""
        return self.summary["success_rate"]

    @property
    def interval(self) -> tuple[float, float]:
        """The success rate's 95 % Wilson interval."""
        lo, hi = self.summary["success_rate_95"]
        return lo, hi

    def __repr__(self) -> str:
        s = self.summary
        rate = "n/a" if s["success_rate"] is None else f"{s['success_rate']:.3f}"
        return (
            f"ValidationReport(cycles={s['cycles']}, piles={s['piles']}, success_rate={rate}, interval={self.interval})"
        )


def write(
    root: Optional[Path], summary: dict, records: Sequence[dict], piles: Sequence[dict], *, parquet: bool = False
) -> ValidationReport:
    """Writes ``report.json``, ``summary.png`` and (``parquet``) ``records.parquet`` into ``root``
    (nothing when None); the report."""
    files: dict[str, Path] = {}
    if root is not None:
        files["records"] = root / "records.jsonl"
        files["piles"] = root / "piles.jsonl"
        files["report"] = root / "report.json"
        write_atomic(files["report"], json.dumps(summary, indent=1))
        if records:
            files["summary"] = save_summary(root / "summary.png", summary, records)
        if parquet:
            files["parquet"] = write_parquet(root / "records.parquet", records)
        for kind, pic in summary["failure_pictures"].items():
            files[f"failure {kind}"] = root / pic["file"]
    return ValidationReport(tuple(records), tuple(piles), summary, files)


def write_parquet(path: Path, records: Sequence[dict]) -> Path:
    """The cycle records as a Parquet table (pyarrow; nested fields as lists and structs)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        error = InvalidInputError('parquet: writing Parquet needs pyarrow: pip install "binpick[parquet]"')
        error.cli_message = '--parquet: writing Parquet needs pyarrow: pip install "binpick[parquet]"'
        raise error from None
    pq.write_table(pa.Table.from_pylist(list(records)), path)
    return path


def save_summary(path: Path, summary: Mapping[str, Any], records: Sequence[Mapping[str, Any]]) -> Path:
    """``summary.png``: the distribution of cycle times (picked and failed cycles stacked) and the
    failures by kind."""
    from ..viz import _pyplot, _save

    plt = _pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 4.6), gridspec_kw={"width_ratios": [3, 2]})
    ok = [r["cycle_time_s"] for r in records if r["outcome"] == "picked" and r.get("cycle_time_s") is not None]
    bad = [r["cycle_time_s"] for r in records if r["outcome"] != "picked" and r.get("cycle_time_s") is not None]
    if ok or bad:
        left.hist([ok, bad], bins=30, stacked=True, color=["tab:green", "tab:red"], label=["picked", "failed"])
        c = summary["cycle_time_s"]
        left.axvline(c["median"], color="k", linestyle="--", linewidth=0.8, label=f"median {c['median']:.1f} s")
        left.axvline(c["p90"], color="k", linestyle=":", linewidth=0.8, label=f"p90 {c['p90']:.1f} s")
        left.legend(fontsize=8)
    left.set_xlabel("physical cycle time, s (the cell's hardware clock and binpick's compute)")
    left.set_ylabel("cycles")
    pph = summary["picks_per_hour"]
    left.set_title("cycle time" + ("" if pph is None else f" — {pph:.0f} picks per hour"))
    kinds = list(summary["failures"])
    if kinds:
        counts = [summary["failures"][k] for k in kinds]
        right.barh(kinds[::-1], counts[::-1], color="tab:red")
        right.set_xlabel("cycles")
    else:
        right.text(0.5, 0.5, "no failures", ha="center", va="center", transform=right.transAxes)
        right.set_xticks([])
        right.set_yticks([])
    right.set_title("failures by kind")
    lo, hi = summary["success_rate_95"]
    fig.suptitle(
        f"{summary['part']}: {summary['success_rate']:.1%} of {summary['cycles']} cycles picked "
        f"(95 % interval {lo:.1%}-{hi:.1%}), {summary['bins_emptied']} of {summary['piles']} bins emptied"
    )
    fig.tight_layout()
    return _save(fig, path)
