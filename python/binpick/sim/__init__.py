"""The simulated cell: physics piles of parts in a bin and the eye-in-hand camera with its swept
laser line, rendered as the real camera would grab them, with depth and instance-id ground truth.

>>> import binpick
>>> from binpick import sim
>>> scan = sim.simulate_scan(binpick.parts.tee(), 12, seed=3)     # doctest: +SKIP
>>> sim.write_scan(scan, "scan/")                                   # doctest: +SKIP
"""

from __future__ import annotations

from .cell import Bin, Camera, Cell, Laser, Lighting, SensorNoise, look_down, rot_y
from .dataset import GLOSSY_PART_SPECULAR, SimulatedScan, contact_sheet, simulate_scan, write_scan
from .pile import Pile, SettleReport, convex_decomposition, max_interpenetration
from .render import BIN_ID, NO_SURFACE, TABLE_ID, View, World, render_checkerboard

__all__ = [
    "BIN_ID",
    "GLOSSY_PART_SPECULAR",
    "Bin",
    "Camera",
    "Cell",
    "Laser",
    "Lighting",
    "NO_SURFACE",
    "Pile",
    "SensorNoise",
    "SettleReport",
    "SimulatedScan",
    "TABLE_ID",
    "View",
    "World",
    "contact_sheet",
    "convex_decomposition",
    "look_down",
    "max_interpenetration",
    "render_checkerboard",
    "rot_y",
    "simulate_scan",
    "write_scan",
]
