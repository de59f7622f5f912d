"""Calibration of the measuring chain: the cell's calibration file, camera intrinsics,
the laser projector (the paper's Table 1), the general laser plane and hand-eye."""

from __future__ import annotations

from ..camera import CameraIntrinsics
from ._file import FORMAT_VERSION, CellCalibration
from .camera import (
    CalibrationLimits,
    CalibrationQuality,
    CameraCalibration,
    board_object_points,
    board_pose,
    calibrate_camera,
    find_checkerboard,
)
from .hand_eye import HAND_EYE_METHODS, HandEyeCalibration, calibrate_hand_eye
from .laser import LaserCalibration, fit_plane, laser_points_on_board
from .projector import ProjectorCalibration, axis_depth, calibrate_projector

__all__ = [
    "FORMAT_VERSION",
    "HAND_EYE_METHODS",
    "CalibrationLimits",
    "CalibrationQuality",
    "CameraCalibration",
    "CameraIntrinsics",
    "CellCalibration",
    "HandEyeCalibration",
    "LaserCalibration",
    "ProjectorCalibration",
    "axis_depth",
    "board_object_points",
    "board_pose",
    "calibrate_camera",
    "calibrate_hand_eye",
    "calibrate_projector",
    "find_checkerboard",
    "fit_plane",
    "laser_points_on_board",
]
