"""The ``binpick`` command.

    binpick demo       the whole simulated cell: a pile of parts, emulated robot, laser motor and
                       gripper on ptys, scan, locate, pick; pictures into --out
    binpick pick       the real cell from a cell file (TOML); --dry-run scans and locates only
    binpick simulate   render a simulated scan to a scan folder
    binpick emulate    serve one emulated device on a pty
    binpick estimate   a scene (PLY/PCD/NPY/XYZ cloud or a scan folder) and a part model → pose as JSON
                       and a picture
    binpick reconstruct  a scan folder → a scene cloud file (PLY/PCD/XYZ/NPY)
    binpick calibrate  camera intrinsics from a folder of checkerboard images
    binpick validate   the success rate and picks per hour of a part over many simulated piles
    binpick bench      run the benchmarks of a source checkout

Exit codes: 0 done, 1 failed (the message says why), 2 bad usage or input (checkerboard images that
cannot give intrinsics to trust included: ``binpick calibrate`` names each cause and its flag).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional

from ._cli_calibrate import _add_calibrate
from ._cli_parts import _existing, _model, _Usage, collision_exit, error_text, run_bench
from ._cli_report import _pictures, _print_table, interrupted, outcome_line, run_keeping_picks
from ._cli_validate import _add_validate
from .errors import BinpickError, InvalidInputError, NoObjectFound
from .parts import BUILT_IN

__all__ = ["main"]


# --------------------------------------------------------------------------- demo


def _demo(args: argparse.Namespace) -> int:
    from .cell import ProgressPrinter
    from .sim import SimulatedCell

    if args.picks < 1 or args.count < 1 or args.frames < 2:
        raise _Usage("--picks and --count must be at least 1, --frames at least 2")
    out = Path(args.out)
    t0 = time.perf_counter()
    model = _model(args.part, args.unit)
    progress = ProgressPrinter()
    progress(
        "demo",
        f"{args.count} {model.name} parts, {args.picks} picks, {args.frames} "
        f"frames per scan, seed {args.seed}, pictures into {out}",
    )
    with SimulatedCell(
        model,
        count=args.count,
        seed=args.seed,
        frames=args.frames,
        progress=progress,
        estimate_options=_estimate_options(args),
    ) as sim:
        bin_bounds = sim.cell.config.bin_bounds
        report, stopped_by_user = run_keeping_picks(sim.cell, args.picks)
        failures = sim.emulator_failures
    written = _pictures(out, report, model, bin_bounds)
    print()
    _print_table(report)
    print()
    for p in written:
        print(f"wrote {p}")
    if failures:
        print("emulator failures (a bug): " + "; ".join(failures), file=sys.stderr)
    if stopped_by_user:
        return interrupted("demo", report, out)
    picked = report.successes
    print(outcome_line(report, time.perf_counter() - t0))
    if picked == 0:
        print(
            "binpick demo: no part was picked — " + (report.stopped or "every pick failed (see the table)"),
            file=sys.stderr,
        )
        return collision_exit(report, "demo") or 1
    return collision_exit(report, "demo") or 0


def _estimate_options(args: argparse.Namespace) -> dict:
    opts = {}
    if getattr(args, "d_star", None) is not None:
        opts["d_star"] = args.d_star
    if getattr(args, "min_points", None) is not None:
        opts["min_points"] = args.min_points
    return opts


# --------------------------------------------------------------------------- pick


def _pick(args: argparse.Namespace) -> int:
    from .cell import CELL_FILE_EXAMPLE, ProgressPrinter, cell_from_file, load_cell_file

    if args.example:
        print(CELL_FILE_EXAMPLE, end="")
        return 0
    if not args.config:
        raise _Usage("give the cell file: binpick pick CELL.toml (binpick pick --example prints one)")
    if args.picks < 1:
        raise _Usage("--picks must be at least 1")
    t0 = time.perf_counter()
    progress = ProgressPrinter()
    cell = cell_from_file(load_cell_file(args.config), progress=progress)
    out = Path(args.out)
    recorder = None
    if args.save_scans:
        from .cell import ScanRecorder

        recorder = cell.camera = ScanRecorder(cell.camera, cell.config.calibration, out / "scans")
    with cell:
        if args.dry_run:
            return _dry_run(cell, out)
        report, stopped_by_user = run_keeping_picks(cell, args.picks)
    written = _pictures(out, report, cell.config.model, cell.config.bin_bounds)
    _print_table(report)
    for p in written + ([] if recorder is None else recorder.saved):
        print(f"wrote {p}")
    if stopped_by_user:
        return interrupted("pick", report, out)
    print(outcome_line(report, time.perf_counter() - t0))
    if report.successes == 0:
        print("binpick pick: no part was picked — " + (report.stopped or "see the table"), file=sys.stderr)
        return collision_exit(report, "pick") or 1
    return collision_exit(report, "pick") or 0


def _dry_run(cell: Any, out: Path) -> int:
    """``binpick pick --dry-run``: scan and locate once, write the pictures, print the pose."""
    from .cell import RunReport

    scan = cell.scan()
    try:
        located = cell.locate(scan)
    except BinpickError as exc:
        report = RunReport(records=(), stopped=str(exc), last_scan=scan)
        _pictures(out, report, cell.config.model, cell.config.bin_bounds)
        print(f"binpick pick --dry-run: {exc}", file=sys.stderr)
        return 1
    report = RunReport(records=(), stopped="dry run", last_scan=scan, last_located=located)
    written = _pictures(out, report, cell.config.model, cell.config.bin_bounds)
    pose = located.T_base_object
    print(
        json.dumps(
            {
                "T_base_object": pose.round(4).tolist(),
                "score": located.result.score,
                "rmse_mm": located.result.rmse,
                "points": len(scan.points),
            },
            indent=1,
        )
    )
    for p in written:
        print(f"wrote {p}")
    return 0


# --------------------------------------------------------------------------- estimate


def _scan_folder(path: str) -> bool:
    """Whether ``path`` is a scan folder (a folder, and not a ROS 2 bag's)."""
    from .ros import is_rosbag

    return os.path.isdir(path) and not is_rosbag(path)


def _read_scene(path: str, unit: Optional[str] = None) -> tuple[Any, Any, Optional[str]]:
    """The scene cloud (N, 3) mm of ``path`` — a scene file (PLY, PCD, NPY, XYZ, a ROS 2 bag) or a scan folder,
    reconstructed — the sensor's position in its frame where the file or the scan says it, and the unit
    the file was read in (None for a scan folder, reconstructed in mm by its calibration)."""
    from .clouds import read_scene

    if _scan_folder(path):
        if unit is not None:
            raise _Usage("--scene-unit: a scan folder is reconstructed in mm; leave the option out")
        scan = _load_scan_folder(path)  # the camera where its first frame was grabbed: the viewpoint
        return _reconstruct(scan).points, (scan.T_base_flanges[0] @ scan.calibration.T_flange_camera)[:3, 3], None
    cloud = read_scene(path, unit=unit)
    return cloud.points, cloud.viewpoint, unit or cloud.file_unit or "mm"


def _load_scan_folder(folder: str) -> Any:
    """The scan of the scan folder ``folder``."""
    from .scan import load_scan

    if not os.path.isfile(os.path.join(folder, "scan.json")):
        raise _Usage(f"{folder} is a folder without scan.json; give a scan folder or a scene file")
    return load_scan(folder)


def _reconstruct(scan: Any) -> Any:
    """The cloud of ``scan`` (binpick.vision.reconstruct)."""
    from .vision import reconstruct

    return reconstruct(scan)


def _reconstruct_command(args: argparse.Namespace) -> int:
    from .clouds import write_scene

    _existing(args.scan, "SCAN_DIR", "scan folder", folder=True, fix="binpick simulate writes one")
    t0 = time.perf_counter()
    cloud = _reconstruct(_load_scan_folder(args.scan))
    out = write_scene(args.out, cloud.points)
    print(f"wrote {out}: {len(cloud)} points in {time.perf_counter() - t0:.1f} s")
    return 0


def _estimate(args: argparse.Namespace) -> int:
    from . import _sizes, viz
    from .poses import estimate_poses

    scene, stated, scene_unit = _read_scene(args.scene, args.scene_unit)
    model = _model(args.model, args.unit, "MODEL")
    if scene_unit is not None:  # a scene file: its size against the part's, before any work (binpick._sizes)
        _sizes.check_scene(scene, model, unit=scene_unit)
    bin_box = None if args.bin is None else (tuple(args.bin[:3]), tuple(args.bin[3:]))
    viewpoint = _viewpoint_option(args, stated)
    # A scan folder is a swept laser scan: judged along up, as the cell asks (binpick.cell).
    swept = _scan_folder(args.scene) and args.viewpoint is None and not args.camera_frame
    found = estimate_poses(
        scene,
        model,
        bin=bin_box,
        method=args.method,
        max_instances=args.instances,
        viewpoint=viewpoint,
        along_rays=not swept,
        up=None if args.up is None else tuple(args.up),
        noise_mm=args.noise_mm,
        **_estimate_options(args),
    )
    noise, source = _judge_noise(scene, args, viewpoint, along_rays=not swept)
    docs = [
        {
            "T_scene_model": r.T_scene_model.tolist(),
            "confidence": r.confidence,
            "confidence_any": r.confidence_any,
            "ambiguous": r.ambiguous,
            "alternatives": [a.T_scene_model.tolist() for a in r.alternatives],
            "free_axis": None if r.free_axis is None else [float(v) for v in r.free_axis],
            "score": r.score,
            "rmse_mm": r.rmse,
            "fit": r.fit,
            "noise_mm": noise,
            "noise_source": source,
            "points": int(len(r.indices)),
            "method": r.method,
            "pickability": r.pickability,
            "viewpoint": None if viewpoint is None else [float(v) for v in viewpoint],
            "timings_ms": {k: float(v) for k, v in r.timings.items()},
        }
        for r in found
    ]
    print(json.dumps(docs[0] if args.instances == 1 else docs, indent=1))
    png = viz.save_instances(
        Path(args.png),
        scene,
        model,
        [r.T_scene_model for r in found],
        labels=[_instance_label(r) for r in found],
        highlights=[r.indices for r in found],
        bin_bounds=bin_box,
        title=f"{model.name}: {len(found)} of {args.instances} instances asked for found; "
        f"1: score {found[0].score:.2f}, rmse {found[0].rmse:.2f} mm",
    )
    print(f"wrote {png}", file=sys.stderr)
    return 0


def _instance_label(r: Any) -> str:
    """An instance's legend entry in estimate's picture: its confidence and whether it is ambiguous."""
    n = len(r.alternatives)
    alternatives = f" ({n} alternative{'s' if n != 1 else ''})" if n else ""
    return f"confidence {r.confidence:.2f}" + (f", ambiguous{alternatives}" if r.ambiguous else ", decided")


def _judge_noise(scene: Any, args: argparse.Namespace, viewpoint: Any, *, along_rays: bool) -> tuple[Any, str]:
    """The sensor's depth noise σ (mm) every tolerance of the estimate's judge derived from, and
    where it came from: ``--noise-mm``, else read from the scan as the judge reads it
    (:func:`binpick.scan_noise` along the sensor's rays from the viewpoint, else along up); None
    where the scan is too sparse to tell."""
    from .models import scan_noise

    if args.noise_mm is not None:
        return float(args.noise_mm), "declared (--noise-mm)"
    if viewpoint is not None and along_rays:
        return scan_noise(scene, viewpoint=viewpoint), "read from the scan"
    return scan_noise(scene, direction=(0.0, 0.0, 1.0) if args.up is None else tuple(args.up)), "read from the scan"


def _viewpoint_option(args: argparse.Namespace, stated: Any) -> Any:
    """The sensor's position of an estimate: ``--viewpoint``, the camera's origin with
    ``--camera-frame``, or what the scene file or scan states."""
    import numpy as np

    if args.viewpoint is not None and args.camera_frame:
        raise _Usage("--camera-frame puts the sensor at the origin; give it or --viewpoint, not both")
    if args.camera_frame:
        return np.zeros(3)
    if args.viewpoint is not None:
        return np.asarray(args.viewpoint, dtype=np.float64)
    return stated


# --------------------------------------------------------------------------- parser


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    p = argparse.ArgumentParser(prog="binpick", description="Eye-in-hand laser-line bin picking.")
    p.add_argument("--version", action="version", version=f"binpick {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for add in (
        _add_demo,
        _add_pick,
        _add_forwarded,
        _add_estimate,
        _add_reconstruct,
        _add_calibrate,
        _add_validate,
        _add_bench,
    ):
        add(sub)
    return p


def _pose_options(q: argparse.ArgumentParser) -> None:
    """The options of a pose request that the demo and estimate commands share."""
    q.add_argument("--d-star", type=float, default=None, help="segmentation distance d* (mm); default: the estimator's")
    q.add_argument(
        "--min-points", type=int, default=None, help="fewest points of a part region; default: the estimator's"
    )


def _add_demo(sub: Any) -> None:
    """``binpick demo``."""
    d = sub.add_parser(
        "demo",
        help="the whole simulated cell picking parts over emulated serial devices",
        description="Drops a pile of parts into the simulated bin, then scans, locates and picks them with the "
        "real drivers talking to emulated devices on ptys; writes pictures into --out.",
    )
    d.add_argument(
        "--part",
        default="tee",
        help="built-in part (tee, elbow, cross, or a near-symmetric part: "
        + ", ".join(list(BUILT_IN)[3:])
        + ") or a mesh file (default tee)",
    )
    d.add_argument("--unit", default="mm", help="unit of a mesh file (mm, cm, m, in)")
    d.add_argument("--count", type=int, default=12, help="parts in the pile (default 12)")
    d.add_argument("--picks", type=int, default=3, help="picks to attempt (default 3)")
    d.add_argument("--seed", type=int, default=0, help="seed of the pile and the sensor noise (default 0)")
    d.add_argument("--frames", type=int, default=90, help="laser frames per scan (default 90)")
    d.add_argument("--out", default="binpick-demo", help="folder for the pictures (default ./binpick-demo)")
    _pose_options(d)
    d.set_defaults(run=_demo)


def _add_pick(sub: Any) -> None:
    """``binpick pick``."""
    k = sub.add_parser(
        "pick",
        help="pick parts in the real cell described by a cell file",
        description="Connects to the robot, laser motor, gripper and camera of a cell file (TOML) and picks parts.",
    )
    k.add_argument("config", nargs="?", help="the cell file (TOML); `binpick pick --example` prints one")
    k.add_argument("--picks", type=int, default=1, help="picks to attempt (default 1)")
    k.add_argument(
        "--dry-run",
        action="store_true",
        help="only scan and locate: the arm goes to the scan pose, the gripper stays open",
    )
    k.add_argument("--out", default="binpick-pick", help="folder for the pictures (default ./binpick-pick)")
    k.add_argument(
        "--save-scans",
        action="store_true",
        help="also save every sweep's frames, laser angles and robot pose as a scan folder OUT/scans/sweep_NNN "
        '(replay one with [camera] source = "replay", or `binpick reconstruct` it)',
    )
    k.add_argument("--example", action="store_true", help="print an example cell file and exit")
    k.set_defaults(run=_pick)


def _add_forwarded(sub: Any) -> None:
    """``binpick simulate`` and ``binpick emulate``: their own parsers read the rest."""
    s = sub.add_parser(
        "simulate", help="render a simulated scan to a scan folder (see `binpick simulate --help`)", add_help=False
    )
    s.set_defaults(forward="simulate")
    e = sub.add_parser(
        "emulate",
        help="serve an emulated robot, motor or gripper on a pty (see `binpick emulate --help`)",
        add_help=False,
    )
    e.set_defaults(forward="emulate")
    v = sub.add_parser(
        "serve", help="serve the cell's vision to its robot program over TCP (`binpick serve --help`)", add_help=False
    )
    v.set_defaults(forward="serve")


#: The commands whose own parsers read the rest: name -> (module, entry point).
_FORWARDED = {
    "simulate": (".sim.cli", "simulate_main"),
    "emulate": (".devices.cli", "emulate_main"),
    "serve": (".server.cli", "serve_main"),
}


def _add_estimate(sub: Any) -> None:
    """``binpick estimate``."""
    t = sub.add_parser(
        "estimate",
        help="estimate a part's pose in a scene cloud",
        description="Reads a scene (a PLY, PCD, NPY or XYZ cloud, mm, or a scan folder, reconstructed first) "
        "and a part, prints the pose as JSON and writes a picture.",
    )
    t.add_argument("scene", help="scene: a .ply, .pcd, .npy or .xyz cloud (mm) or a scan folder")
    t.add_argument(
        "--scene-unit",
        default=None,
        help="unit of the scene file's coordinates (mm, cm, m, in); default: the unit the file declares, else mm",
    )
    t.add_argument("model", help="built-in part (tee, elbow, cross, keyed_shaft, …) or a mesh file")
    t.add_argument("--unit", default="mm", help="unit of a mesh file (mm, cm, m, in)")
    t.add_argument(
        "--method", default="auto", choices=("auto", "ppf", "ccp", "centroid"), help="coarse pose method (default auto)"
    )
    t.add_argument(
        "--instances",
        type=int,
        default=1,
        help="instances to report, most pickable first (default 1: one JSON object; more: a list)",
    )
    t.add_argument(
        "--bin",
        type=float,
        nargs=6,
        metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
        help="bin box in the scene frame, mm",
    )
    t.add_argument(
        "--viewpoint",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="the sensor's optical centre in the scene frame, mm (default: the one the scene file or scan states)",
    )
    t.add_argument(
        "--camera-frame",
        action="store_true",
        help="the scene is in the camera's own frame (+z forward, away from the camera), as depth cameras "
        "and PCL write it: the sensor is at the origin",
    )
    t.add_argument(
        "--up",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="the direction out of the bin toward the sensor (default +z, or toward the viewpoint when that "
        "lies more than 80 degrees off +z from the scene, as in a camera's own frame)",
    )
    t.add_argument(
        "--noise-mm",
        type=float,
        default=None,
        help="the sensor's depth noise σ, mm (default: read from the scan)",
    )
    t.add_argument("--png", default="estimate.png", help="picture to write (default estimate.png)")
    _pose_options(t)
    t.set_defaults(run=_estimate)


def _add_reconstruct(sub: Any) -> None:
    """``binpick reconstruct``."""
    r = sub.add_parser(
        "reconstruct",
        help="reconstruct a scan folder into a scene cloud file",
        description="Extracts the laser line of every frame of a scan folder, triangulates the points in the "
        "robot's base frame (mm) and writes them as PLY, PCD, XYZ or NPY by the extension of --out.",
    )
    r.add_argument("scan", metavar="SCAN_DIR", help="scan folder (scan.json, calibration.toml, frames/)")
    r.add_argument("--out", default="scene.ply", help="cloud file: .ply, .pcd, .xyz or .npy (default scene.ply)")
    r.set_defaults(run=_reconstruct_command)


def _add_bench(sub: Any) -> None:
    """``binpick bench``."""
    b = sub.add_parser("bench", help="run the benchmarks of a source checkout")
    b.add_argument("names", nargs="*", help="benches to run (default all)")
    b.add_argument("--list", action="store_true", help="list the benches")
    b.set_defaults(run=run_bench)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Runs ``binpick`` with ``argv`` (without the program name; default ``sys.argv[1:]``); returns the exit code:
    0 done, 1 a fault, a safety refusal or another error, 2 bad input (checkerboard images that cannot give
    intrinsics to trust included), 3 no object found, 4 a pick run in which the gripper collided, 130
    interrupted."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in _FORWARDED:
        module, entry = _FORWARDED[argv[0]]
        return _forward(getattr(importlib.import_module(module, __package__), entry), argv[1:])
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse printed the usage and the problem
        return int(exc.code or 0)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    if args.command in ("demo", "pick", "validate"):
        _take_ctrl_c()
    try:
        return int(args.run(args))
    except (_Usage, InvalidInputError) as exc:
        print(f"binpick {args.command}: {error_text(exc)}", file=sys.stderr)
        return 2
    except BinpickError as exc:  # no object found: 3; a fault, a safety refusal or another error: 1
        print(f"binpick {args.command}: {type(exc).__name__}: {error_text(exc)}", file=sys.stderr)
        return 3 if isinstance(exc, NoObjectFound) else 1
    except KeyboardInterrupt:
        print(f"binpick {args.command}: interrupted", file=sys.stderr)
        return 130  # as a shell reports SIGINT


def _take_ctrl_c() -> None:
    """A run that moves a cell stops on Ctrl-C (SIGINT), the arm stopped and the picks kept,
    even when started from a script in the background, which inherits SIGINT ignored."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _forward(entry: Any, argv: list[str]) -> int:
    try:
        return int(entry(argv) or 0)
    except SystemExit as exc:
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
