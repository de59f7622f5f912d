"""Calibration of the measuring chain: the cell's calibration file, camera intrinsics,
the laser projector (the paper's Table 1), the general laser plane and hand-eye."""

from __future__ import annotations

from ._file import FORMAT_VERSION, CameraIntrinsics, CellCalibration

__all__ = ["FORMAT_VERSION", "CameraIntrinsics", "CellCalibration"]
