"""The plain results of the pick loop: a scan, a located part (and its truth in the simulator),
a pick plan, a pick record and a run report. Lengths in mm, transforms 4×4 ``T_to_from``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from types import MappingProxyType
from typing import Any, Optional

import numpy as np

from ..transforms import inverse
from .symmetry import continuous_near_axis

__all__ = [
    "ScanResult",
    "line_step",
    "PoseTruth",
    "Located",
    "Skipped",
    "PickPlan",
    "PickRecord",
    "RunReport",
    "FAILURE_KINDS",
    "with_collisions",
    "judge_located",
    "grasp_fits_truth",
    "pick_outcome",
    "PICK_GRADE_DEG",
    "PICK_GRADE_MM",
    "CYCLE_STAGES",
    "cycle_stages_s",
    "picks_per_hour",
]

#: What a failed pick attempt can have gone wrong with, in the order a pick meets them.
FAILURE_KINDS: tuple[str, ...] = (
    "nothing found",  # no part located in the scan
    "no grasp",  # parts located, none with a usable grasp
    "empty grip",  # the gripper closed on nothing
    "nothing lifted",  # the gripper held, but no part left the bin
    "wrong pose",  # a part left the bin, but the located pose was not that part's, or not pick-grade
    # with a grasp none of the cell's on the part as it lay (grasp_fits_truth)
    "fault",  # a device fault or safety refusal stopped the arm
    "collision",  # the gripper touched a part other than the one it grasped, or the bin
)


#: A pose is pick-grade within this rotation error (degrees) and :data:`PICK_GRADE_MM` of
#: translation error of the true one, modulo the part's symmetries (the BOP-style measure).
PICK_GRADE_DEG = 5.0
#: A pose is pick-grade within this translation error (mm) and :data:`PICK_GRADE_DEG`.
PICK_GRADE_MM = 3.0


def line_step(cloud: Any) -> Optional[np.ndarray]:
    """The step (3,) from one laser line to the next on the scanned surfaces of a swept scan
    (``cloud`` a :class:`binpick.vision.Cloud`, whose ``frame`` numbers each point's line): the
    median shift between the centres of consecutive lines, horizontal. None for a cloud that is
    not a sweep of lines (one depth shot, a file), whose points lie a pixel apart.

    What lies between two lines is not seen: an edge a line did not catch can stand out up to a
    step beyond the last line that saw its part, and a finger there would come down on it."""
    frame = np.asarray(getattr(cloud, "frame", ()), dtype=np.int64).reshape(-1)
    points = np.asarray(getattr(cloud, "points", np.zeros((0, 3))), dtype=np.float64)
    if len(frame) != len(points) or len(frame) == 0:
        return None
    ids, inverse_, counts = np.unique(frame, return_inverse=True, return_counts=True)
    if len(ids) < 3:
        return None
    centres = np.stack([np.bincount(inverse_, weights=points[:, k]) / counts for k in range(2)], axis=1)
    consecutive = np.flatnonzero((np.diff(ids) == 1) & (counts[:-1] >= 10) & (counts[1:] >= 10))
    if len(consecutive) < 2:
        return None
    steps = centres[consecutive + 1] - centres[consecutive]
    direction = np.median(steps, axis=0)
    norm = float(np.linalg.norm(direction))
    if norm <= 1e-9:
        return None
    u = direction / norm
    size = float(np.median(np.abs(steps @ u)))
    return np.array([u[0] * size, u[1] * size, 0.0])


@dataclass(frozen=True, eq=False)
class ScanResult:
    """One scan: the cloud in the base frame, the motor angle (rad) and flange pose of every frame,
    a few kept frames (index → BGR image) and the stage timings (ms). ``carried``: how many of
    the first points were carried over from the scan before and not seen again (a rescan of
    what a pick changed, :mod:`binpick.cell.rescan`); 0 for a scan seen whole."""

    cloud: Any
    angles: np.ndarray
    T_base_flanges: np.ndarray
    frames: Mapping[int, np.ndarray]
    timings: Mapping[str, float]
    carried: int = 0

    @property
    def points(self) -> np.ndarray:
        """(N, 3) points, mm, base frame."""
        return self.cloud.points

    @cached_property
    def line_step(self) -> Optional[np.ndarray]:
        """The step from one laser line to the next (:func:`line_step`), worked out once per
        scan: every part planned on it asks."""
        return line_step(self.cloud)

    def seen_again(self, indices: Any) -> float:
        """The share of the points ``indices`` this scan saw itself (not carried over), 1 for none."""
        idx = np.asarray(indices, dtype=np.int64)
        return float(np.mean(idx >= self.carried)) if len(idx) else 1.0

    def joined(self, later: ScanResult) -> ScanResult:
        """This scan and a ``later`` one of the same bin from another pose, as one: their points
        (each with its frame, renumbered after this scan's), angles and flange poses in turn, the
        later scan's kept frames and timings. The camera rides on the arm and both poses are
        known, so a feature one view shows and the other does not is judged with everything
        else both show."""
        from ..vision import Cloud

        n = len(self.angles)
        a, b = self.cloud, later.cloud
        cloud = Cloud(
            points=np.concatenate([a.points, b.points]),
            frame=np.concatenate([a.frame, np.asarray(b.frame) + n]),
            pixels=np.concatenate([a.pixels, b.pixels]),
            angle=np.concatenate([a.angle, b.angle]),
        )
        return ScanResult(
            cloud=cloud,
            angles=np.concatenate([self.angles, later.angles]),
            T_base_flanges=np.concatenate([self.T_base_flanges, later.T_base_flanges]),
            frames=MappingProxyType({k + n: v for k, v in later.frames.items()}),
            timings=later.timings,
            carried=self.carried,
        )


@dataclass(frozen=True)
class PoseTruth:
    """A located pose judged against ground truth: the nearest true instance, the errors
    (minimised over the part's symmetries), whether they are pick-grade (under
    :data:`PICK_GRADE_DEG` and :data:`PICK_GRADE_MM`) and the instance's true pose
    (``T_base_truth``, when the truth gives it: what a grasp is judged against,
    :func:`grasp_fits_truth`)."""

    instance: int
    rotation_error_deg: float
    translation_error_mm: float
    T_base_truth: Optional[np.ndarray] = field(default=None, compare=False, repr=False)

    @property
    def pick_grade(self) -> bool:
        """Rotation error under 5° and translation error under 3 mm."""
        return self.rotation_error_deg < PICK_GRADE_DEG and self.translation_error_mm < PICK_GRADE_MM


def located_line(result: Any, T: np.ndarray, truth: Optional[PoseTruth]) -> str:
    """The progress line of a located part: method, score, where, how long, and against the truth."""
    t = T[:3, 3]
    judged = ""
    if truth is not None:
        grade = "pick-grade" if truth.pick_grade else "NOT pick-grade"
        judged = f"; vs truth {truth.rotation_error_deg:.2f}°, {truth.translation_error_mm:.2f} mm ({grade})"
    return (
        f"{result.method} score {result.score:.2f}, rmse {result.rmse:.2f} mm, at ({t[0]:.1f}, {t[1]:.1f}, "
        f"{t[2]:.1f}) mm in {sum(result.timings.values()):.0f} ms{judged}"
    )


@dataclass(frozen=True, eq=False)
class Located:
    """The part found in a scan: the pose result, ``T_base_object``, the indices of its points in
    the scan's cloud and, when the cell knows the truth (the simulator), how good it is."""

    scan: ScanResult
    result: Any
    T_base_object: np.ndarray
    indices: np.ndarray
    truth: Optional[PoseTruth] = None


@dataclass(frozen=True, eq=False)
class Skipped:
    """A located part the loop passed over: where, why (a few words), for the picture a few of
    the refused gripper poses per reason (reason → (K, 4, 4) ``T_base_gripper``), the
    alternative poses the scan could not rule out when the pose was ambiguous, and whether another
    look cannot change why it was passed over (:func:`binpick.cell.views.settled`)."""

    T_base_object: np.ndarray
    reason: str
    truth: Optional[PoseTruth] = None
    refused: Mapping[str, np.ndarray] = field(default_factory=dict)
    alternatives: tuple[np.ndarray, ...] = ()
    settled: bool = False

    def as_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "T_base_object": np.round(self.T_base_object, 6).tolist(),
            "reason": self.reason,
            "truth": _truth_dict(self.truth),
        }


def _truth_dict(truth: Optional[PoseTruth]) -> Optional[dict]:
    if truth is None:
        return None
    return {
        "instance": truth.instance,
        "rotation_error_deg": truth.rotation_error_deg,
        "translation_error_mm": truth.translation_error_mm,
        "pick_grade": truth.pick_grade,
    }


@dataclass(frozen=True, eq=False)
class PickPlan:
    """The chosen grasp and the motion: ``waypoints`` are (name, T_base_flange, linear) in order;
    ``opening_mm`` how far apart the fingers are on the way in, the opening the plan was checked
    with (None: fully open)."""

    grasp: str
    T_base_gripper: np.ndarray
    T_base_flange: np.ndarray
    tilt_deg: float
    waypoints: tuple[tuple[str, np.ndarray, bool], ...]
    considered: int
    rejected: Mapping[str, int]
    opening_mm: Optional[float] = None

    def pose(self, name: str) -> np.ndarray:
        """The flange pose of waypoint ``name``."""
        for n, T, _ in self.waypoints:
            if n == name:
                return T
        raise KeyError(name)


#: The stages of a cycle's physical time (:func:`cycle_stages_s`), in the order they run.
CYCLE_STAGES = ("scan.move", "scan.sweep", "compute", "motion", "other")


def cycle_stages_s(timings: Mapping[str, float]) -> Optional[dict[str, float]]:
    """The physical time of a cycle's stages, s, from a record's timings (ms), or None when the
    cell kept no hardware clock (:attr:`binpick.cell.Cell.clock`: a real cell, whose wall clock
    is its physical time): ``scan.move`` (the arm to each scan pose), ``scan.sweep`` (the laser
    motor's steps and the camera's frames), ``motion`` (the pick: approach, grasp, lift, carry,
    release), ``other`` (what else the hardware did in the cycle: nudges), all from the clock;
    and ``compute``, binpick's own compute as measured (the CPU time of line extraction, pose,
    planning, nudge planning and the wall time of triangulation), which the cell waits for
    between them. A cycle that nudged is counted whole: every look and nudge in it."""
    if "phys.cycle" not in timings:
        return None
    ms = {k: float(timings.get(k, 0.0)) for k in ("scan.phys.move", "scan.phys.sweep", "phys.motion")}
    compute = sum(float(v) for k, v in timings.items() if k.startswith(("cpu.", "scan.cpu.")))
    compute += float(timings.get("scan.triangulate", 0.0))
    return {
        "scan.move": ms["scan.phys.move"] / 1e3,
        "scan.sweep": ms["scan.phys.sweep"] / 1e3,
        "compute": compute / 1e3,
        "motion": ms["phys.motion"] / 1e3,
        "other": max(0.0, float(timings["phys.cycle"]) - sum(ms.values())) / 1e3,
    }


#: Timings of an attempt that a cycle's later attempts do not add to (:func:`with_earlier`): the
#: plan made ahead is only the first attempt's, and the totals are the whole cycle's.
_PER_ATTEMPT = frozenset({"ahead.used", "ahead.window", "ahead.wait", "total", "phys.cycle"})


def with_earlier(timings: Mapping[str, float], earlier: Mapping[str, float]) -> dict[str, float]:
    """An attempt's ``timings`` (ms) with those of the attempts and nudges before it in the same
    cycle added (:meth:`binpick.cell.Cell._cycle`), but for the per-attempt ones."""
    times = dict(timings)
    for key, v in earlier.items():
        if key not in _PER_ATTEMPT:
            times[key] = times.get(key, 0.0) + v
    return times


def picks_per_hour(picked: int, cycle_times_s: Sequence[float]) -> Optional[float]:
    """3600 × ``picked`` / the sum of every cycle's time, failed ones included: the rate parts
    come out of the bin (None without time)."""
    total = float(sum(cycle_times_s))
    return 3600.0 * picked / total if total > 0 else None


@dataclass(frozen=True, eq=False)
class PickRecord:
    """What one pick attempt did.

    ``success``: the part was lifted out (with ground truth: the removed part is the located one,
    and its pose was pick-grade or the grasp is one of the cell's grasps on the part as it truly
    lay — ``grasp_fits_truth``, :func:`grasp_fits_truth`: a pose the scan left off by a turn
    or a slide the grip does not care about); ``held``: what the gripper reported (None when it cannot tell);
    ``error``: why the attempt failed, None on success; ``failure``: its kind, one of
    :data:`FAILURE_KINDS` (None on success); ``timings``: stage → ms (the whole attempt's, its
    nudges and the looks before and after them included); ``skipped``: the located parts passed
    over on the way, since the last nudge (no usable grasp, low confidence, …); ``looks``: how
    many scans the attempt took (more than one when the first showed nothing pickable, or after a
    nudge); ``scan``: the last
    of them (for the picture of a failure); ``nudges``: the :class:`~binpick.cell.nudge.NudgePlan`
    s run before it, when every part located was blocked. ``bin_empty``: the attempt found the bin
    empty (no part left in it by the ground truth; without it, nothing standing above its floor) —
    the end of the run, neither a pick nor a failure (``success`` and ``failure`` say so: False,
    None). ``confidence`` and ``confidence_any``:
    the located pose's (:class:`binpick.PoseResult`); ``orientation_decided``: False when the scan
    could not rule out alternatives (a hidden keyway, a flip the feature of which is out of sight)
    and the part was picked with a grasp the same on all of them — its orientation in the gripper
    is still open. For such a pick, the hand-off to the station that places it:
    ``T_gripper_object_options``, the part's pose in the gripper (4×4 ``T_gripper_object``) under
    the located pose and under each alternative the scan left open, one of which is the part's;
    ``free_axis_gripper``, the unit axis (gripper frame, through the part's symmetry centre)
    about which its turn is open, or None. A check at the station (a camera, a probe, a fixture
    that only one of them fits) decides among them. ``collisions``: every contact of the gripper
    with something other than the part it grasped during the pick's cycle, as the ground truth
    saw it (``with``, ``points``, ``opening_mm``, the flange pose at the first touch); any makes
    the pick a ``"collision"`` failure.
    """

    index: int
    success: bool
    T_base_object: Optional[np.ndarray] = None
    score: Optional[float] = None
    rmse: Optional[float] = None
    method: Optional[str] = None
    confidence: Optional[float] = None
    confidence_any: Optional[float] = None
    orientation_decided: Optional[bool] = None
    points: int = 0
    grasp: Optional[str] = None
    held: Optional[bool] = None
    truth: Optional[PoseTruth] = None
    picked_instance: Optional[int] = None
    error: Optional[str] = None
    fault: bool = False
    failure: Optional[str] = None
    timings: Mapping[str, float] = field(default_factory=dict)
    skipped: tuple[Skipped, ...] = ()
    looks: int = 1
    scan: Optional[ScanResult] = None
    nudges: tuple[Any, ...] = ()
    T_gripper_object_options: tuple[np.ndarray, ...] = ()
    free_axis_gripper: Optional[np.ndarray] = None
    collisions: tuple[Mapping[str, Any], ...] = ()
    bin_empty: bool = False
    grasp_fits_truth: Optional[bool] = None

    @property
    def cycle_time_s(self) -> Optional[float]:
        """The cycle's physical time, s (the sum of :func:`cycle_stages_s`), or None without a hardware clock."""
        stages = cycle_stages_s(self.timings)
        return None if stages is None else sum(stages.values())

    def as_dict(self) -> dict:
        """A JSON-ready summary."""
        return {
            "index": self.index,
            "success": self.success,
            "T_base_object": None if self.T_base_object is None else np.round(self.T_base_object, 6).tolist(),
            "score": self.score,
            "rmse_mm": self.rmse,
            "method": self.method,
            "confidence": self.confidence,
            "confidence_any": self.confidence_any,
            "orientation_decided": self.orientation_decided,
            "T_gripper_object_options": [np.round(T, 6).tolist() for T in self.T_gripper_object_options],
            "free_axis_gripper": None
            if self.free_axis_gripper is None
            else np.round(self.free_axis_gripper, 6).tolist(),
            "points": self.points,
            "grasp": self.grasp,
            "held": self.held,
            "truth": _truth_dict(self.truth),
            "picked_instance": self.picked_instance,
            "error": self.error,
            "failure": self.failure,
            "bin_empty": self.bin_empty,
            "timings_ms": dict(self.timings),
            "cycle_time_s": self.cycle_time_s,
            "stage_s": cycle_stages_s(self.timings),
            "looks": self.looks,
            "skipped": [k.as_dict() for k in self.skipped],
            "nudges": [n.as_dict() for n in self.nudges],
            "collisions": [dict(c) for c in self.collisions],
        }


def pose_trust(result: Any, T_base_gripper: Optional[np.ndarray] = None) -> dict:
    """A located pose's ``confidence``, ``confidence_any`` and ``orientation_decided`` (see
    :class:`PickRecord`) from its :class:`binpick.PoseResult` (a bare one reads as sure); with the
    grasp ``T_base_gripper`` of a pick whose orientation is open, the hand-off too
    (``T_gripper_object_options``, ``free_axis_gripper``)."""
    c = float(getattr(result, "confidence", 1.0))
    any_ = float(getattr(result, "confidence_any", c))
    decided = not getattr(result, "ambiguous", False)
    out = {"confidence": c, "confidence_any": any_, "orientation_decided": decided}
    if decided or T_base_gripper is None:
        return out
    T_gb = inverse(np.asarray(T_base_gripper, dtype=np.float64))
    poses = [result.T_scene_model, *(a.T_scene_model for a in getattr(result, "alternatives", ()))]
    out["T_gripper_object_options"] = tuple(T_gb @ np.asarray(P, dtype=np.float64) for P in poses)
    axis = getattr(result, "free_axis", None)
    if axis is not None:
        a = T_gb[:3, :3] @ np.asarray(axis, dtype=np.float64)
        out["free_axis_gripper"] = a / np.linalg.norm(a)
    return out


@dataclass(frozen=True, eq=False)
class RunReport:
    """The picks of :meth:`Cell.run`, why it stopped (None when every pick was tried), the last
    scan and location, and whether the cell knew which part left the bin (``ground_truth``: the
    simulator does; real drivers, the twin's among them, do not)."""

    records: tuple[PickRecord, ...]
    stopped: Optional[str]
    last_scan: Optional[ScanResult] = None
    last_located: Optional[Located] = None
    ground_truth: bool = False

    @property
    def successes(self) -> int:
        """How many picks succeeded."""
        return sum(r.success for r in self.records)

    @property
    def removed(self) -> Optional[tuple[int, ...]]:
        """The parts that left the bin, in order (a wrong-pose lift counts too); None without
        ground truth, where nothing tells which part left (see :attr:`lifted`)."""
        if not self.ground_truth:
            return None
        return tuple(r.picked_instance for r in self.records if r.picked_instance is not None)

    @property
    def bin_empty(self) -> bool:
        """Whether the run ended finding the bin empty (its last record's :attr:`PickRecord.bin_empty`)."""
        return bool(self.records) and self.records[-1].bin_empty

    @property
    def lifted(self) -> tuple[int, ...]:
        """The picks (their indices) whose gripper reported holding a part as it lifted."""
        return tuple(r.index for r in self.records if r.held is True)

    def failures_by_kind(self) -> dict[str, int]:
        """Failed attempts per kind of :data:`FAILURE_KINDS` (the kinds that occurred, in that order)."""
        counts = {kind: sum(r.failure == kind for r in self.records) for kind in FAILURE_KINDS}
        return {kind: n for kind, n in counts.items() if n}


def with_collisions(record: PickRecord, truth: Any, scan: Optional[ScanResult]) -> PickRecord:
    """``record`` with the contacts the ground truth saw during its cycle (``truth.take_collisions()``:
    the simulator's and the twin's physics; none without one): a pick whose gripper touched
    anything but the part it grasped failed with a ``"collision"`` whatever else it did (the
    part may have left the bin; a failure found before is kept in the error), with the cycle's
    last ``scan`` for its picture."""
    take = getattr(truth, "take_collisions", None)
    touched = tuple(MappingProxyType(dict(c)) for c in (take() if take is not None else ()))
    if not touched:
        return record
    what = "; ".join(f"{c['with']} ({c['points']} points inside the gripper)" for c in touched)
    before = f"; and {record.failure}: {record.error}" if record.failure else ""
    return replace(
        record,
        success=False,
        failure="collision",
        error=f"the gripper touched {what}{before}",
        collisions=touched,
        scan=record.scan if record.scan is not None else scan,
    )


def failed_record(
    i: int,
    scan: Optional[ScanResult],
    loc: Optional[Located],
    exc: BaseException,
    times: dict[str, float],
    *,
    failure: str,
) -> PickRecord:
    """The record of pick ``i`` that failed with ``exc`` (of kind ``failure``) before any motion."""
    res = None if loc is None else loc.result
    return PickRecord(
        index=i,
        success=False,
        T_base_object=None if loc is None else loc.T_base_object,
        score=None if res is None else float(res.score),
        rmse=None if res is None else float(res.rmse),
        method=None if res is None else res.method,
        points=0 if scan is None else len(scan.points),
        truth=None if loc is None else loc.truth,
        error=str(exc),
        fault=failure == "fault",
        failure=failure,
        timings=MappingProxyType(dict(times)),
    )


def emptied_record(i: int, scan: ScanResult, times: dict[str, float], looks: int) -> PickRecord:
    """The record of attempt ``i`` that found the bin empty in ``scan`` after ``looks`` looks."""
    return PickRecord(
        index=i,
        success=False,
        points=len(scan.points),
        timings=MappingProxyType(dict(times)),
        looks=looks,
        scan=scan,
        bin_empty=True,
    )


def grasp_fits_truth(config: Any, T_base_gripper: np.ndarray, truth: Optional[PoseTruth]) -> Optional[bool]:
    """Whether the grasp ``T_base_gripper``, on the part where it truly lies (``truth.T_base_truth``),
    is one of the cell's grasps (``config.ambiguity_matcher``: within the ambiguity tolerances,
    modulo the part's symmetries and a turn about its near-symmetry axis) — the grip the cell
    would have planned on the true pose, the test a grasp passes on every alternative of an
    undecided pose; None without the true pose."""
    if truth is None or truth.T_base_truth is None:
        return None
    T_gripper_object = inverse(np.asarray(T_base_gripper, dtype=np.float64)) @ truth.T_base_truth
    return bool(config.ambiguity_matcher.matches(T_gripper_object[None])[0])


def pick_outcome(
    truth: Optional[PoseTruth], picked: Optional[int], fits: Optional[bool]
) -> tuple[Optional[str], Optional[str]]:
    """With ground truth, the kind of failure of a pick whose located pose was judged ``truth``,
    that lifted the part ``picked`` (None: none) with a grasp that ``fits`` the true pose or not
    (:func:`grasp_fits_truth`), and why; (None, None) for a pick that succeeded."""
    if picked is not None and truth is not None and picked == truth.instance and (truth.pick_grade or fits):
        return None, None
    if picked is None:
        return "nothing lifted", "no part left the bin"
    if truth is None or picked != truth.instance:
        owner = "no part" if truth is None else f"part {truth.instance}"
        return "wrong pose", f"part {picked} left the bin, but the located pose was {owner}'s"
    off = f"{truth.rotation_error_deg:.1f}°, {truth.translation_error_mm:.1f} mm"
    grasp = "" if fits is None else " and the grasp is none of the cell's grasps on the part as it lay"
    return "wrong pose", f"part {picked} left the bin, but its located pose was {off} off (not pick-grade){grasp}"


def judge_located(truth: Any, model: Any, result: Any, T: np.ndarray) -> PoseTruth:
    """The truth (``truth.judge``, the cell's ground truth) of the pose ``T`` located as
    ``result`` of ``model``. For a pose flagged ambiguous the best of it and its alternatives: the
    cell picks such a pose only with a grasp that grips every alternative the same way, so
    whichever of them is true, the pick is; with a free axis, only across that axis, so any turn
    about it is as good."""
    about = continuous_near_axis(model) if getattr(result, "free_axis", None) is not None else None
    poses = [T, *(a.T_scene_model for a in result.alternatives)] if getattr(result, "ambiguous", False) else [T]
    truths = [truth.judge(np.asarray(P, dtype=np.float64), turn_about=about) for P in poses]
    return min(truths, key=lambda t: (not t.pick_grade, t.rotation_error_deg / 5.0 + t.translation_error_mm / 3.0))
