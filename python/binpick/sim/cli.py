"""``binpick simulate``: render a simulated scan of a pile to a scan folder."""

from __future__ import annotations

import argparse
import sys
import time

from .._cli_parts import _model, _Usage, error_text
from ..errors import BinpickError

__all__ = ["simulate_main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="binpick simulate",
        description="Drop parts into the simulated bin, scan the pile with the laser and write a scan folder "
        "(frames/*.png, scan.json, calibration.toml, ground_truth.json, contact_sheet.png).",
    )
    p.add_argument(
        "--part",
        default="tee",
        help="built-in part (tee, elbow, cross, keyed_shaft, …) or a mesh file (STL/PLY/OBJ, mm)",
    )
    p.add_argument("--count", type=int, default=12, help="parts in the pile (default 12)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pile and the sensor noise")
    p.add_argument("--frames", type=int, default=90, help="laser frames across the bin (default 90)")
    p.add_argument("--speckle", type=float, default=0.0, help="laser speckle contrast (0 = none)")
    p.add_argument("--reflections", type=float, default=0.0, help="strength of one-bounce laser reflections (0 = none)")
    p.add_argument("--unit", default="mm", help="unit of a mesh file (mm, cm, m, in)")
    p.add_argument("--out", required=True, help="output folder")
    return p


def simulate_main(argv: list[str]) -> int:
    """Runs ``binpick simulate`` with ``argv`` (without the program name); returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        from dataclasses import replace

        from .cell import Cell
        from .dataset import simulate_scan, write_scan

        model = _model(args.part, args.unit)
        cell = Cell()
        cell = replace(cell, noise=replace(cell.noise, speckle=args.speckle, reflections=args.reflections))
        t0 = time.perf_counter()
        scan = simulate_scan(model, args.count, seed=args.seed, frames=args.frames, cell=cell)
        t1 = time.perf_counter()
        root = write_scan(scan, args.out)
        t2 = time.perf_counter()
    except (_Usage, BinpickError) as exc:
        print(f"binpick simulate: {error_text(exc)}", file=sys.stderr)
        return 2
    print(
        f"{len(scan.pile)} {args.part} parts, {len(scan.frames)} frames "
        f"rendered in {t1 - t0:.1f} s, written to {root} in {t2 - t1:.1f} s"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(simulate_main(sys.argv[1:]))
