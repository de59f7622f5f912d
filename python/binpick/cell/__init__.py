"""The cell: the pick loop and what it works with.

* :mod:`~binpick.cell.config` — :class:`CellConfig`, :class:`GripperGeometry`, the laser sweep
* :mod:`~binpick.cell.records` — :class:`ScanResult`, :class:`Located`, :class:`PickPlan`, :class:`PickRecord`, …
* :mod:`~binpick.cell.frames` — :class:`FrameSource`, :class:`OpenCVCamera`, :class:`TwinCamera`,
  :class:`FolderReplay`, :class:`ScanRecorder`
* :mod:`~binpick.cell.grasp` — grasp generation and checks as pure functions
* :mod:`~binpick.cell.nudge` — at a dead end, the closed gripper pushes a blocked part over (plans checked whole)
* :mod:`~binpick.cell.loop` — :class:`Cell`, the pick loop (the same for the simulated and the real cell)
* :mod:`~binpick.cell.cell_file` — the real cell's TOML file

The simulated cell (:class:`binpick.sim.SimulatedCell`) lives in :mod:`binpick.sim`.
"""

from __future__ import annotations

from .cell_file import CELL_FILE_EXAMPLE, CellFile, cell_from_file, config_from_file, load_cell_file
from .config import CellConfig, GripperGeometry, check_static_poses, sweep_angles
from .frames import FolderReplay, FrameSource, OpenCVCamera, ReplayMismatchError, ScanRecorder, TwinCamera
from .grasp import GraspMatcher, NoGraspError, branch_grasps, plan_grasp, symmetry_maps
from .loop import Cell, ProgressPrinter
from .nudge import NudgePlan, NudgeRefused, plan_nudge
from .records import FAILURE_KINDS, Located, PickPlan, PickRecord, PoseTruth, RunReport, ScanResult

__all__ = [
    "CELL_FILE_EXAMPLE",
    "FAILURE_KINDS",
    "Cell",
    "CellConfig",
    "CellFile",
    "FrameSource",
    "GraspMatcher",
    "GripperGeometry",
    "Located",
    "NoGraspError",
    "NudgePlan",
    "NudgeRefused",
    "OpenCVCamera",
    "FolderReplay",
    "ReplayMismatchError",
    "ScanRecorder",
    "TwinCamera",
    "PickPlan",
    "PickRecord",
    "PoseTruth",
    "ProgressPrinter",
    "RunReport",
    "ScanResult",
    "branch_grasps",
    "cell_from_file",
    "check_static_poses",
    "config_from_file",
    "load_cell_file",
    "plan_grasp",
    "plan_nudge",
    "sweep_angles",
    "symmetry_maps",
]
