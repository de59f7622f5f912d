"""Helpers shared by the cell tests."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import MappingProxyType, SimpleNamespace
from typing import Any

import numpy as np

from binpick.cell.records import Located, ScanResult


def located(T_base_object: np.ndarray, result: Any) -> Located:
    """A located part at ``T_base_object`` with pose result ``result`` and an empty scan."""
    scan = ScanResult(
        cloud=SimpleNamespace(points=np.zeros((0, 3))),
        angles=np.zeros(0),
        T_base_flanges=np.zeros((0, 4, 4)),
        frames=MappingProxyType({}),
        timings=MappingProxyType({}),
    )
    return Located(scan=scan, result=result, T_base_object=T_base_object, indices=np.zeros(0, dtype=np.int64))


@contextmanager
def emulators() -> Iterator[tuple[Any, Any, Any]]:
    """The robot (the simulated cell's arm, 20 times faster than life), laser motor and gripper
    emulators on their ptys."""
    from binpick.devices.emulators import DynamixelEmulator, GripperEmulator, RobotEmulator, RobotEmulatorConfig
    from binpick.sim import SIM_ARM

    with ExitStack() as stack:
        robot = stack.enter_context(RobotEmulator(config=RobotEmulatorConfig(arm=SIM_ARM, speed_scale=20.0)))
        yield robot, stack.enter_context(DynamixelEmulator()), stack.enter_context(GripperEmulator())


def emulated_cell_file(
    folder: Path, robot: Any, motor: Any, gripper: Any, *, camera: str, frames: int = 60, tail: str = ""
) -> Path:
    """``folder/cell.toml`` for the emulators ``robot``, ``motor`` and ``gripper`` in the simulated
    cell's layout, with its calibration (written beside it) and limits, ``frames`` a scan, the
    ``[camera]`` table's lines ``camera`` and any further tables ``tail``."""
    from binpick.sim import Cell as Layout
    from binpick.sim import sim_limits

    layout = Layout()
    layout.calibration().save(folder / "calibration.toml")
    limits = sim_limits(layout)
    lo, hi = layout.bin.bounds
    path = folder / "cell.toml"
    path.write_text(f"""
[robot]
port = "{robot.slave_path}"
override_percent = 50
linear_speed_mm_s = 250
[motor]
port = "{motor.slave_path}"
[gripper]
port = "{gripper.slave_path}"
[camera]
{camera}
[part]
model = "tee"
[cell]
calibration = "calibration.toml"
bin_min_mm = {lo.tolist()}
bin_max_mm = {hi.tolist()}
scan_pose = [400.0, 0.0, 620.0, 180.0, 0.0, 0.0]
drop_pose = [400.0, -250.0, 350.0, 180.0, 0.0, 0.0]
frames = {frames}
{tail}
[limits]
workspace_min_mm = {list(limits.workspace_min_mm)}
workspace_max_mm = {list(limits.workspace_max_mm)}
approach_height_mm = {limits.approach_height_mm}
""")
    return path


def recording_tee_cell(**settings: Any) -> Any:
    """A started simulated cell of tees (``settings``: the pile's count and seed, the frames, the
    cell's options), searched with the cell tests' fast estimate options; every (stage, message)
    it prints is kept in its ``lines``."""
    import binpick
    from binpick.sim import SimulatedCell

    lines: list[tuple[str, str]] = []
    sim = SimulatedCell(
        binpick.parts.tee(),
        estimate_options={"d_star": 12.0, "min_points": 500},
        progress=lambda s, m: lines.append((s, m)),
        **settings,
    )
    sim.lines = lines
    sim.start()
    return sim
