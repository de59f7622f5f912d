"""``binpick validate PART``: the share of picks that succeed for a part and a gripper, and
picks per hour, from seeded pick cycles over many simulated piles (:func:`binpick.validate`),
in worker processes here or on Ray."""

from __future__ import annotations

import argparse
import re
import sys
from typing import Any

from ._cli_parts import _model, _Usage


def _validate(args: argparse.Namespace) -> int:
    from .sim.validate import validate
    from .sim.validate_report import table

    model = _model(args.part, args.unit, "PART")
    options = {}
    if args.d_star is not None:
        options["d_star"] = args.d_star
    if args.min_points is not None:
        options["min_points"] = args.min_points
    try:
        report = validate(
            model,
            seeds=args.seeds,
            first_seed=args.first_seed,
            cycles=args.cycles,
            count=_count_range(args.count),
            frames=args.frames,
            cell=args.cell,
            estimate_options=options,
            out=args.out,
            workers=args.workers,
            ray=args.ray,
            parquet=args.parquet,
            progress=lambda line: print(line, flush=True),
        )
    except KeyboardInterrupt:
        print(
            f"binpick validate: interrupted; the piles finished are in {args.out}/records.jsonl, "
            "and the same command resumes the run",
            file=sys.stderr,
        )
        return 130
    print()
    print(table(report.summary))
    for name in ("records", "report", "summary", "parquet"):
        if name in report.files:
            print(f"wrote {report.files[name]}")
    failures = report.summary["emulator_failures"]
    if failures:
        print("emulator failures (a bug): " + "; ".join(failures[:5]), file=sys.stderr)
    missing = report.summary["picture_errors"]
    if missing:
        print("failure pictures not drawn (a bug): " + "; ".join(missing[:5]), file=sys.stderr)
    return 0


def _count_range(text: str) -> tuple[int, int]:
    """``--count A-B`` (or ``N``) as (A, B)."""
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", text)
    if not m:
        raise _Usage(f"--count: expected parts per pile as A-B or N (e.g. 8-12), got {text!r:.40}")
    lo = int(m.group(1))
    return lo, int(m.group(2)) if m.group(2) is not None else lo


def _add_validate(sub: Any) -> None:
    """``binpick validate``."""
    v = sub.add_parser(
        "validate",
        help="the success rate and picks per hour of a part over many simulated piles",
        description="Runs seeded pick cycles of a part over many simulated piles (the whole simulated cell, "
        "one pile per worker process, or on Ray) and reports the success rate with its 95 % interval, bins "
        "emptied, failures by kind with a picture of each, the cycle time and picks per hour. Writes "
        "OUT/records.jsonl (a line per cycle), OUT/piles.jsonl, OUT/report.json and OUT/summary.png as piles "
        "finish: run the same command again to resume a run that was stopped.",
    )
    v.add_argument(
        "part",
        metavar="PART",
        help="built-in part (tee, elbow, cross, or a near-symmetric part such as keyed_shaft) or a mesh file",
    )
    v.add_argument("--unit", default="mm", help="unit of a mesh file (mm, cm, m, in)")
    n = v.add_mutually_exclusive_group()
    n.add_argument("--seeds", type=int, default=None, help="piles to run, one seed each (default 10)")
    n.add_argument(
        "--cycles", type=int, default=None, help="run piles in seed order until this many pick cycles are done"
    )
    v.add_argument("--first-seed", type=int, default=0, help="the first pile's seed (default 0)")
    v.add_argument("--count", default="8-12", help="parts per pile, A-B: each seed's pile gets one size (default 8-12)")
    v.add_argument("--frames", type=int, default=None, help="laser frames per scan (default: the cell file's, else 90)")
    v.add_argument(
        "--cell",
        default=None,
        metavar="CELL.toml",
        help="a cell file whose frames, sweep, rescan, plan_ahead, [estimate], gripper, tool and [limits] speeds "
        "are used (the bin, camera and arm stay simulated)",
    )
    v.add_argument("--d-star", type=float, default=None, help="segmentation distance d* (mm); default: the estimator's")
    v.add_argument(
        "--min-points", type=int, default=None, help="fewest points of a part region; default: the estimator's"
    )
    v.add_argument(
        "--workers", type=int, default=None, help="piles run at a time (default: the cores; with --ray: its CPUs)"
    )
    v.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="run on Ray: alone, a local Ray instance; with ADDRESS (host:port), that cluster "
        '(pip install "binpick[ray]")',
    )
    v.add_argument("--out", default="binpick-validate", help="the run's folder (default ./binpick-validate)")
    v.add_argument("--parquet", action="store_true", help="also write OUT/records.parquet (needs pyarrow)")
    v.set_defaults(run=_validate)
