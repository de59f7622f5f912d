"""binpick — eye-in-hand laser-line robotic bin picking.

Scan a pile with a camera and a swept laser line, triangulate a point cloud, segment the top
part, estimate its 6-DoF pose against the part's CAD model and compute the grip pose.
Lengths are millimetres, angles radians; transforms are 4×4 arrays named ``T_to_from``.
"""

from __future__ import annotations

from . import _core
from . import parts
from .errors import (
    BinpickError,
    CalibrationError,
    DegenerateCloudError,
    DeviceError,
    DeviceTimeout,
    DTypeError,
    InternalError,
    InvalidInputError,
    MeshFileError,
    MeshFileNotFoundError,
    NoObjectFound,
    NonFiniteError,
    ProtocolError,
    SafetyError,
    ShapeError,
    TooFewPointsError,
    UnknownUnitError,
)
from .models import Branch, Model, estimate_normals, read_ply, voxel_downsample, write_ply
from .poses import IcpResult, PoseResult, estimate_pose, grasp_pose, icp

__version__ = _core.__version__

__all__ = [
    "__version__",
    "BinpickError",
    "Branch",
    "CalibrationError",
    "DegenerateCloudError",
    "DeviceError",
    "DeviceTimeout",
    "DTypeError",
    "IcpResult",
    "InternalError",
    "InvalidInputError",
    "MeshFileError",
    "MeshFileNotFoundError",
    "Model",
    "NoObjectFound",
    "NonFiniteError",
    "ProtocolError",
    "SafetyError",
    "ShapeError",
    "TooFewPointsError",
    "UnknownUnitError",
    "estimate_normals",
    "estimate_pose",
    "grasp_pose",
    "PoseResult",
    "icp",
    "parts",
    "read_ply",
    "voxel_downsample",
    "write_ply",
]
