"""Physics piles: instances of a part dropped into a bin and settled (rapier3d in the core)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _core
from .._validate import as_float_array, as_points, as_transform, check_finite, count, instance_of, non_negative, number
from ..errors import InvalidInputError
from ..models import MAX_SPACING, MIN_SPACING, Model, _check_spacing
from .cell import Bin

__all__ = ["Pile", "SettleReport", "PushReport", "max_interpenetration", "convex_decomposition"]


class SettleReport:
    """What one settling did: ``steps``, ``simulated_time`` (s), ``settled`` (all parts at rest),
    ``max_speed`` (mm/s)."""

    __slots__ = ("steps", "simulated_time", "settled", "max_speed")

    def __init__(self, raw: tuple) -> None:
        self.steps, self.simulated_time, self.settled, self.max_speed = (
            int(raw[0]),
            float(raw[1]),
            bool(raw[2]),
            float(raw[3]),
        )

    def __repr__(self) -> str:
        return (
            f"SettleReport(settled={self.settled}, steps={self.steps}, "
            f"simulated_time={self.simulated_time:.3f} s, max_speed={self.max_speed:.3g} mm/s)"
        )


class PushReport:
    """What one push did: ``push_steps`` (physics steps the tool moved for), ``settle`` (the
    :class:`SettleReport` after the tool was taken away) and ``moved`` (ids of the parts that
    moved more than 1 mm or turned more than 2°)."""

    __slots__ = ("push_steps", "settle", "moved")

    def __init__(self, raw: tuple) -> None:
        self.push_steps = int(raw[0])
        self.settle = SettleReport(raw[1])
        self.moved = [int(i) for i in raw[2]]

    def __repr__(self) -> str:
        return f"PushReport(moved={self.moved}, push_steps={self.push_steps}, {self.settle!r})"


#: Fastest tool speed of :meth:`Pile.push`, mm/s (the core's bound; its slowest is 0.1 mm/s).
MAX_PUSH_SPEED = 5000.0


def _transforms(value: Any, name: str) -> np.ndarray:
    T = as_float_array(value, name)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise InvalidInputError(f"{name}: expected an (N, 4, 4) array, got shape {T.shape}")
    for i, t in enumerate(T):
        as_transform(t, f"{name}[{i}]")
    return T


#: Most parts one pile holds (the core's bound); beyond it settling would take hours.
MAX_PARTS = 500

#: Range of the physics time step, s: finer than a millisecond multiplies the steps (and the
#: quiet steps a settled pile needs) without changing the pile; coarser than 50 ms the core refuses.
TIME_STEP_RANGE = (1e-3, 0.05)

#: Longest settling, simulated seconds: a pile at rest takes a few; a pile that never rests
#: stops here rather than stepping for ever.
MAX_SETTLE_TIME = 60.0

#: Ranges of the convex decomposition's voxel resolution (the core's) and of its hull count.
DECOMPOSITION_RESOLUTION_RANGE = (8, 256)
MAX_CONVEX_HULLS = 256


def _model(model: Any) -> Model:
    return instance_of(model, Model, "model", "binpick.parts.tee()")


def _sample_spacing(model: Model, spacing: Any) -> float:
    s = number(spacing, "spacing", MIN_SPACING, MAX_SPACING, unit="mm")
    _check_spacing(model.vertices, model.faces, s)  # a spacing that would sample too many points
    return s


def _mesh(model: Model) -> tuple[np.ndarray, np.ndarray]:
    return (
        np.ascontiguousarray(model.vertices, dtype=np.float64),
        np.ascontiguousarray(model.faces, dtype=np.int64),
    )


def _bin_args(bin: Bin) -> tuple:
    return tuple(bin.center), tuple(bin.size), float(bin.floor_z), float(bin.wall_thickness)


def _physics(friction: Any, restitution: Any, time_step: Any, max_settle_time: Any, skin: Any) -> tuple:
    return (
        non_negative(friction, "friction"),
        number(restitution, "restitution", 0.0, 1.0),
        number(time_step, "time_step", *TIME_STEP_RANGE, unit="s"),
        number(max_settle_time, "max_settle_time", 1e-3, MAX_SETTLE_TIME, unit="s"),
        number(skin, "skin", 0.0, 5.0, unit="mm"),
    )


def _decomposition(resolution: Any, hulls: Any) -> tuple[int, int]:
    return (
        count(resolution, "decomposition_resolution", *DECOMPOSITION_RESOLUTION_RANGE),
        count(hulls, "max_convex_hulls", 1, MAX_CONVEX_HULLS),
    )


class Pile:
    """``count`` instances of ``model`` dropped from random poses into ``bin`` and left to settle.

    Deterministic for ``seed``. Parts collide through convex pieces enclosing the mesh (V-HACD,
    rebuilt on the mesh's vertices, rounded by ``skin`` mm). Instance ids run 0..count−1 in drop
    order and stay valid after removals. ``poses`` are ``T_base_object`` (model frame → base).
    """

    def __init__(
        self,
        model: Model,
        count_: int = 12,
        *,
        bin: Bin | None = None,
        seed: int = 0,
        friction: float = 0.5,
        restitution: float = 0.05,
        time_step: float = 1.0 / 120.0,
        max_settle_time: float = 6.0,
        skin: float = 0.3,
        decomposition_resolution: int = 48,
        max_convex_hulls: int = 24,
    ) -> None:
        self.model = _model(model)
        self.bin = Bin() if bin is None else instance_of(bin, Bin, "bin", "binpick.sim.Bin()")
        n = count(count_, "count", 1, MAX_PARTS)
        self._raw = _core.SimPile(
            *_mesh(self.model),
            n,
            *_bin_args(self.bin),
            count(seed, "seed"),
            *_physics(friction, restitution, time_step, max_settle_time, skin),
            *_decomposition(decomposition_resolution, max_convex_hulls),
        )

    @classmethod
    def placed(
        cls,
        model: Model,
        poses: Any,
        *,
        bin: Bin | None = None,
        friction: float = 0.5,
        restitution: float = 0.05,
        time_step: float = 1.0 / 120.0,
        max_settle_time: float = 6.0,
        skin: float = 0.3,
        decomposition_resolution: int = 48,
        max_convex_hulls: int = 24,
    ) -> Pile:
        """Instances of ``model`` placed at ``poses`` (``T_base_object``, (N, 4, 4), mm) in
        ``bin`` and left to settle — a scene as a scan located it, to predict what a push does
        there (:meth:`push`). Ids run 0..N−1 in the order of ``poses``; parts placed overlapping
        each other or the bin are pushed apart by the physics as it settles."""
        pile = cls.__new__(cls)
        pile.model = _model(model)
        pile.bin = Bin() if bin is None else instance_of(bin, Bin, "bin", "binpick.sim.Bin()")
        T = _transforms(poses, "poses")
        count(len(T), "poses (their number)", 1, MAX_PARTS)
        pile._raw = _core.SimPile.placed(
            *_mesh(pile.model),
            T,
            *_bin_args(pile.bin),
            *_physics(friction, restitution, time_step, max_settle_time, skin),
            *_decomposition(decomposition_resolution, max_convex_hulls),
        )
        return pile

    @property
    def ids(self) -> np.ndarray:
        """Ids of the parts still in the bin (int64)."""
        return self._raw.poses()[0]

    @property
    def poses(self) -> np.ndarray:
        """``T_base_object`` of the remaining parts, (N, 4, 4), in the order of :attr:`ids`."""
        return self._raw.poses()[1]

    def pose(self, id: int) -> np.ndarray:
        """``T_base_object`` of part ``id``."""
        ids, poses = self._raw.poses()
        hit = np.flatnonzero(ids == count(id, "id"))
        if len(hit) == 0:
            raise InvalidInputError(f"id: no part {id} in the pile (remaining: {ids.tolist()})")
        return poses[hit[0]]

    def __len__(self) -> int:
        return int(self._raw.remaining())

    def remove(self, id: int) -> SettleReport:
        """Takes part ``id`` out (a pick) and lets the others settle again."""
        return SettleReport(self._raw.remove(count(id, "id")))

    def set_poses(self, poses: Any) -> SettleReport:
        """Moves the remaining parts (in the order of :attr:`ids`) to ``poses`` (N, 4, 4), at
        rest, and lets them settle: the same scene tried again without rebuilding its shapes."""
        T = _transforms(poses, "poses")
        if len(T) != len(self):
            raise InvalidInputError(f"poses: {len(T)} poses for {len(self)} parts; pass one per remaining part")
        return SettleReport(self._raw.set_poses(T))

    def settle(self) -> SettleReport:
        """Steps the simulation until every part is at rest."""
        return SettleReport(self._raw.settle())

    def push(self, boxes: Any, path: Any, speed: float = 50.0) -> PushReport:
        """Pushes the pile with a kinematic tool and lets it settle.

        ``boxes``: the tool's shape, a sequence of ``(half_extents (3,), T_tool_box (4, 4))``, mm.
        ``path``: ``T_base_tool`` poses (P ≥ 2, 4, 4) the tool moves through, straight (and
        slerped) between them, at ``speed`` mm/s for its fastest point. Parts it touches are
        shoved by the physics; the tool is then removed and the pile settles."""
        items = list(boxes) if isinstance(boxes, (list, tuple)) else None
        if not items or any(not isinstance(b, (list, tuple)) or len(b) != 2 for b in items):
            raise InvalidInputError(
                "boxes: pass a non-empty list of (half_extents, T_tool_box) pairs, e.g. [((10, 10, 20), np.eye(4))]"
            )
        halves = as_points([h for h, _ in items], "boxes half_extents")
        poses = _transforms([t for _, t in items], "boxes T_tool_box")
        T = _transforms(path, "path")
        v = number(speed, "speed", 0.1, MAX_PUSH_SPEED, unit="mm/s")
        return PushReport(self._raw.push(halves, poses, T, v))

    @property
    def last_settle(self) -> SettleReport:
        """The report of the last settling."""
        return SettleReport(self._raw.last_settle())

    def collision_hulls(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The convex pieces (vertices, faces) each part collides with, in the model frame."""
        return self._raw.collision_hulls()

    def max_interpenetration(self, spacing: float = 1.0) -> float:
        """Deepest penetration (mm) of any part's surface into another part's mesh (real meshes)."""
        return max_interpenetration(self.model, self.poses, spacing=spacing)

    def __repr__(self) -> str:
        return f"Pile({self.model.name!r}, parts={len(self)}, bin={self.bin.size}, {self.last_settle!r})"


def max_interpenetration(model: Model, poses: Any, *, spacing: float = 1.0) -> float:
    """How deep (mm) points sampled every ``spacing`` mm on each instance's surface lie inside
    another instance's mesh; 0 when no instance overlaps another."""
    model = _model(model)
    T = as_float_array(poses, "poses")
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise InvalidInputError(f"poses: expected an (N, 4, 4) array, got shape {T.shape}")
    check_finite(T, "poses")
    samples = _core.sample_mesh(
        np.ascontiguousarray(model.vertices, dtype=np.float64),
        np.ascontiguousarray(model.faces, dtype=np.int64),
        _sample_spacing(model, spacing),
        None,
        1,
    )[0]
    return float(
        _core.sim_max_interpenetration(
            np.ascontiguousarray(model.vertices, dtype=np.float64),
            np.ascontiguousarray(model.faces, dtype=np.int64),
            T,
            np.ascontiguousarray(samples, dtype=np.float64),
        )
    )


def convex_decomposition(
    model: Model, *, decomposition_resolution: int = 48, max_convex_hulls: int = 24
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The convex pieces (vertices, faces) enclosing ``model`` that a pile collides with."""
    model = _model(model)
    return _core.sim_convex_decomposition(
        np.ascontiguousarray(model.vertices, dtype=np.float64),
        np.ascontiguousarray(model.faces, dtype=np.int64),
        *_decomposition(decomposition_resolution, max_convex_hulls),
    )
