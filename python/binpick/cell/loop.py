"""The pick loop — the same code drives the simulated cell and the real one.

A :class:`Cell` holds the drivers (robot, laser motor, gripper), a :class:`FrameSource` (the
camera) and a :class:`CellConfig` (calibration, part model and grasps, bin box, scan and drop
poses, gripper geometry, motion limits). One pick is::

    cell.scan()    robot to the scan pose (checked by the safety layer), sweep the laser motor,
                   grab a frame per angle, extract the line where the sheet can meet the scan
                   volume (``config.scan_volume``), triangulate → cloud in the base frame
    cell.locate_all()  estimate_poses(cloud, model, bin box) → every distinct part found, most
                   pickable first; :meth:`Cell.locate_and_plan` tries each in turn (and searches
                   the points left for more), and :meth:`Cell.run` looks again from
                   ``config.look_again_poses`` when a scan shows nothing pickable
    cell.plan()    every declared grasp: T_base_gripper = T_base_object · T_gripper_object⁻¹ (Eq. 30),
                   T_base_flange = T_base_gripper · T_flange_gripper⁻¹; keep the ones within the
                   tool-tilt limit, reachable, free of the scene, whose whole motion passes the
                   safety rules; take the one touching the fewest scene points, the most
                   vertical among equals (:func:`binpick.cell.grasp.plan_grasp`)
    cell.pick()    open, above → approach → grasp (straight along the gripper axis), close, lift
                   straight up, drop pose, open; on any fault the arm is stopped and the fault raised;
                   with ``config.plan_ahead``, the next pick is planned during the carry and used
                   where the next scan confirms its part and clears its gripper (:mod:`binpick.cell.ahead`)

The simulated cell (:class:`binpick.sim.SimulatedCell`) runs this loop on emulated devices; this
module loads neither the emulators nor the simulator.

Lengths in mm, angles in radians; transforms are 4×4 ``T_to_from``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from types import MappingProxyType
from typing import Any, Callable, Optional

import numpy as np

from .._validate import as_transform, count, number
from ..devices.gripper import Gripper
from ..devices.motor import LaserMotor
from ..devices.robot import Robot
from ..errors import BinpickError, DeviceError, InvalidInputError, InvalidTypeError, NoObjectFound, RunInterrupted
from ..poses import estimate_poses
from ..vision import describe_frames, triangulate
from .ahead import PlanAhead
from .config import CellConfig, check_static_poses
from .frames import FrameSource, Sweep
from .grasp import NoGraspError, plan_grasp, staked_filter
from .nudge import nudge_blocked
from .plan_check import PICK_MOVES, check_plan
from .progress import ProgressPrinter, quiet
from .records import (
    Located,
    PickPlan,
    PickRecord,
    PoseTruth,
    RunReport,
    ScanResult,
    Skipped,
    emptied_record,
    failed_record,
    grasp_fits_truth,
    judge_located,
    located_line,
    pick_outcome,
    pose_trust,
    with_collisions,
    with_earlier,
)
from .rescan import SEEN_AGAIN, RescanBasis, basis_after, part_box, rescan
from .scene import planner_scene
from .shots import DepthSource, depth_scan
from .sweeps import sweep_laser
from .views import deciding_first, settled, something_in_bin, worth_another_look

__all__ = ["Cell", "PICK_MOVES", "ProgressPrinter", "quiet"]


def _ms_since(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3


def _phys_ms(clock: Optional[Callable[[], float]], since: Optional[float]) -> float:
    """The hardware time since ``since`` on ``clock``, ms (0 without a clock)."""
    return 0.0 if clock is None or since is None else (clock() - since) * 1e3


class Cell:
    """The pick loop on a cell's drivers (see the module docstring).

    Args:
        config: the cell's calibration, part, poses, gripper and limits.
        robot: the robot driver; its ``limits`` must be ``config.limits`` (the driver checks every motion).
        motor: the laser motor driver.
        gripper: the gripper driver.
        camera: where frames come from.
        progress: called with (stage, message) as the work goes on; None = silent.
        truth: optional ground truth (the simulator) with ``judge(T_base_object) -> PoseTruth``,
            ``take_picked() -> Optional[int]`` (the instance that left the bin since the last call)
            and ``parts_left() -> int`` (the parts in the bin).
        clock: the cell's hardware time, s (a function of no arguments; a simulated cell's
            emulators keep it: :class:`binpick.devices.emulators.clock.PhysicalClock`), read at
            the edges of each stage into the ``phys.*`` timings of every record; None: the
            timings are the wall clock's alone, as on a real cell.
    """

    EMPTY_GRIP_RADIUS_MM = 15.0
    """A pose located within this distance, and :attr:`EMPTY_GRIP_TURN_DEG`, of one at which the
    gripper closed on nothing earlier in the run is passed over: it is most likely the same wrong
    pose found again. One as near a part passed over earlier in the run is tried after the others."""
    EMPTY_GRIP_TURN_DEG = 15.0
    """The angle (modulo the part's symmetries) for :attr:`EMPTY_GRIP_RADIUS_MM`: a pose as near
    but turned differently is another answer for what lies there, and is tried."""
    LOCATE_BATCH = 3
    """Parts located (their poses' trust assessed) per search, sized for ``max_candidates``;
    most picks take the first, and each further batch searches without the parts tried."""

    def __init__(
        self,
        config: CellConfig,
        *,
        robot: Robot,
        motor: LaserMotor,
        gripper: Gripper,
        camera: FrameSource,
        progress: Optional[Callable[[str, str], None]] = None,
        truth: Any = None,
        clock: Optional[Callable[[], float]] = None,
    ) -> None:
        if not isinstance(config, CellConfig):
            raise InvalidInputError(f"config: expected a CellConfig, got {type(config).__name__}")
        if not isinstance(camera, (FrameSource, DepthSource)):
            raise InvalidInputError(f"camera: expected a FrameSource or a DepthSource, got {type(camera).__name__}")
        if progress is not None and not callable(progress):
            raise InvalidTypeError(f"progress: expected a function (stage, message), got {type(progress).__name__}")
        if robot.limits is not None and robot.limits != config.limits:
            raise InvalidInputError(
                "robot: the driver's CellLimits differ from config.limits; open the robot with limits=config.limits"
            )
        if config.gripper.preshape_clearance_mm is not None and not getattr(gripper, "sets_width", False):
            # Its fingers open fully for every grasp: plan every grasp with them fully open.
            config = replace(config, gripper=replace(config.gripper, preshape_clearance_mm=None))
        self.config = config
        self.robot = robot
        self.motor = motor
        self.gripper = gripper
        self.camera = camera
        self.progress = progress or quiet
        self.truth = truth
        if clock is not None and not callable(clock):
            raise InvalidTypeError(f"clock: expected a function returning seconds, got {type(clock).__name__}")
        self.clock = clock
        self._basis: Optional[RescanBasis] = None  # what the next scan may build on (config.rescan)
        self._empty_grips: list[np.ndarray] = []
        self._passed_over: list[np.ndarray] = []  # where parts were passed over earlier in the run
        self._declined: list[np.ndarray] = []  # parts the robot program would not try (the vision server)
        self._cpu: dict[str, float] = {}
        self._cpu_now: Callable[[], float] = time.process_time  # the planning-ahead thread counts its own
        self._ahead: Optional[PlanAhead] = None  # the next pick, planned during the carry (config.plan_ahead)
        self._after_lift: Optional[Callable[[], None]] = None
        check_static_poses(config)

    # -- life cycle
    def open(self) -> Cell:
        """Opens the robot session, enables the laser motor, activates and opens the gripper."""
        self.progress("connect", "robot session, laser motor torque, gripper activation")
        self.robot.open_session()
        self.motor.enable()
        self.gripper.activate()
        self.gripper.open()
        return self

    def close(self) -> None:
        """Closes the robot session and releases the motor, the camera and the ports (best effort)."""
        for action in (self.robot.close_session, self.motor.disable):
            try:
                action()
            except DeviceError:
                pass
        for closer in (self.robot.close, self.motor.close, self.gripper.close_port, self.camera.close):
            try:
                closer()
            except (DeviceError, OSError):
                pass

    def __enter__(self) -> Cell:
        try:
            return self.open()
        except BaseException:
            self.close()
            raise

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- motion
    def _halt(self) -> str:
        try:
            self.robot.stop()
        except DeviceError as exc:
            return f"STOP could not be sent ({exc}); stop the arm by hand"
        return "the arm was stopped"

    def _move(self, T: np.ndarray, linear: bool) -> None:
        self.robot.move_to(T, linear=linear)

    def _go_above_approach(self) -> None:
        """From wherever the arm is, straight up to the clearance height if it is below the approach height."""
        here = self.robot.read_pose()
        if here[2, 3] < self.config.limits.approach_height_mm:
            up = here.copy()
            up[2, 3] = self.config.clearance_z_mm
            self._move(up, linear=True)

    # -- scan
    def scan(self, poses: Optional[Sequence[Any]] = None) -> ScanResult:
        """Scans the bin from every scan pose (or from the flange poses ``poses``, each swept
        across the bin: a second look); returns the cloud in the base frame."""
        cfg = self.config
        if isinstance(self.camera, DepthSource):  # a fixed 3-D camera: one shot, the arm parked
            return depth_scan(self, poses)
        if poses is None:
            views = [(T, cfg.angles_for(i)) for i, T in enumerate(cfg.scan_poses)]
            basis, self._basis = self._basis, None
            if basis is not None:  # only what the last pick changed, where that is safe
                planned = self._ahead.planned_box() if self._ahead is not None else None
                if planned is not None:  # and the part planned next, which the fresh lines must confirm
                    basis = replace(basis, also=(planned,))
                return rescan(self, basis, views)
        else:
            views = [(T, cfg.sweep_from(T)) for T in (as_transform(T, f"poses[{i}]") for i, T in enumerate(poses))]
        return self.sweep_views(views)

    def _sweep_part(self, scan: ScanResult, located: Located, views: list) -> ScanResult:
        """``scan`` with the laser angles across the part at ``located`` swept again (its box
        grown by a tenth of its size), :func:`binpick.cell.rescan.rescan` on it: for a part chosen
        on points a rescan kept from the scan before."""
        self.progress("scan", "the part chosen lies where this sweep kept the last scan's points: it is swept again")
        lo, hi = part_box(self.config.model, located.T_base_object, 0.1)
        return rescan(self, RescanBasis(scan=scan, lo=lo, hi=hi), views, around="the part chosen")

    def sweep_views(self, views: Sequence[tuple[np.ndarray, np.ndarray]]) -> ScanResult:
        """Sweeps the laser through the angles of each (flange pose, angles) of ``views``; the
        cloud in the base frame."""
        cfg = self.config
        timings: dict[str, float] = {"move": 0.0, "sweep": 0.0, "extract": 0.0, "cpu.extract": 0.0}
        sweep = Sweep()
        for T_scan, wanted in views:
            t0, c0 = time.perf_counter(), self.clock and self.clock()
            self._go_above_approach()
            self._move(T_scan, linear=False)
            T_bf = self.robot.read_pose()
            t1, c1 = time.perf_counter(), self.clock and self.clock()
            timings["move"] += (t1 - t0) * 1e3
            extract_s, extract_cpu = sweep_laser(self, sweep, wanted, T_bf)
            timings["sweep"] += (time.perf_counter() - t1 - extract_s) * 1e3
            if self.clock is not None:  # the hardware's time (a simulated cell's)
                timings["phys.move"] = timings.get("phys.move", 0.0) + (c1 - c0) * 1e3
                timings["phys.sweep"] = timings.get("phys.sweep", 0.0) + _phys_ms(self.clock, c1)
            timings["extract"] += extract_s * 1e3
            timings["cpu.extract"] += extract_cpu * 1e3
            done = sweep.angles[-len(wanted) :]
            self.progress(
                "scan",
                f"{len(wanted)} frames from flange ({T_bf[0, 3]:.1f}, {T_bf[1, 3]:.1f}, {T_bf[2, 3]:.1f}) mm, "
                f"laser {math.degrees(min(done)):.1f}°..{math.degrees(max(done)):.1f}°",
            )
        t2 = time.perf_counter()
        cloud = triangulate(
            np.concatenate(sweep.pixels),
            np.concatenate(sweep.frame_of),
            np.array(sweep.angles),
            np.stack(sweep.poses),
            cfg.calibration,
            num_threads=cfg.num_threads,
        )
        timings["triangulate"] = _ms_since(t2)
        self.progress(
            "cloud",
            f"{len(cloud)} points (extract {timings['extract']:.0f} ms, triangulate {timings['triangulate']:.0f} ms)",
        )
        return ScanResult(
            cloud=cloud,
            angles=np.array(sweep.angles),
            T_base_flanges=np.stack(sweep.poses),
            frames=MappingProxyType(sweep.kept),
            timings=MappingProxyType(timings),
        )

    # -- locate and plan
    def locate(self, scan: Optional[ScanResult] = None, *, exclude: Optional[np.ndarray] = None) -> Located:
        """The top pickable part in ``scan`` (a new scan when None), leaving out the points where
        ``exclude`` (bool, one per point) is true; NoObjectFound when there is none."""
        return self.locate_all(scan, exclude=exclude, max_instances=1)[0]

    def locate_all(
        self, scan: Optional[ScanResult] = None, *, exclude: Optional[np.ndarray] = None, max_instances: int = 0
    ) -> list[Located]:
        """Every distinct part :func:`binpick.estimate_poses` finds in ``scan`` (a new scan when
        None), most pickable first, up to ``max_instances`` (0: ``config.max_candidates``), searched
        without the points where ``exclude`` is true (the judge still reads them) and without poses
        scoring below ``config.min_score``; NoObjectFound when there is none."""
        scan = self.scan() if scan is None else scan
        cfg = self.config
        aside = None if exclude is None else np.asarray(exclude, dtype=bool)  # still the judge's evidence
        keep = np.arange(len(scan.points)) if aside is None else np.flatnonzero(~aside)
        if len(keep) < 10:
            seen = describe_frames(scan.frames.values())
            raise NoObjectFound(f"the scan holds {len(keep)} usable points ({seen}; see scan_contact_sheet.png)")
        span = float(np.linalg.norm(np.ptp(scan.points[keep], axis=0)))
        if span < 0.2 * cfg.model.diameter:  # the estimator's own floor for a scene of this part
            raise NoObjectFound(
                f"the scan's {len(keep)} usable points span {span:.0f} mm, less than a fifth of the "
                f"{cfg.model.name} ({cfg.model.diameter:.0f} mm): nothing to locate"
            )
        wanted = count(max_instances, "max_instances") or cfg.max_candidates
        c0 = self._cpu_now()
        results = estimate_poses(
            scan.points, cfg.model, bin=cfg.bin_bounds, max_instances=wanted, exclude=aside, **self.pose_options(scan)
        )
        self._cpu["cpu.pose"] = self._cpu.get("cpu.pose", 0.0) + (self._cpu_now() - c0) * 1e3
        found = []
        for result in results:
            if result.score < cfg.min_score:
                continue
            T = np.asarray(result.T_scene_model, dtype=np.float64)
            truth = self._judge_located(result, T)
            self.progress("locate", located_line(result, T, truth))
            idx = np.asarray(result.indices, dtype=np.int64)
            found.append(
                Located(
                    scan=scan,
                    result=result,
                    T_base_object=T,
                    indices=idx[(idx >= 0) & (idx < len(scan.points))],
                    truth=truth,
                )
            )
        if not found:
            raise NoObjectFound(
                f"the best pose scores {max(r.score for r in results):.2f}, below the cell's min_score "
                f"{cfg.min_score:.2f}"
            )
        return found

    def pose_options(self, scan: ScanResult) -> dict[str, Any]:
        """The options ``scan`` is judged with: the camera orients the normals, the laser lit it (for
        looks from several poses joined: up, no light); a sweep is judged along up (its lines alias
        a grid of the camera's rays), a fixed camera's shot along its rays; config.estimate_options."""
        cfg = self.config
        T_base_cameras = np.asarray(scan.T_base_flanges) @ cfg.calibration.T_flange_camera
        origins = (T_base_cameras[:, :3, 3], (T_base_cameras @ cfg.calibration.T_camera_laser)[:, :3, 3])
        camera, laser = (x[0] if np.ptp(x, axis=0).max() < 1.0 else None for x in origins)
        fixed = getattr(scan.cloud, "viewpoint", None)
        camera, laser = (camera, laser) if fixed is None else (fixed, None)  # a fixed camera's shot: no laser
        defaults = dict(num_threads=cfg.num_threads, search_instances=cfg.max_candidates, viewpoint=camera, light=laser)
        return {**defaults, "along_rays": fixed is not None, **cfg.estimate_options}

    def _judge_located(self, result: Any, T: np.ndarray) -> Optional[PoseTruth]:
        """The truth of a located pose, None without ground truth (:func:`~binpick.cell.records.judge_located`)."""
        return None if self.truth is None else judge_located(self.truth, self.config.model, result, T)

    def locate_and_plan(
        self, scan: ScanResult, skipped: Optional[list[Skipped]] = None, *, exclude: Optional[np.ndarray] = None
    ) -> tuple[Located, PickPlan]:
        """Locates the parts in ``scan`` (without the points where ``exclude`` is true) and plans
        the pick of the first one that can be picked: every part :meth:`locate_all` finds, in
        turn; when none can, their points are left out and the scan is searched again, up to
        ``config.max_candidates`` parts. The parts passed over go into ``skipped``. NoGraspError
        (the last part's) when none can be picked, NoObjectFound when no part is found."""
        skipped = [] if skipped is None else skipped
        excluded = np.zeros(len(scan.points), dtype=bool)
        if exclude is not None:
            excluded |= np.asarray(exclude, dtype=bool)
        last: Optional[NoGraspError] = None
        tried: list[np.ndarray] = []
        while len(tried) < self.config.max_candidates:
            try:
                wanted = min(self.LOCATE_BATCH, self.config.max_candidates - len(tried))
                found = self.locate_all(scan, exclude=excluded, max_instances=wanted)
            except NoObjectFound:
                if last is None:
                    raise
                break  # the parts found had no usable grasp: that is the reason to report
            # A part passed over earlier in the run and still in place is tried after the others.
            passed = [k.T_base_object for k in skipped] + self._passed_over
            found.sort(key=lambda located: self._near_any(located.T_base_object, passed))
            fresh = False
            for located in found:
                fresh |= bool(len(located.indices)) and not excluded[located.indices].all()
                excluded[located.indices] = True
                t = located.T_base_object[:3, 3]
                if any(np.linalg.norm(t - u) < self.config.model.diameter / 4 for u in tried):
                    continue  # the same part again, from what the search left of it
                tried.append(t)
                try:
                    self._refuse_empty_grip_spot(located)
                    c0, w0 = self._cpu_now(), self.config.openings_cpu_ms
                    try:
                        return located, self.plan(located)
                    finally:
                        # Measuring a grasp's opening is done once per part (then looked up):
                        # counted apart from the pick's planning.
                        widths = self.config.openings_cpu_ms - w0
                        self._cpu["cpu.grasp_widths"] = self._cpu.get("cpu.grasp_widths", 0.0) + widths
                        plan_ms = (self._cpu_now() - c0) * 1e3 - widths
                        self._cpu["cpu.plan"] = self._cpu.get("cpu.plan", 0.0) + plan_ms
                except NoGraspError as exc:
                    last = exc
                    res = located.result
                    alts = tuple(
                        np.asarray(a.T_scene_model, dtype=np.float64)
                        for a in (getattr(res, "alternatives", ()) if getattr(res, "ambiguous", False) else ())
                    )
                    final = settled(self.config, res, exc.refused)  # no other look can change it
                    skipped.append(Skipped(located.T_base_object, exc.reason, located.truth, exc.refused, alts, final))
                    self.progress(
                        "skip", f"{self.config.model.name} at ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm: {exc.reason}"
                    )
            if not fresh:
                break
        if last is None:
            raise NoObjectFound("no part was found that had not been tried already")
        raise last

    def _near_any(self, T: np.ndarray, poses: Sequence[np.ndarray]) -> bool:
        """Whether ``T`` is within :attr:`EMPTY_GRIP_RADIUS_MM` and :attr:`EMPTY_GRIP_TURN_DEG` of one of ``poses``."""
        errors = (self.config.model.pose_error(T, P) for P in poses)
        return any(mm < self.EMPTY_GRIP_RADIUS_MM and deg < self.EMPTY_GRIP_TURN_DEG for deg, mm in errors)

    def decline(self, located: Optional[Located]) -> None:
        """Leaves the part at ``located`` out of later plans (the vision server's robot program
        would not try it); ``None`` forgets every part declined (a new scan)."""
        self._declined = [] if located is None else [*self._declined, located.T_base_object.copy()]

    def _refuse_empty_grip_spot(self, located: Located) -> None:
        t = located.T_base_object[:3, 3]
        if self._near_any(located.T_base_object, self._declined):
            raise NoGraspError("the robot program declined this part", reason="declined by the robot program")
        if self._near_any(located.T_base_object, self._empty_grips):
            raise NoGraspError(
                f"the gripper closed on nothing at this located {self.config.model.name} "
                f"({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm in an earlier pick of this run",
                reason="the gripper closed on nothing here earlier in this run",
            )

    def plan(self, located: Located) -> PickPlan:
        """The declared grasp that is within the tilt limit, reachable, clear of the scene and of
        the located part's own other branches, and whose whole motion passes the safety rules —
        the one with the fewest scene points inside the gripper, the most vertical among equals
        (:func:`binpick.cell.grasp.plan_grasp`); NoGraspError when none is."""
        scene = planner_scene(located.scan.points, located.indices, located.T_base_object, self.config.model)
        res = located.result
        accept = staked_filter(self.config, res)  # a grasp the same on every alternative stakes confidence_any
        try:
            free = getattr(res, "free_axis", None) is not None
            plan, hits = plan_grasp(
                self.config,
                located.T_base_object,
                scene,
                self.robot.read_pose(),
                accept,
                free,
                located.scan.line_step,
            )
        except NoGraspError as exc:
            if accept is not None and exc.reason.startswith("none") and "ambiguous" in exc.reason:
                raise NoGraspError(str(exc), reason=f"ambiguous: {exc.reason}", refused=exc.refused) from None
            raise
        rejected = ", ".join(f"{v} {k}" for k, v in plan.rejected.items() if v) or "none rejected"
        self.progress(
            "plan",
            f"grasp {plan.grasp}, tool tilt {plan.tilt_deg:.1f}°, {hits} scene points in the gripper "
            f"({plan.considered} grasps: {rejected})",
        )
        return plan

    # -- pick
    def pick(self, located: Optional[Located] = None, *, plan: Optional[PickPlan] = None, index: int = 1) -> PickRecord:
        """Scans and locates (unless ``located`` is given), plans and picks one part.

        Device faults and safety refusals stop the arm and are raised; a failed grip is a record
        with ``success=False``.
        """
        times: dict[str, float] = {}
        t0 = time.perf_counter()
        located, plan = self._located_and_planned(located, plan, times)
        res = located.result
        times.update({f"estimate.{k}": float(v) for k, v in dict(getattr(res, "timings", {})).items()})
        t3, c3 = time.perf_counter(), self.clock and self.clock()
        held = self._execute(plan)
        times["motion"] = _ms_since(t3)
        if self.clock is not None:
            times["phys.motion"] = _phys_ms(self.clock, c3)
        picked = self.truth.take_picked() if self.truth is not None else None
        fits = grasp_fits_truth(self.config, plan.T_base_gripper, located.truth)
        failure, error = self.judge_pick(located, held, picked, fits)
        ok = failure is None
        times["total"] = _ms_since(t0)
        self.progress(
            "pick",
            ("picked" if ok else "FAILED")
            + (f" part {picked}" if picked is not None else "")
            + f" with grasp {plan.grasp} in {times['motion'] / 1e3:.1f} s"
            + (f" — {error}" if error else ""),
        )
        return PickRecord(
            index=index,
            success=ok,
            T_base_object=located.T_base_object,
            score=float(res.score),
            rmse=float(res.rmse),
            method=getattr(res, "method", None),
            **pose_trust(res, plan.T_base_gripper),
            points=len(located.scan.points),
            grasp=plan.grasp,
            held=held,
            truth=located.truth,
            picked_instance=picked,
            grasp_fits_truth=fits,
            error=error,
            failure=failure,
            timings=MappingProxyType(times),
            scan=None if ok else located.scan,
        )

    def _located_and_planned(
        self, located: Optional[Located], plan: Optional[PickPlan], times: dict[str, float]
    ) -> tuple[Located, PickPlan]:
        """What :meth:`pick` was given, completed: a scan, location and plan when ``located`` is
        None, a plan when only ``plan`` is; their timings go into ``times``."""
        if located is None:
            scan = self.scan()
            times.update({f"scan.{k}": v for k, v in scan.timings.items()})
            t1 = time.perf_counter()
            located, plan = self.locate_and_plan(scan)
            times["locate+plan"] = _ms_since(t1)
        elif plan is None:
            t1 = time.perf_counter()
            plan = self.plan(located)
            times["plan"] = _ms_since(t1)
        return located, plan

    def judge_pick(
        self, located: Located, held: Optional[bool], picked: Optional[int], fits: Optional[bool] = None
    ) -> tuple[Optional[str], Optional[str]]:
        """The kind of failure of the pick (None when it succeeded, see :attr:`PickRecord.failure`)
        and why; ``fits``: whether the grasp is one of the cell's on the true pose
        (:func:`~binpick.cell.records.grasp_fits_truth`); remembers where the gripper closed on nothing."""
        if held is False:
            self._empty_grips.append(located.T_base_object.copy())
            return "empty grip", "the gripper closed on nothing (no part between the fingers)"
        return (None, None) if self.truth is None else pick_outcome(located.truth, picked, fits)

    def check_plan(self, plan: PickPlan) -> dict[str, tuple[np.ndarray, bool]]:
        """The moves of ``plan`` as :meth:`pick` makes them, checked whole before the first
        (:func:`binpick.cell.plan_check.check_plan`); waypoint → (pose, linear)."""
        return check_plan(self, plan)

    def finger_opening(self, plan: PickPlan) -> float:
        """How far apart the fingers will be on the way in for ``plan``: its opening where the
        gripper can be set to a width, fully open otherwise; InvalidInputError for an opening
        that is not a width between 0 and the gripper's ``open_width_mm``."""
        full = float(self.config.gripper.open_width_mm)
        if plan.opening_mm is None or not getattr(self.gripper, "sets_width", False):
            return full
        return number(plan.opening_mm, "plan.opening_mm", 1e-3, full)

    def _execute(self, plan: PickPlan) -> Optional[bool]:
        """Runs the plan, checked whole first (:meth:`check_plan`); returns what the gripper said
        about holding. Faults stop the arm and are raised."""
        moves = self.check_plan(plan)
        opening = self.finger_opening(plan)
        try:
            # Open as wide as the collision checks assumed (fully when the gripper cannot be set to
            # a width) on the way to above the part, over the bin: the fingers must be there before
            # the arm goes down into it.
            self.gripper.open_for_grasp(opening, wait=False)
            self._move(*moves["above"])
            self.gripper.settle()
            for name in ("approach", "grasp"):
                self._move(*moves[name])
            held = self.gripper.close()
            self._move(*moves["lift"])
            if held is False:
                self.gripper.open()
                return False
            if self._after_lift is not None:  # the carry has begun: plan the next pick meanwhile
                self._after_lift()
            self._move(*moves["drop"])
            self.gripper.release(opening)  # as wide as around the part on the way in: it is free
            return held
        except BinpickError as exc:
            note = self._halt()
            self.progress("FAULT", f"{exc} — {note}")
            raise

    # -- run
    def run(self, n_picks: int) -> RunReport:
        """Up to ``n_picks`` picks; stops early when the bin is empty, nothing is found, no grasp
        fits, or a device faults (the arm is stopped). Ctrl-C raises :class:`binpick.RunInterrupted`
        carrying the report of the picks finished before it."""
        n = count(n_picks, "n_picks", 1)
        self._empty_grips, self._passed_over = [], []
        records: list[PickRecord] = []
        self._last: tuple[Optional[ScanResult], Optional[Located]] = (None, None)
        self._basis = None
        self._ahead = PlanAhead(self) if self.config.plan_ahead else None
        stopped: Optional[str] = None
        try:
            for i in range(1, n + 1):
                self.progress("pick", f"— pick {i} of {n} —")
                record, stopped = self._cycle(i, records[-1] if records else None)
                record = with_collisions(record, self.truth, self._last[0])
                self._basis = basis_after(self, record, self._last[0])
                self._passed_over += [k.T_base_object for k in record.skipped]
                records.append(record)
                if stopped is not None:
                    break
        except KeyboardInterrupt:
            raise RunInterrupted(self._report(records, f"interrupted (Ctrl-C) in pick {len(records) + 1}")) from None
        finally:
            if self._ahead is not None:
                self._ahead.discard()
            self._ahead = None
        return self._report(records, stopped)

    def _report(self, records: list[PickRecord], stopped: Optional[str]) -> RunReport:
        last_scan, last_located = self._last
        return RunReport(tuple(records), stopped, last_scan, last_located, ground_truth=self.truth is not None)

    def _cycle(self, i: int, before: Optional[PickRecord] = None) -> tuple[PickRecord, Optional[str]]:
        """One pick of :meth:`run` (:meth:`_look_and_pick`); at a dead end (parts located, none
        pickable from any view) a blocked part is nudged (:mod:`binpick.cell.nudge`) and the cell
        looks again, up to ``config.max_nudges`` times. The record's timings and looks are the
        whole cycle's: every attempt's, and the nudges' (their planning as ``cpu.nudge``, their
        motion in the cycle's physical time)."""
        t0, c0 = time.perf_counter(), self.clock and self.clock()
        nudges: list = []
        spent: dict[str, float] = {}  # the timings of the attempts and nudges before this one
        looks = 0
        settle = True  # a look is cut short where a nudge follows, until a nudge is not found

        def whole(record: PickRecord) -> PickRecord:
            times = with_earlier(record.timings, spent)
            times["total"] = _ms_since(t0)
            if self.clock is not None:
                times["phys.cycle"] = _phys_ms(self.clock, c0)
            return replace(record, timings=MappingProxyType(times), looks=looks + record.looks, nudges=tuple(nudges))

        while True:
            short = settle and len(nudges) < self.config.max_nudges
            record, why = self._look_and_pick(i, None if nudges else before, nudged=bool(nudges), settle=short)
            dead_end = why is not None and record.failure == "no grasp" and bool(record.skipped)
            if not dead_end or record.scan is None:
                return whole(record), why
            if len(nudges) >= self.config.max_nudges:
                after = f" (after {len(nudges)} nudges)" if nudges else ""
                return whole(record), f"{why}{after}"
            self._cpu = {}
            fault: Optional[BinpickError] = None
            try:
                plan = nudge_blocked(self, list(record.skipped), record.scan, nudges)
            except BinpickError as exc:
                plan, fault = None, exc
            record = replace(record, timings=MappingProxyType({**record.timings, **self._cpu}))
            if fault is not None:
                error = f"nudge: {type(fault).__name__}: {fault}"
                return replace(whole(record), failure="fault", fault=True, error=error), f"pick {i}: {error}"
            if plan is None and self._cut_short:  # no nudge after all: the views not taken first
                settle, spent, looks = False, dict(whole(record).timings), looks + record.looks
                continue
            if plan is None:
                return whole(record), f"{why} (no nudge passes the checks)"
            spent = dict(whole(record).timings)
            looks += record.looks
            nudges.append(plan)

    def _look_and_pick(
        self, i: int, before: Optional[PickRecord] = None, nudged: bool = False, settle: bool = False
    ) -> tuple[PickRecord, Optional[str]]:
        """Scan, locate and plan — looking again from each of ``config.look_again_poses`` while
        nothing is pickable (from one only when neither look finds any part, or, ``nudged``, when
        the first finds parts: a nudge moved only the part it pushed; with ``settle`` — a nudge to
        follow — from none when every part found was refused for where it lies, see
        :func:`~binpick.cell.views.worth_another_look`), each look judged together with the first;
        then pick. The record, and why the run stops (None to go on). ``before``: the pick just
        made, whose plan made ahead (:mod:`binpick.cell.ahead`) the first look may confirm."""
        t0, c0 = time.perf_counter(), self.clock and self.clock()
        self._cpu, self._cut_short = {}, False
        scan = first = None  # the look now, and the first look each later one is judged with
        located: Optional[Located] = None
        skipped: list[Skipped] = []
        times: dict[str, float] = {}
        again = () if isinstance(self.camera, DepthSource) else self.config.look_again_poses  # a fixed camera: one view
        views_whole = [(T, self.config.angles_for(j)) for j, T in enumerate(self.config.scan_poses)]
        views: list[Optional[tuple[np.ndarray, ...]]] = [None, *((T,) for T in again)]
        looks = 0
        try:
            for k, view in enumerate(views):
                seen_before = len(skipped)
                if k:
                    T = view[0]
                    self.progress(
                        "look",
                        f"nothing pickable; looking again from flange ({T[0, 3]:.1f}, {T[1, 3]:.1f}, {T[2, 3]:.1f}) "
                        f"mm, tool tilted {math.degrees(math.acos(max(-1.0, min(1.0, -T[2, 2])))):.0f}°",
                    )
                scan = self.scan(view) if first is None else first.joined(self.scan(view))
                first = first or scan
                looks += 1
                self._last = (scan, self._last[1])
                for key, v in scan.timings.items():
                    times[f"scan.{key}"] = times.get(f"scan.{key}", 0.0) + v
                t1 = time.perf_counter()
                ahead = self._ahead.take(before, scan, times) if self._ahead is not None and k == 0 else None
                try:
                    located, plan = ahead if ahead is not None else self.locate_and_plan(scan, skipped)
                    for whole in (False, True) if k == 0 else (True,):
                        if scan.seen_again(located.indices) >= SEEN_AGAIN:
                            break
                        # Chosen on points the sweep kept from the last scan: its band swept again
                        # (the whole bin when that is most of it, or when it shows a move), then
                        # the whole bin if the part chosen then is again one on kept points. A
                        # later look's scan joins other views, whose laser angles are another
                        # frame's: there, the whole bin from the scan pose.
                        swept = self.sweep_views(views_whole) if whole else self._sweep_part(scan, located, views_whole)
                        for key, v in swept.timings.items():
                            times[f"scan.{key}"] = times.get(f"scan.{key}", 0.0) + v
                        scan = first = swept
                        self._last = (scan, self._last[1])
                        times.pop("ahead.used", None)
                        located, plan = self.locate_and_plan(scan, skipped)
                except (NoObjectFound, NoGraspError):
                    # Two looks that found no part in a bin with nothing in it: the bin is empty as
                    # far as the cell can see; parts not pickable for a reason a view can change, or
                    # something in the bin no pose explains, are worth every view there is.
                    here, last = skipped[seen_before:], k == len(views) - 1
                    empty = k >= 1 and not skipped and not something_in_bin(self.config, scan)
                    self._cut_short = (
                        settle and not last and bool(here) and not worth_another_look(self.config, scan, here)
                    )
                    if last or empty or self._cut_short:
                        raise
                    if k == 0:
                        views[1:] = deciding_first(self.config, views[1:], skipped, self.progress)
                        views[2 if nudged and skipped else len(views) :] = []
                    continue
                finally:
                    times["locate+plan"] = times.get("locate+plan", 0.0) + _ms_since(t1)
                break
            self._last = (scan, located)
            if self._ahead is not None and looks == 1:
                self._after_lift = lambda: self._ahead.start(located, skipped)
            try:
                record = self.pick(located, plan=plan, index=i)
            finally:
                self._after_lift = None
            times.update(record.timings)
            times.update(self._cpu)
            times["total"] = _ms_since(t0)
            if self.clock is not None:
                times["phys.cycle"] = _phys_ms(self.clock, c0)
            return replace(record, timings=MappingProxyType(times), skipped=tuple(skipped), looks=looks), None
        except (NoObjectFound, NoGraspError, BinpickError) as exc:
            failure = (
                "nothing found"
                if isinstance(exc, NoObjectFound)
                else "no grasp"
                if isinstance(exc, NoGraspError)
                else "fault"
            )
            why = f"pick {i}: {exc}" if failure != "fault" else f"pick {i}: {type(exc).__name__}: {exc}"
            if failure == "no grasp" or (failure == "nothing found" and skipped):
                failure = "no grasp"
                why = f"pick {i}: none of the {len(skipped)} parts located in {looks} looks could be picked — {exc}"
            times.update(self._cpu)
            times["total"] = _ms_since(t0)
            if self.clock is not None:
                times["phys.cycle"] = _phys_ms(self.clock, c0)
            if failure == "nothing found" and scan is not None and not self._parts_left(scan):
                return emptied_record(i, scan, times, looks), f"pick {i}: the bin is empty ({exc})"
            record = failed_record(i, scan, located, exc, times, failure=failure)
            return replace(record, skipped=tuple(skipped), looks=looks, scan=scan), why

    def _parts_left(self, scan: ScanResult) -> bool:
        """Whether parts are left in the bin: the ground truth's word where the cell has one, else
        whether ``scan`` shows something standing in it (:func:`binpick.cell.views.something_in_bin`)."""
        return self.truth.parts_left() > 0 if self.truth is not None else something_in_bin(self.config, scan)
