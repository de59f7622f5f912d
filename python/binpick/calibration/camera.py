"""Camera intrinsics and distortion from checkerboard images (OpenCV), and board poses (Eq. 15)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np

from .._validate import as_float_array, as_image, as_points, count, flag, instance_of, positive
from ..camera import CameraIntrinsics
from ..errors import CalibrationError, InvalidInputError, UntrustedCalibrationError, UntrustedCalibrationWarning
from .quality import CalibrationLimits, CalibrationQuality, assess

__all__ = [
    "CalibrationLimits",
    "CalibrationQuality",
    "CameraCalibration",
    "board_object_points",
    "board_pose",
    "calibrate_camera",
    "find_checkerboard",
]


#: Most inner corners a checkerboard may have along one side: printed boards have tens, and
#: beyond this a pattern is a mistake that would allocate its corners (a million of them) for nothing.
MAX_PATTERN_SIDE = 1000

#: The cv2.calibrateCamera flags :func:`calibrate_camera` passes on: those that fix or drop terms
#: of the five-coefficient model ``[k1, k2, p1, p2, k3]`` binpick keeps, and the solver choice.
#: The rational, thin-prism and tilted models would return coefficients the camera cannot hold;
#: the intrinsic and extrinsic guesses need starting values this function does not take.
CALIBRATION_FLAGS = {
    "CALIB_FIX_ASPECT_RATIO": cv2.CALIB_FIX_ASPECT_RATIO,
    "CALIB_FIX_PRINCIPAL_POINT": cv2.CALIB_FIX_PRINCIPAL_POINT,
    "CALIB_ZERO_TANGENT_DIST": cv2.CALIB_ZERO_TANGENT_DIST,
    "CALIB_FIX_K1": cv2.CALIB_FIX_K1,
    "CALIB_FIX_K2": cv2.CALIB_FIX_K2,
    "CALIB_FIX_K3": cv2.CALIB_FIX_K3,
    "CALIB_USE_LU": cv2.CALIB_USE_LU,
    "CALIB_USE_QR": cv2.CALIB_USE_QR,
}
_FLAG_MASK = sum(CALIBRATION_FLAGS.values())


def _pattern(pattern) -> tuple[int, int]:
    """(columns, rows) of inner corners, each a whole number in [3, :data:`MAX_PATTERN_SIDE`]
    (OpenCV finds no board with fewer than three inner corners along a side)."""
    try:
        cols, rows = pattern
    except (TypeError, ValueError):
        raise InvalidInputError(f"pattern: expected (columns, rows) of inner corners, got {pattern!r:.60}") from None
    return (
        count(cols, "pattern columns (inner corners)", 3, MAX_PATTERN_SIDE),
        count(rows, "pattern rows (inner corners)", 3, MAX_PATTERN_SIDE),
    )


def _flags(flags) -> int:
    """``flags`` as a bitwise OR of :data:`CALIBRATION_FLAGS`, or InvalidInputError naming the others."""
    v = count(flags, "flags", 0, 2**31 - 1)  # OpenCV takes an int
    if v & ~_FLAG_MASK:
        raise InvalidInputError(
            f"flags: {v:#x} sets bits {v & ~_FLAG_MASK:#x} that calibrate_camera does not take; "
            f"combine only {', '.join('cv2.' + n for n in CALIBRATION_FLAGS)}"
        )
    return v


def board_object_points(pattern: tuple[int, int], square: float) -> np.ndarray:
    """The inner corners in the board frame (z = 0), row by row as OpenCV finds them, mm (N, 3)."""
    cols, rows = _pattern(pattern)
    sq = positive(square, "square")
    gx, gy = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([gx.ravel(), gy.ravel(), np.zeros(cols * rows)], axis=1) * sq


def find_checkerboard(image: np.ndarray, pattern: tuple[int, int], *, orient: bool = False) -> np.ndarray | None:
    """The checkerboard's inner corners to sub-pixel accuracy, (N, 2) float64, or None if not found.

    ``orient``: put the corners in the board's own order whatever the view — the first corner is
    the one whose diagonal square away from the grid is dark (OpenCV's order turns with the image,
    which would give a board seen upside down a different frame; a board with an even number of
    squares along one side tells its two ends apart by colour)."""
    img = as_image(image, "image")
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    size = _pattern(pattern)
    found, corners = cv2.findChessboardCorners(
        grey, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(grey, corners, _refine_window(corners.reshape(-1, 2), size), (-1, -1), criteria)
    corners = corners.reshape(-1, 2).astype(np.float64)
    return _oriented(grey, corners, size) if orient else corners


def _refine_window(corners: np.ndarray, size: tuple[int, int]) -> tuple[int, int]:
    """cornerSubPix's half window, px: 7 (a 15 px search), narrowed on small squares so that the
    window stays inside the four squares around its corner — a wider one reaches the next corner
    and pulls both onto the same point."""
    cols, rows = size
    grid = corners.reshape(rows, cols, 2)
    spacing = min(
        float(np.linalg.norm(np.diff(grid, axis=1), axis=2).min()),
        float(np.linalg.norm(np.diff(grid, axis=0), axis=2).min()),
    )
    half = int(min(7, max(1, (spacing - 1) // 2)))
    return half, half


def _oriented(grey: np.ndarray, corners: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``corners`` or the same reversed, so that the square diagonally outside the first corner
    is darker than its neighbour outside the first row (board frame squares (−1, −1) and (0, −1))."""
    cols = size[0]
    c0, step_x, step_y = corners[0], corners[1] - corners[0], corners[cols] - corners[0]

    def sample(p: np.ndarray) -> float:
        u, v = int(round(p[0])), int(round(p[1]))
        h, w = grey.shape
        return float(grey[min(max(v, 0), h - 1), min(max(u, 0), w - 1)])

    diagonal = sample(c0 - 0.5 * step_x - 0.5 * step_y)
    beside = sample(c0 + 0.5 * step_x - 0.5 * step_y)
    return corners if diagonal <= beside else corners[::-1].copy()


def _pose(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = np.ravel(tvec)
    return T


def board_pose(corners: np.ndarray, camera: CameraIntrinsics, pattern: tuple[int, int], square: float) -> np.ndarray:
    """``T_camera_board`` from the board's detected corners (the paper's Eq. 15, by PnP)."""
    obj = board_object_points(pattern, square)
    instance_of(camera, CameraIntrinsics, "camera", "CameraIntrinsics.pinhole(width, height, fx, fy, cx, cy)")
    arr = as_float_array(corners, "corners")
    if arr.ndim == 3 and arr.shape[1] == 1:  # OpenCV's (N, 1, 2)
        arr = arr[:, 0, :]
    pts = as_points(arr, "corners", columns=2)
    if len(pts) != len(obj):
        raise InvalidInputError(f"corners: {len(pts)} corners for a {pattern} pattern of {len(obj)}; pass every corner")
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, pts, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE)
    except cv2.error as exc:
        raise CalibrationError(
            f"corners: solvePnP failed ({str(exc).strip()[-120:]}); pass the corners find_checkerboard found"
        ) from None
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        raise CalibrationError("corners: solvePnP found no board pose; check the pattern size and the corners")
    T = _pose(rvec, tvec)
    if T[2, 3] <= 0:
        raise CalibrationError(
            "corners: the only board pose that fits lies behind the camera; the corners are not a view of this board"
        )
    return T


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """The outcome of :func:`calibrate_camera`.

    ``camera``: the intrinsics; ``rms``: the RMS reprojection error over all corners (pixels);
    ``per_view_rms``: that error per used view; ``views``: indices of the images where the
    board was found; ``T_camera_boards``: the board pose in each used view; ``corners``: the
    corners found in each used view, (N, 2) px; ``quality``: how far it can be trusted (figures,
    limits, problems; see :class:`CalibrationQuality`).
    """

    camera: CameraIntrinsics
    rms: float
    per_view_rms: np.ndarray
    views: np.ndarray
    T_camera_boards: tuple[np.ndarray, ...]
    corners: tuple[np.ndarray, ...] = ()
    quality: Optional[CalibrationQuality] = None

    @property
    def trusted(self) -> bool:
        """Whether every quality figure is within its limit."""
        return self.quality is not None and self.quality.trusted

    def __repr__(self) -> str:
        trust = "" if self.quality is None else (", trusted" if self.quality.trusted else ", NOT TRUSTED")
        return f"CameraCalibration({self.camera!r}, rms={self.rms:.3f} px over {len(self.views)} views{trust})"


def calibrate_camera(
    images: Sequence[np.ndarray],
    pattern: tuple[int, int],
    square: float,
    *,
    flags: int = 0,
    orient: bool = False,
    limits: Optional[CalibrationLimits] = None,
    accept_untrusted: bool = False,
) -> CameraCalibration:
    """Intrinsics and distortion ``[k1, k2, p1, p2, k3]`` from checkerboard images, judged.

    ``pattern`` is (columns, rows) of inner corners, ``square`` the square size in mm. Images
    where the board is not found are skipped. The reprojection error is reported overall and per
    view. ``orient``: see :func:`find_checkerboard` (needed when the board poses are used
    together, as hand-eye does).

    The result is judged against ``limits`` (default :class:`CalibrationLimits`: at least 8
    views and the board in half of the images, 25 % of the image covered, board planes 20° apart,
    reprojection RMS 0.5 px, focal length 1-sigma 0.5 %; the reasons are in its doc). When one is
    missed, :class:`~binpick.errors.UntrustedCalibrationError` names each cause and its fix
    (``exc.calibration`` is the result refused); with ``accept_untrusted=True`` the result is
    returned with an :class:`~binpick.errors.UntrustedCalibrationWarning` instead. Either way
    ``result.quality`` holds the figures.
    """
    flags = _flags(flags)
    limits = (
        CalibrationLimits()
        if limits is None
        else instance_of(limits, CalibrationLimits, "limits", "CalibrationLimits(min_views=8)")
    )
    accept_untrusted = flag(accept_untrusted, "accept_untrusted")
    imgs = list(images)
    if not imgs:
        raise CalibrationError("images: no checkerboard images given")
    shapes = {as_image(im, f"images[{i}]").shape[:2] for i, im in enumerate(imgs)}
    if len(shapes) != 1:
        raise CalibrationError(f"images: all images must come from one camera at one size, got sizes {sorted(shapes)}")
    height, width = shapes.pop()
    obj = board_object_points(pattern, square).astype(np.float32)
    corners, views = [], []
    for i, im in enumerate(imgs):
        c = find_checkerboard(im, pattern, orient=orient)
        if c is not None:
            corners.append(c.astype(np.float32).reshape(-1, 1, 2))
            views.append(i)
    found = f"the {pattern} checkerboard was found in {len(views)} of {len(imgs)} images"
    if not views:
        raise CalibrationError(f"images: {found}; check the pattern size (inner corners) and the lighting")
    try:
        rms, K, dist, rvecs, tvecs, std, _, _ = cv2.calibrateCameraExtended(
            [obj] * len(views), corners, (width, height), None, None, flags=flags
        )
    except cv2.error as exc:
        raise CalibrationError(
            f"images: OpenCV could not calibrate from these views ({found}: {str(exc).strip()[-120:]}); "
            f"use at least {limits.min_views} views of the board at several tilts"
        ) from None
    if not (np.isfinite(K).all() and np.isfinite(dist).all() and np.isfinite(rms)):
        raise CalibrationError(
            f"images: the calibration diverged ({found}); use at least {limits.min_views} views of the board at "
            "several tilts"
        )
    per_view = []
    for c, r, t in zip(corners, rvecs, tvecs):
        proj, _ = cv2.projectPoints(obj, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj - c).reshape(-1, 2) ** 2, axis=1)))))
    poses = tuple(_pose(r, t) for r, t in zip(rvecs, tvecs))
    quality = assess(
        images=len(imgs),
        corners=[c.reshape(-1, 2) for c in corners],
        size=(width, height),
        rotations=[T[:3, :3] for T in poses],
        rms=float(rms),
        K=K,
        std_intrinsics=std,
        per_view_rms=np.array(per_view),
        view_ids=np.array(views),
        limits=limits,
    )
    result = CameraCalibration(
        camera=CameraIntrinsics(width=width, height=height, K=K, dist=np.ravel(dist)[:5]),
        rms=float(rms),
        per_view_rms=np.array(per_view),
        views=np.array(views),
        T_camera_boards=poses,
        corners=tuple(c.reshape(-1, 2).astype(np.float64) for c in corners),
        quality=quality,
    )
    if not quality.trusted:
        if not accept_untrusted:
            raise UntrustedCalibrationError(quality.message(), result)
        warnings.warn(
            "kept on request (accept_untrusted=True), this camera calibration cannot be trusted: "
            + "; ".join(quality.problems),
            UntrustedCalibrationWarning,
            stacklevel=2,
        )
    return result
