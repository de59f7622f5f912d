"""The grasps a cell plans with when none are declared: across every cylindrical branch of a part
(:func:`branch_grasps`), else parallel-jaw grasps sampled from its mesh (:func:`mesh_grasps`).
Pure functions of the part and the gripper; :mod:`binpick.cell.grasp` checks and chooses among
them. The gripper frame: z is the approach direction (into the part), x the fingers' closing
direction, the origin the TCP between the fingertips. Lengths in mm, transforms 4×4 ``T_to_from``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .._validate import count, instance_of, non_negative, positive
from ..errors import InvalidInputError
from ..models import Model
from ..transforms import inverse, rotation_about

if TYPE_CHECKING:  # annotations only: config imports this module's functions
    from .config import GripperGeometry

__all__ = ["branch_grasps", "mesh_grasps", "DISTINCT_CLOSING_DEG", "SHALLOW_BITE_MM", "MAX_BRANCH_STEPS"]


#: Most approach directions :func:`branch_grasps` takes around a branch: one every 0.1°, far finer
#: than a gripper needs; each direction makes 20 grasps per branch.
MAX_BRANCH_STEPS = 3600


def branch_grasps(
    model: Model,
    *,
    finger_width_mm: float = 20.0,
    tip_depth_mm: float = 10.0,
    steps: int = 72,
    pitches_deg: Sequence[float] = (-30.0, -15.0, 0.0, 15.0, 30.0),
    end_pitches_deg: Sequence[float] = (90.0, 75.0, 60.0),
) -> dict[str, np.ndarray]:
    """Grasps across every cylindrical branch of ``model`` (``model.branches``): the TCP on the
    branch axis, ``finger_width_mm / 2 + 7`` mm in from the end face, the fingers closing across
    the axis, approached from ``steps`` directions around it, each also pitched by
    ``pitches_deg`` about the closing direction (the approach leaning along the branch), and each
    turned half a turn about the approach axis (the same grip with the wrist the other way round;
    ``steps`` at most :data:`MAX_BRANCH_STEPS`, each direction named by its angle to 0.001°);
    every grasp also comes raised by half of ``tip_depth_mm`` (how far the fingertips reach past
    the TCP) along the approach, the fingertips half as far past the axis — still past the
    cylinder's widest line, where parallel fingers touch it — for parts lying on the bin floor.

    The steps are fine (5° by default) because a part in a pile usually has a branch tilted and
    neighbours close by: the approaches within the tool-tilt limit and clear of the neighbours are
    often a narrow range about the branch (12 steps of 30° routinely missed all of them). A pitched
    grip is as good on a cylinder: the fingers still close square to its axis and touch it along a
    line across their pads; the pitch lets the palm lean away from a bin wall or a neighbour
    beside a part lying flat, where turning about the axis would dip the fingertips into the floor.

    Grasps from the branch's end (``end_pitches_deg``, 0 excluded, 90 = straight along the axis)
    close the same way, square to the axis, with the approach leaning that far from square
    towards the end face: the pads then touch the cylinder along its length, the fingertips on
    the axis ``finger_width_mm`` in from the end face (or halfway along a shorter branch), so
    the contact is as long as a square grasp's. They grip a branch standing up, which no square
    approach within a tool-tilt limit reaches (a cross on edge against a wall, an elbow or a tee
    with a branch pointing up), from above it. At 90° a half turn about the axis is the
    flipped grip, so only the unflipped one is made.

    Returns name → ``T_gripper_object``.
    """
    instance_of(model, Model, "model", "binpick.parts.tee()")
    if not model.branches:
        raise InvalidInputError(
            f"model: {model.name!r} declares no cylindrical branches, so no grasps can be derived; declare grasps "
            "with model.add_grasp(name, T_gripper_object)"
        )
    half = positive(finger_width_mm, "finger_width_mm") / 2.0
    tip = non_negative(tip_depth_mm, "tip_depth_mm", "mm")
    raises = (0.0, tip / 2.0)
    n = count(steps, "steps", 1, MAX_BRANCH_STEPS)
    pitches = [float(p) for p in pitches_deg]
    if not pitches or any(not -90.0 < p < 90.0 for p in pitches):
        raise InvalidInputError(f"pitches_deg: expected one or more angles in (-90, 90) degrees, got {pitches_deg!r}")
    ends = [float(q) for q in end_pitches_deg]
    if any(not 0.0 < q <= 90.0 for q in ends):
        raise InvalidInputError(
            f"end_pitches_deg: expected angles in (0, 90] degrees (90: along the branch's axis), "
            f"got {end_pitches_deg!r}"
        )
    grasps: dict[str, np.ndarray] = {}
    square = list(itertools.product(range(n), pitches, (0, 1), raises))
    from_end = [(k, q, f, r) for k, q, f, r in itertools.product(range(n), ends, (0, 1), raises) if q < 90.0 or not f]
    a = np.array([2 * math.pi * k / n for k, _, _, _ in square + from_end])
    p = np.radians([c[1] for c in square + from_end])
    sign = np.array([-1.0 if c[2] else 1.0 for c in square + from_end])[:, None]
    raised = np.array([c[3] for c in square + from_end])[:, None]
    end = np.arange(len(a)) >= len(square)
    for i, b in enumerate(model.branches):
        d = np.asarray(b.direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        s = max(b.length - half - 7.0, 0.0)
        helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        z0 = np.cross(d, helper)
        z0 /= np.linalg.norm(z0)
        # z0 turned about the branch by a (square to it), the closing direction across both, and
        # the approach pitched about the closing direction by p (z_square is square to x); from
        # the end, the approach leans by p from z_square towards -d (into the end face).
        z_square = np.cos(a)[:, None] * z0 + np.sin(a)[:, None] * np.cross(d, z0)
        x = sign * np.cross(d, z_square)
        z = np.cos(p)[:, None] * z_square + np.sin(p)[:, None] * np.where(end[:, None], -d, np.cross(x, z_square))
        R = np.stack([x, np.cross(z, x), z], axis=2)  # columns: the gripper axes in the object frame
        # Square: the TCP on the axis s from the origin. From the end: the fingertips on the axis
        # a finger's width in from the end face, the TCP tip_depth back along the approach.
        tip_at = max(b.length - 2.0 * half, b.length / 2.0)
        origin = np.where(end[:, None], tip_at * d - tip * z, s * d) - raised * z
        T_go = np.zeros((len(a), 4, 4))
        T_go[:, :3, :3] = np.transpose(R, (0, 2, 1))
        T_go[:, :3, 3] = -np.einsum("nji,nj->ni", R, origin)
        T_go[:, 3, 3] = 1.0
        for T, (k, pitch, flip, lift), is_end in zip(T_go, square + from_end, end):
            name = (
                f"branch{i}/{round(360 * k / n, 3):g}°"
                + (f"/end{pitch:g}°" if is_end else f"/pitch{pitch:+g}°" if pitch else "")
                + ("/flipped" if flip else "")
                + (f"/raised{lift:g}mm" if lift else "")
            )
            grasps[name] = T
    return grasps


#: Two antipodal pairs through about the same point are distinct grasps when their closing
#: directions differ by more than this (degrees): across another pair of faces.
DISTINCT_CLOSING_DEG = 20.0

#: How far (mm) past the contacts the fingertips reach in each mesh grasp's shallow variant: an
#: edge pinched from above while the fingertips stay clear of what the part lies on (a plate
#: 10 mm thick lying on the floor: the full grasp's fingertips, ``tip_depth_mm`` past its middle,
#: would reach through the floor).
SHALLOW_BITE_MM = 4.0


def mesh_grasps(
    model: Model,
    gripper: GripperGeometry,
    *,
    pairs: int = 24,
    approaches: int = 12,
    max_angle_deg: float = 15.0,
) -> dict[str, np.ndarray]:
    """Parallel-jaw grasps sampled from any part's surface samples (``model.points``/``normals``),
    for a part without declared grasps or branches.

    An antipodal pair is a sample and the nearest sample straight across it (along its inward
    normal, within one sample spacing sideways) whose normal points back within
    ``max_angle_deg``, no farther apart than the open fingers (``open_width_mm`` less 2 mm). Its
    quality is the mean alignment of the two normals with the closing direction less the
    distance from the pair's midpoint to the samples' centroid (the centre of mass of a shell,
    a stand-in for the solid's) in units of the part's diameter. The best ``pairs`` pairs whose
    midpoints lie at least a finger width apart, or whose closing directions differ by more than
    :data:`DISTINCT_CLOSING_DEG` (the three pairs of flats of a hex through one centre), are kept;
    each is approached from ``approaches`` directions about the closing axis, the TCP at the
    midpoint (so the contacts lie within the fingers' depth), both ways round the wrist; and each
    again shallow (named ``…/shallow``, after all the full ones): the TCP drawn back so that the
    fingertips reach only :data:`SHALLOW_BITE_MM` past the contacts, for an edge gripped from
    above off a floor (where the gripper's ``tip_depth_mm`` exceeds that bite). Returns
    name → ``T_gripper_object``; names say the pair, the quality and the approach.
    """
    instance_of(model, Model, "model", "binpick.parts.tee()")
    pts = np.asarray(model.points, dtype=np.float64)
    nrm = np.asarray(model.normals, dtype=np.float64)
    step = max(1, len(pts) // 600)
    p, n = pts[::step], nrm[::step]
    lateral_tol = max(float(model.spacing or 0.0), float(model.diameter) / 100.0, 0.5) * step**0.5
    cos_tol = math.cos(math.radians(max_angle_deg))
    widest = gripper.open_width_mm - 2.0
    centre = pts.mean(axis=0)
    found = []
    for i in range(len(p)):
        d = -n[i]
        rel = p - p[i]
        along = rel @ d
        side = np.linalg.norm(rel - along[:, None] * d, axis=1)
        ok = (along > 1.0) & (along <= widest) & (side <= lateral_tol) & ((n @ n[i]) <= -cos_tol)
        if not ok.any():
            continue
        j = int(np.flatnonzero(ok)[np.argmin(along[ok])])
        # The closing direction along the mean of the two inward normals (flat faces: exactly
        # along their normal), the quality from the alignment of the contacts' line with it.
        u = (n[j] - n[i]) / np.linalg.norm(n[j] - n[i])
        mid = (p[i] + p[j]) / 2.0
        line = (p[j] - p[i]) / np.linalg.norm(p[j] - p[i])
        quality = (abs(n[i] @ line) + abs(n[j] @ line)) / 2.0 - np.linalg.norm(mid - centre) / model.diameter
        found.append((float(quality), mid, u))
    found.sort(key=lambda f: -f[0])
    kept: list = []
    distinct = math.cos(math.radians(DISTINCT_CLOSING_DEG))
    for q, mid, u in found:
        if all(np.linalg.norm(mid - m) >= gripper.finger_width_mm or abs(u @ v) < distinct for _, m, v in kept):
            kept.append((q, mid, u))
        if len(kept) == pairs:
            break
    grasps: dict[str, np.ndarray] = {}
    draws = [(0.0, "")]
    if gripper.tip_depth_mm > SHALLOW_BITE_MM:
        draws.append((gripper.tip_depth_mm - SHALLOW_BITE_MM, "/shallow"))
    for back, tag in draws:
        for k, (q, mid, u) in enumerate(kept):
            helper = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            z0 = np.cross(u, helper)
            z0 /= np.linalg.norm(z0)
            for a in range(approaches):
                z = rotation_about(u, 2 * math.pi * a / approaches) @ z0
                for flip in (1.0, -1.0):
                    x = flip * u
                    T_object_gripper = np.eye(4)
                    T_object_gripper[:3, :3] = np.column_stack([x, np.cross(z, x), z])
                    T_object_gripper[:3, 3] = mid - back * z
                    name = f"mesh{k}/q{q:.2f}/{round(360 * a / approaches)}°{'/flipped' if flip < 0 else ''}{tag}"
                    grasps[name] = inverse(T_object_gripper)
    return grasps
