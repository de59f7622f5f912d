"""The whole measuring chain on a scan: extract the line in every frame, then triangulate."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_image
from ..errors import InvalidInputError
from ..scan import Scan
from ._extract import extract_line
from ._triangulate import Cloud, triangulate
from ._window import LaserWindow

__all__ = ["reconstruct"]


def reconstruct(scan: Scan, *, volume: Any = None, num_threads: int = 0, **extract_options: Any) -> Cloud:
    """The scan's point cloud in the base frame: :func:`extract_line` on every frame (keyword
    options passed on), then :func:`triangulate`; rays parallel to the laser plane are dropped.
    ``volume`` ((xmin, ymin, zmin), (xmax, ymax, zmax)) mm, optional: look for the line only where
    the sheet can meet it (:class:`LaserWindow`), as the cell does with ``CellConfig.scan_volume``."""
    if not isinstance(scan, Scan):
        raise InvalidInputError(f"scan: expected a binpick.scan.Scan (see load_scan), got {type(scan).__name__}")
    shape = scan.calibration.camera.shape
    windows: dict[bytes, LaserWindow] = {}
    pixels, frames = [], []
    for f, frame in enumerate(scan.frames):
        img = as_image(frame.image(), f"frame {f} ({frame.image_path})", shape=shape)
        if volume is None:
            uv = extract_line(img, **extract_options)
        else:
            key = frame.T_base_flange.tobytes()
            if key not in windows:
                windows[key] = LaserWindow(scan.calibration, frame.T_base_flange, volume)
            uv = windows[key].extract(img, frame.angle, **extract_options)
        pixels.append(uv)
        frames.append(np.full(len(uv), f, dtype=np.int64))
    return triangulate(
        np.concatenate(pixels) if pixels else np.zeros((0, 2)),
        np.concatenate(frames) if frames else np.zeros(0, dtype=np.int64),
        scan.angles,
        scan.T_base_flanges,
        scan.calibration,
        num_threads=num_threads,
    )
