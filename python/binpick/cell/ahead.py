"""Planning the next pick while the arm carries the last one away (``CellConfig.plan_ahead``).

Once the gripper has lifted a part (it reports holding it), the arm still has the carry to the
drop pose, the release, the way back to the scan pose and the next sweep ahead of it: seconds in
which binpick's computer would otherwise wait. The cell uses them to locate and plan the next
part in the scan it already has, without the points of the part in the gripper — on a thread
that has no device to talk to (its arm answers only "where will you be": the scan pose the next
pick starts from) and no ground truth to ask.

The plan was made on a bin that has since changed, so the next scan judges it before it is
used, and it is used only when

* the pick it follows was clean (held, nothing nudged or touched, one look) and the next scan
  is a first look from the scan pose;
* the new scan confirms the part where the plan has it: the pose judged on the new scan
  exactly as :func:`binpick.estimate_poses` judges the poses it finds
  (:func:`binpick.verify_pose`: the depth test, the checks and the trust stage's confidence and
  alternatives) scores at least ``config.min_score``, stays the pose planned (the verdict may
  turn it to an alternative the new scan supports better: then it is not used) and still
  stakes the plan's grasp (:func:`binpick.cell.grasp.staked_filter`: confidence, and a grasp the
  same on every alternative the new scan leaves open);
* the plan's gripper at the grasp holds no more of the new scan's points than
  ``config.max_collision_points``, counted as the planner counts them
  (:func:`binpick.cell.grasp.scene_hits`).

Otherwise the cell locates and plans on the new scan as it always does. Either way the plan is
checked whole against the arm's real pose before the first motion
(:meth:`binpick.cell.Cell.check_plan`), and the pose used is the new scan's verdict, judged
against the ground truth (the simulator) when it is used.

Time: the planning's time on its own thread is recorded as ``ahead.compute.pose``,
``ahead.compute.plan`` and ``ahead.compute.grasp_widths`` (ms, wall: the pose search runs on a
worker thread of its own, which a thread's CPU clock would miss), with the hardware time it
overlapped (``ahead.window``: from the lift to the end of the next scan, or to its start where
a rescan of what changed must sweep the part planned too). What the cell had to
wait for beyond that window is compute on the critical path (``cpu.ahead_wait``, in the cycle's
``compute`` stage); the check on the new scan is too (``cpu.confirm``). On a real cell, whose
wall clock is its physical time, the wait is the wall time the next cycle spent joining the
thread (``ahead.wait``).
"""

from __future__ import annotations

import copy
import inspect
import threading
import time
from typing import Any, Optional

import numpy as np

from ..errors import BinpickError
from ..poses import verify_pose
from .grasp import NoGraspError, scene_hits, staked_filter
from .records import Located, PickPlan, PickRecord, ScanResult, Skipped
from .rescan import clean_pick, part_box
from .scene import planner_scene

__all__ = ["PlanAhead", "SAME_POSE_DEG", "SAME_POSE_MM"]

#: The new scan's verdict is the pose planned when it is within these of it (modulo the part's
#: symmetries): the verdict is not refined, so it is the pose itself or a different answer.
SAME_POSE_DEG = 0.5
SAME_POSE_MM = 0.5

_VERIFY_OPTIONS = frozenset(inspect.signature(verify_pose).parameters) - {"scene", "model", "T_scene_model", "bin"}


class _ParkedArm:
    """The arm as the planning thread sees it: where it will be when the next pick starts. It
    has no port, so nothing the thread does can reach the robot."""

    def __init__(self, T_base_flange: np.ndarray, limits: Any) -> None:
        self._T = np.array(T_base_flange, dtype=np.float64)
        self.limits = limits

    def read_pose(self) -> np.ndarray:
        return self._T.copy()


class PlanAhead:
    """The next pick, planned on a thread during the carry (see the module docstring)."""

    def __init__(self, cell: Any) -> None:
        self.cell = cell
        self._thread: Optional[threading.Thread] = None
        self._done: dict[str, Any] = {}
        self._since: tuple[float, Optional[float]] = (0.0, None)
        #: when the cell first needed the plan (wall, clock), and the wall time it then waited
        self._needed: Optional[tuple[float, Optional[float], float]] = None

    def start(self, located: Located, skipped: list[Skipped]) -> None:
        """Starts planning the pick after the one of ``located`` (just lifted) on its scan,
        without its points; ``skipped``: the parts passed over in that scan."""
        self.discard()
        cell = self.cell
        ahead = copy.copy(cell)  # the cell's settings and memory, with no device and no truth
        ahead.robot = _ParkedArm(cell.config.scan_poses[-1], cell.config.limits)
        ahead.motor = ahead.gripper = ahead.camera = None
        ahead.truth = None
        ahead._cpu = {}
        ahead._cpu_now = time.perf_counter  # its own thread's wall time (see the module docstring)
        ahead._empty_grips = list(cell._empty_grips)
        ahead._passed_over = [*cell._passed_over, *(k.T_base_object for k in skipped)]
        ahead._declined = list(cell._declined)
        say = cell.progress
        ahead.progress = lambda stage, message: say(stage, f"(planning ahead) {message}")
        done: dict[str, Any] = {"picked": located}
        self._done = done
        self._since = (time.perf_counter(), cell.clock() if cell.clock is not None else None)
        self._thread = threading.Thread(
            target=_plan, args=(ahead, located, done), name="binpick-plan-ahead", daemon=True
        )
        self._thread.start()

    def discard(self) -> None:
        """Forgets any plan made ahead (waits for the thread: it has no device to stop)."""
        if self._thread is not None:
            self._thread.join()
        self._thread, self._done, self._needed = None, {}, None

    def planned_box(self) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """The box (base frame, mm) of the part planned ahead at its planned pose, or None when
        nothing was (waits for the planning: the next scan must sweep that part again, see
        :mod:`binpick.cell.rescan`)."""
        if self._thread is None:
            return None
        cell = self.cell
        wait0 = time.perf_counter()
        self._thread.join()
        self._needed = (wait0, cell.clock() if cell.clock is not None else None, time.perf_counter() - wait0)
        found = self._done.get("found")
        if found is None:
            return None
        return part_box(cell.config.model, found[0].T_base_object)

    def take(self, record: Optional[PickRecord], scan: ScanResult, times: dict) -> Optional[tuple[Located, PickPlan]]:
        """The part and plan made ahead, when the pick they followed (``record``) was clean and
        ``scan`` (the next scan) confirms them (see the module docstring): the part as the new
        scan judges it, and the plan. None otherwise (the plan is forgotten). The planning's
        times go into ``times``."""
        if self._thread is None:
            return None
        t0, c0 = self._since
        wait0 = time.perf_counter()
        self._thread.join()
        done, cell = self._done, self.cell
        waited = time.perf_counter() - wait0
        c1 = cell.clock() if c0 is not None else None
        if self._needed is not None:  # the scan needed the plan first (planned_box): the window ended there
            wait0, c1, waited = self._needed
        self._thread, self._done, self._needed = None, {}, None
        if "error" in done:  # a bug, not a finding: never hidden behind a fallback
            raise done["error"]
        window_ms = (c1 - c0) * 1e3 if c0 is not None and c1 is not None else (wait0 - t0) * 1e3
        spent = {f"ahead.compute.{k.removeprefix('cpu.')}": v for k, v in done.get("cpu", {}).items()}
        times.update(spent)
        times["ahead.window"] = window_ms
        times["ahead.wait"] = waited * 1e3
        times["cpu.ahead_wait"] = max(0.0, sum(spent.values()) - window_ms) if c0 is not None else 0.0
        if "found" not in done:
            cell.progress("plan", f"nothing was planned during the carry ({done.get('why')}); locating in the new scan")
            return None
        if record is None or not clean_pick(record):
            cell.progress("plan", "the pick before was not clean: the plan made during the carry is dropped")
            return None
        c1 = time.process_time()
        try:
            confirmed, why = _confirm(cell, *done["found"], scan)
        finally:
            times["cpu.confirm"] = (time.process_time() - c1) * 1e3
        if confirmed is None:
            cell.progress("plan", f"the plan made during the carry is dropped: {why}; locating in the new scan")
            return None
        times["ahead.used"] = 1.0
        cell.progress("plan", f"the plan made during the carry stands: {why}")
        return confirmed, done["found"][1]


def _plan(ahead: Any, picked: Located, done: dict) -> None:
    """The planning thread: :meth:`binpick.cell.Cell.locate_and_plan` on the lifted part's scan
    without its points; what it found (or why not) and its time go into ``done``."""
    scan = picked.scan
    exclude = np.zeros(len(scan.points), dtype=bool)
    exclude[picked.indices] = True
    try:
        done["found"] = ahead.locate_and_plan(scan, [], exclude=exclude)
    except BinpickError as exc:  # nothing pickable found (NoObjectFound, NoGraspError), or bad input
        done["why"] = f"{type(exc).__name__}: {exc}"
    except BaseException as exc:  # noqa: BLE001 - handed to the cell's thread, which raises it
        done["error"] = exc
    done["cpu"] = dict(ahead._cpu)


def _confirm(cell: Any, located: Located, plan: PickPlan, scan: ScanResult) -> tuple[Optional[Located], str]:
    """The part planned ahead as the new ``scan`` judges it, or None; and why."""
    cfg = cell.config
    T = located.T_base_object
    options = {k: v for k, v in cell.pose_options(scan).items() if k in _VERIFY_OPTIONS}
    try:
        verdict = verify_pose(scan.points, cfg.model, T, bin=cfg.bin_bounds, **options)
    except BinpickError as exc:
        return None, f"the new scan does not show the part where it was planned ({exc})"
    T_new = np.asarray(verdict.T_scene_model, dtype=np.float64)
    deg, mm = cfg.model.pose_error(T_new, T)
    if verdict.score < cfg.min_score:
        return None, f"the new scan scores the part {verdict.score:.2f}, below the cell's min_score {cfg.min_score:.2f}"
    if deg > SAME_POSE_DEG or mm > SAME_POSE_MM:
        return None, f"the new scan supports the part {deg:.1f}°, {mm:.1f} mm from the pose planned better"
    try:
        accept = staked_filter(cfg, verdict)
    except NoGraspError as exc:
        return None, f"the new scan does not stake the plan: {exc.reason}"
    if accept is not None and not accept(np.asarray(plan.T_base_gripper, dtype=np.float64)):
        return (
            None,
            "the new scan leaves the part's pose open, and the plan's grasp is not the same on every alternative",
        )
    idx = np.asarray(verdict.indices, dtype=np.int64)
    own = np.unique(idx[(idx >= 0) & (idx < len(scan.points))])
    free = getattr(verdict, "free_axis", None) is not None
    hits = scene_hits(cfg, plan, T_new, planner_scene(scan.points, own, T_new, cfg.model), free, scan.line_step)
    if hits > cfg.max_collision_points:
        return None, f"{hits} points of the new scan lie inside the plan's gripper (at most {cfg.max_collision_points})"
    truth = cell._judge_located(verdict, T_new)
    found = Located(scan=scan, result=verdict, T_base_object=T_new, indices=own, truth=truth)
    return found, f"the new scan scores the part {verdict.score:.2f} where it was planned, {hits} points in the gripper"
