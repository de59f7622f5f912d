"""Simulated scans written as real ones: frames, angles, calibration, ground truth, contact sheet."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .._sizes import check_part
from .._validate import MAX_IMAGE_SIDE, MAX_SHEET_TILES, count, instance_of, non_negative, thread_count
from ..errors import FileWriteError, InvalidInputError
from ..models import Model
from ..transforms import MAX_SWEEP_FRAMES
from .cell import Cell
from .pile import Pile
from .render import View, World

__all__ = ["GLOSSY_PART_SPECULAR", "SimulatedScan", "simulate_scan", "write_scan", "contact_sheet"]

#: The parts' specular strength in scans rendered with reflections (machined brass or chrome-like).
GLOSSY_PART_SPECULAR = 0.5


@dataclass(frozen=True, eq=False)
class SimulatedScan:
    """A rendered scan in memory: RGB ``frames`` (K, H, W, 3) uint8, motor ``angles`` (rad), the
    robot pose, the cell, the pile, the ``view`` (depth / id ground truth) and the ``world`` it was
    rendered from (exact distances to its surfaces: :meth:`World.nearest_surface`)."""

    frames: np.ndarray
    angles: np.ndarray
    T_base_flange: np.ndarray
    cell: Cell
    pile: Pile
    view: View
    world: Optional[World] = None

    def ground_truth(self) -> dict:
        """The ground_truth.json document."""
        return {
            "version": 1,
            "part": self.pile.model.name,
            "ids": [int(i) for i in self.pile.ids],
            "T_base_object": [T.tolist() for T in self.pile.poses],
            "bin": self.cell.bin.bounds.tolist(),
        }


def simulate_scan(
    model: Model,
    count_: int = 12,
    *,
    seed: int = 0,
    frames: int = 90,
    cell: Optional[Cell] = None,
    part_specular: Optional[float] = None,
    num_threads: int = 0,
) -> SimulatedScan:
    """Drops ``count_`` parts into the cell's bin (seeded), casts the view from the scan pose once,
    and renders ``frames`` laser frames sweeping the bin.

    ``part_specular`` is the parts' gloss (the laser's mirror highlight and what
    ``cell.noise.reflections`` bounces off them); None makes them glossy
    (:data:`GLOSSY_PART_SPECULAR`) when the cell's noise has reflections and matte otherwise, so
    that ``binpick simulate --reflections`` shows them."""
    cell = Cell() if cell is None else instance_of(cell, Cell, "cell", "binpick.sim.Cell()")
    thread_count(num_threads)
    # Before the pile drops: a part the bin holds, of a size a cell picks (binpick._sizes).
    check_part(instance_of(model, Model, "model", "binpick.parts.tee()"), bin_bounds=cell.bin.bounds)
    if part_specular is None:
        part_specular = GLOSSY_PART_SPECULAR if cell.noise.reflections > 0 else 0.0
    pile = Pile(model, count_, bin=cell.bin, seed=seed)
    world = World.of_pile(pile, part_specular=non_negative(part_specular, "part_specular"))
    view = world.view(cell, num_threads=num_threads)
    angles = cell.sweep(count(frames, "frames", 1, MAX_SWEEP_FRAMES))
    imgs = view.frames(angles, seed=seed, num_threads=num_threads)
    return SimulatedScan(
        frames=imgs, angles=angles, T_base_flange=cell.T_base_flange, cell=cell, pile=pile, view=view, world=world
    )


def contact_sheet(frames: np.ndarray, *, picks: int = 6, columns: int = 3, width: int = 1200) -> np.ndarray:
    """A BGR image tiling ``picks`` evenly chosen RGB frames, each labelled with its index."""
    import cv2

    if not isinstance(frames, np.ndarray) or frames.dtype != np.uint8:
        raise InvalidInputError("frames: expected a uint8 array of (K, H, W, 3) RGB frames")
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise InvalidInputError(f"frames: expected (K, H, W, 3) RGB frames, got shape {frames.shape}")
    picks = count(picks, "picks", 1, MAX_SHEET_TILES)
    columns = count(columns, "columns", 1, MAX_SHEET_TILES)
    width = count(width, "width", columns, MAX_IMAGE_SIDE)
    idx = np.unique(np.linspace(0, len(frames) - 1, min(picks, len(frames))).round().astype(int))
    h, w = frames.shape[1:3]
    tw = max(1, width // columns)
    th = max(1, int(round(h * tw / w)))
    rows = int(np.ceil(len(idx) / columns))
    sheet = np.zeros((rows * th, columns * tw, 3), dtype=np.uint8)
    for k, i in enumerate(idx):
        tile = cv2.resize(np.ascontiguousarray(frames[i][:, :, ::-1]), (tw, th), interpolation=cv2.INTER_AREA)
        cv2.putText(tile, f"frame {i}", (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2)
        r, c = divmod(k, columns)
        sheet[r * th : (r + 1) * th, c * tw : (c + 1) * tw] = tile
    return sheet


def write_scan(scan: SimulatedScan, directory: str | os.PathLike[str]) -> Path:
    """Writes ``scan`` as a scan folder binpick reads like a real one (``binpick.scan.load_scan``):
    frames/NNN.png, scan.json, calibration.toml, ground_truth.json, contact_sheet.png."""
    import cv2

    from ..scan import save_scan

    instance_of(scan, SimulatedScan, "scan", "binpick.sim.simulate_scan(model)")
    root = save_scan(
        directory,
        [np.ascontiguousarray(f[:, :, ::-1]) for f in scan.frames],
        scan.angles,
        [scan.T_base_flange] * len(scan.frames),
        scan.cell.calibration(),
        ground_truth=scan.ground_truth(),
    )
    path = Path(root) / "contact_sheet.png"
    if not cv2.imwrite(str(path), contact_sheet(scan.frames)):
        raise FileWriteError(f"{path}: cannot write the contact sheet")
    return Path(root)
