"""A part's symmetries as the pick loop and the simulated gripper use them: the discrete turns
as ``T_object_object`` maps, the continuous axis, and :class:`GraspMatcher`, which judges a
part's pose in the gripper against every declared grasp modulo those symmetries."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Optional

import numpy as np

from .._validate import as_transform, as_vector, instance_of, positive
from ..errors import InvalidInputError
from ..transforms import rotation_angle_deg

__all__ = ["GraspMatcher", "continuous_symmetry", "continuous_near_axis", "symmetry_maps"]


def symmetry_maps(symmetries: Any) -> tuple[np.ndarray, ...]:
    """A part's discrete proper symmetries (a :class:`binpick.models.Symmetries`) as 4×4
    ``T_object_object`` maps, the turns about its centre, without the identity (which
    :class:`GraspMatcher` adds). A continuous axis has no finite set of maps and is left out."""
    from ..models import Symmetries

    symmetries = instance_of(symmetries, Symmetries, "symmetries", "model.symmetries")
    c = np.asarray(symmetries.center, dtype=np.float64)
    maps = np.tile(np.eye(4), (len(symmetries.rotations), 1, 1))
    maps[:, :3, :3] = symmetries.rotations
    maps[:, :3, 3] = c - maps[:, :3, :3] @ c
    return tuple(S for S in maps if not np.allclose(S, np.eye(4)))


def continuous_symmetry(symmetries: Any) -> Optional[tuple[np.ndarray, np.ndarray]]:
    """A part's continuous symmetry (a :class:`binpick.models.Symmetries`) as (centre, unit axis)
    in the object frame, for :class:`GraspMatcher`; None when it has none."""
    from ..models import Symmetries

    symmetries = instance_of(symmetries, Symmetries, "symmetries", "model.symmetries")
    if symmetries.continuous_axis is None:
        return None
    return np.asarray(symmetries.center, dtype=np.float64), np.asarray(symmetries.continuous_axis, dtype=np.float64)


def continuous_near_axis(model: Any) -> Optional[tuple[np.ndarray, np.ndarray]]:
    """A part's continuous near-symmetry (a round shaft whose keyway alone fixes the turn about
    it) as (centre, unit axis) in the object frame; None when it has none. Every turn about it maps
    all of the part but the feature onto itself: a grasp across the round body grips the same at
    any turn."""
    for near in model.near_symmetries:
        if near.angle is None:
            return np.asarray(near.center, dtype=np.float64), np.asarray(near.axis, dtype=np.float64)
    return None


class GraspMatcher:
    """Matches a part's pose in the gripper against every declared grasp at once.

    :meth:`error` is :func:`binpick.transforms.pose_error` against the nearest grasp (nearest in
    units of the tolerances), vectorised over grasps and symmetries so that the simulated gripper
    answers within its serial timeout even with hundreds of grasps.

    Args:
        grasps: name → ``T_gripper_object`` (or a sequence of them).
        symmetries: ``T_object_object`` maps of the part onto itself (the identity is added).
        tolerance_deg: the grip tolerance in rotation, degrees …
        tolerance_mm: … and in translation, mm.
        continuous: the part's continuous symmetry as (centre, axis) in the object frame (a
            shaft turned about its axis is the same shaft), or None: every turn about it is
            allowed too, the best one found in closed form per grasp and symmetry.
    """

    def __init__(
        self,
        grasps: Any,
        symmetries: Sequence[Any] = (),
        *,
        tolerance_deg: float,
        tolerance_mm: float,
        continuous: Optional[tuple[Any, Any]] = None,
    ) -> None:
        named = grasps.items() if isinstance(grasps, Mapping) else enumerate(grasps)
        stack = [as_transform(T, f"grasps[{k!r:.40}]") for k, T in named]
        if not stack:
            raise InvalidInputError("grasps: no grasps to match against; declare at least one")
        syms = [np.eye(4), *[as_transform(S, f"symmetries[{i}]") for i, S in enumerate(symmetries)]]
        self._stack = np.einsum("gij,sjk->gsik", np.stack(stack), np.stack(syms))  # T_go · S for every pair
        self.tolerance_deg = positive(tolerance_deg, "tolerance_deg", "deg")
        self.tolerance_mm = positive(tolerance_mm, "tolerance_mm")
        self._axis: Optional[tuple[np.ndarray, np.ndarray]] = None
        if continuous is not None:
            centre = as_vector(continuous[0], "continuous centre", 3)
            axis = as_vector(continuous[1], "continuous axis", 3)
            norm = float(np.linalg.norm(axis))
            if not norm > 1e-9:
                raise InvalidInputError("continuous: the symmetry axis has no direction; pass a unit vector")
            self._axis = (centre, axis / norm)

    def _turned(self, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For M = (B·S)_Rᵀ A_R per grasp and symmetry: the turn R_θ about the continuous axis that
        brings B·S·R_θ nearest A in rotation (θ maximises tr(R_θᵀ M): closed form), and R_θ."""
        _, a = self._axis
        K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        along = np.einsum("i,...ij,j->...", a, M, a)
        theta = np.arctan2(np.einsum("ij,...ij->...", K, M), np.trace(M, axis1=-2, axis2=-1) - along)
        c, s = np.cos(theta)[..., None, None], np.sin(theta)[..., None, None]
        R = c * np.eye(3) + s * K + (1.0 - c) * np.outer(a, a)
        return np.einsum("...ji,...jk->...ik", R, M), R

    def error(self, T_gripper_object: np.ndarray) -> tuple[float, float]:
        """(rotation error deg, translation error mm) against the nearest declared grasp."""
        B = self._stack
        A = as_transform(T_gripper_object, "T_gripper_object")
        M = np.einsum("gsji,jk->gsik", B[:, :, :3, :3], A[:3, :3])  # B_Rᵀ A_R
        t = B[:, :, :3, 3]
        if self._axis is not None:
            M, R = self._turned(M)
            c = self._axis[0]
            t = t + np.einsum("gsij,gsj->gsi", B[:, :, :3, :3], c - np.einsum("gsij,j->gsi", R, c))
        deg = rotation_angle_deg(M)
        mm = np.linalg.norm(t - A[:3, 3], axis=-1)
        s = np.argmin(deg / 5.0 + mm / 3.0, axis=1)  # pose_error's choice of symmetry, per grasp
        g_idx = np.arange(len(B))
        deg, mm = deg[g_idx, s], mm[g_idx, s]
        g = int(np.argmin(deg / self.tolerance_deg + mm / self.tolerance_mm))
        return float(deg[g]), float(mm[g])

    def cost(self, error: tuple[float, float]) -> float:
        """An error in units of the tolerances (≤ 2 when both are within them)."""
        return error[0] / self.tolerance_deg + error[1] / self.tolerance_mm

    def within(self, error: tuple[float, float]) -> bool:
        """Whether an error is within both tolerances."""
        return error[0] <= self.tolerance_deg and error[1] <= self.tolerance_mm
