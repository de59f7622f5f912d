"""A part's symmetries as the pick loop and the simulated gripper use them: the discrete turns
as ``T_object_object`` maps, the continuous axis, and :class:`GraspMatcher`, which judges a
part's pose in the gripper against every declared grasp modulo those symmetries."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Optional

import numpy as np

from .._validate import as_float_array, as_transform, as_vector, check_finite, check_rigid, instance_of, positive
from ..errors import InvalidInputError, ShapeError

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


def _skew(a: np.ndarray) -> np.ndarray:
    """[a]×, the cross-product matrix of ``a``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


#: The most grasp × symmetry × pose triples :meth:`GraspMatcher.errors` weighs at once (a few
#: tens of MB of temporaries).
_MATCH_CHUNK = 1 << 16


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
        self._weights: Optional[np.ndarray] = None
        self._swing: Optional[tuple[np.ndarray, np.ndarray]] = None
        self._flat_arrays: Optional[tuple[np.ndarray, ...]] = None
        self._across = np.zeros(3)  # the continuous axis's centre, its part across the axis: u, mm
        if continuous is not None:
            centre = as_vector(continuous[0], "continuous centre", 3)
            axis = as_vector(continuous[1], "continuous axis", 3)
            norm = float(np.linalg.norm(axis))
            if not norm > 1e-9:
                raise InvalidInputError("continuous: the symmetry axis has no direction; pass a unit vector")
            self._axis = (centre, axis / norm)
            self._across = centre - (self._axis[1] @ centre) * self._axis[1]

    def error(self, T_gripper_object: np.ndarray) -> tuple[float, float]:
        """(rotation error deg, translation error mm) against the nearest declared grasp."""
        A = as_transform(T_gripper_object, "T_gripper_object")
        deg, mm = self._errors(A[None])
        return float(deg[0]), float(mm[0])

    def errors(self, T_gripper_objects: Any) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`error` of each of a stack of poses in the gripper (K, 4, 4): rotation errors
        (K,) deg and translation errors (K,) mm, each against its nearest declared grasp, in a
        few array operations for all."""
        return self._errors(self._checked(T_gripper_objects))

    def matches(self, T_gripper_objects: Any) -> np.ndarray:
        """Whether each of a stack of poses in the gripper (K, 4, 4) is within both tolerances of
        some declared grasp, modulo the symmetries: (K,) bool. The question a planner weighing a
        batch of grasps against a pose's alternatives asks thousands of times a pick, answered
        without weighing every grasp: only the grasps whose part lies within the translation
        tolerance of the pose's (and the swing a turn about the continuous axis can add) are
        weighed in rotation."""
        A = self._checked(T_gripper_objects)
        W, Bt, Bt2, u, w = self._flat()
        # A turn about the axis moves the part's origin by at most twice its distance from it, |u|.
        reach = self.tolerance_mm + 2.0 * float(np.linalg.norm(self._across)) + 1e-6
        out = np.zeros(len(A), dtype=bool)
        chunk = max(1, _MATCH_CHUNK // len(Bt))
        for i in range(0, len(A), chunk):
            At = A[i : i + chunk, :3, 3]
            d2 = Bt2[:, None] - 2.0 * (Bt @ At.T) + np.einsum("ij,ij->i", At, At)[None]
            gs, k = np.nonzero(d2 <= reach * reach)
            if len(gs) == 0:
                continue
            v = np.einsum("pfi,pi->pf", W[gs], A[i + k, :3, :3].reshape(len(k), 9))
            deg, mm = self._deg_mm(v, Bt[gs], At[k], u[gs], w[gs])
            out[i + k[(deg <= self.tolerance_deg) & (mm <= self.tolerance_mm)]] = True
        return out

    def _flat(self) -> tuple[np.ndarray, ...]:
        """What :meth:`matches` reads per grasp × symmetry, flat (G·S first), made once: the
        forms (G·S, F, 9), the translations (G·S, 3) and their squared norms, and the swing
        ``u``, ``w`` (G·S, 3) (zeros without a continuous axis)."""
        if self._flat_arrays is None:
            B = self._stack
            GS = B.shape[0] * B.shape[1]
            W = self._forms().reshape(GS, -1, 9)
            Bt = np.ascontiguousarray(B[:, :, :3, 3].reshape(GS, 3))
            if self._swing is None:
                u = w = np.zeros((GS, 3))
            else:
                u, w = (np.ascontiguousarray(x.reshape(GS, 3)) for x in self._swing)
            self._flat_arrays = (W, Bt, np.einsum("ij,ij->i", Bt, Bt), u, w)
        return self._flat_arrays

    def _checked(self, T_gripper_objects: Any) -> np.ndarray:
        """A stack (K, 4, 4) of rigid transforms, checked in a few array operations (ShapeError,
        or check_rigid's error naming the first that is not rigid)."""
        A = as_float_array(T_gripper_objects, "T_gripper_objects")
        if A.ndim != 3 or A.shape[1:] != (4, 4):
            raise ShapeError(f"T_gripper_objects: expected a stack (K, 4, 4) of transforms, got shape {A.shape}")
        check_finite(A, "T_gripper_objects")
        R = A[:, :3, :3]
        off = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2), initial=0.0)
        last = (np.abs(A[:, 3] - (0.0, 0.0, 0.0, 1.0)) > (1e-9, 1e-9, 1e-9, 1e-9 + 1e-5)).any(axis=1)
        bad = np.flatnonzero((off > 1e-6) | (np.linalg.det(R) < 0) | last)  # check_rigid's rules
        if len(bad):
            check_rigid(A[bad[0]], f"T_gripper_objects[{bad[0]}]")  # raises, naming the first
        return A

    def _errors(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`errors` of checked poses, in chunks of at most :data:`_MATCH_CHUNK` grasp ×
        symmetry × pose triples."""
        B = self._stack
        chunk = max(1, _MATCH_CHUNK // (B.shape[0] * B.shape[1]))
        parts = [self._errors_of(A[i : i + chunk]) for i in range(0, len(A), chunk)]
        if not parts:  # no poses: no errors
            return np.zeros(0), np.zeros(0)
        return np.concatenate([d for d, _ in parts]), np.concatenate([m for _, m in parts])

    def _forms(self) -> np.ndarray:
        """The linear forms of a pose's rotation A_R that :meth:`_errors_of` reads, per grasp and
        symmetry: (G·S·F, 9) weights on A_R's entries. With M = B_Rᵀ A_R (B = T_go · S), a form
        Σ C ∘ M is Σ (B_R C) ∘ A_R. The forms: tr M and M's axial part (its angle); with a
        continuous axis a also aᵀMa, ⟨[a]×, M⟩ (the best turn θ about a, in closed form) and the
        axial parts of [a]× M and a aᵀ M (those of R_θᵀ M, from θ)."""
        if self._weights is None:
            E = np.zeros((3, 3, 3))
            for k, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):  # axial part: M[i, j] − M[j, i]
                E[k, i, j], E[k, j, i] = 1.0, -1.0
            forms = [np.eye(3), *E]
            if self._axis is not None:
                a = self._axis[1]
                K = _skew(a)
                aa = np.outer(a, a)
                forms += [aa, K, *(K.T @ e for e in E), *(aa @ e for e in E)]
            BR = self._stack[:, :, :3, :3]
            W = np.einsum("gsij,fjk->gsfik", BR, np.stack(forms))
            self._weights = W.reshape(-1, 9)
            if self._axis is not None:
                # B_R (c₀ − R_θ c₀) = (1 − cos θ) B_R u − sin θ B_R (a × c₀), u = c₀'s part across a.
                centre, a = self._axis
                self._swing = BR @ self._across, BR @ np.cross(a, centre)
        return self._weights

    def _errors_of(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        deg, mm = self._pair_errors(A)
        g = np.argmin(deg / self.tolerance_deg + mm / self.tolerance_mm, axis=0)
        k = np.arange(len(A))
        return deg[g, k], mm[g, k]

    def _pair_errors(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(deg, mm), each (G, K): the error of each pose A (K, 4, 4) against each grasp, at the
        symmetry nearest it."""
        B = self._stack
        G, S = B.shape[:2]
        v = (self._forms() @ A[:, :3, :3].reshape(len(A), 9).T).reshape(G, S, -1, len(A))  # (G, S, F, K)
        u, w = (0.0, 0.0) if self._swing is None else (x[:, :, None, :] for x in self._swing)
        deg, mm = self._deg_mm(np.moveaxis(v, 2, 3), B[:, :, None, :3, 3], A[:, :3, 3], u, w)  # (G, S, K)
        s_best = np.argmin(deg / 5.0 + mm / 3.0, axis=1)[:, None]  # pose_error's choice of symmetry, per grasp
        return np.take_along_axis(deg, s_best, axis=1)[:, 0], np.take_along_axis(mm, s_best, axis=1)[:, 0]

    def _deg_mm(self, v: np.ndarray, Bt: Any, At: Any, u: Any, w: Any) -> tuple[np.ndarray, np.ndarray]:
        """(deg, mm) of pose/grasp pairs from their forms ``v`` (…, F) (:meth:`_forms` applied to
        the pose's rotation), the grasp's translation ``Bt`` and the pose's ``At`` (…, 3), and the
        swing ``u``, ``w`` (…, 3) of a turn about the continuous axis (unused without one)."""
        trace, axial = v[..., 0], v[..., 1:4]
        t = Bt
        if self._axis is not None:
            # The turn θ about the axis that brings B·S·R_θ nearest A: θ = atan2(Q, P) maximises
            # tr(R_θᵀ M) = cos θ P + sin θ Q + aᵀMa; R_θᵀ M's axial part is linear in cos θ, sin θ.
            along, Q = v[..., 4], v[..., 5]
            P = trace - along
            r = np.hypot(P, Q)
            safe = np.where(r > 0.0, r, 1.0)
            c, s = np.where(r > 0.0, P / safe, 1.0), np.where(r > 0.0, Q / safe, 0.0)
            trace = c * P + s * Q + along
            axial = c[..., None] * axial - s[..., None] * v[..., 6:9] + (1.0 - c)[..., None] * v[..., 9:12]
            t = t + (1.0 - c)[..., None] * u - s[..., None] * w
        # The angle as rotation_angle_deg takes it: atan2 of the axial part's half norm and (tr − 1) / 2.
        deg = np.degrees(np.arctan2(np.linalg.norm(axial, axis=-1) / 2.0, (trace - 1.0) / 2.0))
        return deg, np.linalg.norm(t - At, axis=-1)

    def cost(self, error: tuple[float, float]) -> float:
        """An error in units of the tolerances (≤ 2 when both are within them)."""
        return error[0] / self.tolerance_deg + error[1] / self.tolerance_mm

    def within(self, error: tuple[float, float]) -> bool:
        """Whether an error is within both tolerances."""
        return error[0] <= self.tolerance_deg and error[1] <= self.tolerance_mm
