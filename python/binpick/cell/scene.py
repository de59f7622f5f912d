"""The scene the grasp planner checks a pick against: the scan without the part to be picked.

The planner lets each scene point stand for what lies straight below it (no sensor sees under a
surface: a finger may not reach in under one), and checks the part itself whole against its
model at the located pose. So the part's own points must leave the scene — not only those the
segmentation gave it, but every scanned point on its surface: a stray point of its top left in
the scene stands for a column through the part, and a finger closing on the part beside it
meets that column (a heap of ring screws, each with a few points of its ring left out, had no
usable grasp).

What the part hides under itself is then not in the scene: a finger that reaches in under the
part may meet a neighbour it lies on. Measured over 10 ring-screw heaps, that is 4 touches in 100
picks; letting the part's own points stand for the space under its underside prevented 2 of
them and left 15 of the 100 parts in the bin (no grasp), so it is not done."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..models import nearest_distances

__all__ = ["OWN_POINT_MM", "near_part", "planner_scene"]

#: Scanned points within this distance (mm) of the located part's model belong to the part: the
#: scan's noise, the pose's error at the part's far end and the model's sampling together.
OWN_POINT_MM = 4.0


def near_part(points: np.ndarray, part_points: np.ndarray, radius: float = OWN_POINT_MM) -> np.ndarray:
    """Which ``points`` (N, 3) lie within ``radius`` mm of one of the posed part's
    ``part_points`` (only those in the part's box are measured): (N,) bool."""
    lo, hi = part_points.min(axis=0) - radius, part_points.max(axis=0) + radius
    out = np.zeros(len(points), dtype=bool)
    cand = np.flatnonzero(((points >= lo) & (points <= hi)).all(axis=1))
    out[cand] = nearest_distances(points[cand], part_points) <= radius
    return out


def planner_scene(points: Any, own: Any, T_base_object: Any, model: Any) -> np.ndarray:
    """The scan ``points`` (N, 3, base frame) the planner checks the pick of the part at
    ``T_base_object`` against (:func:`~binpick.cell.grasp.plan_grasp`'s ``scene``): all but the
    part's ``own`` (its indices in the scan) and those within :data:`OWN_POINT_MM` of ``model``'s
    points there (its surface the segmentation left out)."""
    pts = np.asarray(points, dtype=np.float64)
    keep = np.ones(len(pts), dtype=bool)
    idx = np.asarray(own, dtype=np.int64).reshape(-1)
    keep[idx[(idx >= 0) & (idx < len(pts))]] = False
    T = np.asarray(T_base_object, dtype=np.float64)
    keep[keep] = ~near_part(pts[keep], np.asarray(model.points) @ T[:3, :3].T + T[:3, 3])
    return pts[keep]
