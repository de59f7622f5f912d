"""Grasps as pure functions: the grasps of a part (made in :mod:`binpick.cell.grasp_sets`), the checks a grasp
must pass (tool tilt, reach, collision with the scene and with the part itself, the safety
rules for its whole motion), the choice of the usable one touching the fewest scene points, most
vertical among equals, and the matching of a
part's pose in the gripper against the declared grasps (the simulated gripper's test of a grip).

The gripper frame: z is the approach direction (into the part), x the fingers' closing
direction, the origin the TCP between the fingertips. Lengths in mm, transforms 4×4 ``T_to_from``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Optional

import numpy as np

from .._validate import as_points, as_transform
from ..devices import safety
from ..errors import BinpickError, InvalidTypeError, SafetyError
from ..models import Model
from ..transforms import inverse, rotation_about
from .grasp_sets import branch_grasps, mesh_grasps
from .records import PickPlan
from .symmetry import GraspMatcher, continuous_near_axis, continuous_symmetry, symmetry_maps

if TYPE_CHECKING:  # annotations only: config imports this module for grasp_widths
    from .config import CellConfig, GripperGeometry

__all__ = [
    "NoGraspError",
    "GraspMatcher",
    "branch_grasps",
    "mesh_grasps",
    "tool_tilt_deg",
    "pick_waypoints",
    "points_in_gripper",
    "bin_clash",
    "grip_width",
    "grasp_openings",
    "grasp_widths",
    "plan_grasp",
    "scene_hits",
    "GraspTest",
    "grasp_filter",
    "symmetry_maps",
    "continuous_symmetry",
]

Waypoint = tuple[str, np.ndarray, bool]


class NoGraspError(BinpickError):
    """The located part has no declared grasp that is reachable, collision-free and safe to approach.

    ``reason`` says why in a few words, for the one line a skipped part gets in a report; the
    message adds what to do about it.
    """

    def __init__(
        self, message: str, *, reason: Optional[str] = None, refused: Optional[Mapping[str, np.ndarray]] = None
    ) -> None:
        super().__init__(message)
        self.reason = reason if reason is not None else message
        #: A few refused gripper poses per reason (reason → (K, 4, 4) ``T_base_gripper``), for pictures.
        self.refused: Mapping[str, np.ndarray] = MappingProxyType(dict(refused or {}))


_SAMPLES = 8
"""Refused gripper poses kept per reason for the picture of a skipped part."""


def _keep_some(samples: dict[str, list], why: str, T_bg: np.ndarray) -> None:
    """Adds up to :data:`_SAMPLES` poses of ``T_bg`` ((K, 4, 4), evenly spaced) to ``samples[why]``."""
    have = samples.setdefault(why, [])
    room = _SAMPLES - len(have)
    if room > 0 and len(T_bg):
        have.extend(T_bg[np.unique(np.linspace(0, len(T_bg) - 1, min(room, len(T_bg))).round().astype(int))])


def tool_tilt_deg(T_base_flange: np.ndarray) -> float:
    """How far the tool axis (flange z) tilts from straight down, degrees."""
    return math.degrees(math.acos(max(-1.0, min(1.0, -float(T_base_flange[2, 2])))))


def pick_waypoints(
    T_base_flange: np.ndarray,
    T_base_gripper: np.ndarray,
    *,
    approach_distance_mm: float,
    clearance_z_mm: float,
    drop_pose: np.ndarray,
) -> list[Waypoint]:
    """The motion of one pick as (name, T_base_flange, linear): above the approach, the straight
    approach along the gripper axis, the grasp, the lift straight up, the drop pose."""
    approach = T_base_flange.copy()
    approach[:3, 3] -= approach_distance_mm * T_base_gripper[:3, 2]
    above = approach.copy()
    above[2, 3] = max(clearance_z_mm, approach[2, 3])
    lift = T_base_flange.copy()
    lift[2, 3] = max(clearance_z_mm, T_base_flange[2, 3])
    return [
        ("above", above, False),
        ("approach", approach, True),
        ("grasp", T_base_flange, True),
        ("lift", lift, True),
        ("drop", drop_pose, False),
    ]


def points_in_gripper(
    gripper: GripperGeometry, points_base: np.ndarray, T_base_gripper: np.ndarray, opening_mm: Optional[float] = None
) -> int:
    """How many of the points (N, 3, base frame) lie inside the gripper at ``T_base_gripper``, its
    fingers ``opening_mm`` apart (``open_width_mm`` by default): :meth:`GripperGeometry.hits`."""
    opening = gripper.open_width_mm if opening_mm is None else opening_mm
    return int(gripper.hits(points_base, np.asarray(T_base_gripper)[None], np.array([opening]))[0])


def _occupied_sphere(gripper: GripperGeometry) -> tuple[float, float]:
    """(z of the centre on the gripper axis, radius) of a sphere holding the open fingers and the body."""
    top = gripper.tip_depth_mm - gripper.finger_length_mm
    z_lo, z_hi = top - gripper.body_length_mm, gripper.tip_depth_mm
    z_mid = (z_lo + z_hi) / 2.0
    finger_x = gripper.open_width_mm / 2 + gripper.finger_thickness_mm
    across = max(gripper.body_radius_mm, math.hypot(finger_x, gripper.finger_width_mm / 2))
    return z_mid, math.hypot(across, (z_hi - z_lo) / 2.0) + 1e-6


def bin_clash(
    gripper: GripperGeometry,
    T_base_flange: np.ndarray,
    bin_bounds: np.ndarray,
    *,
    floor_clearance_mm: float = 0.0,
    opening_mm: Optional[float] = None,
) -> Optional[str]:
    """Why the whole gripper (fingers ``opening_mm`` apart, ``open_width_mm`` by default; palm;
    flange: :meth:`GripperGeometry.outline`) at the flange pose ``T_base_flange`` hits the bin
    ``bin_bounds`` ((lo, hi) of its inner volume, hi z the rim), or None when it is clear: any
    point below the floor plus ``floor_clearance_mm`` ("floor", with how far below), or below
    the rim and outside the inner walls ("wall").

    Each piece of the gripper is convex and the bin's inner volume too, so a straight move whose
    two ends are clear is clear all along: checking a motion's waypoints checks its whole path."""
    T_bg = T_base_flange @ gripper.T_flange_gripper
    pts = gripper.outline(opening_mm) @ T_bg[:3, :3].T + T_bg[:3, 3]
    below, wall = _bin_clashes(pts[None], bin_bounds, floor_clearance_mm)
    if below[0] > 1e-9:
        return f"floor ({below[0]:.1f} mm below)"
    return "wall" if wall[0] else None


def _bin_clashes(points: np.ndarray, bin_bounds: Any, floor_clearance_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """For gripper outlines ``points`` (..., M, 3, base frame): how far (mm) each dips below the
    floor plus the clearance (≤ 0 when it does not), and whether it crosses a wall below the rim."""
    lo, hi = np.asarray(bin_bounds[0], dtype=np.float64), np.asarray(bin_bounds[1], dtype=np.float64)
    below = lo[2] + floor_clearance_mm - points[..., 2].min(axis=-1)
    xy = points[..., :2]
    outside = ((xy < lo[:2] - 1e-9) | (xy > hi[:2] + 1e-9)).any(axis=-1) & (points[..., 2] < hi[2])
    return below, outside.any(axis=-1)


def plan_bin_clash(
    config: CellConfig, waypoints: Sequence[Waypoint], opening_mm: Optional[float] = None
) -> Optional[tuple[str, str]]:
    """(waypoint, why) of the first waypoint of a pick's motion in the bin (approach, grasp,
    lift: the straight moves into and out of it) where :func:`bin_clash` finds the gripper, its
    fingers ``opening_mm`` apart, hitting the bin's floor or walls, or None."""
    for name, T, _ in waypoints:
        if name in ("approach", "grasp", "lift"):
            why = bin_clash(
                config.gripper,
                T,
                config.bin_bounds,
                floor_clearance_mm=config.floor_clearance_mm,
                opening_mm=opening_mm,
            )
            if why is not None:
                return name, why
    return None


def grip_width(gripper: GripperGeometry, model_points: np.ndarray, T_gripper_object: np.ndarray) -> Optional[float]:
    """The width (mm) across the fingers of the part at ``T_gripper_object``, or None when none
    of its points lies between the fingers."""
    local = model_points @ T_gripper_object[:3, :3].T + T_gripper_object[:3, 3]
    between = gripper.between_fingers(local)
    if not between.any():
        return None
    return float(2.0 * np.abs(local[between, 0]).max())


def grasp_openings(
    gripper: GripperGeometry, model: Model, grasps: Mapping[str, np.ndarray], points: Optional[np.ndarray] = None
) -> dict[str, Optional[float]]:
    """Grasp name → the finger opening (mm) for it, or None when the part does not fit between
    the open fingers there (a finger would come down on it): :meth:`GripperGeometry.opening_for`
    the width :func:`grasp_widths` measures."""
    return {n: opening_for_width(gripper, w) for n, w in grasp_widths(gripper, model, grasps, points).items()}


def opening_for_width(gripper: GripperGeometry, width: Optional[float]) -> Optional[float]:
    """The finger opening (mm) for a grasp across ``width`` mm of the part (None: nothing between
    the fingers), or None when that is wider than the open fingers."""
    if width is not None and width > gripper.open_width_mm:
        return None
    return gripper.opening_for(width)


def grasp_widths(
    gripper: GripperGeometry, model: Model, grasps: Mapping[str, np.ndarray], points: Optional[np.ndarray] = None
) -> dict[str, Optional[float]]:
    """Grasp name → the part's width (mm) across the fingers there, or None when none of it lies
    between them: twice the farthest of its points in the slab the fingers sweep (more than
    :data:`GRAZE_MM` inside it: a finger's edge may graze the part), out to the open fingers'
    outer faces (what lies beyond them is for the collision checks). Every grasp at once.
    ``points``: the part's points to measure (default ``model.points``; :func:`swept_points` for
    a part whose turn about its near axis is open)."""
    names = list(grasps)
    if not names:
        return {}
    pts = np.asarray(model.points if points is None else points, dtype=np.float64)
    widest = gripper.widest(pts, np.stack([np.asarray(grasps[n], dtype=np.float64) for n in names]), GRAZE_MM)
    return {n: (2.0 * w if w >= 0.0 else None) for n, w in zip(names, widest.tolist())}


#: How far (mm) a point of the part must lie inside a finger's sweep to count as in its way: a
#: finger's edge grazing the part is no collision. The simulated gripper counts a finger as
#: landing on the part at twice this (:data:`binpick.sim.twin.FINGER_LANDING_MM`).
GRAZE_MM = 0.5


def _candidates(
    config: CellConfig,
    T_base_object: np.ndarray,
    rejected: dict[str, int],
    samples: dict[str, list],
    free_turn: bool = False,
) -> Iterator[tuple]:
    """(tilt, name, T_base_gripper, T_base_flange, waypoints, opening, closing: the width the
    fingers close to) of every grasp within the tool-tilt limit whose gripper clears the bin's
    floor and walls along approach, grasp and lift, most vertical first; the others counted in
    ``rejected`` (a few kept in ``samples``). All grasps at once (one matrix product per check),
    so that thousands of grasps are planned in milliseconds."""
    names, T_og = config.grasp_frames
    T_bo = np.asarray(T_base_object, dtype=np.float64)
    # About a continuous symmetry, or a near-symmetry whose turn the scan left open (a keyed shaft
    # with its keyway hidden), the grasps turn to the most upright: the located turn is arbitrary.
    continuous = continuous_symmetry(config.model.symmetries)
    if continuous is None and free_turn:
        continuous = continuous_near_axis(config.model)
    if continuous is not None:
        T_og = _most_upright(T_bo, T_og, *continuous)
    T_bg = T_bo @ T_og
    T_bf = T_bg @ inverse(config.gripper.T_flange_gripper)
    tilt = np.degrees(np.arccos(np.clip(-T_bf[:, 2, 2], -1.0, 1.0)))
    ok = np.radians(tilt) <= config.limits.max_tool_tilt_rad
    rejected["tilt"] += int((~ok).sum())
    _keep_some(samples, "tilt", T_bg[~ok])
    # The outline at the grasp, shifted back along the approach and straight up for the lift
    # (only for the grasps within the tilt limit: most are not).
    idx = np.flatnonzero(ok)
    widths = config.grip_widths([names[i] for i in idx], swept=free_turn)
    openings = config.openings_for(widths)
    fits = ~np.isnan(openings)
    rejected["width"] += int((~fits).sum())
    _keep_some(samples, "width", T_bg[idx[~fits]])
    idx, openings = idx[fits], openings[fits]
    closing = _closing(widths[fits], openings)
    R, t = T_bg[idx, :3, :3], T_bg[idx, :3, 3]
    at_grasp = np.einsum("kmj,kij->kmi", config.gripper.outlines(openings), R) + t[:, None]
    back = at_grasp - config.approach_distance_mm * R[:, None, :, 2]
    up = at_grasp.copy()
    up[..., 2] += np.maximum(config.clearance_z_mm - T_bf[idx, 2, 3], 0.0)[:, None]
    free = np.ones(len(idx), dtype=bool)
    for pts in (back, at_grasp, up):
        below, wall = _bin_clashes(pts, config.bin_bounds, config.floor_clearance_mm)
        free &= (below <= 1e-9) & ~wall
    rejected["bin"] += int((~free).sum())
    _keep_some(samples, "bin", T_bg[idx[~free]])
    clear = idx[free]
    opening_of = dict(zip(clear.tolist(), zip(openings[free].tolist(), closing[free].tolist())))
    for i in clear[np.argsort(tilt[clear], kind="stable")]:
        waypoints = pick_waypoints(
            T_bf[i],
            T_bg[i],
            approach_distance_mm=config.approach_distance_mm,
            clearance_z_mm=config.clearance_z_mm,
            drop_pose=config.drop_pose,
        )
        yield float(tilt[i]), names[i], T_bg[i], T_bf[i], waypoints, *opening_of[int(i)]


def swept_points(model: Model) -> np.ndarray:
    """The part's points with the feature of its continuous near-symmetry (a shaft's key or flat,
    a flange's pin) turned all the way about the near axis, in steps no longer than the part's
    sample spacing at the feature's radius: where the part may lie at any turn about that axis,
    what the gripper must clear. ``model.points`` for a part without a continuous near axis."""
    pts = np.asarray(model.points, dtype=np.float64)
    for near in model.near_symmetries:
        if near.angle is not None or len(near.feature) == 0:
            continue
        a = np.asarray(near.axis, dtype=np.float64)
        c = np.asarray(near.center, dtype=np.float64)
        f = np.asarray(near.feature, dtype=np.float64) - c
        radius = float(np.linalg.norm(f - np.outer(f @ a, a), axis=1).max())
        steps = int(np.clip(np.ceil(2.0 * np.pi * radius / float(model.spacing)), 8, 720))
        turns = [rotation_about(a, 2.0 * np.pi * k / steps) for k in range(1, steps)]
        return np.concatenate([pts] + [f @ R.T + c for R in turns])
    return pts


def _most_upright(T_bo: np.ndarray, T_og: np.ndarray, centre: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The grasps ``T_og`` (K, 4, 4, object frame) of a part that any turn about ``axis`` through
    ``centre`` (object frame) maps onto itself, each turned about that axis so that its approach
    (the gripper's z) points down in the base frame as nearly as it can: the located turn of such
    a part is arbitrary, so its grasps' tilts must not be. Closed form per grasp: with g the
    approach and w the downward direction in the object frame, g·w after a turn θ is
    cos θ (g·w − (a·g)(a·w)) + sin θ (a×g)·w + const."""
    a = axis / np.linalg.norm(axis)
    w = T_bo[:3, :3].T @ np.array([0.0, 0.0, -1.0])
    g = T_og[:, :3, 2]
    theta = np.arctan2(np.cross(a, g) @ w, g @ w - (g @ a) * float(a @ w))
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    S = np.zeros_like(T_og)
    S[:, :3, :3] = c * np.eye(3) + s * K + (1.0 - c) * np.outer(a, a)
    S[:, :3, 3] = centre - S[:, :3, :3] @ centre
    S[:, 3, 3] = 1.0
    return S @ T_og


def _near(points: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """The points within ``radius`` of ``centre`` horizontally, at any height (a point high above
    stands for what lies below it)."""
    if len(points) == 0:
        return points
    d = points[:, :2] - centre[:2]
    return points[np.einsum("ij,ij->i", d, d) <= radius * radius]


def _unseen(points: np.ndarray, step: Optional[np.ndarray]) -> np.ndarray:
    """The scene points, each standing for the surface it lies on out to (not onto) the next
    laser line either side (``step`` of :func:`~binpick.cell.records.line_step`): copies of every point along the step,
    at most :data:`_UNSEEN_SPACING_MM` apart, out to :data:`GRAZE_MM` short of the next line, so
    that a finger coming down where an unseen edge may stand meets them."""
    if step is None or len(points) == 0:
        return points
    size = float(np.linalg.norm(step))
    reach = size - GRAZE_MM
    if reach <= GRAZE_MM:
        return points
    k = int(math.ceil(reach / _UNSEEN_SPACING_MM))
    offsets = np.linspace(-reach, reach, 2 * k + 1)[:, None] * (np.asarray(step, dtype=np.float64) / size)
    return (points[None, :, :] + offsets[:, None, :]).reshape(-1, 3)


#: The spacing (mm) of the copies :func:`_unseen` spreads between laser lines: under a
#: quarter of a finger's thickness, so that an unseen edge reaching that far into a finger is met.
_UNSEEN_SPACING_MM = 2.0


def _refusal(
    config: CellConfig, waypoints: list[Waypoint], hits: int, self_hits: int, here: np.ndarray
) -> Optional[str]:
    """Why a grasp that passed the tilt and bin checks cannot be used (None when it can), given
    the scene points and the part's own model points inside its gripper."""
    if hits > config.max_collision_points:
        return "collision"
    if self_hits > 0:
        return "self-collision"
    if config.reachable is not None and not all(config.reachable(T) for _, T, _ in waypoints):
        return "reach"
    try:
        safety.check_sequence(here, [T for _, T, _ in waypoints], [lin for _, _, lin in waypoints], config.limits)
    except SafetyError:
        return "safety"
    return None


_BATCH = 32
"""At most this many grasps have their collisions counted together (most vertical first, in
batches of 4, 8, 16, …: planning stops at the first usable one clear of the scene)."""


#: The fields of a :class:`~binpick.cell.CellConfig` the planners read (config.py imports this
#: module, so the class is recognised by its fields rather than imported).
_PLANNER_FIELDS = (
    "model",
    "gripper",
    "grasps",
    "symmetries",
    "limits",
    "bin_bounds",
    "drop_pose",
    "approach_distance_mm",
    "clearance_z_mm",
    "floor_clearance_mm",
    "max_collision_points",
    "scan_clearance_mm",
    "reachable",
)


def plan_inputs(
    config: Any, T_base_object: Any, scene: Any, T_now: Any, now_name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The planners' arguments checked before any planning: ``config`` a CellConfig
    (InvalidTypeError otherwise), the part's pose and the arm's flange pose rigid 4×4 transforms
    and the scan an (N, 3) finite cloud (InvalidInputError naming the argument otherwise)."""
    if not all(hasattr(config, name) for name in _PLANNER_FIELDS):
        raise InvalidTypeError(f"config: expected a binpick.cell.CellConfig, got {type(config).__name__}")
    return (
        as_transform(T_base_object, "T_base_object"),
        as_points(scene, "scene", min_points=0),
        as_transform(T_now, now_name),
    )


def grasp_filter(config: CellConfig, result: Any) -> Optional[GraspTest]:
    """For a pose the scan cannot settle, the test ``T_base_gripper → bool`` a grasp must pass
    (a :class:`GraspTest`, which also weighs a stack of grasps at once; None when the pose is
    unambiguous and has no free axis):

    - ``result.ambiguous``: the gripper pose, expressed against every alternative pose of the
      part (``result.alternatives``), must land the fingers on it as one of the cell's grasps
      does (within ``config.ambiguity_tolerance_deg`` / ``_mm``, modulo the part's symmetries) —
      whichever of the poses is true, the grip is the same;
    - ``result.free_axis`` (a continuous near-symmetry leaves the turn about it open): the TCP on
      that axis and the fingers closing square to it (across a shaft's body, from its side or
      end-on), so that any turn about the axis turns the grip about it and leaves it unchanged.
    """
    tests: list[Callable[[np.ndarray], np.ndarray]] = []  # each: (K, 4, 4) T_base_gripper → (K,) bool
    if getattr(result, "ambiguous", False) and getattr(result, "alternatives", ()):
        matcher = config.ambiguity_matcher
        alternatives = [np.asarray(a.T_scene_model, dtype=np.float64) for a in result.alternatives]

        def on_every_alternative(T_bg: np.ndarray) -> np.ndarray:
            T_gb = np.zeros_like(T_bg)  # the inverses, rigid: Rᵀ, −Rᵀ t
            T_gb[:, :3, :3] = np.swapaxes(T_bg[:, :3, :3], 1, 2)
            T_gb[:, :3, 3] = -np.einsum("kij,kj->ki", T_gb[:, :3, :3], T_bg[:, :3, 3])
            T_gb[:, 3, 3] = 1.0
            ok = np.ones(len(T_bg), dtype=bool)
            for T_a in alternatives:
                ok[ok] = matcher.matches((T_gb @ T_a)[ok])
                if not ok.any():
                    break
            return ok

        tests.append(on_every_alternative)
    axis = getattr(result, "free_axis", None)
    if axis is not None:
        a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        T_bo = np.asarray(result.T_scene_model, dtype=np.float64)
        centre = np.asarray(config.model.symmetries.center, dtype=np.float64)
        for near in config.model.near_symmetries:
            if abs(float((T_bo[:3, :3] @ near.axis) @ a)) > 0.99:
                centre = np.asarray(near.center, dtype=np.float64)
                break
        c = T_bo[:3, :3] @ centre + T_bo[:3, 3]
        sin_tol = math.sin(math.radians(config.ambiguity_tolerance_deg))

        def across(T_bg: np.ndarray) -> np.ndarray:
            off = T_bg[:, :3, 3] - c
            off_axis = np.linalg.norm(off - (off @ a)[:, None] * a, axis=1)
            return (np.abs(T_bg[:, :3, 0] @ a) <= sin_tol) & (off_axis <= config.ambiguity_tolerance_mm)

        tests.append(across)
    if not tests:
        return None
    return GraspTest(tests)


class GraspTest:
    """The test of :func:`grasp_filter`: called with one ``T_base_gripper`` it says whether that
    grasp passes; :meth:`many` says it for a stack (K, 4, 4) at once (the planner's batches)."""

    def __init__(self, tests: list[Callable[[np.ndarray], np.ndarray]]) -> None:
        self._tests = tests

    def many(self, T_base_grippers: np.ndarray) -> np.ndarray:
        """(K,) bool: which of the grasps (K, 4, 4) pass every test."""
        T = np.asarray(T_base_grippers, dtype=np.float64)
        ok = np.ones(len(T), dtype=bool)
        for test in self._tests:
            if ok.any():
                ok[ok] = test(T[ok])
        return ok

    def __call__(self, T_base_gripper: np.ndarray) -> bool:
        return bool(self.many(np.asarray(T_base_gripper, dtype=np.float64)[None])[0])


def staked_filter(config: CellConfig, result: Any) -> Optional[GraspTest]:
    """The grasp test of :func:`grasp_filter` for a located pose, once the pose's stake is checked:
    NoGraspError (reason "low confidence") when the pose — or, planned with a grasp the same on
    every alternative, the pose or one of its alternatives (``confidence_any``) — is less
    confident than ``config.min_confidence``; NoGraspError (reason "orientation undecided") for
    an undecided pose when ``config.orientation_needed`` (the part is placed by its orientation:
    the cell looks again, and a look that decides it is picked)."""
    accept = grasp_filter(config, result)
    name = config.model.name
    if accept is not None and config.orientation_needed:
        what = "turn about its axis" if getattr(result, "free_axis", None) is not None else "flip"
        raise NoGraspError(
            f"the scan cannot decide the located {name}'s {what} and the cell places parts by their "
            "orientation (orientation_needed); it is not picked until a look decides it",
            reason="orientation undecided",
        )
    confidence = float(getattr(result, "confidence" if accept is None else "confidence_any", 1.0))
    if confidence < config.min_confidence:
        raise NoGraspError(
            f"the located {name}{'' if accept is None else ' (or one of its alternatives)'} has confidence "
            f"{confidence:.2f}, below the cell's min_confidence {config.min_confidence:.2f}; it is not picked",
            reason="low confidence",
        )
    return accept


def _plan(
    config: CellConfig,
    name: str,
    T_bg: np.ndarray,
    T_bf: np.ndarray,
    tilt: float,
    waypoints: list[Waypoint],
    opening: float,
    rejected: dict[str, int],
) -> PickPlan:
    return PickPlan(
        grasp=name,
        T_base_gripper=T_bg,
        T_base_flange=T_bf,
        tilt_deg=tilt,
        waypoints=tuple(waypoints),
        considered=len(config.grasps),
        rejected=MappingProxyType(dict(rejected)),
        opening_mm=opening,
    )


def _first_usable(
    config: CellConfig,
    batch: list[tuple[tuple, int]],
    part: np.ndarray,
    here: np.ndarray,
    rejected: dict[str, int],
    samples: dict[str, list],
) -> Optional[tuple[PickPlan, int]]:
    """The first of ``batch`` (candidates of :func:`_candidates`, each with the scene points
    inside its gripper) that :func:`_refusal` lets through, as (plan, points); the ones before it
    counted in ``rejected`` (a few kept in ``samples``). None when none is usable."""
    clear = [c for c, h in batch if h <= config.max_collision_points]
    poses = np.array([c[2] for c in clear]).reshape(-1, 4, 4)
    own = config.gripper.hits(part, poses, np.array([c[5] for c in clear]), GRAZE_MM, at_most=1)
    own = dict(zip((id(c) for c in clear), own))
    for c, hits in batch:
        tilt, name, T_bg, T_bf, waypoints, opening, _ = c
        why = _refusal(config, waypoints, hits, int(own.get(id(c), 0)), here)
        if why is not None:
            rejected[why] += 1
            _keep_some(samples, why, T_bg[None])
            continue
        return _plan(config, name, T_bg, T_bf, tilt, waypoints, opening, rejected), hits
    return None


def _reachable_scene(
    config: CellConfig, T_base_object: np.ndarray, scene: np.ndarray, free_turn: bool, unseen_step: Any
) -> tuple[Optional[np.ndarray], np.ndarray, np.ndarray]:
    """What :func:`plan_grasp` checks a grasp against: the part's points swept about its free
    axis (None when its turn is decided), the part's points at ``T_base_object`` (swept, where
    they are), and the scene points the fingers and body can reach on their way to and from a
    TCP on the part (:func:`_motion_hits`), each standing for its surface out to the next laser
    line (:func:`_unseen`)."""
    own = config.swept_points if free_turn and continuous_near_axis(config.model) is not None else None
    part = np.asarray(config.model.points if own is None else own) @ T_base_object[:3, :3].T + T_base_object[:3, 3]
    z_mid, radius = _occupied_sphere(config.gripper)
    centre = part.mean(axis=0)
    reach = abs(z_mid) + radius + float(np.linalg.norm(part - centre, axis=1).max())
    return own, part, _unseen(_near(scene, centre, reach + float(config.approach_distance_mm)), unseen_step)


def scene_hits(
    config: CellConfig, plan: PickPlan, T_base_object: Any, scene: Any, free_turn: bool, unseen_step: Any
) -> int:
    """The scene points (base frame, the part's own left out) inside the gripper of ``plan`` at
    its grasp, counted as :func:`plan_grasp` counts them when it chooses a grasp: for a plan made
    on an earlier scan, checked against a new one."""
    T_base_object, scene, _ = plan_inputs(config, T_base_object, scene, plan.T_base_flange, "plan.T_base_flange")
    _, _, near = _reachable_scene(config, T_base_object, scene, free_turn, unseen_step)
    opening = config.gripper.open_width_mm if plan.opening_mm is None else float(plan.opening_mm)
    closing = _closing(config.grip_widths([plan.grasp], swept=free_turn), np.array([opening]))
    T_bg = np.asarray(plan.T_base_gripper, dtype=np.float64)[None]
    return int(_motion_hits(config, near, T_bg, np.array([opening]), closing)[0])


def _closing(widths: np.ndarray, openings: np.ndarray) -> np.ndarray:
    """The widths the fingers close to from ``openings``: the part's ``widths`` across them
    (:meth:`CellConfig.grip_widths`), their opening where nothing lies between them (NaN)."""
    return np.where(np.isnan(widths), openings, np.minimum(widths, openings))


def _motion_hits(
    config: CellConfig,
    points: Any,
    T_bg: np.ndarray,
    openings: np.ndarray,
    closing: np.ndarray,
    at_most: Optional[int] = None,
) -> np.ndarray:
    """How many scene ``points`` (base frame) the gripper meets on each pick's way in and out
    (:meth:`GripperGeometry.hits`): coming in along its axis from the approach to the grasp
    ``T_bg`` (K, 4, 4), fingers ``openings`` (K,) apart, closing there to ``closing`` (K,), and
    rising straight up from anywhere on that way (the descent to the approach and the lift), each
    point standing for what lies straight below it down to the bin's floor, which the scan did
    not see: a finger may not reach in under a seen surface, nor close onto a neighbour. The
    gripper is grown by ``config.scan_clearance_mm``; ``at_most``: counts stop there."""
    return config.gripper.hits(
        points,
        T_bg,
        openings,
        grow_mm=float(config.scan_clearance_mm),
        back_mm=float(config.approach_distance_mm),
        floor_z_mm=float(config.bin_bounds[0][2]),
        closing_mm=closing,
        at_most=at_most,
    )


def plan_grasp(
    config: CellConfig,
    T_base_object: np.ndarray,
    scene: np.ndarray,
    here: np.ndarray,
    accept: Optional[Callable[[np.ndarray], bool]] = None,
    free_turn: bool = False,
    unseen_step: Optional[np.ndarray] = None,
) -> tuple[PickPlan, int]:
    """The declared grasp of the part at ``T_base_object`` that is within the tilt limit,
    reachable, clear of the ``scene`` points (base frame, the part's own left out) on its whole
    way in and out — the approach along its axis, the rise from it, and nothing reached in under
    a seen surface (:func:`_motion_hits`) — and of the part's own model at that pose (none more
    than :data:`GRAZE_MM` inside the gripper), whose whole motion from the flange pose ``here``
    passes the safety rules, and which ``accept`` (``T_base_gripper → bool``, see
    :func:`grasp_filter`) accepts — of those, the one with the fewest scene points in its way,
    the most vertical among equals; with that number of points. NoGraspError when none is.
    ``free_turn``: the part's turn about its continuous near-symmetry axis is open (the result's
    ``free_axis``): the grasps turn to the most upright about it, and the fingers' opening and the
    part's own collisions are checked against the part at every turn (:func:`swept_points`).
    ``unseen_step``: the step between the scan's laser lines (:func:`~binpick.cell.records.line_step`); each scene
    point then stands for its surface out to the next line either side, which the scan did not
    see. The part's own model may not lie more than :data:`GRAZE_MM` inside the gripper anywhere
    (the physics' measure of a touch); the scene may, by up to ``config.max_collision_points``
    (stray points)."""
    T_base_object, scene, here = plan_inputs(config, T_base_object, scene, here, "here")
    if accept is not None and not callable(accept):
        raise InvalidTypeError(f"accept: expected a function T_base_gripper → bool, got {type(accept).__name__}")
    rejected = {
        "tilt": 0,
        "width": 0,
        "bin": 0,
        "ambiguous": 0,
        "collision": 0,
        "self-collision": 0,
        "reach": 0,
        "safety": 0,
    }
    # The part's own points lie between the fingers and are not in the scene, but the gripper must
    # not run into its other branches either: those are checked against the model at the located
    # pose, which also covers the part's unseen underside. Only scene points the fingers and
    # body can reach from a TCP on the part are kept.
    own, part, scene = _reachable_scene(config, T_base_object, scene, free_turn, unseen_step)
    scene = config.gripper.scene(scene)  # bucketed once for every batch's count
    samples: dict[str, list] = {}
    candidates = _candidates(config, T_base_object, rejected, samples, own is not None)
    # The grasps with scene points inside the gripper (up to max_collision_points: stray points,
    # a neighbour's edge) are tried only after every clean one: most vertical first among the
    # clean, then fewest points first (most vertical among equals).
    touching: list[tuple[int, int, tuple]] = []
    size = 4
    while batch := list(itertools.islice(candidates, size)):
        size = min(2 * size, _BATCH)  # the first usable grasp is often among the most vertical few
        if accept is not None:
            many = getattr(accept, "many", None)  # a GraspTest weighs the batch at once
            passes = many(np.stack([c[2] for c in batch])) if many is not None else [accept(c[2]) for c in batch]
            kept = []
            for c, ok in zip(batch, passes):
                if ok:
                    kept.append(c)
                else:
                    rejected["ambiguous"] += 1
                    _keep_some(samples, "ambiguous", c[2][None])
            batch = kept
        if not batch:
            continue
        # Counted up to one past the most a grasp may have (more are refused whatever their number).
        poses, openings, closing = np.stack([c[2] for c in batch]), [c[5] for c in batch], [c[6] for c in batch]
        scene_hits = _motion_hits(
            config, scene, poses, np.array(openings), np.array(closing), at_most=config.max_collision_points + 1
        )
        now = []
        for c, h in zip(batch, scene_hits.tolist()):
            if 0 < h <= config.max_collision_points:
                touching.append((h, len(touching), c))
            else:
                now.append((c, h))
        found = _first_usable(config, now, part, here, rejected, samples)
        if found is not None:
            return found
    touching.sort(key=lambda t: t[:2])
    for k in range(0, len(touching), _BATCH):
        found = _first_usable(config, [(c, h) for h, _, c in touching[k : k + _BATCH]], part, here, rejected, samples)
        if found is not None:
            return found
    why = ", ".join(f"{v} {k}" for k, v in rejected.items() if v)
    raise NoGraspError(
        f"none of the {len(config.grasps)} grasps of the located {config.model.name} can be used (rejected: "
        + ", ".join(f"{v} for {k}" for k, v in rejected.items() if v)
        + "); declare more grasps, widen CellLimits.max_tool_tilt_rad, or allow nudges (CellConfig.max_nudges)",
        reason=f"none of {len(config.grasps)} grasps usable ({why})",
        refused={k: np.stack(v) for k, v in samples.items() if v},
    )
