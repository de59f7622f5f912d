"""Where in a frame the laser line can be: the part of the image onto which the laser sheet's
cut through the working volume projects. Extracting only there skips the pixels no point of
the volume can light (most of the frame: the sheet crosses a bin in a band a few percent of the
image wide), and a reflection outside the band can no longer be taken for the line."""

from __future__ import annotations

from typing import Any, Optional

import cv2
import numpy as np

from .._validate import as_box, as_transform, count, number
from ..calibration._file import CellCalibration
from ..camera import CameraIntrinsics
from ..errors import InvalidInputError
from ..transforms import inverse
from ._extract import extract_line
from ._triangulate import pixel_rays

__all__ = ["LaserWindow"]

#: Points sampled along each edge of the sheet's cut before projecting (the lens bends the edges).
_EDGE_SAMPLES = 16
#: Nearest distance along the optical axis considered, mm.
_NEAR_MM = 1.0
#: The 12 edges of a box, as pairs of its corners numbered by bits (x, y, z).
_BOX_EDGES = np.array(
    [(a, a | bit) for bit in (1, 2, 4) for a in range(8) if not a & bit],
    dtype=np.intp,
)


class LaserWindow:
    """Where the laser line can appear in the frames of one sweep: the pixels whose ray meets the
    laser sheet inside ``volume`` (an axis-aligned box ((xmin, ymin, zmin), (xmax, ymax, zmax))
    in the base frame, mm), seen with the flange at ``T_base_flange``. Built once per sweep;
    :meth:`extract` finds a frame's line there, :meth:`roi` gives the frame's rectangle."""

    def __init__(
        self,
        calibration: CellCalibration,
        T_base_flange: np.ndarray,
        volume: tuple[np.ndarray, np.ndarray] | np.ndarray,
        *,
        pad: int = 8,
    ) -> None:
        if not isinstance(calibration, CellCalibration):
            raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
        lo, hi = as_box(volume, "volume")
        self.pad = count(pad, "pad", 0, 10_000)
        self.calibration = calibration
        T_camera_base = inverse(as_transform(T_base_flange, "T_base_flange") @ calibration.T_flange_camera)
        corners = np.array([[(hi if i >> k & 1 else lo)[k] for k in range(3)] for i in range(8)])
        self._corners = corners @ T_camera_base[:3, :3].T + T_camera_base[:3, 3]
        xmin, xmax, ymin, ymax = _field_of_view(calibration.camera)
        # The view as half-spaces p · n ≥ offset in the camera frame: in front of the lens, and
        # inside the rays through the image border.
        self._view = [
            (np.array(n), offset)
            for n, offset in (
                ((0.0, 0.0, 1.0), _NEAR_MM),
                ((1.0, 0.0, -xmin), 0.0),
                ((-1.0, 0.0, xmax), 0.0),
                ((0.0, 1.0, -ymin), 0.0),
                ((0.0, -1.0, ymax), 0.0),
            )
        ]

    def roi(self, angle: float) -> Optional[tuple[int, int, int, int]]:
        """The image rectangle ``(u0, v0, u1, v1)`` (pixels, half-open) holding every pixel whose
        ray meets the sheet at motor ``angle`` (rad) inside the volume, widened by ``pad``
        pixels on every side; None when the sheet meets no part of the volume in view."""
        angle = number(angle, "angle", -np.pi, np.pi, unit="rad")
        T_camera_laser = self.calibration.T_camera_laser_at(angle)
        # The sheet is the laser frame's plane x = 0; its y and z axes span it.
        normal, inplane = T_camera_laser[:3, 0], T_camera_laser[:3, 1:3]
        polygon = _cut(self._corners, self._corners @ normal - normal @ T_camera_laser[:3, 3], inplane)
        for n, offset in self._view:
            if polygon is None:
                return None
            polygon = _clip(polygon, n, offset)
        if polygon is None:
            return None
        cam = self.calibration.camera
        t = np.linspace(0.0, 1.0, _EDGE_SAMPLES, endpoint=False)[:, None, None]
        samples = (polygon + t * (np.roll(polygon, -1, axis=0) - polygon)).reshape(-1, 3)
        uv, _ = cv2.projectPoints(samples, np.zeros(3), np.zeros(3), cam.K, cam.dist)
        uv = uv.reshape(-1, 2)
        u0, v0 = np.floor(uv.min(axis=0)).astype(int) - self.pad
        u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + self.pad + 1
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, cam.width), min(v1, cam.height)
        if u1 - u0 < 2 or v1 - v0 < 2:
            return None
        return int(u0), int(v0), int(u1), int(v1)

    def extract(self, image: np.ndarray, angle: float, **options: Any) -> np.ndarray:
        """The laser line in ``image``, grabbed with the laser at motor ``angle`` (rad), searched
        only inside :meth:`roi`: :func:`extract_line` (``options`` passed on), or no point (0, 2)
        when the sheet meets no part of the volume in view."""
        roi = self.roi(angle)
        return np.zeros((0, 2)) if roi is None else extract_line(image, roi=roi, **options)


def _cut(corners: np.ndarray, side: np.ndarray, inplane: np.ndarray) -> Optional[np.ndarray]:
    """The convex polygon (K, 3), in order around it, where the plane ``side == 0`` (spanned by
    the columns of ``inplane``) cuts the box with these corners; None when it misses the box or
    only touches it."""
    a, b = corners[_BOX_EDGES[:, 0]], corners[_BOX_EDGES[:, 1]]
    sa, sb = side[_BOX_EDGES[:, 0]], side[_BOX_EDGES[:, 1]]
    crossing = (sa < 0) != (sb < 0)
    t = sa[crossing] / (sa[crossing] - sb[crossing])
    points = a[crossing] + t[:, None] * (b[crossing] - a[crossing])
    if len(points) < 3:
        return None
    flat = (points - points.mean(axis=0)) @ inplane
    return points[np.argsort(np.arctan2(flat[:, 1], flat[:, 0]))]


def _clip(polygon: np.ndarray, normal: np.ndarray, offset: float) -> Optional[np.ndarray]:
    """The part of a convex polygon where ``p · normal ≥ offset`` (Sutherland–Hodgman, one
    plane); None when nothing with area is left."""
    d = polygon @ normal - offset
    if (d >= 0).all():
        return polygon
    out = []
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if d[i] >= 0:
            out.append(polygon[i])
        if (d[i] >= 0) != (d[j] >= 0):
            out.append(polygon[i] + d[i] / (d[i] - d[j]) * (polygon[j] - polygon[i]))
    return np.array(out) if len(out) >= 3 else None


def _field_of_view(cam: CameraIntrinsics) -> tuple[float, float, float, float]:
    """The camera's view as bounds on x/z and y/z: those of the rays through the image border,
    where the calibrated lens model holds (beyond it a polynomial distortion can fold back)."""
    u = np.linspace(0.0, cam.width - 1.0, 65)
    v = np.linspace(0.0, cam.height - 1.0, 65)
    border = np.concatenate(
        [np.stack([u, np.zeros_like(u)], 1), np.stack([u, np.full_like(u, cam.height - 1.0)], 1)]
        + [np.stack([np.zeros_like(v), v], 1), np.stack([np.full_like(v, cam.width - 1.0), v], 1)]
    )
    rays = pixel_rays(border, cam)
    return float(rays[:, 0].min()), float(rays[:, 0].max()), float(rays[:, 1].min()), float(rays[:, 1].max())
