"""Where the camera looks from: the scan poses of a second look, which of them best shows what
tells an ambiguous pose from its alternatives, and whether another look is worth it at all.
Lengths in mm, transforms 4×4 ``T_to_from``."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import positive
from ..devices import safety
from ..errors import SafetyError
from ..models import Model, nearest_distances
from ..transforms import rotation_about

if TYPE_CHECKING:  # annotations only: config imports this module
    from .config import CellConfig

__all__ = [
    "IN_BIN_MM",
    "PLACE_REFUSALS",
    "turned_scan_poses",
    "deciding_views",
    "deciding_first",
    "something_in_bin",
    "settled",
    "worth_another_look",
]

#: Scan points more than this far (mm) inside the bin's walls and above its floor are something in
#: the bin (many times the scan's noise, less than any part is thick): see :func:`something_in_bin`.
IN_BIN_MM = 3.0

#: The reasons a grasp is refused that depend only on where the part lies and on what the scan
#: already shows around it (:func:`binpick.cell.grasp.plan_grasp`): the tool's tilt, the opening,
#: the bin's walls, scene points in the gripper (a later look joins the first, so its points only
#: add), the part's own other branches, the arm's reach and the safety rules. Another view of the
#: same pose cannot lift them.
PLACE_REFUSALS = frozenset({"tilt", "width", "bin", "collision", "self-collision", "reach", "safety"})


def turned_scan_poses(config: CellConfig, *, tilt_deg: float = 20.0) -> tuple[np.ndarray, ...]:
    """The first scan pose turned by ``tilt_deg`` about the centre of the bin's floor toward each
    of the bin's four sides (the camera keeps the bin in view and sees the pile's sides that face
    that way), keeping those within the cell's limits, above the approach height and, when the
    config knows the arm's kinematics (``reachable``), reachable."""
    lo, hi = config.bin_bounds
    centre = np.array([(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, lo[2]])
    T0 = config.scan_poses[0]
    angle = math.radians(positive(tilt_deg, "tilt_deg", "deg"))
    turned = []
    for axis in ((0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)):
        R = rotation_about(np.array(axis), angle)
        T = np.eye(4)
        T[:3, :3] = R @ T0[:3, :3]
        T[:3, 3] = centre + R @ (T0[:3, 3] - centre)
        try:
            safety.check_pose(T, config.limits, name="look-again pose")
        except SafetyError:
            continue
        if T[2, 3] >= config.limits.approach_height_mm and (config.reachable is None or config.reachable(T)):
            turned.append(T)
    return tuple(turned)


def deciding_views(
    model: Model,
    T_base_object: np.ndarray,
    alternatives: Sequence[np.ndarray],
    views: Sequence[np.ndarray],
    T_flange_camera: np.ndarray,
    *,
    tolerance_mm: float = 3.0,
    samples: int = 600,
) -> list[int]:
    """The indices of ``views`` (flange poses), best first, for telling the pose
    ``T_base_object`` from its ``alternatives``: the deciding feature is the part's surface
    that one pose has and the other lacks (model samples farther than ``tolerance_mm`` from the
    other pose's surface, both ways round); a view scores by how squarely that surface faces
    its camera (the sum over those samples of the cosine between the outward normal and the
    direction to the camera, facing away counted 0)."""
    step = max(1, len(model.points) // samples)
    pts = np.asarray(model.points, dtype=np.float64)[::step]
    nrm = np.asarray(model.normals, dtype=np.float64)[::step]

    def posed(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return pts @ T[:3, :3].T + T[:3, 3], nrm @ T[:3, :3].T

    features = []
    here = posed(np.asarray(T_base_object, dtype=np.float64))
    for T_alt in alternatives:
        there = posed(np.asarray(T_alt, dtype=np.float64))
        for (p, n), (q, _) in ((here, there), (there, here)):
            far = nearest_distances(p, q) > tolerance_mm
            features.append((p[far], n[far]))
    if not features:
        return list(range(len(views)))
    p = np.vstack([f[0] for f in features])
    n = np.vstack([f[1] for f in features])
    scores = []
    for T in views:
        cam = (np.asarray(T, dtype=np.float64) @ T_flange_camera)[:3, 3]
        to_cam = cam - p
        to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
        scores.append(float(np.clip((n * to_cam).sum(axis=1), 0.0, None).sum()))
    return sorted(range(len(views)), key=lambda i: -scores[i])


def deciding_first(config: CellConfig, views: list, skipped: Sequence, progress) -> list:
    """The look-again ``views`` (each a tuple whose first item is the flange pose), the one that
    best shows what tells the first ambiguous part of ``skipped`` (the parts passed over, see
    :class:`binpick.cell.records.Skipped`) from its alternatives first (:func:`deciding_views`);
    ``progress(stage, text)`` says which."""
    ambiguous = next((k for k in skipped if k.alternatives), None)
    if ambiguous is None or len(views) < 2:
        return views
    order = deciding_views(
        config.model,
        ambiguous.T_base_object,
        ambiguous.alternatives,
        [v[0] for v in views],
        config.calibration.T_flange_camera,
        tolerance_mm=config.ambiguity_tolerance_mm,
    )
    T = views[order[0]][0]
    progress(
        "look",
        f"the ambiguous {config.model.name} is best told apart from flange "
        f"({T[0, 3]:.1f}, {T[1, 3]:.1f}, {T[2, 3]:.1f}) mm: looking from there first",
    )
    return [views[i] for i in order]


def something_in_bin(config: CellConfig, scan: Any) -> bool:
    """Whether ``scan`` (a :class:`binpick.cell.records.ScanResult`) shows something standing in
    the bin: at least 10 points more than :data:`IN_BIN_MM` inside its walls and above its
    floor, spanning a fifth of the part's size (what the cell needs to search at all)."""
    return _something(config, _in_bin(config, scan.points))


def _in_bin(config: CellConfig, points: np.ndarray) -> np.ndarray:
    """Those of ``points`` more than :data:`IN_BIN_MM` inside the bin's walls and above its floor."""
    lo, hi = config.bin_bounds
    m, p = IN_BIN_MM, np.asarray(points, dtype=np.float64)
    return p[np.all(p[:, :2] > lo[:2] + m, axis=1) & np.all(p[:, :2] < hi[:2] - m, axis=1) & (p[:, 2] > lo[2] + m)]


def _something(config: CellConfig, inside: np.ndarray) -> bool:
    """Whether points in the bin (:func:`_in_bin`) are something: at least 10, spanning a fifth of the part."""
    return len(inside) >= 10 and float(np.linalg.norm(np.ptp(inside, axis=0))) >= 0.2 * config.model.diameter


def settled(config: CellConfig, result: Any, refused: Mapping[str, Any]) -> bool:
    """Whether another look cannot change why a located part was passed over: its pose is one
    the cell would pick on (unambiguous, ``confidence`` at least ``config.min_confidence``) and
    every grasp was refused for a reason of :data:`PLACE_REFUSALS` (``refused``: reason → the
    refused gripper poses, as :class:`binpick.cell.grasp.NoGraspError` keeps them). A pose
    refused for its confidence or its ambiguity, or one the scan leaves open, is not settled:
    a view that decides it may change its grasps."""
    if not refused or not set(refused) <= PLACE_REFUSALS:
        return False
    if getattr(result, "ambiguous", False) or getattr(result, "free_axis", None) is not None:
        return False
    return float(getattr(result, "confidence", 1.0)) >= config.min_confidence


def worth_another_look(config: CellConfig, scan: Any, skipped: Sequence) -> bool:
    """Whether looking from another pose may find a part to pick, after a look whose located
    parts (``skipped``, :class:`binpick.cell.records.Skipped`) were all passed over: yes when one
    of them is not :func:`settled`, or when ``scan`` shows something in the bin that none of them
    explains (as :func:`something_in_bin` counts it: points farther than :data:`IN_BIN_MM` plus the
    model's sample spacing from every located part's surface) — a part the search could not
    locate from here. No when every part seen is settled and explained: the cell goes on to its
    nudge at once instead of sweeping from every view."""
    if not skipped or not all(k.settled for k in skipped):
        return True
    p = _in_bin(config, scan.points)
    reach = IN_BIN_MM + float(config.model.spacing or 0.0)
    surface = np.asarray(config.model.points, dtype=np.float64)
    for k in skipped:
        if not len(p):
            break
        T = np.asarray(k.T_base_object, dtype=np.float64)
        p = p[nearest_distances(p, surface @ T[:3, :3].T + T[:3, 3]) > reach]
    return _something(config, p)
