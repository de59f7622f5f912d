"""Registration (ICP) and pose estimation."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from . import _core
from ._validate import (
    as_float_array,
    as_mask,
    as_points,
    as_transform,
    as_vector,
    count,
    flag,
    native_config,
    non_negative,
    number,
    optional_count,
    optional_number,
    positive,
    thread_count,
)
from .errors import InvalidInputError, InvalidTypeError
from .models import Model, estimate_normals

__all__ = [
    "IcpResult",
    "icp",
    "Alternative",
    "PoseResult",
    "SensorModel",
    "estimate_pose",
    "estimate_poses",
    "grasp_pose",
    "verify_pose",
]

#: Ceilings of the counts that size work or allocations: beyond them a value is a mistake.
MAX_ITERATIONS = 100_000  # ICP updates
MAX_INSTANCES = 1000  # poses estimate_poses returns
MAX_HYPOTHESES = 100_000  # PPF pose clusters refined

# The core's defaults, read once: the signatures below show them, the core writes them.
_ICP = _core.IcpConfig()
_POSE = _core.PoseConfig()


@dataclass(frozen=True, repr=False)
class IcpResult:
    """The outcome of :func:`icp`.

    Attributes:
        T_target_source: (4, 4) transform taking source points into the target frame.
        converged: the last update fell below both tolerances within ``max_iterations``.
        iterations: updates applied.
        fitness: fraction of source points with a target point within the correspondence distance.
        rmse: RMS distance of those pairs, mm.
        num_inliers: number of those pairs.
    """

    T_target_source: np.ndarray
    converged: bool
    iterations: int
    fitness: float
    rmse: float
    num_inliers: int

    @classmethod
    def _from_native(cls, res: _core.IcpResult) -> IcpResult:
        return cls(res.T_target_source, res.converged, res.iterations, res.fitness, res.rmse, res.num_inliers)

    def __repr__(self) -> str:
        return (
            f"IcpResult(converged={self.converged}, iterations={self.iterations}, fitness={self.fitness:.4f}, "
            f"rmse={self.rmse:.4f} mm, num_inliers={self.num_inliers})"
        )


def icp(
    source: Any,
    target: Any,
    *,
    max_correspondence_distance: float,
    init: Any = None,
    method: str = _ICP.method,
    target_normals: Any = None,
    max_iterations: int = _ICP.max_iterations,
    rotation_tolerance: float = _ICP.rotation_tolerance,
    translation_tolerance: float = _ICP.translation_tolerance,
    kernel: str = _ICP.kernel,
    kernel_scale: Optional[float] = None,
    trim_fraction: float = _ICP.trim_fraction,
    num_threads: int = _ICP.num_threads,
) -> IcpResult:
    """Registers ``source`` (N, 3) onto ``target`` (M, 3) with KD-tree ICP.

    Args:
        max_correspondence_distance: pairs farther apart (mm) are ignored.
        init: initial (4, 4) ``T_target_source``; identity when None.
        method: ``"point_to_point"`` (closed-form SVD, as in the paper) or ``"point_to_plane"``
            (Gauss–Newton on SE(3); uses ``target_normals``, estimated from 20 neighbours if None).
        max_iterations: upper bound on updates, at most 100000.
        rotation_tolerance: stop when an update rotates less than this (radians) …
        translation_tolerance: … and translates less than this (mm).
        kernel: robust IRLS weighting, ``"none"``, ``"huber"``, ``"tukey"`` or ``"cauchy"``.
        kernel_scale: the kernel's scale in mm (default: a third of the correspondence distance).
        trim_fraction: fraction in [0, 0.9] of the farthest pairs dropped each iteration.
        num_threads: worker threads, 0 = all cores, at most 256 (a request above the machine's
            cores is clamped to them). The GIL is released while ICP runs; Ctrl-C stops the call and its work.
    """
    config = native_config(
        _core.IcpConfig,
        method=method,
        max_correspondence_distance=positive(max_correspondence_distance, "max_correspondence_distance"),
        max_iterations=count(max_iterations, "max_iterations", 0, MAX_ITERATIONS),
        rotation_tolerance=non_negative(rotation_tolerance, "rotation_tolerance", "rad"),
        translation_tolerance=non_negative(translation_tolerance, "translation_tolerance", "mm"),
        kernel=kernel,
        kernel_scale=optional_number(kernel_scale, "kernel_scale"),
        trim_fraction=number(trim_fraction, "trim_fraction"),
        num_threads=thread_count(num_threads),
    )
    plane = config.method == "point_to_plane"
    src = as_points(source, "source", min_points=6 if plane else 3)
    tgt = as_points(target, "target", min_points=3)
    init_m = np.eye(4) if init is None else as_transform(init, "init")
    normals = None
    if plane:
        if target_normals is None:
            normals = estimate_normals(tgt, k=min(20, len(tgt)), num_threads=config.num_threads)
        else:
            normals = as_points(target_normals, "target_normals", min_points=0)
            if len(normals) != len(tgt):
                raise InvalidInputError(f"target_normals: has {len(normals)} rows but target has {len(tgt)}")
            lengths = np.linalg.norm(normals, axis=1)
            normals = normals / np.where(lengths > 0, lengths, 1.0)[:, None]
            if (lengths == 0).any():
                raise InvalidInputError(f"target_normals: row {int(np.argmax(lengths == 0))} is a zero vector")
    return IcpResult._from_native(_core.icp(src, tgt, normals, init_m, config))


@dataclass(frozen=True)
class SensorModel:
    """The depth noise of the sensor that made a scan, which every tolerance of pose estimation
    derives from (the judge's depth test, a pose's inliers, the reach of its refinement, the
    neighbourhood of the scan's normals).

    Attributes:
        noise_mm: standard deviation of the depth noise along the sensor's rays, mm (at range 0
            when it grows with range). None (the default): read from the scan itself, which
            binpick does well on any sensor: declare it only to override that reading.
        noise_per_m2: growth with the range r from the viewpoint, mm per square metre:
            σ(r) = noise_mm + noise_per_m2 · (r / 1 m)², as a triangulating depth camera's noise
            grows (a Kinect-like camera: about 0.9 mm and 1 mm/m²; a structured-light camera:
            about 0.05 mm and 0.15 mm/m²). Needs ``noise_mm`` and a ``viewpoint``; σ is taken at
            the scan's median range.

    Typical σ: laser-line scanners 0.05–0.2 mm, industrial structured light 0.1–0.5 mm, stereo
    and Kinect-like depth cameras 1–5 mm, time of flight 1–3 mm.
    """

    noise_mm: Optional[float] = None
    noise_per_m2: float = 0.0

    def __post_init__(self) -> None:
        top = _POSE_MAX_NOISE_MM
        if self.noise_mm is not None:
            object.__setattr__(self, "noise_mm", positive(self.noise_mm, "noise_mm"))
            if self.noise_mm > top:
                raise InvalidInputError(
                    f"noise_mm: {self.noise_mm:g} mm is beyond the {top:g} mm binpick takes; is the scan in mm?"
                )
        object.__setattr__(self, "noise_per_m2", number(self.noise_per_m2, "noise_per_m2", 0.0, top, "mm/m²"))
        if self.noise_per_m2 > 0 and self.noise_mm is None:
            raise InvalidInputError(
                "noise_per_m2: a noise growing with range needs noise_mm, the noise at the sensor; give both"
            )


#: The largest depth noise the core takes, mm.
_POSE_MAX_NOISE_MM = _core.MAX_NOISE_MM


def _sensor_model(sensor: Any, noise_mm: Any) -> SensorModel:
    """The sensor model of ``sensor=`` / ``noise_mm=`` (at most one of them)."""
    if sensor is not None and noise_mm is not None:
        raise InvalidInputError("noise_mm: give either sensor= or noise_mm=, not both (noise_mm is sensor's noise_mm)")
    if sensor is None:
        return SensorModel(noise_mm=noise_mm)
    if not isinstance(sensor, SensorModel):
        raise InvalidTypeError(
            "sensor: expected a binpick.SensorModel (e.g. binpick.SensorModel(noise_mm=2.0)), "
            f"got {type(sensor).__name__}"
        )
    return sensor


@dataclass(frozen=True)
class Alternative:
    """A distinct pose the scan cannot rule out (see :attr:`PoseResult.alternatives`).

    Attributes:
        T_scene_model: (4, 4) model → scene.
        evidence: what the scan says about it in the feature regions (as
            :attr:`PoseResult.feature_evidence`).
    """

    T_scene_model: np.ndarray
    evidence: dict


@dataclass(frozen=True, repr=False)
class PoseResult:
    """A verified pose of one object (see :func:`estimate_pose` and :func:`estimate_poses`).

    Attributes:
        T_scene_model: (4, 4) model (mesh file) frame → scene frame, in the canonical form of the
            model's symmetries (:attr:`Model.symmetries`): any two poses that differ only by a
            symmetry are reported alike.
        T_scene_model_coarse: the coarse pose (CCP, PPF cluster or centroid) before ICP.
        score: quality in [0, 1]. CCP and centroid: the fraction of the object's points within
            the inlier distance of the posed model. PPF: the fraction of the posed model's
            sensor-facing surface, where the scan can judge it, that the scan confirms (the rest
            lies where the sensor saw through it).
        rmse: RMS distance of the inlier points, mm.
        indices: scene indices of the points on the posed model.
        timings: milliseconds per stage (bin_removal, normals, ... as the method runs them); a
            stage that ran more than once (CCP's, once per region it tried) gives its total.
        method: the coarse method that found it: ``"ccp"``, ``"ppf"`` or ``"centroid"``.
        iterations: ICP iterations of the refinement.
        visible_fraction: share of the model's sensor-facing surface that the scan confirms
            (NaN where not judged).
        occluded_fraction: share of that surface lying under other objects (NaN where not judged).
        pickability: rank score in [0, 1] among the instances found: height in the pile (half),
            visible share (a third), nothing on top (a sixth); uncovered instances come first.
        confidence: in [0, 1], how likely the pose is pick-grade (rotation within 5°, translation
            within 3 mm, modulo the part's symmetries). Calibrated: of the poses reported at
            confidence ≥ c, at least a fraction c were pick-grade on the project's test sets
            (``benches/near_symmetric.py`` prints the reliability table).
        confidence_any: in [0, 1], how likely the pose or one of its ``alternatives`` (any turn about
            ``free_axis``) is pick-grade: what a grasp that is the same on every one of them stakes
            (a grip across a shaft whose keyway is hidden; the cell picks an ambiguous part with
            such grasps, judged by this; ``benches/near_symmetric.py`` prints its reliability table
            too). Equal to ``confidence`` for a pose without alternatives.
        ambiguous: True when the scan cannot rule out a distinct alternative: a near-symmetric
            flip whose deciding feature is out of sight, a turn about a free axis, or a turn or
            slide that what the view shows leaves open (one leg of an elbow seen alone, a shaft
            whose ends are hidden).
        alternatives: those alternatives, each an :class:`Alternative` (pose and evidence).
        free_axis: (3,) unit axis, scene frame, through the part's symmetry centre, of a continuous
            near-symmetry the scan cannot fix (a shaft whose keyway is out of sight): the turn
            about it is unknown, and ``T_scene_model``'s turn about it is arbitrary. None otherwise.
        feature_evidence: what the scan says in the near-symmetries' feature regions about the
            pose kept (``fits``, ``misfits``, ``seen_through``, ``tolerance``, ``score``), or None
            for a part without near-symmetries.
        fit: how well the pose's points lie on the posed model against the scan's own noise
            (``residual_sigma_mm``: robust σ of the point-to-plane residuals; ``noise_floor_mm``:
            the sensor's noise where the part lies, read from the scan without the model;
            ``ratio``; ``factor``: the share of ``confidence`` it keeps — 1 up to 2 times the
            noise, an e-fold fall per further 0.5), or None where too few points judge it. A
            pose whose points sit several times the noise off the surface is wrong, or the part
            differs from its model; beyond 2.5 times it is not reported at all.
    """

    T_scene_model: np.ndarray
    T_scene_model_coarse: np.ndarray
    score: float
    rmse: float
    indices: np.ndarray
    timings: dict
    method: str
    iterations: int
    visible_fraction: float = float("nan")
    occluded_fraction: float = float("nan")
    pickability: float = 1.0
    confidence: float = 0.0
    confidence_any: float = 0.0
    ambiguous: bool = False
    alternatives: tuple = ()
    free_axis: Optional[np.ndarray] = None
    feature_evidence: Optional[dict] = None
    fit: Optional[dict] = None

    @classmethod
    def _from_native(cls, e: _core.PoseEstimate) -> PoseResult:
        """The result of a core estimate; fractions it did not judge read NaN, an unranked pose 1.0."""
        fields = {
            name: getattr(e, name)
            for name in ("T_scene_model", "T_scene_model_coarse", "score", "rmse", "indices", "timings", "method")
        }
        return cls(
            **fields,
            iterations=e.iterations,
            visible_fraction=float("nan") if e.visible_fraction is None else e.visible_fraction,
            occluded_fraction=float("nan") if e.occluded_fraction is None else e.occluded_fraction,
            pickability=1.0 if e.pickability is None else e.pickability,
            confidence=e.confidence,
            confidence_any=e.confidence_any,
            ambiguous=e.ambiguous,
            alternatives=tuple(Alternative(a["T_scene_model"], a["evidence"]) for a in e.alternatives),
            free_axis=None if e.free_axis is None else np.asarray(e.free_axis, dtype=np.float64),
            feature_evidence=e.feature_evidence,
            fit=e.fit,
        )

    def __repr__(self) -> str:
        t = self.T_scene_model[:3, 3]
        return (
            f"PoseResult(method={self.method!r}, score={self.score:.3f}, "
            f"rmse={self.rmse:.3f} mm, points={len(self.indices)}, "
            f"t=[{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] mm, "
            f"pickability={self.pickability:.2f}, confidence={self.confidence:.2f}, "
            f"ambiguous={self.ambiguous}, total={sum(self.timings.values()):.1f} ms)"
        )


def estimate_poses(
    scene: Any,
    model: Model,
    bin: Any = None,
    *,
    max_instances: int = 5,
    method: str = _POSE.method,
    up: Any = None,
    viewpoint: Any = None,
    along_rays: bool = _POSE.along_rays,
    light: Any = None,
    sensor: Optional[SensorModel] = None,
    noise_mm: Optional[float] = None,
    d_star: Optional[float] = None,
    min_points: Optional[int] = None,
    max_normal_angle: float = _POSE.max_normal_angle,
    inlier_distance: Optional[float] = None,
    min_fitness: float = _POSE.min_fitness,
    min_coverage: float = _POSE.min_coverage,
    ccp_closer_radius: Optional[float] = None,
    ccp_tau: Optional[float] = None,
    reference_fraction: Optional[float] = None,
    max_hypotheses: Optional[int] = None,
    search_instances: int = _POSE.search_instances,
    num_threads: int = _POSE.num_threads,
    exclude: Any = None,
) -> list[PoseResult]:
    """Up to ``max_instances`` (at most 1000) verified instances of ``model`` in ``scene``, most
    pickable first. ``num_threads``: 0 = all cores, at most 256 (clamped to the machine's cores).

    ``exclude`` (optional, one bool per scene point) sets points aside from the search — the parts
    a cell has tried already — while the judge still reads them as surfaces the sensor saw, which
    no pose may claim was free space. Removed from ``scene`` instead, they would leave a hole in
    which a pose could hide a branch the scan shows elsewhere. The instances' ``indices`` never
    include them.

    ``scene`` is an (N, 3) cloud in mm. ``viewpoint`` (optional, and worth giving) is the sensor's
    optical centre in the scene frame: the depth test then looks along the sensor's own rays, as a
    fixed camera at an angle or a scene in the camera's own frame (``viewpoint=(0, 0, 0)``) need,
    and the scan's normals face it; without it, the sensor is taken to look down along ``up``.
    ``up`` is the direction out of the bin toward the sensor: by default +z, or, when the
    direction from the scene to the viewpoint lies more than 80° off +z (a scene in the camera's
    frame, +z away from the camera), the direction toward the viewpoint; an ``up`` that points
    away from the viewpoint is an error. ``along_rays=False`` keeps the depth test looking along
    ``up`` though a viewpoint is given (which then orients the normals only): for a laser-line
    scan swept over the bin by a camera looking down on it, whose lines, several millimetres
    apart, alias a grid of the camera's rays (binpick's cell asks so). ``bin`` is an axis-aligned
    box ``((xmin, ymin, zmin), (xmax, ymax, zmax))`` in the scene frame (whose up must then be
    +z); without it, support planes much larger than the part (floor, walls) are found and
    removed.

    ``light`` (optional) is where the light that made the scan came from, when not from the
    camera: a laser-line projector's origin (the cell gives it). A point the scan holds was lit as
    well as seen, so a pose standing between it and the light is refused too; without ``light``
    the depth test asks the camera's line of sight alone, and a laser scan's points in a pose's
    shadow say nothing against it.

    ``sensor`` (a :class:`SensorModel`) or ``noise_mm`` (its ``noise_mm`` alone) declares the
    sensor's depth noise; by default binpick reads it from the scan. Every tolerance derives from
    it (the depth test takes 3σ, and no less than 1 mm), so a noisier sensor is judged at its own
    noise rather than refused.

    ``method``:

    - ``"ppf"``: point-pair-feature detection for any rigid part: votes of scene point pairs
      against the model's feature table, pose clustering modulo the part's symmetries, ICP of
      every hypothesis, verification against the scan (a depth test of the surface each pose
      predicts), one pose per instance, ranked by pickability (height, visible share, nothing on
      top). ``reference_fraction`` of the scene samples vote (default 0.1, at least 60 samples);
      ``max_hypotheses`` clusters are refined (default 16, at least 8 per instance searched for).
      The search is sized for ``max(max_instances, search_instances)`` instances (default 5):
      asking for fewer instances of the same search only truncates the answer, so a caller that
      takes instances a few at a time (as the cell does) keeps the search of a wider one.
    - ``"ccp"``: the paper's computed closer point on the top object (needs the model's branches,
      :meth:`Model.declare_branches`); top-object segmentation (Table 2) → CCP → ICP. One instance.
    - ``"centroid"``: the paper's baseline, ICP from the centroids. One instance.
    - ``"auto"`` (default): PPF; for a model with declared branches, CCP too, and the pose the scan
      confirms better leads.

    Raises :class:`binpick.NoObjectFound` when no instance is confirmed (CCP: ``min_fitness`` of
    the object's points on the model; PPF: ``min_coverage`` of the predicted sensor-facing
    surface confirmed where the scan can judge it, enough of it over scanned cells, and no pose
    through the bin's floor or walls); it never returns a guess.
    """
    _check_model(model)
    config = _pose_config(
        bin=bin,
        up=up,
        method=method,
        viewpoint=viewpoint,
        along_rays=flag(along_rays, "along_rays"),
        light=light,
        sensor=sensor,
        noise_mm=noise_mm,
        d_star=optional_number(d_star, "d_star"),
        min_points=optional_count(min_points, "min_points"),
        max_normal_angle=number(max_normal_angle, "max_normal_angle"),
        inlier_distance=optional_number(inlier_distance, "inlier_distance"),
        min_fitness=number(min_fitness, "min_fitness"),
        min_coverage=number(min_coverage, "min_coverage"),
        ccp_closer_radius=optional_number(ccp_closer_radius, "ccp_closer_radius"),
        ccp_tau=optional_number(ccp_tau, "ccp_tau"),
        reference_fraction=optional_number(reference_fraction, "reference_fraction"),
        max_hypotheses=optional_count(max_hypotheses, "max_hypotheses", 0, MAX_HYPOTHESES),
        max_instances=count(max_instances, "max_instances", 1, MAX_INSTANCES),
        search_instances=count(search_instances, "search_instances", 1, MAX_INSTANCES),
        num_threads=thread_count(num_threads),
    )
    if config.method == "ccp" and not model.branches:
        raise InvalidInputError(
            "method: 'ccp' needs the model's cylindrical branches; "
            "declare them with Model.declare_branches, or use method='ppf'"
        )
    pts = as_points(scene, "scene", min_points=10)
    mask = None if exclude is None else as_mask(exclude, "exclude", len(pts))
    return [PoseResult._from_native(e) for e in _core.estimate_poses(pts, model.prepared(), config, mask)]


def _check_model(model: Any) -> None:
    if not isinstance(model, Model):
        raise InvalidInputError(
            f"model: expected a binpick.Model, got {type(model).__name__}; build one with binpick.Model.from_mesh"
        )


def _pose_config(
    *, bin: Any, up: Any, viewpoint: Any, sensor: Any, noise_mm: Any, light: Any = None, **checked: Any
) -> Any:
    """The native pose configuration of a call: the scene's frame and sensor checked here, the
    other options as the caller checked them."""
    noise = _sensor_model(sensor, noise_mm)
    return native_config(
        _core.PoseConfig,
        bin=None if bin is None else as_float_array(bin, "bin"),
        up=None if up is None else as_vector(up, "up"),
        viewpoint=None if viewpoint is None else as_vector(viewpoint, "viewpoint"),
        light=None if light is None else as_vector(light, "light"),
        noise_mm=noise.noise_mm,
        noise_per_m2=noise.noise_per_m2,
        **checked,
    )


def verify_pose(
    scene: Any,
    model: Model,
    T_scene_model: Any,
    bin: Any = None,
    *,
    up: Any = None,
    viewpoint: Any = None,
    along_rays: bool = _POSE.along_rays,
    light: Any = None,
    sensor: Optional[SensorModel] = None,
    noise_mm: Optional[float] = None,
    min_coverage: float = _POSE.min_coverage,
    num_threads: int = _POSE.num_threads,
) -> PoseResult:
    """The verdict on a given pose ``T_scene_model`` (4, 4) of ``model`` in ``scene``, judged exactly
    as :func:`estimate_poses` judges the poses it finds — the same depth test and checks, then the
    trust stage's confidence, alternatives and fit — but not refined (the pose returned may
    still differ from the one given: by a turn of the part onto itself where the scan supports
    that turn better, or, where the trust stage finds a better-supported alternative, by it). For
    a pose from elsewhere (an operator's teach-in, another vision system, a ground truth) to learn
    whether the scan supports it and how sure binpick would be of it. Raises
    :class:`binpick.NoObjectFound` naming the test it fails. The arguments are
    :func:`estimate_poses`'s; ``method`` reads ``"given"``."""
    _check_model(model)
    config = _pose_config(
        bin=bin,
        up=up,
        viewpoint=viewpoint,
        along_rays=flag(along_rays, "along_rays"),
        light=light,
        sensor=sensor,
        noise_mm=noise_mm,
        min_coverage=number(min_coverage, "min_coverage"),
        num_threads=thread_count(num_threads),
    )
    pts = as_points(scene, "scene", min_points=10)
    T = as_transform(T_scene_model, "T_scene_model")
    return PoseResult._from_native(_core.verify_pose(pts, model.prepared(), config, T))


def estimate_pose(scene: Any, model: Model, bin: Any = None, **options: Any) -> PoseResult:
    """The pose of the top pickable object of ``scene`` against ``model``: exactly the first of
    :func:`estimate_poses` for the same keyword arguments (``max_instances`` aside: the search
    does not depend on it, so asking for one instance only truncates the answer)."""
    if "max_instances" in options:
        raise InvalidInputError("max_instances: estimate_pose returns one pose; use estimate_poses for several")
    return estimate_poses(scene, model, bin, max_instances=1, **options)[0]


def _one_instance_signature() -> inspect.Signature:
    sig = inspect.signature(estimate_poses)
    params = [p for name, p in sig.parameters.items() if name != "max_instances"]
    return sig.replace(parameters=params, return_annotation="PoseResult")


# help() and IDEs show estimate_pose's real keyword arguments (those of estimate_poses).
estimate_pose.__signature__ = _one_instance_signature()  # type: ignore[attr-defined]


def grasp_pose(T_base_object: Any, T_gripper_object: Any) -> np.ndarray:
    """The gripper pose that grips the object as declared (paper Eq. 30):
    ``T_base_gripper = T_base_object · T_gripper_object⁻¹``."""
    a = as_transform(T_base_object, "T_base_object")
    b = as_transform(T_gripper_object, "T_gripper_object")
    inv = np.eye(4)
    inv[:3, :3] = b[:3, :3].T
    inv[:3, 3] = -b[:3, :3].T @ b[:3, 3]
    return a @ inv
