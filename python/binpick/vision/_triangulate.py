"""Triangulation of laser-line pixels into points of the robot's base frame (paper Eq. 10–14,
generalised to a full projector pose, lens distortion and the robot pose of each frame)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import _core
from .._validate import as_angles, as_float_array, as_points, as_transform, check_finite, choice, thread_count
from ..calibration._file import CellCalibration
from ..camera import CameraIntrinsics, camera_args
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


def pixel_rays(pixels: np.ndarray, camera: CameraIntrinsics) -> np.ndarray:
    """Undistorted rays ``(x, y, 1)`` in the camera frame through ``pixels`` (N, 2) of (u, v).

    Raises SingularGeometryError if the distortion cannot be inverted at some pixel."""
    px = as_points(pixels, "pixels", columns=2, min_points=0)
    rays = _core.pixel_rays(camera_args(camera), px)
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

    Rays come from a table of the camera's rays built once per camera (a few ms, then cached)
    and one Newton step; they agree with :func:`pixel_rays` (Newton to convergence) to about
    1e-7 px.
    """
    if not isinstance(calibration, CellCalibration):
        raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
    choice(on_singular, "on_singular", ("drop", "raise"))
    threads = thread_count(num_threads)
    # NaN and pixels outside the image are named by the core's checks (NonFiniteError, InvalidInputError).
    px = as_float_array(pixels, "pixels")
    if px.ndim != 2 or px.shape[1] != 2:
        raise ShapeError(f"pixels: expected an (N, 2) array of (u, v), got shape {px.shape}")
    idx = _frame_indices(frame_index, len(px))
    ang = as_angles(angles, "angles")
    poses = _poses(T_base_flanges, len(ang))
    pts, status, kept_pixels, kept = _core.triangulate_scan(
        camera_args(calibration.camera),
        np.ascontiguousarray(calibration.T_camera_laser),
        np.ascontiguousarray(calibration.T_flange_camera),
        ang,
        poses,
        px,
        idx,
        threads,
    )
    # The core moved the pixels that gave a point, and their points, to the front, in order.
    if kept == len(px):
        return Cloud(points=pts, frame=idx.copy() if idx is frame_index else idx, pixels=kept_pixels, angle=ang[idx])
    if on_singular == "raise":
        i = int(np.argmax(status != 0))
        raise SingularGeometryError(
            f"pixels: row {i} {px[i].tolist()} in frame {idx[i]}: {STATUS_REASONS[int(status[i])]}; "
            "check the laser calibration and the motor angle, or pass on_singular='drop'"
        )
    idx = idx[status == 0]
    return Cloud(points=pts[:kept], frame=idx, pixels=kept_pixels[:kept], angle=ang[idx])


def _frame_indices(frame_index: np.ndarray | Sequence[int], n: int) -> np.ndarray:
    """The frame indices as int64 (whole numbers given as floats accepted); their range is
    checked by the core."""
    raw = np.asarray(frame_index)
    if raw.dtype.kind in "iu" and raw.dtype.itemsize <= 8 and raw.dtype != np.uint64:
        idx = np.ascontiguousarray(raw, dtype=np.int64)
        if idx.shape != (n,):
            raise ShapeError(f"frame_index: expected {n} frame indices (one per pixel), got shape {idx.shape}")
        return idx
    idx = as_float_array(frame_index, "frame_index")
    if idx.shape != (n,):
        raise ShapeError(f"frame_index: expected {n} frame indices (one per pixel), got shape {idx.shape}")
    check_finite(idx, "frame_index")
    if (idx != np.round(idx)).any():
        raise InvalidInputError("frame_index: frame indices must be whole numbers")
    huge = np.abs(idx) > 2**62
    if huge.any():
        i = int(np.argmax(huge))
        raise InvalidInputError(f"frame_index: entry {i} is {idx[i]}, beyond any frame of the scan")
    return idx.astype(np.int64)


def _poses(T_base_flanges: np.ndarray | Sequence[np.ndarray], frames: int) -> np.ndarray:
    """The flange poses as a C-contiguous (frames, 4, 4) float64 stack of rigid transforms,
    checked all at once; a bad one is named by :func:`as_transform`."""
    poses = as_float_array(T_base_flanges, "T_base_flanges")
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) != frames:
        raise ShapeError(f"T_base_flanges: expected shape ({frames}, 4, 4), one pose per angle, got {poses.shape}")
    rot = poses[:, :3, :3]
    gram = np.einsum("fji,fjk->fik", rot, rot) - np.eye(3)
    good = (
        np.isfinite(poses).all(axis=(1, 2))
        & (np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]) <= 1e-9).all(axis=1)
        & (np.abs(gram).max(axis=(1, 2), initial=0.0) <= 1e-6)
        & (np.linalg.det(rot) >= 0 if frames else True)
    )
    for i in np.flatnonzero(~good):
        as_transform(poses[i], f"T_base_flanges[{i}]")
    return poses
