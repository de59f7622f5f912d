"""The simulated cell: physics piles of parts in a bin and the eye-in-hand camera with its swept
laser line, rendered as the real camera would grab them, with depth and instance-id ground truth;
and the digital twin (:class:`SimulatedCell`): the pick loop on emulated devices over ptys.

* :mod:`~binpick.sim.cell` — the layout: camera, laser, lighting, noise, bin, scan pose
* :mod:`~binpick.sim.pile`, :mod:`~binpick.sim.render` — physics piles and the renderer
* :mod:`~binpick.sim.sensors` — depth cameras (structured light, Kinect-like, time of flight) at fixed
  poses, their published noise models, and :func:`render_depth`
* :mod:`~binpick.sim.dataset` — simulated scans written to disk
* :mod:`~binpick.sim.camera` — virtual cameras for the pick loop
* :mod:`~binpick.sim.twin` — :class:`TwinWorld` (the twin's pile and emulators), :class:`SimulatedCell`, its arm
  gripper and limits
* :mod:`~binpick.sim.twin_process` — the twin as its own process (``binpick emulate cell``)

>>> import binpick
>>> from binpick import sim
>>> scan = sim.simulate_scan(binpick.parts.tee(), 12, seed=3)     # doctest: +SKIP
>>> sim.write_scan(scan, "scan/")                                   # doctest: +SKIP
"""

from __future__ import annotations

from .camera import RenderedCamera, SimCamera
from .cell import Bin, Camera, Cell, Laser, Lighting, SensorNoise, look_down, rot_y
from .dataset import GLOSSY_PART_SPECULAR, SimulatedScan, contact_sheet, simulate_scan, write_scan
from .hardware import SIM_ARM, sim_arm, sim_gripper, sim_limits
from .pile import Pile, PushReport, SettleReport, convex_decomposition, max_interpenetration
from .render import BIN_ID, NO_SURFACE, TABLE_ID, Surfaces, View, World, render_checkerboard
from .sensors import DepthCamera, DepthFrame, DepthNoise, render_depth
from .twin import SimulatedCell, TwinWorld, simulated_cell

__all__ = [
    "BIN_ID",
    "GLOSSY_PART_SPECULAR",
    "Bin",
    "Camera",
    "Cell",
    "DepthCamera",
    "DepthFrame",
    "DepthNoise",
    "Laser",
    "Lighting",
    "NO_SURFACE",
    "RenderedCamera",
    "SIM_ARM",
    "sim_arm",
    "sim_gripper",
    "SimCamera",
    "SimulatedCell",
    "Pile",
    "SensorNoise",
    "PushReport",
    "SettleReport",
    "SimulatedScan",
    "Surfaces",
    "TABLE_ID",
    "TwinWorld",
    "View",
    "World",
    "contact_sheet",
    "convex_decomposition",
    "look_down",
    "max_interpenetration",
    "render_checkerboard",
    "render_depth",
    "rot_y",
    "sim_limits",
    "simulate_scan",
    "simulated_cell",
    "write_scan",
]
