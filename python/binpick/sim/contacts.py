"""Contacts of the gripper with the world along a motion: the simulated cell's and the twin's
collision check (the physics' view, not the planner's).

A motion of the arm is a path of gripper poses; at each, the gripper's solids (fingers at their
opening now, palm) are checked against every part in the bin other than the one held (its true
pose and its model's points) and against the bin's walls and floor. A part's surface counts
only when it lies more than :data:`binpick.cell.grasp.GRAZE_MM` inside a solid, the tolerance
the planner allows a finger's edge (so planner and physics judge a grasp alike); the bin's walls
count at any depth. Lengths in mm, transforms 4×4 ``T_to_from``."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..cell.config import GripperGeometry
from ..cell.grasp import GRAZE_MM
from ..transforms import inverse

__all__ = ["Contact", "contacts_along", "bin_contact_points"]


@dataclass(frozen=True)
class Contact:
    """What the gripper touched along a motion: ``what`` (``"part 3"``, ``"bin"``), the most
    points inside the gripper at one pose of the path, and the first pose (index into the path)
    where it touched."""

    what: str
    points: int
    first: int


def bin_contact_points(
    gripper: GripperGeometry, T_base_gripper: np.ndarray, opening_mm: float, bounds: tuple, wall_mm: float
) -> np.ndarray:
    """How many of the gripper's outline points (:meth:`GripperGeometry.outline`) lie inside the
    bin's walls or under its floor, at each of the poses (K, 4, 4): (K,) counts."""
    outline = gripper.outline(max(float(opening_mm), 1.0))
    pts = np.einsum("kij,mj->kmi", T_base_gripper[:, :3, :3], outline) + T_base_gripper[:, None, :3, 3]
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    t = float(wall_mm)
    in_outer = ((pts[..., :2] >= lo[:2] - t) & (pts[..., :2] <= hi[:2] + t)).all(axis=-1)
    in_outer &= (pts[..., 2] >= lo[2] - t) & (pts[..., 2] <= hi[2])
    in_inner = ((pts >= lo) & (pts <= hi)).all(axis=-1)
    return (in_outer & ~in_inner).sum(axis=-1)


def contacts_along(
    gripper: GripperGeometry,
    T_base_gripper: np.ndarray,
    opening_mm: float,
    parts: Iterable[tuple[int, np.ndarray]],
    model_points: np.ndarray,
    *,
    bounds: tuple,
    wall_mm: float,
    held: Optional[int] = None,
) -> list[Contact]:
    """Every contact of the gripper along the path ``T_base_gripper`` (K, 4, 4), the fingers
    ``opening_mm`` apart: with each part (id, true ``T_base_object``) but ``held``, whose surface
    is sampled by ``model_points`` (model frame), and with the bin (``bounds`` of its inner
    volume, walls ``wall_mm`` thick)."""
    path = np.asarray(T_base_gripper, dtype=np.float64).reshape(-1, 4, 4)
    found: list[Contact] = []
    n_bin = bin_contact_points(gripper, path, opening_mm, bounds, wall_mm)
    if n_bin.any():
        found.append(Contact("bin", int(n_bin.max()), int(np.flatnonzero(n_bin)[0])))
    pts = np.asarray(model_points, dtype=np.float64)
    centre = pts.mean(axis=0)
    radius = float(np.linalg.norm(pts - centre, axis=1).max())
    # The box (gripper frame) round the fingers at this opening and the palm: a part whose
    # bounding sphere stays clear of it at a pose is not touched there.
    top = gripper.tip_depth_mm - gripper.finger_length_mm
    half_x = max(float(opening_mm) / 2 + gripper.finger_thickness_mm, gripper.body_radius_mm)
    half_y = max(gripper.finger_width_mm / 2, gripper.body_radius_mm)
    box_lo = np.array([-half_x, -half_y, top - gripper.body_length_mm])
    box_hi = np.array([half_x, half_y, gripper.tip_depth_mm])
    inv = np.stack([inverse(T) for T in path])
    pts32 = pts.astype(np.float32)
    for pid, T_bo in parts:
        if held is not None and int(pid) == int(held):
            continue
        T_bo = np.asarray(T_bo, dtype=np.float64)
        c = T_bo[:3, :3] @ centre + T_bo[:3, 3]
        c_local = np.einsum("kij,j->ki", inv[:, :3, :3], c) + inv[:, :3, 3]
        gap = np.linalg.norm(np.maximum(0.0, np.maximum(box_lo - c_local, c_local - box_hi)), axis=1)
        near = np.flatnonzero(gap <= radius)
        if not len(near):
            continue
        T_go = (inv[near] @ T_bo).astype(np.float32)
        local = pts32 @ T_go[:, :3, :3].transpose(0, 2, 1) + T_go[:, None, :3, 3]
        inside = gripper.occupied(local, opening_mm, margin_mm=GRAZE_MM).sum(axis=1)
        if inside.any():
            found.append(Contact(f"part {int(pid)}", int(inside.max()), int(near[np.flatnonzero(inside)[0]])))
    return found
