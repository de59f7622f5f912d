"""Triangulation of laser-line pixels into points of the robot's base frame (paper Eq. 10–14,
generalised to a full projector pose, lens distortion and the robot pose of each frame)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import _core
from .._validate import as_float_array, as_points, as_transform, check_finite, count
from ..calibration import CameraIntrinsics, CellCalibration
from ..calibration._checks import as_angles
from ..errors import InvalidInputError, ShapeError, SingularGeometryError

__all__ = ["Cloud", "pixel_rays", "triangulate"]

#: Why a pixel gave no point, by the status code the core returns.
STATUS_REASONS = {
    1: "its camera ray is parallel to the laser plane",
    2: "its camera ray meets the laser plane behind the camera",
    3: "the lens distortion cannot be inverted there (far outside the calibrated field)",
}


@dataclass(frozen=True, eq=False)
class Cloud:
    """Triangulated points in the base frame (mm) and where each came from.

    ``points`` (N, 3); ``frame`` (N,) the frame index; ``pixels`` (N, 2) the sub-pixel (u, v);
    ``angle`` (N,) the motor angle (rad) of the point's frame.
    """

    points: np.ndarray
    frame: np.ndarray
    pixels: np.ndarray
    angle: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        frames = len(np.unique(self.frame)) if len(self.frame) else 0
        return f"Cloud({len(self)} points from {frames} frames)"


def _camera_args(camera: CameraIntrinsics) -> tuple:
    if not isinstance(camera, CameraIntrinsics):
        raise InvalidInputError(f"camera: expected a CameraIntrinsics, got {type(camera).__name__}")
    return camera.width, camera.height, np.ascontiguousarray(camera.K), np.ascontiguousarray(camera.dist)


def pixel_rays(pixels: np.ndarray, camera: CameraIntrinsics) -> np.ndarray:
    """Undistorted rays ``(x, y, 1)`` in the camera frame through ``pixels`` (N, 2) of (u, v).

    Raises SingularGeometryError if the distortion cannot be inverted at some pixel."""
    px = as_points(pixels, "pixels", columns=2, min_points=0)
    rays = _core.pixel_rays(*_camera_args(camera), px)
    bad = ~np.isfinite(rays[:, 0])
    if bad.any():
        i = int(np.argmax(bad))
        raise SingularGeometryError(f"pixels: row {i} {px[i].tolist()}: {STATUS_REASONS[3]}")
    return rays


def triangulate(
    pixels: np.ndarray,
    frame_index: np.ndarray | Sequence[int],
    angles: np.ndarray | Sequence[float],
    T_base_flanges: np.ndarray | Sequence[np.ndarray],
    calibration: CellCalibration,
    *,
    on_singular: str = "drop",
    num_threads: int = 0,
) -> Cloud:
    """Points in the base frame from laser-line pixels of a scan.

    ``pixels`` (N, 2) are (u, v) seen in frame ``frame_index[i]``; frame ``f`` was captured at
    motor angle ``angles[f]`` (radians) with the flange at ``T_base_flanges[f]`` (4×4, mm).
    A pixel whose ray is parallel to the laser plane or meets it behind the camera has no
    point: ``on_singular="drop"`` leaves it out, ``"raise"`` raises SingularGeometryError
    naming it. ``num_threads``: 0 = all cores.
    """
    if not isinstance(calibration, CellCalibration):
        raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
    if on_singular not in ("drop", "raise"):
        raise InvalidInputError(f"on_singular: {on_singular!r} is not 'drop' or 'raise'")
    threads = count(num_threads, "num_threads")
    px = as_points(pixels, "pixels", columns=2, min_points=0)
    idx = as_float_array(frame_index, "frame_index")
    if idx.shape != (len(px),):
        raise ShapeError(f"frame_index: expected {len(px)} frame indices (one per pixel), got shape {idx.shape}")
    check_finite(idx, "frame_index")
    if (idx != np.round(idx)).any():
        raise InvalidInputError("frame_index: frame indices must be whole numbers")
    idx = idx.astype(np.int64)
    ang = as_angles(angles, "angles")
    poses = np.asarray(T_base_flanges, dtype=np.float64) if not isinstance(T_base_flanges, np.ndarray) else T_base_flanges
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) != len(ang):
        raise ShapeError(f"T_base_flanges: expected shape ({len(ang)}, 4, 4), one pose per angle, got {poses.shape}")
    poses = np.ascontiguousarray(np.stack([as_transform(p, f"T_base_flanges[{i}]") for i, p in enumerate(poses)]) if len(poses) else poses.astype(np.float64))
    pts, status = _core.triangulate_scan(
        *_camera_args(calibration.camera),
        np.ascontiguousarray(calibration.T_camera_laser),
        np.ascontiguousarray(calibration.T_flange_camera),
        ang,
        poses,
        px,
        idx,
        threads,
    )
    valid = status == 0
    if not valid.all() and on_singular == "raise":
        i = int(np.argmax(~valid))
        raise SingularGeometryError(
            f"pixels: row {i} {px[i].tolist()} in frame {idx[i]}: {STATUS_REASONS[int(status[i])]}; "
            "check the laser calibration and the motor angle, or pass on_singular='drop'"
        )
    return Cloud(points=pts[valid], frame=idx[valid], pixels=px[valid], angle=ang[idx[valid]] if len(ang) else np.zeros(0))
