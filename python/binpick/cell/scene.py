"""The scene the grasp planner checks a pick against: the scan, the part to be picked standing
for what it hides.

The planner lets each scene point stand for what lies straight below it (no sensor sees under a
surface: a finger may not reach in under one), and checks the part itself whole against its
model at the located pose. So a point on the part's surface must not stand for the column
through the part — not only the points the segmentation gave the part, but every scanned point
on its surface (a stray point of a ring's top left in the scene stands for a column down through
the ring, which a tilted finger closing on the ring meets: a heap of ring screws had no usable
grasp) — but neither may it leave the scene: what the part hides under itself is no more known
to be free than what a neighbour hides (dropped, they let a finger in under a ring onto the
neighbour it lay on). Each moves down onto the part's underside below it."""

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
    ``T_base_object`` against (:func:`~binpick.cell.grasp.plan_grasp`'s ``scene``), each standing
    for what lies straight below it: the points not the part's — neither its ``own`` (its indices
    in the scan) nor within :data:`OWN_POINT_MM` of ``model``'s points there (its surface the
    segmentation left out) — and, for each of the part's, a point on the part's underside below
    it (:func:`_underside`): what the part hides under itself is no more known to be free than
    what a neighbour hides, but the part itself is checked whole against its model."""
    pts = np.asarray(points, dtype=np.float64)
    mine = np.zeros(len(pts), dtype=bool)
    idx = np.asarray(own, dtype=np.int64).reshape(-1)
    mine[idx[(idx >= 0) & (idx < len(pts))]] = True
    T = np.asarray(T_base_object, dtype=np.float64)
    part = np.asarray(model.points) @ T[:3, :3].T + T[:3, 3]
    mine[~mine] = near_part(pts[~mine], part)
    return np.concatenate([pts[~mine], _underside(pts[mine], part)])


#: The cells (mm) of the part's footprint over which its underside is looked up: about its
#: sample points' spacing, so that each cell under the part holds some of them.
_UNDERSIDE_CELL_MM = 2.0


def _underside(points: np.ndarray, part: np.ndarray) -> np.ndarray:
    """``points`` (on the part) moved straight down to the part's lowest surface under them: the
    lowest of the posed part's sample points ``part`` in the footprint cell of each point and its
    eight neighbours; a point with none there (no part under it) stays where it is."""
    if len(points) == 0 or len(part) == 0:
        return points
    c = _UNDERSIDE_CELL_MM
    lo = part[:, :2].min(axis=0) - c
    size = np.ceil((part[:, :2].max(axis=0) + c - lo) / c).astype(np.int64) + 1
    low = np.full((size[0] + 2, size[1] + 2), np.inf)
    ij = np.floor((part[:, :2] - lo) / c).astype(np.int64) + 1
    np.minimum.at(low, (ij[:, 0], ij[:, 1]), part[:, 2])
    # The lowest over each cell and its eight neighbours.
    spread = low.copy()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            spread[1:-1, 1:-1] = np.minimum(
                spread[1:-1, 1:-1], low[1 + di : low.shape[0] - 1 + di, 1 + dj : low.shape[1] - 1 + dj]
            )
    at = np.floor((points[:, :2] - lo) / c).astype(np.int64) + 1
    inside = (at >= 1).all(axis=1) & (at[:, 0] < size[0] + 1) & (at[:, 1] < size[1] + 1)
    below = np.full(len(points), np.inf)
    below[inside] = spread[at[inside, 0], at[inside, 1]]
    out = points.copy()
    out[:, 2] = np.minimum(points[:, 2], below)
    return out
