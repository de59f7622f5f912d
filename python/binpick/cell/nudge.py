"""The nudge: when every located part is blocked (standing, leaning on a wall, no grasp within
the tool-tilt limit, lying in a row of its kind), the closed gripper pushes one of them and the
cell looks again.

First, a push that frees a part (:func:`plan_separating`): parts lying side by side — shafts that
rolled together, plates edge to edge — leave no room for a finger between them, and pushing
one across the row moves the row. For each located part, each direction (along the part's
length first: a shaft slides past its neighbours' ends) and each distance (the shortest first,
:data:`SEPARATE_STEP_MM` apart, within the safety module's ``max_push_mm``), the part is moved
by that much on paper: the push is taken when the part's footprint stays in the bin, meets no
other scanned part on its way (it would shove them too), and a grasp plan
(:func:`~binpick.cell.grasp.plan_grasp`) passes at the part's new place against the scan. The
cell scans again after any nudge and plans the pick on what it sees then: the prediction
chooses the push, nothing is picked on it.

Next, a push the cell's own physics predicts (:func:`plan_predicted`) for a part resting on the
floor that no straight push frees — a shaft lying along a wall, which no finger can get behind and
pushing along the wall only slides, is turned off it by a push on its end. The located part
alone is placed in the bin in the simulator's physics (:meth:`binpick.sim.Pile.placed`), pushed
by the closed fingers along each candidate path at a low and a high friction, and the push is
taken where both leave it clear of the other scanned parts and a grasp passes where it rests.
As for a freeing push, the cell scans again and plans on what it sees.

Otherwise, a push that topples or shifts a blocked part:

A nudge of a located part (``T_base_object``) is planned with the tool pointing straight down:
above a start point ``NUDGE_START_MM`` outside the part's footprint (30 mm, else 8 mm: between
a part and a wall), straight down until the
fingertips are at two thirds of the part's height above the floor (its top minus a third of its
height), straight across through the part to ``NUDGE_PAST_MM`` beyond its centre (to the centre when
that would bring the gripper against a wall; in steps no
longer than the cell's ``max_lateral_below_mm``, the whole push within ``max_push_mm``: the
safety module's rule 5), and
straight up again. Directions are tried in turn — towards the bin's centre first, then away from
the nearest wall, then the others — and the first plan that passes every check is run. A part
lying against a wall (too close for the closed fingers to go down between them) whose top leans
away from that wall (by ``LEAN_MM`` or more past its bottom) is pushed towards the wall first: a
push from the wall's side cannot start, a push along the wall only slides it, and every approach
to its leaning top within the tool-tilt limit comes from the wall's side; pushed over towards
the wall, it leans the other way and is grasped from the open side. A part pushed once and
still blocked is pushed another way next (``RETRY_APART_DEG``); a way that did not move it
(``UNMOVED_MM``: the push met a wall, or the part only rocked) is not tried again for it.

- every pose within the workspace and the tool-attitude limit, the whole sequence from the arm's
  pose now within the approach and push rules (:mod:`binpick.devices.safety`, rules 3 and 5);
- every pose reachable with the arm's kinematics (``config.reachable``);
- the whole gripper (fingers closed, as they are throughout; palm, flange) clear of the bin's floor and
  walls at every waypoint (:func:`~binpick.cell.grasp.bin_clash`; convex pieces in a convex bin,
  so the straight moves between them are clear too);
- the straight descent lands on no scanned point but the part's own (the closed fingers' and the
  palm's columns, down to where they stop).

Nothing moves before the plan is checked whole; a refused plan raises :class:`NudgeRefused`
(a :class:`~binpick.errors.SafetyError`). Lengths in mm, angles in radians.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from ..devices import safety
from ..errors import BinpickError, SafetyError
from ..transforms import inverse, look_down
from .config import CellConfig
from .grasp import NoGraspError, bin_clash, plan_grasp, plan_inputs
from .scene import OWN_POINT_MM, near_part
from .symmetry import continuous_near_axis

__all__ = [
    "NudgePlan",
    "NudgeRefused",
    "plan_nudge",
    "plan_predicted",
    "plan_separating",
    "check_nudge",
    "nudge_directions",
]

#: How far outside the part's footprint the closed fingers go down, mm: the first distance
#: tried, then the second (a part near a wall leaves a narrow gap between them).
NUDGE_START_MM = (30.0, 8.0)
#: How far past the part's centre the push goes, mm.
NUDGE_PAST_MM = 20.0
#: Directions tried per part (towards the bin centre, away from the nearest wall, then others).
NUDGE_DIRECTIONS = 8
#: A part pushed once and still blocked is pushed next in a direction at least this far from
#: the first push's, where one passes the checks, degrees.
RETRY_APART_DEG = 45.0
#: A part located again within this of where a push found it (:func:`_moved`) did not move: the
#: located pose's own scatter is a few tenths of a millimetre, and pushes that each inch a part
#: along by more add up, mm.
UNMOVED_MM = 2.0
#: A part whose top (highest third) lies this far or more past its bottom (lowest third) leans, mm.
LEAN_MM = 5.0
#: The fingertips stay at least this far above the floor (beyond ``floor_clearance_mm``), mm.
TIP_FLOOR_MARGIN_MM = 5.0
#: The distances a freeing push (:func:`plan_separating`) moves a part are multiples of this, mm.
SEPARATE_STEP_MM = 10.0
#: The cells of the map of what stands in a freeing push's way, mm: finer than a finger, coarser
#: than the scan's points are apart along a line.
PATH_CELL_MM = 2.0
#: Scanned points lower than this above the floor are the floor's, not a part's in the way, mm.
PATH_FLOOR_MM = 2.0
#: A part lying on the floor is pushed no nearer than this to a wall, mm.
WALL_MARGIN_MM = 2.0
#: A part whose height is at most this many times its thinnest extent lies on its broad side.
FLAT_RATIO = 1.25
#: A part whose lowest point is within this of the floor rests on the floor, mm.
FLAT_FLOOR_MM = 5.0

#: The physics-predicted push (:func:`plan_predicted`): the frictions it must free the part at,
PREDICT_FRICTIONS = (0.3, 0.7)
#: how far past first contact it pushes (mm, the shortest first; within ``max_push_mm``),
PREDICT_DISTANCES_MM = (25.0, 45.0, 70.0)
#: how many directions it tries (:func:`nudge_directions`),
PREDICT_DIRECTIONS = 16
#: where across the part the closed fingers meet it (shares of its half-width across the push),
PREDICT_OFFSETS = (0.0, -0.6, 0.6, -1.2, 1.2)
#: the least a push must move some point of the part, mm,
PREDICT_MIN_MOVE_MM = 5.0
#: the most the physics may move the located part as it settles before any push, mm: a part
#: balanced on an edge or a boss rolls off it a few millimetres, and is pushed from there; one
#: that falls farther lay on something the scan did not show, and nothing is predicted for it,
PREDICT_REST_MM = 8.0
#: the least angle from along a wall at which a push heads into it (a shallower one slides the
#: part along it), degrees,
ALONG_WALL_DEG = 10.0
#: the most the physics may let it sink as it settles, mm (more: it lay on a part the physics,
#: which holds the located part alone, does not have),
PREDICT_DROP_MM = 3.0
#: the tallest a part it pushes may stand, as a share of its length (a taller one topples),
PREDICT_HEIGHT_SHARE = 0.5
#: the most pushes it simulates for one part,
PREDICT_BUDGET = 60
#: the longest the physics may take to bring the part to rest, simulated s (a shaft rolls for
#: seconds after a push; a part still moving after this rocks on a pose the physics cannot hold,
#: and no prediction for it is trusted),
PREDICT_SETTLE_S = 6.0
#: and how high above the part's top the simulated fingers start their descent and end their
#: retreat, mm (above it they meet nothing the physics holds: the rest of the way is not simulated).
PREDICT_ABOVE_MM = 10.0


class NudgeRefused(SafetyError):
    """No nudge plan for this part passed the checks; nothing was sent."""


@dataclass(frozen=True, eq=False)
class NudgePlan:
    """A checked nudge: the part pushed (``T_base_object``), the push direction (unit, base xy),
    the fingertips' height (mm), and the moves as (name, T_base_flange, linear)."""

    T_base_object: np.ndarray
    direction: np.ndarray
    tip_z_mm: float
    waypoints: tuple[tuple[str, np.ndarray, bool], ...]
    #: A freeing push's (:func:`plan_separating`): where the part is planned to come to rest
    #: and the grasp that passes there; None for a push that topples or shifts a blocked part.
    T_after: Optional[np.ndarray] = None
    grasp_after: Optional[str] = None

    @property
    def heading_deg(self) -> float:
        """The push direction as an angle from base +x, degrees."""
        return math.degrees(math.atan2(float(self.direction[1]), float(self.direction[0])))

    def as_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "T_base_object": np.round(self.T_base_object, 6).tolist(),
            "heading_deg": round(self.heading_deg, 1),
            "tip_z_mm": round(self.tip_z_mm, 1),
            "frees": None
            if self.T_after is None
            else {"T_after": np.round(self.T_after, 6).tolist(), "grasp": self.grasp_after},
        }


def nudge_directions(
    config: CellConfig, centre_xy: np.ndarray, *, first: Optional[np.ndarray] = None, count: int = NUDGE_DIRECTIONS
) -> list[np.ndarray]:
    """Unit push directions for a part at ``centre_xy``: ``first`` if given, towards the bin's
    centre, away from the nearest wall, then the rest of ``count`` evenly spaced ones, nearest
    first."""
    lo, hi = (np.asarray(b, dtype=float) for b in config.bin_bounds)
    to_centre = (lo[:2] + hi[:2]) / 2 - centre_xy
    gaps = [centre_xy[0] - lo[0], hi[0] - centre_xy[0], centre_xy[1] - lo[1], hi[1] - centre_xy[1]]
    away = [np.array(v, dtype=float) for v in ((1, 0), (-1, 0), (0, 1), (0, -1))][int(np.argmin(gaps))]
    towards = to_centre / np.linalg.norm(to_centre) if np.linalg.norm(to_centre) > 1.0 else away
    angle0 = math.atan2(towards[1], towards[0])
    ring = [angle0 + 2 * math.pi * k / count for k in range(1, count)]
    ring.sort(key=lambda a: abs(math.remainder(a - angle0, 2 * math.pi)))
    out = [towards, away] + [np.array([math.cos(a), math.sin(a)]) for a in ring]
    if first is not None:
        out.insert(0, np.asarray(first, dtype=float) / np.linalg.norm(first))
    return _distinct(out)


def _distinct(directions: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``directions`` in order, each more than 10° from every one kept before it."""
    unique: list[np.ndarray] = []
    for d in directions:
        if all(float(d @ u) < math.cos(math.radians(10.0)) for u in unique):
            unique.append(np.asarray(d, dtype=float))
    return unique


def _tool_down(config: CellConfig, x: float, y: float, tip_z: float) -> np.ndarray:
    """The flange pose with the tool straight down and the fingertips at (x, y, tip_z)."""
    T = look_down(x, y, 0.0)
    g = config.gripper
    tip = (T @ g.T_flange_gripper @ np.array([0.0, 0.0, g.tip_depth_mm, 1.0]))[:3]
    T[:3, 3] += np.array([x, y, tip_z]) - tip
    return T


def _waypoints(
    config: CellConfig, start: np.ndarray, end: np.ndarray, tip_z: float
) -> list[tuple[str, np.ndarray, bool]]:
    lim = config.limits
    above = _tool_down(config, *start, tip_z)
    above[2, 3] = config.clearance_z_mm
    down = _tool_down(config, *start, tip_z)
    span = float(np.linalg.norm(end - start))
    steps = max(1, math.ceil(span / (0.95 * lim.max_lateral_below_mm)))
    moves = [("above", above, False), ("descend", down, True)]
    for k in range(1, steps + 1):
        moves.append((f"push {k}", _tool_down(config, *(start + (end - start) * k / steps), tip_z), True))
    up = moves[-1][1].copy()
    up[2, 3] = config.clearance_z_mm
    moves.append(("retreat", up, True))
    return moves


def _descent_hits(config: CellConfig, T_down: np.ndarray, points: np.ndarray) -> int:
    """How many ``points`` (base frame) the closed gripper meets on its straight way down to
    ``T_down``: points in the column of a finger or of the palm, above where that piece stops."""
    T_gb = inverse(T_down @ config.gripper.T_flange_gripper)
    local = points @ T_gb[:3, :3].T + T_gb[:3, 3]
    hits = np.zeros(len(points), dtype=bool)
    for half, T_gbox in config.gripper.boxes(0.0):
        T_boxg = inverse(T_gbox)
        p = local @ T_boxg[:3, :3].T + T_boxg[:3, 3]
        # The gripper's z points down: a point above the box's bottom face lies in its path.
        hits |= (np.abs(p[:, 0]) <= half[0]) & (np.abs(p[:, 1]) <= half[1]) & (p[:, 2] <= half[2])
    return int(hits.sum())


def check_nudge(config: CellConfig, waypoints: list, T_now: np.ndarray, scene: np.ndarray) -> Optional[str]:
    """Why the nudge ``waypoints`` (from the arm's pose ``T_now``) may not run, or None: the
    safety rules for the whole sequence, reach, the gripper against the bin, the descent against
    the scanned points ``scene`` (the part's own left out)."""
    names = [n for n, _, _ in waypoints]
    poses = [T for _, T, _ in waypoints]
    try:
        checked = [safety.check_pose(T, config.limits, name=n) for n, T in zip(names, poses)]
        linear = [lin for _, _, lin in waypoints]
        safety.check_sequence(T_now, checked, linear, config.limits, names=names, push=True)
    except SafetyError as exc:
        return f"safety: {exc}"
    if config.reachable is not None:
        for n, T in zip(names, poses):
            if not config.reachable(T):
                return f"{n}: out of the arm's reach"
    for n, T in zip(names[1:], poses[1:]):
        why = bin_clash(
            config.gripper, T, config.bin_bounds, floor_clearance_mm=config.floor_clearance_mm, opening_mm=0.0
        )
        if why is not None:
            return f"{n}: the gripper would hit the bin's {why}"
    hits = _descent_hits(config, poses[1], scene)
    if hits > config.max_collision_points:
        return f"descend: the gripper would land on {hits} scanned points of other parts"
    return None


def _vertices(config: CellConfig, T: np.ndarray) -> np.ndarray:
    """The part's mesh vertices at ``T`` (base frame)."""
    return np.asarray(config.model.vertices) @ T[:3, :3].T + T[:3, 3]


def _part_in_scan(
    config: CellConfig, T: np.ndarray, pts: np.ndarray, verts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The located part at ``T`` (its vertices there ``verts``) against the scan ``pts`` (base
    frame): the centre of its box over the floor (xy), its sample points, and the scan's points
    that are not its own (farther than :data:`~binpick.cell.scene.OWN_POINT_MM` from it)."""
    part = np.asarray(config.model.points) @ T[:3, :3].T + T[:3, 3]
    centre = (verts[:, :2].min(axis=0) + verts[:, :2].max(axis=0)) / 2
    return centre, part, pts[~near_part(pts, part)]


def _push_height(config: CellConfig, verts: np.ndarray) -> float:
    """The fingertips' height for pushing the part whose vertices (base frame) are ``verts``:
    two thirds of its height above the floor, and clear of the floor."""
    floor = float(config.bin_bounds[0][2])
    top = float(verts[:, 2].max())
    return max(top - (top - floor) / 3.0, floor + config.floor_clearance_mm + TIP_FLOOR_MARGIN_MM)


def _closed_reach(config: CellConfig) -> float:
    """How far the closed fingers reach from the TCP across, whichever way the push goes, mm."""
    g = config.gripper
    return math.hypot(g.finger_thickness_mm, g.finger_width_mm / 2)


class _PathMap:
    """Where the scanned points of other parts stand over the bin's floor, on a grid of
    :data:`PATH_CELL_MM` cells: what a part pushed over the floor would run into."""

    def __init__(self, config: CellConfig, others: np.ndarray) -> None:
        lo, hi = (np.asarray(b, dtype=float) for b in config.bin_bounds)
        self.lo, self.hi = lo[:2], hi[:2]
        self.shape = tuple(int(n) for n in np.ceil((self.hi - self.lo) / PATH_CELL_MM).astype(int) + 1)
        self.occupied = np.zeros(self.shape, dtype=bool)
        up = others[(others[:, 2] > lo[2] + PATH_FLOOR_MM) & (others[:, 2] < hi[2])]
        inside = ((up[:, :2] >= self.lo) & (up[:, :2] <= self.hi)).all(axis=1)
        ij = ((up[inside, :2] - self.lo) // PATH_CELL_MM).astype(int)
        self.occupied[ij[:, 0], ij[:, 1]] = True

    def clear(self, footprint: np.ndarray, offset: np.ndarray) -> bool:
        """Whether the part's footprint (its points' xy) moved by ``offset`` (one xy, or one per
        point) lies inside the bin's walls (:data:`WALL_MARGIN_MM` from them, or as near as it
        lies now) on cells no other part stands on."""
        xy = footprint + offset
        # No nearer a wall than the margin, or than the part already lies (a part against a
        # wall may slide along it).
        lo = np.minimum(self.lo + WALL_MARGIN_MM, footprint.min(axis=0))
        hi = np.maximum(self.hi - WALL_MARGIN_MM, footprint.max(axis=0))
        if (xy < lo).any() or (xy > hi).any():
            return False
        # A part located a hair past a wall lies in the edge cells, not wrapped round the map.
        ij = np.clip(((xy - self.lo) // PATH_CELL_MM).astype(int), 0, np.array(self.shape) - 1)
        return not bool(self.occupied[ij[:, 0], ij[:, 1]].any())


def _freeing_directions(config: CellConfig, verts: np.ndarray, centre: np.ndarray) -> list[np.ndarray]:
    """Push directions for a freeing push: along the part's longest extent over the floor both
    ways (a shaft slides out along its axis), then :func:`nudge_directions`."""
    xy = verts[:, :2] - verts[:, :2].mean(axis=0)
    w, v = np.linalg.eigh(xy.T @ xy)
    first = [v[:, 1], -v[:, 1]] if w[1] > 2.0 * max(w[0], 1e-9) else []
    return _distinct(first + nudge_directions(config, centre))


def _room(config: CellConfig, footprint: np.ndarray, d: np.ndarray) -> float:
    """How far the part's footprint (its points' xy) can be pushed along ``d`` before it is
    pressed into one of the bin's walls, mm: walls the push meets at more than 45° from along
    them (a part pushed at a wall more shallowly slides along it); 0 when it is already there."""
    lo, hi = (np.asarray(b, dtype=float)[:2] for b in config.bin_bounds)
    room = math.inf
    for axis in (0, 1):
        if abs(d[axis]) > 1e-9 and abs(d[axis]) >= abs(d[1 - axis]):
            wall = hi[axis] if d[axis] > 0 else lo[axis]
            room = min(room, float(((wall - footprint[:, axis]) / d[axis]).min()))
    return max(room, 0.0)


def _on_floor(config: CellConfig, verts: np.ndarray) -> bool:
    """Whether the part whose vertices (base frame) are ``verts`` rests on the bin's floor: its
    lowest point within :data:`FLAT_FLOOR_MM` of it (beyond the floor clearance)."""
    floor = float(config.bin_bounds[0][2]) + config.floor_clearance_mm
    return float(verts[:, 2].min()) <= floor + FLAT_FLOOR_MM


def _lying(config: CellConfig, verts: np.ndarray) -> bool:
    """Whether the part whose vertices (base frame) are ``verts`` lies on the floor (:func:`_on_floor`),
    no taller than :data:`PREDICT_HEIGHT_SHARE` of its length: pushed, it slides and rolls, as
    the physics can predict; a part standing up topples, which it cannot."""
    centred = verts - verts.mean(axis=0)
    longest = float(np.ptp(centred @ np.linalg.eigh(centred.T @ centred)[1][:, 2]))
    return float(np.ptp(verts[:, 2])) <= PREDICT_HEIGHT_SHARE * longest and _on_floor(config, verts)


def _lies_flat(config: CellConfig, verts: np.ndarray) -> bool:
    """Whether the part whose vertices (base frame) are ``verts`` lies on the bin's floor on its
    broad side (its height no more than :data:`FLAT_RATIO` times its thinnest extent, its bottom
    within :data:`FLAT_FLOOR_MM` of the floor): pushed, it slides or rolls where it is pushed,
    as :func:`plan_separating` plans; a part standing up or lying on others topples instead."""
    centred = verts - verts.mean(axis=0)
    thinnest = float(np.ptp(centred @ np.linalg.eigh(centred.T @ centred)[1][:, 0]))
    return float(np.ptp(verts[:, 2])) <= FLAT_RATIO * thinnest and _on_floor(config, verts)


def plan_separating(config: CellConfig, T_base_object: Any, scene: Any, T_now: Any) -> Optional[NudgePlan]:
    """The shortest push of the located part ``T_base_object`` that frees it (see the module's
    docstring): along each of :func:`_freeing_directions`, by a multiple of
    :data:`SEPARATE_STEP_MM`, its footprint in the bin and clear of other scanned parts all the
    way, a grasp passing at its new place against ``scene`` (base frame; the part's own points
    left out), the push passing :func:`check_nudge`. None when no push does."""
    T, pts, T_now = plan_inputs(config, T_base_object, scene, T_now, "T_now")
    model = config.model
    verts = _vertices(config, T)
    if not _lies_flat(config, verts):
        return None
    centre, part, others = _part_in_scan(config, T, pts, verts)
    footprint = part[:, :2]
    path = _PathMap(config, others)
    tip_z, reach = _push_height(config, verts), _closed_reach(config)
    free_turn = continuous_near_axis(model) is not None
    longest = config.limits.max_push_mm - min(NUDGE_START_MM) - SEPARATE_STEP_MM
    directions = _freeing_directions(config, verts, centre)
    cleared = [0.0] * len(directions)  # how far each direction's way is known clear
    live = list(range(len(directions)))
    grasps: dict[tuple[int, float], Optional[tuple[np.ndarray, Any]]] = {}
    distance = SEPARATE_STEP_MM
    while distance <= longest and live:
        for k in list(live):
            # Robust to a push that carries the part a step short of where it is planned to
            # go: a grasp passes there too.
            d, farther = directions[k], distance + SEPARATE_STEP_MM
            while cleared[k] < farther - 1e-9 and path.clear(footprint, min(cleared[k] + PATH_CELL_MM, farther) * d):
                cleared[k] = min(cleared[k] + PATH_CELL_MM, farther)
            if cleared[k] < farther - 1e-9:  # something in the way: farther is no better
                live.remove(k)
                continue
            for x in (distance, farther):  # each place planned once: a step's farther is the next's
                if (k, x) not in grasps:
                    grasps[k, x] = _grasp_at(config, T, x * d, others, T_now, free_turn)
            if grasps[k, distance] is None or grasps[k, farther] is None:
                continue
            T_after, plan = grasps[k, farther]
            rear = float(((verts[:, :2] - centre) @ d).min())
            end = centre + (rear - reach + farther) * d
            for gap in NUDGE_START_MM:
                moves = _waypoints(config, centre + (rear - gap - reach) * d, end, tip_z)
                if check_nudge(config, moves, T_now, others) is None:
                    return NudgePlan(
                        T_base_object=T,
                        direction=d,
                        tip_z_mm=tip_z,
                        waypoints=tuple(moves),
                        T_after=T_after,
                        grasp_after=plan.grasp,
                    )
        distance += SEPARATE_STEP_MM
    return None


def plan_predicted(
    config: CellConfig,
    T_base_object: Any,
    scene: Any,
    T_now: Any,
    *,
    budget: int = PREDICT_BUDGET,
) -> Optional[NudgePlan]:
    """A push of the located part ``T_base_object`` lying on the floor (:func:`_lying`) that the cell's own
    physics (:meth:`binpick.sim.Pile.push`, the located part alone in the bin) predicts leaves
    it where a grasp passes against ``scene`` (base frame; the part's own points left out) —
    for a part no straight push frees (:func:`plan_separating`): a shaft lying along a wall,
    turned off it by a push on its end.

    Pushes are tried along :data:`PREDICT_DIRECTIONS` directions (:func:`nudge_directions`'s
    order), the closed fingers meeting the part at its middle or towards either side
    (:data:`PREDICT_OFFSETS`, shares of its half-width across the push), over
    :data:`PREDICT_DISTANCES_MM` past first contact (the shortest first). A push is taken when it
    passes :func:`check_nudge`, its descent lands on none of the part's own points, and at both
    of :data:`PREDICT_FRICTIONS` (a real bin's friction is not known better than that) the part
    comes to rest at least :data:`PREDICT_MIN_MOVE_MM` from where it lay, its footprint in the
    bin and clear of the other scanned parts at every quarter of the way there, and a grasp
    passes where it rests (and none passes where it lies now: a part held back by its pose's doubt,
    not by what is around it, is not pushed). ``budget``: most pushes simulated (each at both frictions) before
    giving up. None when no push passes; nothing is sent. The cell scans again after the push and
    plans on what it sees: the prediction chooses the push, nothing is picked on it."""
    T, pts, T_now = plan_inputs(config, T_base_object, scene, T_now, "T_now")
    verts = _vertices(config, T)
    if not _lying(config, verts):
        return None
    centre, part, others = _part_in_scan(config, T, pts, verts)
    free_turn = continuous_near_axis(config.model) is not None
    if _grasp_at(config, T, np.zeros(2), others, T_now, free_turn) is not None:
        return None  # a grasp passes where it lies: what holds it back no push mends (its pose's doubt)
    piles = [_physics_for(config, f) for f in PREDICT_FRICTIONS]
    rests = []
    for pile in piles:
        if not pile.set_poses(T[None]).settled:
            return None  # the physics cannot bring it to rest there: no prediction to trust
        rest = pile.poses[0]
        settled = rest[:3, 3] - T[:3, 3]
        if np.linalg.norm(settled) > PREDICT_REST_MM or -settled[2] > PREDICT_DROP_MM:
            return None  # the physics does not let it lie where it was located: no prediction to trust
        rests.append(rest)
    path = _PathMap(config, others)
    tip_z, reach = _push_height(config, verts), _closed_reach(config)
    top = float(verts[:, 2].max())
    speed = float(config.limits.max_linear_speed_mm_s)
    xy = part[:, :2] - centre
    plans = []  # (direction, across it, offset across, the part's rear along it in that strip)
    for d in nudge_directions(config, centre, count=PREDICT_DIRECTIONS):
        e = np.array([-d[1], d[0]])
        along, across = xy @ d, xy @ e
        half = max(float(np.abs(across).max()), 1e-6)
        for share in PREDICT_OFFSETS:
            o = share * half
            strip = np.abs(across - o) <= reach
            if strip.sum() < 3:
                continue
            plans.append((d, e, o, float(along[strip].min())))
    simulated = 0
    for distance in PREDICT_DISTANCES_MM:
        for d, e, o, rear in plans:
            if simulated >= budget:
                return None
            if _toward_wall(config, part[:, :2], d, distance):
                continue  # never into a wall: the arm would crush the part there
            for gap in NUDGE_START_MM:
                start = centre + o * e + (rear - reach - gap) * d
                moves = _waypoints(config, start, start + (gap + distance) * d, tip_z)
                if _descent_hits(config, moves[1][1], part) or check_nudge(config, moves, T_now, others):
                    continue
                simulated += 1
                tool = np.array([T_f @ config.gripper.T_flange_gripper for _, T_f, _ in moves])
                # The fingers simulated from just above the part's top down and back up to it.
                tool[:, 2, 3] = np.minimum(tool[:, 2, 3], tool[1, 2, 3] + top - tip_z + PREDICT_ABOVE_MM)
                if not all(_predicts_freed(config, p, r, tool, speed, path, part, T) for p, r in zip(piles, rests)):
                    break
                after = [pile.poses[0] for pile in piles]
                grasps = [_grasp_at(config, A, np.zeros(2), others, T_now, free_turn) for A in after]
                if any(g is None for g in grasps):
                    break
                return NudgePlan(
                    T_base_object=T,
                    direction=d,
                    tip_z_mm=tip_z,
                    waypoints=tuple(moves),
                    T_after=grasps[0][0],
                    grasp_after=grasps[0][1].grasp,
                )
    return None


#: The predicted push's physics, one pile per (part, bin, friction), built once (a part's
#: collision hulls take up to a second) and moved to each located pose with ``set_poses``.
_PHYSICS: dict = {}


def _physics_for(config: CellConfig, friction: float) -> Any:
    """The cell's part alone in its bin in the simulator's physics at ``friction``."""
    from ..sim.cell import Bin  # the physics only when a part is blocked: the real loop loads no simulator
    from ..sim.pile import Pile

    lo, hi = (np.asarray(b, dtype=float) for b in config.bin_bounds)
    key = (id(config.model), tuple(lo), tuple(hi), friction)
    pile = _PHYSICS.get(key)
    if pile is None or pile.model is not config.model:
        if len(_PHYSICS) >= 8:
            _PHYSICS.clear()
        box = Bin(size=tuple(hi - lo), center=tuple((lo[:2] + hi[:2]) / 2), floor_z=float(lo[2]))
        # Placed anywhere: every use sets the pose it predicts from.
        T = np.eye(4)
        T[:3, 3] = ((lo + hi) / 2)[:3]
        pile = _PHYSICS[key] = Pile.placed(
            config.model, T[None], bin=box, friction=friction, max_settle_time=PREDICT_SETTLE_S
        )
    return pile


def _toward_wall(config: CellConfig, footprint: np.ndarray, d: np.ndarray, distance: float) -> bool:
    """Whether moving the footprint (the part's points' xy) ``distance`` mm along ``d`` would bring
    it nearer than :data:`WALL_MARGIN_MM` to a wall ``d`` heads into (at more than
    :data:`ALONG_WALL_DEG` from along it): a part pressed into a wall is crushed, or squirts out
    where no physics can say."""
    lo, hi = (np.asarray(b, dtype=float)[:2] for b in config.bin_bounds)
    into = math.sin(math.radians(ALONG_WALL_DEG))
    for axis in (0, 1):
        if d[axis] < -into and float(footprint[:, axis].min()) + distance * d[axis] < lo[axis] + WALL_MARGIN_MM:
            return True
        if d[axis] > into and float(footprint[:, axis].max()) + distance * d[axis] > hi[axis] - WALL_MARGIN_MM:
            return True
    return False


def _predicts_freed(
    config: CellConfig,
    pile: Any,
    rest: np.ndarray,
    tool: np.ndarray,
    speed: float,
    path: _PathMap,
    part: np.ndarray,
    T: np.ndarray,
) -> bool:
    """Whether ``tool`` (``T_base_gripper`` poses) pushing the part in ``pile`` from ``rest`` at
    ``speed`` leaves it at rest, freed (:func:`_freed`) and on the floor."""
    pile.set_poses(rest[None])
    if not pile.push(config.gripper.boxes(0.0), tool, speed).settle.settled:
        return False  # still moving: where it ends is not known
    A = pile.poses[0]
    return _freed(path, part, T, rest, A) and _on_floor(config, _vertices(config, A))


def _freed(path: _PathMap, part: np.ndarray, T: np.ndarray, T_rest: np.ndarray, T_after: np.ndarray) -> bool:
    """Whether the push moved the part (its sample points ``part`` at ``T``, base frame) from
    where the physics let it rest (``T_rest``) to ``T_after`` by at least
    :data:`PREDICT_MIN_MOVE_MM` somewhere, its footprint inside the bin and clear of other parts
    at every quarter of the way from ``T`` (each point moved straight from where it was)."""

    def at(T_to: np.ndarray) -> np.ndarray:
        R = T_to[:3, :3] @ T[:3, :3].T
        return part @ R.T + (T_to[:3, 3] - R @ T[:3, 3])

    moved = at(T_after)
    if float(np.linalg.norm(moved - at(T_rest), axis=1).max()) < PREDICT_MIN_MOVE_MM:
        return False
    return all(path.clear(part[:, :2], k / 4 * (moved[:, :2] - part[:, :2])) for k in range(1, 5))


def _grasp_at(
    config: CellConfig, T: np.ndarray, offset: np.ndarray, others: np.ndarray, T_now: np.ndarray, free_turn: bool
) -> Optional[tuple[np.ndarray, Any]]:
    """The part at ``T`` moved by ``offset`` (xy, mm) and the grasp plan that passes there
    against ``others``, or None when none does."""
    T_after = T.copy()
    T_after[:2, 3] += offset
    try:
        return T_after, plan_grasp(config, T_after, others, T_now, free_turn=free_turn)[0]
    except NoGraspError:
        return None


def plan_nudge(
    config: CellConfig, T_base_object: Any, scene: Any, T_now: Any, *, tried: Sequence[NudgePlan] = ()
) -> NudgePlan:
    """The first nudge of the located part ``T_base_object`` that passes :func:`check_nudge`,
    over :func:`nudge_directions`; NudgeRefused (nothing sent) when none does. ``scene``: the
    scan's points (base frame); ``T_now``: the arm's flange pose now; ``tried``: the nudges
    already made in this pick — a direction within :data:`RETRY_APART_DEG` of one that already
    pushed this part (a nudged part within half its diameter of here) and left it blocked is
    tried last, after the others, and not at all when that push left the part where it was
    (:func:`_moved` less than :data:`UNMOVED_MM`: the same push again does the same nothing)."""
    T, pts, T_now = plan_inputs(config, T_base_object, scene, T_now, "T_now")
    model = config.model
    verts = _vertices(config, T)
    centre, part, others = _part_in_scan(config, T, pts, verts)
    tip_z, reach = _push_height(config, verts), _closed_reach(config)
    why: list[str] = []
    directions = nudge_directions(config, centre, first=_topple(config, verts, reach))
    same = [p for p in tried if np.linalg.norm(p.T_base_object[:2, 3] - T[:2, 3]) < model.diameter / 2]
    before = [p.direction for p in same]
    cos_apart = math.cos(math.radians(RETRY_APART_DEG))
    directions.sort(key=lambda d: any(float(d @ b) > cos_apart for b in before))  # stable: the order otherwise kept
    stuck = [p.direction for p in same if _moved(config, p.T_base_object, T) < UNMOVED_MM]
    for d in stuck:
        why.append(f"{math.degrees(math.atan2(d[1], d[0])):.0f}°: pushed that way already, it did not move")
    directions = [d for d in directions if not any(float(d @ b) > cos_apart for b in stuck)]
    # A part lying on the floor slides as far as it is pushed: never into a wall (the arm would
    # crush it there). One standing topples, and may be pushed over towards a wall.
    footprint = part[:, :2] if _lies_flat(config, verts) else None
    for d in directions:
        s = (verts[:, :2] - centre) @ d
        touch = float(s.min()) - reach  # the TCP's place along d where the fingers meet the part
        # A push that would reach a wall may still reach the centre.
        ends = [NUDGE_PAST_MM, 0.0]
        if footprint is not None:
            room = _room(config, footprint, d) - WALL_MARGIN_MM
            capped = {min(e, touch + room) for e in ends}
            ends = sorted((e for e in capped if e - touch >= SEPARATE_STEP_MM), reverse=True)
            problem = "the part would be pushed into the bin's wall" if not ends else None
        for gap in NUDGE_START_MM:
            start = centre + (touch - gap) * d
            for past in ends:
                moves = _waypoints(config, start, centre + past * d, tip_z)
                problem = check_nudge(config, moves, T_now, others)
                if problem is None:
                    return NudgePlan(T_base_object=T, direction=d, tip_z_mm=tip_z, waypoints=tuple(moves))
        why.append(f"{math.degrees(math.atan2(d[1], d[0])):.0f}°: {problem}")
    raise NudgeRefused(
        f"no nudge of the {model.name} at ({T[0, 3]:.1f}, {T[1, 3]:.1f}, {T[2, 3]:.1f}) mm passes the checks "
        f"({'; '.join(why)}); nothing was sent"
    )


def _moved(config: CellConfig, T_before: np.ndarray, T: np.ndarray) -> float:
    """About how far the part located at ``T`` has moved since it was at ``T_before``, mm: its
    pose error (modulo its symmetries and a turn about its near-symmetry axis: a look places a
    hidden keyway anywhere round its shaft, and a part turned by a symmetry has not moved), the
    rotation counted at half the part's diameter."""
    deg, mm = config.model.pose_error(T, T_before, turn_about=continuous_near_axis(config.model))
    return mm + math.radians(deg) * config.model.diameter / 2


def _topple(config: CellConfig, verts: np.ndarray, reach: float) -> Optional[np.ndarray]:
    """The push towards the nearest wall for a part (``verts``, base frame) lying too close to it
    for the closed fingers (``reach`` from the TCP) to go down between them, whose top (highest
    third) leans away from it by :data:`LEAN_MM` or more past its bottom (lowest third); None for any other part."""
    lo, hi = (np.asarray(b, dtype=float) for b in config.bin_bounds)
    low, high = verts[:, :2].min(axis=0), verts[:, :2].max(axis=0)
    gaps = np.array([low[0] - lo[0], hi[0] - high[0], low[1] - lo[1], hi[1] - high[1]])
    wall = int(np.argmin(gaps))
    if gaps[wall] >= min(NUDGE_START_MM) + 2.0 * reach:
        return None
    towards = np.array([(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)][wall])
    top = float(verts[:, 2].max())
    bottom = float(verts[:, 2].min())
    height = top - bottom
    lean = verts[verts[:, 2] >= top - height / 3.0, :2].mean(axis=0) - verts[
        verts[:, 2] <= bottom + height / 3.0, :2
    ].mean(axis=0)
    return towards if float(lean @ -towards) >= LEAN_MM else None


def nudge_blocked(cell: Any, skipped: list, scan: Any, made: Sequence[NudgePlan] = ()) -> Optional[NudgePlan]:
    """Plans a nudge of the first pose in ``skipped`` (the located parts the loop passed over,
    every look's estimate) that has one, and runs it on ``cell`` (closes the gripper, the moves, gripper left closed);
    the plan run, or None when no part has one (nothing was sent); ``made``: the nudges already
    made in this pick (see :func:`plan_nudge`). Faults stop the arm and are raised."""
    cfg = cell.config
    T_now = cell.robot.read_pose()
    c0 = cell._cpu_now()

    def planned() -> None:  # the planning's CPU, for the cycle's compute
        cell._cpu["cpu.nudge"] = cell._cpu.get("cpu.nudge", 0.0) + (cell._cpu_now() - c0) * 1e3

    # A push that frees a part first, each part once (the looks' estimates of one part agree):
    # a straight one, then one the physics predicts.
    parts: list[Any] = []
    for k in skipped:
        if not any(np.linalg.norm(k.T_base_object[:3, 3] - u.T_base_object[:3, 3]) < OWN_POINT_MM for u in parts):
            parts.append(k)
    predicted = "to free it, as the physics predicts"
    for how in ("to free it", predicted):
        for k in parts:
            if how == predicted:
                plan = plan_predicted(cfg, k.T_base_object, scan.points, T_now)
            else:
                plan = plan_separating(cfg, k.T_base_object, scan.points, T_now)
            if plan is None:
                continue
            t, a = k.T_base_object[:3, 3], plan.T_after[:3, 3]
            cell.progress(
                "nudge",
                f"pushing the {cfg.model.name} at ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm towards "
                f"{plan.heading_deg:.0f}° {how} (a grasp passes at ({a[0]:.1f}, {a[1]:.1f}) mm, "
                f"{np.linalg.norm(a - t):.0f} mm away), fingertips {plan.tip_z_mm:.0f} mm up",
            )
            planned()
            return plan if _execute(cell, plan) else _closed_on_something(cell)
    tried: list[np.ndarray] = []
    refusals = []
    for k in skipped:
        # Each look's estimate of a part is tried: a plan refused for one may pass for another.
        t = k.T_base_object[:3, 3]
        if any(np.abs(k.T_base_object - u).max() < 1e-3 for u in tried):
            continue
        tried.append(k.T_base_object)
        try:
            plan = plan_nudge(cfg, k.T_base_object, scan.points, T_now, tried=made)
        except NudgeRefused as exc:
            refusals.append(str(exc))
            continue
        cell.progress(
            "nudge",
            f"pushing the {cfg.model.name} at ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm towards "
            f"{plan.heading_deg:.0f}° with the closed gripper, fingertips {plan.tip_z_mm:.0f} mm up",
        )
        planned()
        return plan if _execute(cell, plan) else _closed_on_something(cell)
    planned()
    cell.progress("nudge", f"no part can be nudged: {refusals[0] if refusals else 'no part located'}")
    return None


def _closed_on_something(cell: Any) -> None:
    cell.progress("nudge", "the gripper closed on something before the push; nothing was pushed")


def _execute(cell: Any, plan: NudgePlan) -> bool:
    """Closes the gripper and makes the moves; False (and the gripper opened again, the arm not
    moved) when the fingers closed on something."""
    try:
        if cell.gripper.close() is True:
            cell.gripper.open()
            return False
        for _, T, linear in plan.waypoints:
            cell.robot.move_to(T, linear=linear)
        return True
    except BinpickError as exc:
        note = cell._halt()
        cell.progress("FAULT", f"{exc} — {note}")
        raise
