"""binpick — eye-in-hand laser-line robotic bin picking.

Scan a pile with a camera and a swept laser line, triangulate a point cloud, segment the top
part, estimate its 6-DoF pose against the part's CAD model and compute the grip pose.
Lengths are millimetres, angles radians; transforms are 4×4 arrays named ``T_to_from``.
"""

from __future__ import annotations

from . import _core, parts
from .errors import *  # noqa: F401,F403 - the exception classes are public API
from .errors import __all__ as _error_names
from .models import (
    Branch,
    FreeMotion,
    Model,
    PpfParams,
    Symmetries,
    estimate_normals,
    read_ply,
    scan_noise,
    voxel_downsample,
    write_ply,
)
from .poses import (
    Alternative,
    IcpResult,
    PoseResult,
    SensorModel,
    estimate_pose,
    estimate_poses,
    grasp_pose,
    icp,
    verify_pose,
)

__version__ = _core.__version__

# Subpackages and names that pull in OpenCV, serial I/O or the simulator load on first use.
_LAZY_MODULES = ("calibration", "camera", "clouds", "cell", "devices", "scan", "sim", "transforms", "vision", "viz")
_LAZY_NAMES = {
    "Cloud": "vision",
    "SceneCloud": "clouds",
    "read_scene": "clouds",
    "write_scene": "clouds",
    "extract_line": "vision",
    "triangulate": "vision",
    "reconstruct": "vision",
    "CameraIntrinsics": "camera",
    "pose_error": "transforms",
    "CellCalibration": "calibration",
    "Scan": "scan",
    "load_scan": "scan",
    "save_scan": "scan",
    "Cell": "cell",
    "CellConfig": "cell",
    "PickRecord": "cell",
    "simulated_cell": "sim",
    "validate": "sim.validate",
}


def __getattr__(name: str):
    import importlib

    if name in _LAZY_MODULES:
        return importlib.import_module(f".{name}", __name__)
    if name in _LAZY_NAMES:
        return getattr(importlib.import_module(f".{_LAZY_NAMES[name]}", __name__), name)
    raise AttributeError(f"module 'binpick' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_MODULES) | set(_LAZY_NAMES))


__all__ = [
    "__version__",
    "Branch",
    "IcpResult",
    "Model",
    "PoseResult",
    "SensorModel",
    "Alternative",
    "PpfParams",
    "Symmetries",
    "estimate_normals",
    "scan_noise",
    "FreeMotion",
    "estimate_pose",
    "estimate_poses",
    "verify_pose",
    "grasp_pose",
    "icp",
    "parts",
    "read_ply",
    "voxel_downsample",
    "write_ply",
    *_error_names,
    *_LAZY_MODULES,
    *_LAZY_NAMES,
]
