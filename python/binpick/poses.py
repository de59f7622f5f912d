"""Registration (ICP) and pose estimation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from . import _core
from ._validate import as_points, as_transform, count, non_negative, positive
from .errors import InvalidInputError
from .models import estimate_normals

__all__ = ["IcpResult", "icp"]

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
