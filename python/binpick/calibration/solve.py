"""Solving a capture (:func:`binpick.calibration.capture.capture`) into the cell's calibration:
camera intrinsics with distortion from every board frame (OpenCV), the board pose in each,
hand-eye by all five OpenCV methods (the stillest board kept), both refined together by
eye-in-hand bundle adjustment (:mod:`.refine`), the laser sheet at each motor
angle and its rotation axis from the line on the board at the laser stations, and the paper's
Table 1 procedure (the angle at which the line crosses the principal point, at several board
distances) for comparison. :func:`solve` returns a :class:`Solution`; :meth:`Solution.save`
writes ``calibration.toml`` (the :class:`CellCalibration`, version 1, plus its residuals) and a
PNG of the residuals."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .._validate import check_rigid
from ..camera import CameraIntrinsics
from ..errors import BinpickError, CalibrationError, FileWriteError, InvalidInputError
from ._file import CellCalibration, _toml_row
from .camera import CalibrationLimits, CameraCalibration, board_object_points, board_pose, calibrate_camera
from .capture import MANIFEST_VERSION
from .hand_eye import HandEyeCalibration, calibrate_hand_eye
from .laser import LaserCalibration, laser_points_on_board
from .projector import ProjectorCalibration, axis_depth, calibrate_projector
from .refine import EyeInHandRefinement, refine_eye_in_hand

__all__ = ["Capture", "Solution", "load_capture", "solve"]

#: Largest manifest read, bytes (a real one is some tens of kilobytes).
MAX_MANIFEST_BYTES = 8 << 20
#: Laser pixels used must meet the board this far inside its outermost squares, mm (the line
#: is blurred by the squares' edges and the board's border there).
_INSIDE_MM = 2.0
#: Fewest line points on the board for a laser frame to count (a line crossing a few squares).
_MIN_LINE_POINTS = 30
#: Rows around the principal point whose line centres give the line's column there (Table 1), px.
_ROW_BAND_PX = 80.0


@dataclass(frozen=True)
class Capture:
    """A capture read back: the board, and per station its name, the flange pose read from the
    robot, the board frame's path, and the laser frames' (path, angle at rest, planned angle)."""

    folder: Path
    pattern: tuple[int, int]
    square: float
    names: tuple[str, ...]
    T_base_flanges: tuple[np.ndarray, ...]
    board_frames: tuple[Path, ...]
    laser_frames: tuple[tuple[tuple[Path, float, float], ...], ...]


def _field(doc: Any, key: str, kind: type | tuple, where: str, source: Path) -> Any:
    if not isinstance(doc, dict) or key not in doc:
        raise CalibrationError(f"{source}: {where}{key} is missing; the capture is incomplete, capture it again")
    value = doc[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise CalibrationError(f"{source}: {where}{key} is {value!r:.40}, of the wrong type; the manifest is corrupt")
    return value


def _frame_path(folder: Path, shot: Any, where: str, source: Path) -> tuple[Path, float, float]:
    rel = _field(shot, "file", str, where, source)
    path = (folder / rel).resolve()
    if folder.resolve() not in path.parents:
        raise CalibrationError(f"{source}: {where}file {rel!r:.60} points outside the capture folder")
    if not path.is_file():
        raise CalibrationError(f"{source}: {where}file {rel} is missing from the capture folder; capture it again")
    angle = float(_field(shot, "angle", (int, float), where, source))
    goal = float(shot.get("goal", angle)) if isinstance(shot.get("goal", angle), (int, float)) else angle
    if not (np.isfinite(angle) and np.isfinite(goal)):
        raise CalibrationError(f"{source}: {where}angle is not finite; the manifest is corrupt")
    return path, angle, goal


def load_capture(folder: str | os.PathLike) -> Capture:
    """Reads ``folder/manifest.json`` and checks every field and that every frame file exists;
    CalibrationError naming the file and the field otherwise."""
    root = Path(folder)
    source = root / "manifest.json"
    if not root.is_dir():
        raise CalibrationError(f"{root}: not a capture folder; run `binpick calibrate capture CELL.toml --out DIR`")
    if not source.is_file():
        raise CalibrationError(f"{source}: the capture's manifest is missing; run `binpick calibrate capture` again")
    if source.stat().st_size > MAX_MANIFEST_BYTES:
        raise CalibrationError(f"{source}: larger than {MAX_MANIFEST_BYTES} bytes; not a capture manifest")
    try:
        doc = json.loads(source.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"{source}: not a readable JSON manifest ({exc}); capture it again") from None
    version = _field(doc, "version", int, "", source)
    if version != MANIFEST_VERSION:
        raise CalibrationError(f"{source}: manifest version {version}; this binpick reads version {MANIFEST_VERSION}")
    board = _field(doc, "board", dict, "", source)
    pattern = _field(board, "pattern", list, "board.", source)
    if len(pattern) != 2 or not all(isinstance(p, int) and not isinstance(p, bool) and p >= 2 for p in pattern):
        raise CalibrationError(f"{source}: board.pattern is {pattern!r:.40}; expected [columns, rows] of inner corners")
    square = float(_field(board, "square_mm", (int, float), "board.", source))
    if not (np.isfinite(square) and square > 0):
        raise CalibrationError(f"{source}: board.square_mm is {square}; expected the square's size in mm")
    stations = _field(doc, "stations", list, "", source)
    names, poses, boards, lasers = [], [], [], []
    for i, st in enumerate(stations):
        where = f"stations[{i}]."
        names.append(str(_field(st, "name", str, where, source)))
        raw = _field(st, "T_base_flange", list, where, source)
        try:
            T = np.asarray(raw, dtype=np.float64)
            poses.append(check_rigid(T, f"{source}: {where}T_base_flange", CalibrationError))
        except (ValueError, TypeError):
            raise CalibrationError(
                f"{source}: {where}T_base_flange is not a 4×4 matrix; the manifest is corrupt"
            ) from None
        boards.append(
            _frame_path(root, _field(st, "board_frame", dict, where, source), where + "board_frame.", source)[0]
        )
        shots = _field(st, "laser_frames", list, where, source)
        lasers.append(tuple(_frame_path(root, s, f"{where}laser_frames[{k}].", source) for k, s in enumerate(shots)))
    return Capture(root, (pattern[0], pattern[1]), square, tuple(names), tuple(poses), tuple(boards), tuple(lasers))


def _read(path: Path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise CalibrationError(f"{path}: not a readable image; the capture is corrupt, capture it again")
    return img


@dataclass(frozen=True, eq=False)
class Solution:
    """The solved calibration and how well each part fits.

    ``calibration``: the :class:`CellCalibration`; ``camera``: the intrinsics fit (per-view RMS);
    ``view_names``: the station of each used view; ``hand_eye``: every method's transform and
    residuals; ``refined``: the intrinsics and hand-eye refined together from the best method by
    eye-in-hand bundle adjustment (what ``calibration`` holds); ``laser``: the sheet per angle
    and the rotation axis; ``projector``: the paper's Table 1 fit (None when the laser stations
    do not give three crossings of the principal point);
    ``seconds``: time per step."""

    calibration: CellCalibration
    camera: CameraCalibration
    view_names: tuple[str, ...]
    hand_eye: HandEyeCalibration
    refined: EyeInHandRefinement
    laser: LaserCalibration
    projector: Optional[ProjectorCalibration]
    seconds: dict

    def residuals_toml(self) -> str:
        """The residual tables appended to ``calibration.toml`` (ignored when it is loaded)."""
        lines = [
            "[residuals.camera]",
            f"rms_px = {self.camera.rms!r}",
            f"views = [{', '.join(repr(n) for n in self.view_names)}]",
            f"per_view_rms_px = {_toml_row(self.camera.per_view_rms)}",
            "",
            "# how far the intrinsics (before the bundle adjustment) can be trusted: figures, limits, warnings",
            self.camera.quality.toml("quality.camera"),
            "[residuals.hand_eye]",
            f'method = "{self.hand_eye.method}"',
        ]
        for name, (mm, deg) in self.hand_eye.residuals.items():
            lines.append(f"{name} = {{ mm = {mm!r}, deg = {deg!r} }}")
        lines += [
            "",
            "[residuals.refined]",
            "# intrinsics and hand-eye refined together (eye-in-hand bundle adjustment): what this file holds",
            f"rms_px = {self.refined.rms!r}",
            f"per_view_rms_px = {_toml_row(self.refined.per_view_rms)}",
            "",
            "[residuals.laser]",
            f"rms_mm = {self.laser.rms!r}",
            f"angles_rad = {_toml_row(self.laser.angles)}",
            f"per_angle_rms_mm = {_toml_row(self.laser.per_angle_rms)}",
            "",
        ]
        if self.projector is not None:
            p = self.projector
            lines += ["[residuals.table1]", f"p_x_mm = {p.p_x!r}", f"p_z_mm = {p.p_z!r}", f"rms_mm = {p.rms!r}", ""]
        return "\n".join(lines)

    def summary(self) -> str:
        """A plain-text table of the results and residuals."""
        cam = self.calibration.camera
        rows = [
            f"camera   {cam.width}x{cam.height}  fx {cam.K[0, 0]:.2f}  fy {cam.K[1, 1]:.2f}  "
            f"cx {cam.K[0, 2]:.2f}  cy {cam.K[1, 2]:.2f}  dist {np.round(cam.dist, 5).tolist()}",
            f"         reprojection RMS {self.camera.rms:.3f} px over {len(self.view_names)} views, free board poses "
            f"(worst {self.camera.per_view_rms.max():.3f} px)",
            f"         {self.camera.quality.summary()}",
            "hand-eye (board stillness in the base frame):",
            *("  " + line for line in self.hand_eye.residual_table().splitlines()),
            f"refined  intrinsics and hand-eye together from {self.hand_eye.method} (eye-in-hand bundle "
            f"adjustment): reprojection RMS {self.refined.rms:.3f} px, {self.refined.iterations} iterations",
            f"laser    {len(self.laser.angles)} angles, sheet RMS {self.laser.rms:.4f} mm "
            f"(worst angle {self.laser.per_angle_rms.max():.4f} mm); origin "
            f"{np.round(self.calibration.T_camera_laser[:3, 3], 2).tolist()} mm, axis "
            f"{np.round(self.calibration.T_camera_laser[:3, 1], 5).tolist()}",
        ]
        if self.projector is not None:
            p = self.projector
            rows.append(f"table 1  p_x {p.p_x:.2f} mm  p_z {p.p_z:.2f} mm  RMS {p.rms:.3f} mm")
        else:
            rows.append("table 1  not solved: fewer than 3 laser stations saw the line cross the principal point")
        rows.append("time     " + "  ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()))
        return "\n".join(rows)

    def save(self, path: str | os.PathLike, *, picture: bool = True) -> Path:
        """Writes the calibration (TOML, version 1, with the residual tables) to ``path`` and, if
        ``picture``, the residuals as a PNG beside it (``<stem>_residuals.png``); returns ``path``."""
        path = Path(path)
        try:
            path.write_text(self.calibration.to_toml() + "\n" + self.residuals_toml(), encoding="utf-8")
        except OSError as exc:
            raise FileWriteError(f"{path}: cannot write the calibration ({exc})") from None
        if picture:
            self.save_picture(path.with_name(path.stem + "_residuals.png"))
        return path

    def save_picture(self, path: str | os.PathLike) -> Path:
        """The residuals as bars: reprojection RMS per view, board stillness per hand-eye method,
        laser sheet RMS per motor angle."""
        from ..viz import _pyplot, _save

        plt = _pyplot()
        fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
        axes[0].bar(range(len(self.view_names)), self.camera.per_view_rms, color="tab:blue")
        axes[0].set_xticks(range(len(self.view_names)), self.view_names, rotation=90, fontsize=7)
        axes[0].set_ylabel("reprojection RMS, px")
        axes[0].set_title(f"camera: {self.camera.rms:.3f} px overall")
        names = list(self.hand_eye.residuals)
        mm = [self.hand_eye.residuals[n][0] for n in names]
        colors = ["tab:green" if n == self.hand_eye.method else "tab:gray" for n in names]
        axes[1].bar(names, mm, color=colors)
        axes[1].set_ylabel("board stillness RMS, mm")
        axes[1].set_title(f"hand-eye: {self.hand_eye.method} kept")
        for i, n in enumerate(names):
            axes[1].annotate(f"{self.hand_eye.residuals[n][1]:.3f}°", (i, mm[i]), ha="center", va="bottom", fontsize=8)
        axes[2].bar(np.degrees(self.laser.angles), self.laser.per_angle_rms, width=1.2, color="tab:red")
        axes[2].set_xlabel("motor angle, °")
        axes[2].set_ylabel("distance to the sheet RMS, mm")
        axes[2].set_title(f"laser: {self.laser.rms:.4f} mm overall")
        fig.tight_layout()
        return _save(fig, path)


def _on_board(points: np.ndarray, T_camera_board: np.ndarray, pattern: tuple[int, int], square: float) -> np.ndarray:
    """Which camera-frame points lie on the board's squares, ``_INSIDE_MM`` inside their outline."""
    local = (points - T_camera_board[:3, 3]) @ T_camera_board[:3, :3]
    lo, hi = -square + _INSIDE_MM, np.array(pattern) * square - _INSIDE_MM
    return (local[:, 0] >= lo) & (local[:, 0] <= hi[0]) & (local[:, 1] >= lo) & (local[:, 1] <= hi[1])


def _principal_crossing(samples: list[tuple[float, np.ndarray]], camera: CameraIntrinsics) -> Optional[float]:
    """The motor angle at which the line passes through the principal point (Table 1): the line's
    column at the principal row in each frame (a straight fit to the line centres of the rows
    around it), interpolated across the frames' angles; None if the sweep does not cross it."""
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    cols = []
    for angle, uv in samples:
        band = uv[np.abs(uv[:, 1] - cy) <= _ROW_BAND_PX]
        if len(band) >= 5 and np.ptp(band[:, 1]) > _ROW_BAND_PX / 2:
            slope, offset = np.polyfit(band[:, 1], band[:, 0], 1)
            cols.append((angle, slope * cy + offset))
    if len(cols) < 3:
        return None
    a, u = np.array(cols).T
    order = np.argsort(a)
    a, u = a[order], u[order]
    side = np.sign(u - cx)
    flips = np.nonzero(side[:-1] * side[1:] <= 0)[0]
    if len(flips) == 0:
        return None
    k = int(flips[0])
    lo, hi = max(k - 1, 0), min(k + 3, len(a))
    coeffs = np.polyfit(a[lo:hi], u[lo:hi] - cx, min(2, hi - lo - 1))
    roots = [r.real for r in np.roots(coeffs) if abs(r.imag) < 1e-12 and a[k] - 1e-9 <= r.real <= a[k + 1] + 1e-9]
    return float(roots[0]) if roots else float(a[k] + (a[k + 1] - a[k]) * (cx - u[k]) / (u[k + 1] - u[k]))


def solve(
    capture_dir: str | os.PathLike, *, limits: Optional[CalibrationLimits] = None, accept_untrusted: bool = False
) -> Solution:
    """Solves the capture in ``capture_dir`` (see the module doc). CalibrationError when the
    capture is incomplete or corrupt, or when too few views found the board or saw the line;
    UntrustedCalibrationError when the intrinsics cannot be trusted by ``limits`` (see
    :func:`~binpick.calibration.calibrate_camera`, which also says what ``accept_untrusted`` does)."""
    import time

    from ..vision import extract_line

    t0 = time.perf_counter()
    cap = load_capture(capture_dir)
    images = [_read(p) for p in cap.board_frames]
    cam = calibrate_camera(
        images, cap.pattern, cap.square, orient=True, limits=limits, accept_untrusted=accept_untrusted
    )
    t1 = time.perf_counter()
    used = [int(v) for v in cam.views]
    view_names = tuple(cap.names[v] for v in used)
    flanges = [cap.T_base_flanges[v] for v in used]
    hand_eye = calibrate_hand_eye(flanges, list(cam.T_camera_boards))
    obj = board_object_points(cap.pattern, cap.square)
    refined = refine_eye_in_hand(obj, cam.corners, flanges, cam.camera, hand_eye.T_flange_camera, cam.T_camera_boards)
    camera = refined.camera
    board_of = {v: board_pose(c, camera, cap.pattern, cap.square) for v, c in zip(used, cam.corners)}
    t2 = time.perf_counter()
    by_goal: dict[float, list[tuple[float, np.ndarray]]] = {}
    crossings: list[tuple[float, float]] = []
    for i, shots in enumerate(cap.laser_frames):
        if not shots:
            continue
        if i not in board_of:
            raise CalibrationError(
                f"{cap.board_frames[i]}: the board was not found in laser station {cap.names[i]!r}'s board frame; "
                "its laser frames cannot be used — check that the board is in view and the laser parked off it"
            )
        T_cb = board_of[i]
        samples = []
        for path, angle, goal in shots:
            uv = extract_line(_read(path))
            if len(uv) == 0:
                continue
            try:
                pts = laser_points_on_board(uv, camera, T_cb)
            except BinpickError:
                continue
            on = _on_board(pts, T_cb, cap.pattern, cap.square)
            if on.sum() >= _MIN_LINE_POINTS:
                samples.append((angle, uv[on]))
                by_goal.setdefault(round(goal, 9), []).append((angle, pts[on]))
        theta = _principal_crossing(samples, camera)
        if theta is not None:
            crossings.append((axis_depth(T_cb), theta))
    usable = {g: v for g, v in by_goal.items() if len(v) >= 2}
    if len(usable) < 3:
        raise CalibrationError(
            f"{cap.folder}: the laser line was seen on the board from two or more stations at {len(usable)} motor "
            "angles; at least 3 are needed — sweep the line over the board at more angles"
        )
    goals = sorted(usable)
    angles = [float(np.mean([a for a, _ in usable[g]])) for g in goals]
    laser = LaserCalibration.fit(
        angles,
        [np.concatenate([p for _, p in usable[g]]) for g in goals],
        point_angles=[np.concatenate([np.full(len(p), a) for a, p in usable[g]]) for g in goals],
    )
    projector = None
    if len(crossings) >= 3:
        # The paper counts the angle from the sheet parallel to the optical axis; the motor's zero
        # is elsewhere, by the sheet's turn about y at motor angle 0 (from the general fit).
        x0 = laser.T_camera_laser[:3, 0]
        zero = float(np.arctan2(-x0[2], x0[0]))
        try:
            projector = calibrate_projector([d for d, _ in crossings], [zero + a for _, a in crossings])
        except InvalidInputError:  # collinear crossings (e.g. one distance): Table 1 stays unsolved
            projector = None
    t3 = time.perf_counter()
    calibration = CellCalibration(
        camera=camera, T_camera_laser=laser.T_camera_laser, T_flange_camera=refined.T_flange_camera
    )
    seconds = {"intrinsics": t1 - t0, "hand-eye": t2 - t1, "laser": t3 - t2}
    return Solution(calibration, cam, view_names, hand_eye, refined, laser, projector, seconds)
