"""Camera intrinsics: the pinhole-and-distortion model the measuring chain calibrates, the
simulator renders with and triangulation inverts (the core holds the one implementation of the
projection, ``binpick_core::Camera``; this is its description on the Python side, handed to the
native module by :func:`camera_args` alike for rendering and for triangulation).

A leaf module: it imports nothing from binpick but the errors and the validation vocabulary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._validate import calibration_matrix, frozen_copy, image_size, number
from .errors import CalibrationError, InvalidInputError

__all__ = ["CameraIntrinsics", "camera_args", "pinhole_matrix"]


def pinhole_matrix(fx: float, fy: float, cx: float, cy: float, skew: float = 0.0) -> np.ndarray:
    """The 3×3 intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`` (pixels); each
    parameter a finite number (InvalidInputError naming it otherwise)."""
    fx, fy, cx, cy, skew = (
        number(v, name, unit="px") for v, name in ((fx, "fx"), (fy, "fy"), (cx, "cx"), (cy, "cy"), (skew, "skew"))
    )
    return np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class CameraIntrinsics:
    """An OpenCV pinhole camera: image size in pixels, ``K`` (3×3) and ``dist = [k1, k2, p1, p2, k3]``.

    Checked on construction: positive focal lengths, principal point inside the image,
    ``K[2] == [0, 0, 1]``; a wrong value raises ``CalibrationError`` naming the field.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray

    def __post_init__(self) -> None:
        width, height = image_size(self.width, self.height, "camera")
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)
        K = calibration_matrix(self.K, "camera.K", (3, 3))
        dist = np.asarray(self.dist, dtype=np.float64).ravel() if not isinstance(self.dist, str) else self.dist
        dist = calibration_matrix(dist, "camera.dist", (5,))
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(f"camera.K: focal lengths fx={K[0, 0]:g}, fy={K[1, 1]:g} must be positive (pixels)")
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
            raise CalibrationError(f"camera.K: must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        if not (0 <= K[0, 2] <= self.width and 0 <= K[1, 2] <= self.height):
            raise CalibrationError(
                f"camera.K: principal point ({K[0, 2]:g}, {K[1, 2]:g}) lies outside the "
                f"{self.width}×{self.height} image; K and the image size do not belong together"
            )
        object.__setattr__(self, "K", frozen_copy(K))
        object.__setattr__(self, "dist", frozen_copy(dist))

    @classmethod
    def pinhole(
        cls,
        width: int,
        height: int,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        dist: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0),
        skew: float = 0.0,
    ) -> CameraIntrinsics:
        """A camera from its pinhole parameters (pixels) and ``dist = [k1, k2, p1, p2, k3]``; each
        parameter a finite number (InvalidInputError naming it otherwise; :func:`pinhole_matrix` checks them)."""
        return cls(width=width, height=height, K=pinhole_matrix(fx, fy, cx, cy, skew), dist=dist)

    @property
    def fx(self) -> float:
        """Focal length along x, px."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along y, px."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x, px."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y, px."""
        return float(self.K[1, 2])

    @property
    def skew(self) -> float:
        """The skew term K[0, 1], px (0 for the cameras OpenCV calibrates)."""
        return float(self.K[0, 1])

    @property
    def shape(self) -> tuple[int, int]:
        """The image shape as numpy writes it: ``(height, width)``."""
        return (self.height, self.width)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraIntrinsics):
            return NotImplemented
        return (
            (self.width, self.height) == (other.width, other.height)
            and np.array_equal(self.K, other.K)
            and np.array_equal(self.dist, other.dist)
        )

    def __repr__(self) -> str:
        K = self.K
        return (
            f"CameraIntrinsics({self.width}×{self.height}, fx={K[0, 0]:.2f}, fy={K[1, 1]:.2f}, "
            f"cx={K[0, 2]:.2f}, cy={K[1, 2]:.2f}, dist={np.round(self.dist, 5).tolist()})"
        )


def camera_args(camera: Any) -> tuple[int, int, np.ndarray, np.ndarray]:
    """The camera as the native module takes it, for the renderer and triangulation alike:
    ``(width, height, K, dist)``; anything but a :class:`CameraIntrinsics` raises InvalidInputError."""
    if not isinstance(camera, CameraIntrinsics):
        raise InvalidInputError(
            "camera: expected a binpick.camera.CameraIntrinsics (CameraIntrinsics.pinhole(...) or "
            f"binpick.sim.Camera(...)), got {type(camera).__name__}"
        )
    return camera.width, camera.height, np.ascontiguousarray(camera.K), np.ascontiguousarray(camera.dist)
