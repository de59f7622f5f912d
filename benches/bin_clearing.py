"""Issue 14's measurement: the simulated cell empties piles of 8-12 parts.

Per part (tee, elbow, cross, the near-symmetric parts of ``binpick.parts.NEAR_SYMMETRIC`` and
``MORE_NEAR_SYMMETRIC`` (issue 39), and the real CAD parts of ../shared/data/parts in metres where
present; ``--parts`` picks some), seeds × piles: parts removed per pile, bins emptied, wrong-pose lifts (judged modulo
the part's symmetries by the cell), grasps on nothing (the gripper closed empty), gripper-floor
contacts (executed plans whose gripper outline reaches the bin floor), time per cycle by stage
(ms), and the process CPU time per pick (it includes the simulator's renderer and emulators,
which run in the same process, so it bounds binpick's own compute from above), and binpick's
own CPU time per cycle by stage (extraction, pose, planning). Everything runs on one thread
unless ``--threads`` says otherwise, so that binpick's compute is measured on one core; run
two benches at a time on a two-core machine, not more.

    PYTHONPATH=python python benches/bin_clearing.py --quick
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import binpick
from binpick.sim import SimulatedCell

PARTS_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "parts"
CAD = ("IPAGearShaft.stl", "IPARingScrew.stl")
ESTIMATE: dict = {}  # the library's defaults, as `binpick demo` runs
STAGES = ("scan.move", "scan.sweep", "scan.extract", "locate+plan", "motion", "total")
CPU = ("scan.cpu.extract", "cpu.pose", "cpu.plan")  # binpick's own compute per cycle (ms)


def _parts(quick: bool) -> list:
    parts = [("tee", binpick.parts.tee), ("elbow", binpick.parts.elbow), ("cross", binpick.parts.cross)]
    # The near-symmetric parts (issue 39): picked with grasps the same on every pose the scan
    # cannot rule out.
    parts += list(binpick.parts.NEAR_SYMMETRIC.items()) + list(binpick.parts.MORE_NEAR_SYMMETRIC.items())
    for name in CAD[:1] if quick else CAD:
        path = PARTS_DIR / name
        if path.exists():
            parts.append((path.stem, lambda p=path: binpick.Model.from_mesh(p, unit="m")))
        else:
            print(f"skipped {name}: not found in {PARTS_DIR}")
    return parts


def _lowest_above_floor(gripper, floor: float, poses, opening=None) -> float:
    """The lowest point of the gripper's outline, its fingers ``opening`` apart (fully open by
    default), over the flange poses ``poses``, above the floor (mm)."""
    return (
        min(
            float(
                (
                    (gripper.outline(opening) @ (T @ gripper.T_flange_gripper)[:3, :3].T)
                    + (T @ gripper.T_flange_gripper)[:3, 3]
                )[:, 2].min()
            )
            for T in poses
        )
        - floor
    )


def _floor_gap(sim) -> list:
    """Wraps the cell's plan check to record, per executed plan, the lowest gripper point above the floor (mm)."""
    cell, gaps = sim.cell, []
    check = cell.check_plan
    gripper, floor = cell.config.gripper, float(cell.config.bin_bounds[0][2])

    def recording(plan):
        moves = check(plan)
        gaps.append(
            _lowest_above_floor(
                gripper,
                floor,
                [T for name, (T, _) in moves.items() if name in ("approach", "grasp", "lift")],
                cell.finger_opening(plan),
            )
        )
        return moves

    cell.check_plan = recording
    return gaps


def run_pile(make, seed: int, count: int, frames: int, threads: int = 1, orientation_needed: bool = False) -> dict:
    with SimulatedCell(
        make(),
        count=count,
        seed=seed,
        frames=frames,
        estimate_options=ESTIMATE,
        num_threads=threads,
        orientation_needed=orientation_needed,
    ) as sim:
        gaps = _floor_gap(sim)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        report = sim.cell.run(count + 2)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        left = len(sim.pile.ids)
    recs = report.records
    cfg = sim.cell.config
    nudge_gaps = [
        _lowest_above_floor(cfg.gripper, float(cfg.bin_bounds[0][2]), [T for _, T, _ in n.waypoints[1:]])
        for r in recs
        for n in r.nudges
    ]
    return {
        "seed": seed,
        "count": count,
        "removed": count - left,
        "emptied": left == 0,
        "wrong_pose": sum(r.failure == "wrong pose" for r in recs),
        "empty_grip": sum(r.failure == "empty grip" for r in recs),
        "floor_contacts": sum(g <= 0.0 for g in gaps + nudge_gaps),
        # Contacts of the gripper with another part or the bin, as the simulator's physics saw them.
        "collisions": [c["with"] for r in recs for c in r.collisions],
        "nudges": len(nudge_gaps),
        "cycles": len(recs),
        "stages_ms": {s: float(np.mean([r.timings.get(s, 0.0) for r in recs])) for s in STAGES + CPU},
        "looks": sum(r.looks for r in recs),
        # Parts lifted whose orientation the scan left open (picked with a grasp the same on every alternative).
        "orientation_open": sum(r.success and r.orientation_decided is False for r in recs),
        "orientation_undecided_skips": sum(s.reason == "orientation undecided" for r in recs for s in r.skipped),
        "skipped": sum(len(r.skipped) for r in recs),
        "cpu_s_per_pick": cpu / max(1, len(recs)),
        # Measuring each grasp's finger opening, once per grasp and part (not per pick), ms.
        "grasp_widths_ms": float(sum(r.timings.get("cpu.grasp_widths", 0.0) for r in recs)),
        "wall_s": wall,
        "stopped": report.stopped,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed, piles of 8, 45 frames: a smoke run")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0, help="run seeds first-seed .. first-seed + seeds - 1")
    ap.add_argument("--parts", default="", help="comma-separated part names to run (default: all)")
    ap.add_argument("--frames", type=int, default=0, help="laser frames per scan (default: 45 quick, 90 full)")
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="threads for rendering and binpick (default 1: binpick's compute is measured on one core)",
    )
    ap.add_argument(
        "--orientation-needed",
        action="store_true",
        help="the cell places parts by their orientation: undecided poses are not picked (orientation_needed)",
    )
    ap.add_argument("--out", default="bin_clearing.json")
    args = ap.parse_args()
    seeds = range(1) if args.quick else range(args.first_seed, args.first_seed + args.seeds)
    frames = args.frames or (45 if args.quick else 90)
    wanted = {p for p in args.parts.split(",") if p}
    rows = {}
    for name, make in _parts(args.quick):
        if wanted and name not in wanted:
            continue
        piles = []
        for s in seeds:
            count = 8 if args.quick else 8 + s % 5
            piles.append(run_pile(make, s, count, frames, args.threads, args.orientation_needed))
            p = piles[-1]
            print(
                f"{name} seed {s}: removed {p['removed']}/{p['count']} in {p['cycles']} cycles, stopped: {p['stopped']}"
            )
        rows[name] = piles
    print(
        f"\n{'part':<14}{'removed':>9}{'emptied':>9}{'wrong':>7}{'empty':>7}{'floor':>7}"
        f"{'nudges':>8}{'scan ms':>9}{'loc+plan':>9}{'motion':>8}{'cpu s/pick':>11}"
        f"{'extract':>9}{'pose':>7}{'plan':>7}  (binpick's own CPU ms per cycle){'widths':>8}"
    )
    print("  (cpu s/pick: the whole process, the simulator's rendering and physics included; widths: ms per pile)")
    for name, piles in rows.items():
        n = sum(p["count"] for p in piles)
        print(
            f"{name:<14}{sum(p['removed'] for p in piles) / n:>8.0%} "
            f"{sum(p['emptied'] for p in piles):>4}/{len(piles):<3}"
            f"{sum(p['wrong_pose'] for p in piles):>7}{sum(p['empty_grip'] for p in piles):>7}"
            f"{sum(p['floor_contacts'] for p in piles):>7}{sum(p.get('nudges', 0) for p in piles):>8}"
            f"{np.mean([sum(p['stages_ms'][s] for s in STAGES[:3]) for p in piles]):>9.0f}"
            f"{np.mean([p['stages_ms']['locate+plan'] for p in piles]):>9.0f}"
            f"{np.mean([p['stages_ms']['motion'] for p in piles]):>8.0f}"
            f"{np.mean([p['cpu_s_per_pick'] for p in piles]):>11.2f}"
            + "".join(f"{np.mean([p['stages_ms'][s] for p in piles]):>{w}.0f}" for s, w in zip(CPU, (9, 7, 7)))
            + f"{'':>34}{np.mean([p.get('grasp_widths_ms', 0.0) for p in piles]):>8.0f}"
        )
    Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
