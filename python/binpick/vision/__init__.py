"""From camera frames to points: laser-line extraction (BGR → YCrCb, threshold on Cr, one pixel
per scan line, sub-pixel centre) and triangulation into the robot's base frame."""

from __future__ import annotations

from ._extract import describe_frames, extract_line, laser_mask, red_excess
from ._reconstruct import reconstruct
from ._triangulate import Cloud, pixel_rays, triangulate
from ._window import LaserWindow

__all__ = [
    "describe_frames",
    "Cloud",
    "LaserWindow",
    "extract_line",
    "laser_mask",
    "laser_window",
    "pixel_rays",
    "reconstruct",
    "red_excess",
    "triangulate",
]
