"""``binpick calibrate``: a camera's intrinsics from a folder of checkerboard images, and the
cell's calibration (``capture``, ``solve``, ``compare``). The intrinsics are refused when they
cannot be trusted (:class:`binpick.calibration.CalibrationLimits`, exit code 2 with each cause
and its fix); the limit flags move a limit knowingly, ``--accept-untrusted`` keeps the result
with every warning on stderr and in the output."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import warnings
from pathlib import Path
from typing import Any

from ._cli_parts import _existing, _Usage
from .errors import InvalidInputError, UntrustedCalibrationError, UntrustedCalibrationWarning


def _calibrate(args: argparse.Namespace) -> int:
    target = args.target
    if target[0] in ("capture", "compare"):
        given = _judging_flags(args)
        if given:
            raise _Usage(f"{given[0]}: applies to `calibrate FOLDER` and `calibrate solve`, which judge the intrinsics")
    if target[0] == "capture":
        if len(target) != 2:
            raise _Usage("calibrate capture: give one cell file, e.g. `binpick calibrate capture cell.toml --out DIR`")
        return _calibrate_capture(target[1], args)
    if target[0] == "solve":
        if len(target) != 2:
            raise _Usage(
                "calibrate solve: give one capture folder, e.g. `binpick calibrate solve DIR --out calibration.toml`"
            )
        return _calibrate_solve(_existing(target[1], "DIR", "capture folder", folder=True), args)
    if target[0] == "compare":
        if len(target) != 3:
            raise _Usage(
                "calibrate compare: give the solved and the true calibration, e.g. "
                "`binpick calibrate compare calibration.toml true_calibration.toml`"
            )
        return _calibrate_compare(
            _existing(target[1], "CALIBRATION", "calibration file"), _existing(target[2], "TRUTH", "calibration file")
        )
    if len(target) != 1:
        raise _Usage(
            "calibrate: give one folder of checkerboard images, or `capture CELL.toml`, `solve DIR` "
            "or `compare CALIBRATION TRUTH`"
        )
    if args.out is not None:
        raise _Usage("--out: applies to `calibrate capture` and `calibrate solve`; FOLDER's intrinsics print as JSON")
    return _calibrate_folder(args)


def _judging_flags(args: argparse.Namespace) -> list[str]:
    """The trust flags given (limits and ``--accept-untrusted``)."""
    from .calibration.quality import CLI_FLAGS

    return [flag for name, flag in CLI_FLAGS.items() if getattr(args, name) not in (None, False)]


def _limits(args: argparse.Namespace) -> Any:
    """The :class:`CalibrationLimits` with the flags given in place of their defaults."""
    from .calibration import CalibrationLimits
    from .calibration.quality import CLI_FLAGS

    given = {name: getattr(args, name) for name in CLI_FLAGS if name != "accept_untrusted"}
    given = {k: v for k, v in given.items() if v is not None}
    try:
        return dataclasses.replace(CalibrationLimits(), **given)
    except InvalidInputError as exc:
        name, _, rest = str(exc).partition(":")
        raise _Usage(f"{CLI_FLAGS.get(name, name)}:{rest}") from None


def _judged(call: Any, args: argparse.Namespace) -> Any:
    """``call(limits, accept_untrusted)`` with the flags' limits; a refusal prints the figures
    before the error (exit 2), a result kept by ``--accept-untrusted`` prints each warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UntrustedCalibrationWarning)  # printed below, each on its line
        try:
            result = call(_limits(args), args.accept_untrusted)
        except UntrustedCalibrationError as exc:
            if exc.quality is not None:
                print(f"binpick calibrate: {exc.quality.summary()}", file=sys.stderr)
            raise
    return result


def _warn_untrusted(quality: Any) -> None:
    if quality.trusted:
        return
    print(
        "binpick calibrate: WARNING: this camera calibration CANNOT BE TRUSTED; kept because of --accept-untrusted:",
        file=sys.stderr,
    )
    for problem in quality.problems:
        print(f"binpick calibrate: WARNING:   - {problem}", file=sys.stderr)


def _calibrate_capture(cell_path: str, args: argparse.Namespace) -> int:
    from .cell import ProgressPrinter, load_cell_file
    from .cell.cell_file import capture_calibration

    if args.out is None:
        raise _Usage("calibrate capture: --out DIR is required (the folder the frames and manifest go to)")
    manifest, stations = capture_calibration(load_cell_file(cell_path), args.out, progress=ProgressPrinter())
    print(f"wrote {manifest} ({stations} stations)", file=sys.stderr)
    return 0


def _calibrate_solve(folder: str, args: argparse.Namespace) -> int:
    from .calibration import eye_to_hand
    from .calibration.solve import solve

    if eye_to_hand.is_capture(folder):  # a fixed camera's: its pose in the base frame
        given = _judging_flags(args)
        if given:
            raise _Usage(f"{given[0]}: an eye-to-hand capture calibrates no intrinsics; leave the flag out")
        print(eye_to_hand.solve_to_file(folder, args.out or "eye_to_hand.toml"))
        return 0
    out = Path(args.out or "calibration.toml")
    solution = _judged(lambda limits, accept: solve(folder, limits=limits, accept_untrusted=accept), args)
    solution.save(out)
    print(solution.summary())
    _warn_untrusted(solution.camera.quality)
    print(f"wrote {out} and {out.with_name(out.stem + '_residuals.png')}", file=sys.stderr)
    return 0


def _calibrate_compare(solved: str, truth: str) -> int:
    """``binpick calibrate compare``: the errors against the targets; exit 1 when one is missed."""
    from .calibration import CellCalibration
    from .calibration.compare import captured_angles, compare_calibrations

    if "[eye_to_hand]" in Path(solved).read_text(errors="replace"):  # a fixed camera's pose
        from .calibration.eye_to_hand import compare_files

        table, failures = compare_files(solved, truth)
        print(table)
    else:
        captured = captured_angles(solved)
        result = compare_calibrations(CellCalibration.load(solved), CellCalibration.load(truth), captured=captured)
        print(result.table())
        failures = result.failures
    for failure in failures:
        print(f"binpick calibrate compare: {failure}", file=sys.stderr)
    return 1 if failures else 0


def _calibrate_folder(args: argparse.Namespace) -> int:
    import cv2

    from .calibration import calibrate_camera

    folder = Path(_existing(args.target[0], "FOLDER", "folder of checkerboard images", folder=True))
    if not folder.is_dir():
        raise _Usage(f"folder: {folder} is not a folder of checkerboard images")
    try:
        cols, rows = (int(v) for v in args.pattern.lower().split("x"))
    except ValueError:
        raise _Usage(f"--pattern: {args.pattern!r} is not COLSxROWS of inner corners, e.g. 9x6") from None
    paths = sorted(
        p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
    )
    read = [(p, cv2.imread(str(p), cv2.IMREAD_COLOR)) for p in paths]
    paths = [p for p, im in read if im is not None]
    images = [im for _, im in read if im is not None]
    res = _judged(
        lambda limits, accept: calibrate_camera(
            images, (cols, rows), args.square, limits=limits, accept_untrusted=accept
        ),
        args,
    )
    cam = res.camera
    doc = {
        "width": cam.width,
        "height": cam.height,
        "K": cam.K.tolist(),
        "dist": cam.dist.tolist(),
        "rms_px": res.rms,
        "views": [paths[i].name for i in res.views],
        "per_view_rms_px": res.per_view_rms.tolist(),
        "quality": res.quality.as_dict(),
    }
    print(json.dumps(doc, indent=1))
    print(f"{len(res.views)} of {len(read)} images used, reprojection RMS {res.rms:.3f} px", file=sys.stderr)
    print(f"binpick calibrate: {res.quality.summary()}", file=sys.stderr)
    _warn_untrusted(res.quality)
    return 0


def _add_calibrate(sub: Any) -> None:
    """``binpick calibrate``."""
    from .calibration import CalibrationLimits

    d = CalibrationLimits()
    c = sub.add_parser(
        "calibrate",
        help="calibrate the cell (capture, solve) or a camera from checkerboard images",
        description="binpick calibrate FOLDER: finds the checkerboard in every image of FOLDER and prints the "
        "intrinsics and their quality figures as JSON. binpick calibrate capture CELL.toml --out DIR: drives the cell "
        "through the calibration plan (board views, laser sweeps over the board; the board from the cell file's "
        "[calibration_board] table) and saves frames, poses and angles. binpick calibrate solve DIR --out "
        "calibration.toml: solves intrinsics, hand-eye (all five OpenCV methods) and the laser sheet, writes the "
        "calibration and a PNG of the residuals. binpick calibrate compare CALIBRATION TRUTH: prints a solved "
        "calibration's errors against a known one (a twin's true_calibration.toml) and the commissioning targets; "
        "exit 1 when one is missed. FOLDER and solve refuse intrinsics that cannot be trusted (exit 2, naming each "
        "cause and its fix); the limit flags below move a limit knowingly.",
    )
    c.add_argument("target", nargs="+", metavar="FOLDER | capture CELL.toml | solve DIR | compare CALIBRATION TRUTH")
    c.add_argument("--out", default=None, help="capture: the folder to write; solve: the calibration file")
    c.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    c.add_argument("--square", type=float, default=20.0, help="square size, mm (default 20)")
    limits = c.add_argument_group("trust limits of the intrinsics (FOLDER and solve)")
    limits.add_argument(
        "--min-views",
        dest="min_views",
        type=int,
        metavar="N",
        help=f"fewest views with the board (default {d.min_views})",
    )
    limits.add_argument(
        "--min-found-share",
        dest="min_found_share",
        type=float,
        metavar="F",
        help=f"least share of the images with the board found, 0-1 (default {d.min_found_share:g})",
    )
    limits.add_argument(
        "--min-coverage",
        dest="min_coverage",
        type=float,
        metavar="F",
        help=f"least share of the image the board's corners cover, 0-1 (default {d.min_coverage:g})",
    )
    limits.add_argument(
        "--min-tilt-spread",
        dest="min_tilt_spread_deg",
        type=float,
        metavar="DEG",
        help=f"least angle between the board planes of two views, degrees (default {d.min_tilt_spread_deg:g})",
    )
    limits.add_argument(
        "--max-rms",
        dest="max_rms_px",
        type=float,
        metavar="PX",
        help=f"largest reprojection RMS, px (default {d.max_rms_px:g})",
    )
    limits.add_argument(
        "--max-focal-sigma",
        dest="max_focal_sigma_pct",
        type=float,
        metavar="PCT",
        help=f"largest estimated 1-sigma of the focal length, %% (default {d.max_focal_sigma_pct:g})",
    )
    limits.add_argument(
        "--accept-untrusted",
        dest="accept_untrusted",
        action="store_true",
        help="keep intrinsics that miss a limit: every warning is printed to stderr and written to the output",
    )
    c.set_defaults(run=_calibrate)
