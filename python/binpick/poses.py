"""Registration (ICP) and pose estimation."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from . import _core
from ._validate import as_float_array, as_points, as_transform, as_vector, check_finite, count, non_negative, positive
from .errors import InvalidInputError
from .models import Model, estimate_normals

__all__ = ["IcpResult", "icp", "PoseResult", "estimate_pose", "estimate_poses", "grasp_pose"]

_KERNELS = ("none", "huber", "tukey", "cauchy")


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
    method: str = "point_to_plane",
    target_normals: Any = None,
    max_iterations: int = 50,
    rotation_tolerance: float = 1e-6,
    translation_tolerance: float = 1e-4,
    kernel: str = "none",
    kernel_scale: Optional[float] = None,
    trim_fraction: float = 0.0,
    num_threads: int = 0,
) -> IcpResult:
    """Registers ``source`` (N, 3) onto ``target`` (M, 3) with KD-tree ICP.

    Args:
        max_correspondence_distance: pairs farther apart (mm) are ignored.
        init: initial (4, 4) ``T_target_source``; identity when None.
        method: ``"point_to_point"`` (closed-form SVD, as in the paper) or ``"point_to_plane"``
            (Gauss–Newton on SE(3); uses ``target_normals``, estimated from 20 neighbours if None).
        max_iterations: upper bound on updates.
        rotation_tolerance: stop when an update rotates less than this (radians) …
        translation_tolerance: … and translates less than this (mm).
        kernel: robust IRLS weighting, ``"none"``, ``"huber"``, ``"tukey"`` or ``"cauchy"``.
        kernel_scale: the kernel's scale in mm (default: a third of the correspondence distance).
        trim_fraction: fraction in [0, 0.9] of the farthest pairs dropped each iteration.
        num_threads: worker threads, 0 = all cores. The GIL is released while ICP runs.
    """
    method_s = str(method)
    if method_s not in ("point_to_point", "point_to_plane"):
        raise InvalidInputError(f"method: unknown method {method!r}; use 'point_to_point' or 'point_to_plane'")
    needed = 3 if method_s == "point_to_point" else 6
    src = as_points(source, "source", min_points=needed)
    tgt = as_points(target, "target", min_points=3)
    max_d = positive(max_correspondence_distance, "max_correspondence_distance")
    init_m = np.eye(4) if init is None else as_transform(init, "init")
    normals = None
    if method_s == "point_to_plane":
        if target_normals is None:
            normals = estimate_normals(tgt, k=min(20, len(tgt)), num_threads=num_threads) if len(tgt) >= 3 else None
        else:
            normals = as_points(target_normals, "target_normals", min_points=0)
            if len(normals) != len(tgt):
                raise InvalidInputError(f"target_normals: has {len(normals)} rows but target has {len(tgt)}")
            lengths = np.linalg.norm(normals, axis=1)
            normals = normals / np.where(lengths > 0, lengths, 1.0)[:, None]
            if (lengths == 0).any():
                raise InvalidInputError(f"target_normals: row {int(np.argmax(lengths == 0))} is a zero vector")
    kernel_s = str(kernel).lower()
    if kernel_s not in _KERNELS:
        raise InvalidInputError(f"kernel: unknown kernel {kernel!r}; use one of {', '.join(_KERNELS)}")
    scale = max_d / 3.0 if kernel_scale is None else positive(kernel_scale, "kernel_scale")
    raw = _core.icp(
        src,
        tgt,
        normals,
        init_m,
        method_s,
        max_d,
        count(max_iterations, "max_iterations", minimum=1),
        non_negative(rotation_tolerance, "rotation_tolerance", "rad"),
        non_negative(translation_tolerance, "translation_tolerance", "mm"),
        kernel_s,
        scale,
        non_negative(trim_fraction, "trim_fraction"),
        count(num_threads, "num_threads"),
    )
    return IcpResult(**raw)


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
        timings: milliseconds per stage (bin_removal, normals, ... as the method runs them).
        method: the coarse method that found it: ``"ccp"``, ``"ppf"`` or ``"centroid"``.
        iterations: ICP iterations of the refinement.
        visible_fraction: share of the model's sensor-facing surface that the scan confirms
            (NaN where not judged).
        occluded_fraction: share of that surface lying under other objects (NaN where not judged).
        pickability: rank score in [0, 1] among the instances found: height in the pile (half),
            visible share (a third), nothing on top (a sixth).
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

    def __repr__(self) -> str:
        t = self.T_scene_model[:3, 3]
        return (
            f"PoseResult(method={self.method!r}, score={self.score:.3f}, "
            f"rmse={self.rmse:.3f} mm, points={len(self.indices)}, "
            f"t=[{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] mm, "
            f"pickability={self.pickability:.2f}, total={sum(self.timings.values()):.1f} ms)"
        )


_METHODS = ("auto", "ppf", "ccp", "centroid")


def estimate_poses(
    scene: Any,
    model: Model,
    bin: Any = None,
    *,
    max_instances: int = 5,
    method: str = "auto",
    up: Any = (0.0, 0.0, 1.0),
    viewpoint: Any = None,
    d_star: Optional[float] = None,
    min_points: Optional[int] = None,
    max_normal_angle: float = np.radians(70.0),
    inlier_distance: Optional[float] = None,
    min_fitness: float = 0.6,
    min_coverage: float = 0.8,
    ccp_closer_radius: Optional[float] = None,
    ccp_tau: Optional[float] = None,
    reference_fraction: Optional[float] = None,
    max_hypotheses: Optional[int] = None,
    num_threads: int = 0,
) -> list[PoseResult]:
    """Up to ``max_instances`` verified instances of ``model`` in ``scene``, most pickable first.

    ``scene`` is an (N, 3) cloud in mm with ``up`` (default +z) pointing out of the bin toward the
    sensor; ``viewpoint`` (optional) is the sensor's position in the scene frame, which orients
    the scan's normals better than ``up`` on steep faces. ``bin`` is an axis-aligned box
    ``((xmin, ymin, zmin), (xmax, ymax, zmax))`` in the scene frame; without it, support planes
    much larger than the part (floor, walls) are found and removed.

    ``method``:

    - ``"ppf"``: point-pair-feature detection for any rigid part: votes of scene point pairs
      against the model's feature table, pose clustering modulo the part's symmetries, ICP of
      every hypothesis, verification against the scan (a depth test of the surface each pose
      predicts), one pose per instance, ranked by pickability (height, visible share, nothing on
      top). ``reference_fraction`` of the scene samples vote (default 0.1, at least 60 samples);
      ``max_hypotheses`` clusters are refined (default 16, at least 8 per requested instance).
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
    if not isinstance(model, Model):
        raise InvalidInputError(
            f"model: expected a binpick.Model, got {type(model).__name__}; build one with binpick.Model.from_mesh"
        )
    pts = as_points(scene, "scene", min_points=10)
    m = str(method).lower()
    if m not in _METHODS:
        raise InvalidInputError(f"method: unknown method {method!r}; use 'auto', 'ppf', 'ccp' or 'centroid'")
    if m == "ccp" and not model.branches:
        raise InvalidInputError(
            "method: 'ccp' needs the model's cylindrical branches; "
            "declare them with Model.declare_branches, or use method='ppf'"
        )
    box = None
    if bin is not None:
        box = as_float_array(bin, "bin")
        if box.shape != (2, 3):
            raise InvalidInputError(f"bin: expected ((xmin, ymin, zmin), (xmax, ymax, zmax)), got shape {box.shape}")
        check_finite(box, "bin")
        if not (box[1] > box[0]).all():
            raise InvalidInputError(
                f"bin: max corner {box[1].tolist()} must exceed min corner {box[0].tolist()} on every axis"
            )
    up_v = as_vector(up, "up")
    if np.linalg.norm(up_v) == 0:
        raise InvalidInputError("up: must be a non-zero direction")
    vp = None if viewpoint is None else as_vector(viewpoint, "viewpoint")
    if reference_fraction is not None:
        reference_fraction = positive(reference_fraction, "reference_fraction")
        if reference_fraction > 1:
            raise InvalidInputError(f"reference_fraction: must be in (0, 1], got {reference_fraction}")
    raw = _core.estimate_poses(
        pts,
        model.prepared(),
        box,
        up_v,
        m,
        None if d_star is None else positive(d_star, "d_star"),
        None if min_points is None else count(min_points, "min_points", minimum=1),
        positive(max_normal_angle, "max_normal_angle", "rad"),
        None if inlier_distance is None else positive(inlier_distance, "inlier_distance"),
        non_negative(min_fitness, "min_fitness"),
        None if ccp_closer_radius is None else positive(ccp_closer_radius, "ccp_closer_radius"),
        None if ccp_tau is None else positive(ccp_tau, "ccp_tau"),
        count(num_threads, "num_threads"),
        count(max_instances, "max_instances", minimum=1),
        vp,
        reference_fraction,
        None if max_hypotheses is None else count(max_hypotheses, "max_hypotheses", minimum=1),
        non_negative(min_coverage, "min_coverage"),
    )
    return [PoseResult(**r) for r in raw]


def estimate_pose(scene: Any, model: Model, bin: Any = None, **options: Any) -> PoseResult:
    """The pose of the top pickable object of ``scene`` against ``model``: the first of
    :func:`estimate_poses` (the same keyword arguments, ``max_instances`` aside)."""
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
