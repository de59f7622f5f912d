"""The simulated camera and laser: a scene of the bin and the parts, rendered by ray casting.

``World`` holds the meshes and their poses in the base frame; ``World.view(cell)`` casts the
camera's rays once for the cell's robot pose and returns a :class:`View`, whose
:meth:`View.frame` lights the laser line for a motor angle; ``World.surfaces(camera,
T_base_camera)`` casts any camera's rays from a fixed pose (the depth cameras of
:mod:`binpick.sim.sensors`). Depth and instance-id images are the ground truth; instance ids
are the pile's part ids (≥ 0), −2 for the bin, −3 for the table, −1 where nothing is hit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Optional

import numpy as np

from .. import _core
from .._validate import (
    as_angles,
    as_faces,
    as_float_array,
    as_points,
    as_transform,
    as_vector,
    count,
    instance_of,
    non_negative,
    number,
    pixel_window,
    positive,
    thread_count,
)
from ..camera import CameraIntrinsics, camera_args
from ..errors import InvalidInputError
from ..models import Model
from .cell import Bin, Cell, Laser, Lighting, SensorNoise

__all__ = ["World", "Surfaces", "View", "render_checkerboard", "BIN_ID", "TABLE_ID", "NO_SURFACE"]

#: Range of instance ids (the core's 32-bit signed ids).
ID_RANGE = (-(2**31), 2**31 - 1)

#: Most inner corners a rendered checkerboard has along one side, and the largest supersampling
#: (rays per pixel side): beyond either, one render would run for minutes.
MAX_BOARD_CORNERS = 200
MAX_SUPERSAMPLE = 8

BIN_ID = -2
TABLE_ID = -3
NO_SURFACE = -1

PART_ALBEDO = (0.72, 0.72, 0.70)
BIN_ALBEDO = (0.30, 0.34, 0.40)
TABLE_ALBEDO = (0.45, 0.40, 0.33)


def _box(lo: Sequence[float], hi: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    v = np.array(
        [[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]] for i in range(8)],
        dtype=np.float64,
    )
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    f = np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])], dtype=np.int64)
    return v, f


class World:
    """Meshes placed in the robot's base frame, ready to be rendered."""

    def __init__(self) -> None:
        self._scene = _core.SimScene()
        self._meshes: dict[int, int] = {}

    @classmethod
    def of_pile(cls, pile: Any, *, bin: Bin | None = None, table: bool = True, part_specular: float = 0.0) -> World:
        """The bin, a table under it, and every part of ``pile`` at its pose: a :class:`binpick.sim.Pile`,
        or a snapshot of one (anything with its ``bin``, ``model``, ``ids`` and ``poses``, such as the
        parts a twin's ``world.json`` lists)."""
        missing = [a for a in ("bin", "model", "ids", "poses") if not hasattr(pile, a)]
        if missing:
            raise InvalidInputError(
                f"pile: a {type(pile).__name__} has no {', '.join(missing)}; pass a binpick.sim.Pile(model) "
                "or a snapshot with its bin, model, ids and poses"
            )
        w = cls()
        b = pile.bin if bin is None else bin
        w.add_bin(b, table=table)
        w.add_parts(pile.model, pile.ids, pile.poses, specular=part_specular)
        return w

    def add_bin(self, bin: Bin, *, table: bool = True) -> None:
        """Adds the bin (id −2) and, if ``table``, a table top under it (id −3)."""
        bin = instance_of(bin, Bin, "bin", "binpick.sim.Bin()")
        v, f = _core.sim_bin_mesh(tuple(bin.center), tuple(bin.size), float(bin.floor_z), float(bin.wall_thickness))
        m = self._scene.add_mesh(v, f, list(BIN_ALBEDO), 0.0, 10.0)
        self._scene.add_instance(m, np.eye(4), BIN_ID)
        if table:
            z = bin.floor_z - bin.wall_thickness
            cx, cy = bin.center
            tv, tf = _box((cx - 600, cy - 500, z - 20), (cx + 600, cy + 500, z))
            t = self._scene.add_mesh(tv, tf, list(TABLE_ALBEDO), 0.0, 10.0)
            self._scene.add_instance(t, np.eye(4), TABLE_ID)

    def add_mesh(
        self,
        vertices: Any,
        faces: Any,
        *,
        albedo: Sequence[float] = PART_ALBEDO,
        specular: float = 0.0,
        shininess: float = 20.0,
    ) -> int:
        """Adds a mesh (mm, its own frame) and returns its index for :meth:`add_instance`."""
        v = as_points(vertices, "vertices", min_points=3)
        f = as_faces(faces, "faces", len(v))
        rgb = as_vector(albedo, "albedo", 3)
        if ((rgb < 0) | (rgb > 1)).any():
            raise InvalidInputError(f"albedo: each of R, G, B must be in [0, 1], got {rgb.tolist()}")
        spec = non_negative(specular, "specular")
        return int(self._scene.add_mesh(v, f, rgb.tolist(), spec, positive(shininess, "shininess")))

    def add_instance(self, mesh: int, T_base_object: Any, id: int) -> None:
        """Places mesh ``mesh`` at ``T_base_object`` under instance id ``id``."""
        self._scene.add_instance(
            count(mesh, "mesh"), as_transform(T_base_object, "T_base_object"), count(id, "id", *ID_RANGE)
        )

    def add_parts(self, model: Model, ids: Sequence[int], poses: Any, *, specular: float = 0.0) -> None:
        """Adds instances of ``model`` (mesh built once) at ``poses`` (N, 4, 4) with ``ids``."""
        instance_of(model, Model, "model", "binpick.parts.tee()")
        key = id(model)
        if key not in self._meshes:
            self._meshes[key] = self.add_mesh(model.vertices, model.faces, specular=specular)
        poses = as_float_array(poses, "poses")
        if len(ids) != len(poses):
            raise InvalidInputError(f"ids/poses: {len(ids)} ids but {len(poses)} poses")
        for i, T in zip(ids, poses):
            self.add_instance(self._meshes[key], T, i)

    def place_parts(self, model: Model, ids: Sequence[int], poses: Any) -> None:
        """The instances of ``model`` made exactly ``ids`` at ``poses`` (N, 4, 4): those placed
        are moved, those not listed removed and new ones added (the mesh and its ray-casting
        tree kept: a pile after a pick is rendered without building them again)."""
        poses = as_float_array(poses, "poses")
        if len(ids) != len(poses):
            raise InvalidInputError(f"ids/poses: {len(ids)} ids but {len(poses)} poses")
        keep = {int(i) for i in ids}
        for i in self.ids:
            if i >= 0 and i not in keep:
                self.remove(i)
        placed = set(self.ids)
        new = []
        for k, (i, T) in enumerate(zip(ids, poses)):
            if int(i) in placed:
                self.set_pose(int(i), T)
            else:
                new.append(k)
        if new:
            self.add_parts(model, [ids[k] for k in new], poses[new])

    def set_pose(self, id: int, T_base_object: Any) -> None:
        """Moves instance ``id``."""
        self._scene.set_pose(count(id, "id", *ID_RANGE), as_transform(T_base_object, "T_base_object"))

    def remove(self, id: int) -> None:
        """Removes instance ``id`` (e.g. after a pick)."""
        self._scene.remove_instance(count(id, "id", *ID_RANGE))

    @property
    def ids(self) -> list[int]:
        """Ids of the placed instances."""
        return list(self._scene.instance_ids())

    def nearest_surface(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """Exact distance (mm, float64 (N,)) from each point (N, 3) of the base frame to the
        nearest mesh surface of the world, and that surface's instance id (int32 (N,)): the
        ground truth a reconstructed cloud is measured against. (inf, −1) in an empty world."""
        pts = as_points(points, "points", min_points=0)
        return self._scene.nearest_surface(np.ascontiguousarray(pts, dtype=np.float64))

    def view(self, cell: Cell, T_base_flange: Optional[Any] = None, *, num_threads: int = 0) -> View:
        """Casts the camera's rays at robot pose ``T_base_flange`` (default: the cell's scan pose)."""
        if not isinstance(cell, Cell):
            raise InvalidInputError(f"cell: expected a binpick.sim.Cell, got {type(cell).__name__}")
        T_bf = cell.T_base_flange if T_base_flange is None else as_transform(T_base_flange, "T_base_flange")
        T_bc = T_bf @ cell.T_flange_camera
        raw = self._scene.view(camera_args(cell.camera), T_bc, cell.lighting._args(), thread_count(num_threads))
        return View(raw, cell, T_bf, T_bc)

    def surfaces(self, camera: CameraIntrinsics, T_base_camera: Any, *, num_threads: int = 0) -> Surfaces:
        """Casts the rays of ``camera`` posed at ``T_base_camera``: the surfaces a fixed camera (a
        depth camera, a projector) sees, without a cell, a laser or a robot."""
        args = camera_args(camera)
        T_bc = as_transform(T_base_camera, "T_base_camera")
        return Surfaces(self._scene.view(args, T_bc, Lighting()._args(), thread_count(num_threads)), camera, T_bc)


class Surfaces:
    """What a camera sees from one pose: per pixel the first surface's point, normal and instance
    id (the ground truth of every simulated sensor)."""

    def __init__(self, raw: Any, camera: CameraIntrinsics, T_base_camera: np.ndarray) -> None:
        self._raw = raw
        self.camera = camera
        self.T_base_camera = T_base_camera

    @property
    def depth(self) -> np.ndarray:
        """(H, W) float32: z of the seen surface in the camera frame, mm; NaN where none."""
        return self._raw.depth()

    @property
    def ids(self) -> np.ndarray:
        """(H, W) int32 instance ids (parts ≥ 0, bin −2, table −3, nothing −1)."""
        return self._raw.ids()

    @property
    def points(self) -> np.ndarray:
        """(H, W, 3) float32 surface points in the camera frame, mm (NaN where none)."""
        return self._raw.points()

    @property
    def normals(self) -> np.ndarray:
        """(H, W, 3) float32 camera-facing unit normals in the camera frame."""
        return self._raw.normals()


class View(Surfaces):
    """The geometry the cell's camera sees from one robot pose; frames are lit from it per laser angle."""

    def __init__(self, raw: Any, cell: Cell, T_base_flange: np.ndarray, T_base_camera: np.ndarray) -> None:
        super().__init__(raw, cell.camera, T_base_camera)
        self.cell = cell
        self.T_base_flange = T_base_flange

    def frame(
        self, angle: float, *, seed: int = 0, laser: Optional[Laser] = None, noise: Optional[SensorNoise] = None
    ) -> np.ndarray:
        """The RGB frame (H, W, 3) uint8 the camera grabs with the laser at motor angle ``angle`` (rad)."""
        return self.frames([angle], seed=seed, laser=laser, noise=noise)[0]

    def frames(
        self,
        angles: Sequence[float],
        *,
        seed: int = 0,
        laser: Optional[Laser] = None,
        noise: Optional[SensorNoise] = None,
        num_threads: int = 0,
    ) -> np.ndarray:
        """(K, H, W, 3) uint8 RGB frames, one per motor angle; frame k's noise is seeded by ``seed + k``."""
        laser = self.cell.laser if laser is None else instance_of(laser, Laser, "laser", "binpick.sim.Laser()")
        noise = _noise(self.cell.noise if noise is None else noise)
        a = as_angles(angles, "angles")
        return self._raw.frames(
            *laser._args(), a.tolist(), noise._args(), count(seed, "seed"), thread_count(num_threads)
        )

    def ambient_frame(self, *, seed: int = 0, noise: Optional[SensorNoise] = None) -> np.ndarray:
        """The RGB frame without the laser."""
        noise = _noise(self.cell.noise if noise is None else noise)
        return self._raw.ambient_frame(noise._args(), count(seed, "seed"))


def render_checkerboard(
    camera: CameraIntrinsics,
    T_camera_board: Any,
    *,
    pattern: tuple[int, int] = (9, 6),
    square: float = 20.0,
    margin: float = 15.0,
    lighting: Optional[Lighting] = None,
    laser: Optional[Laser] = None,
    angle: float = 0.0,
    noise: Optional[SensorNoise] = None,
    supersample: int = 3,
    seed: int = 0,
    window: Optional[tuple[int, int, int, int]] = None,
) -> np.ndarray:
    """An RGB image (H, W, 3) uint8 of a checkerboard with ``pattern`` = (columns, rows) inner
    corners, ``square`` mm, at ``T_camera_board`` (OpenCV board frame: origin at the first inner
    corner, corners at (i·square, j·square, 0)); with the laser line at ``angle`` if ``laser``.
    ``window`` (u0, v0, u1, v1), pixels, half-open: only those pixels are drawn, each as in the
    whole image (its noise too), the rest left the background's (without noise outside the
    window's rows): for a view that shows the board in a part of the picture."""
    if not isinstance(pattern, (tuple, list)) or len(pattern) != 2:
        raise InvalidInputError(f"pattern: expected (columns, rows) of inner corners, got {pattern!r:.60}")
    cols, rows = (count(p, f"pattern[{i}]", 1, MAX_BOARD_CORNERS) for i, p in enumerate(pattern))
    lighting = (
        Lighting(ambient=150.0, lamp=60.0)
        if lighting is None
        else instance_of(lighting, Lighting, "lighting", "binpick.sim.Lighting()")
    )
    noise = SensorNoise() if noise is None else _noise(noise)
    return _core.sim_render_checkerboard(
        camera_args(camera),
        (cols + 1, rows + 1, positive(square, "square"), non_negative(margin, "margin", "mm")),
        as_transform(T_camera_board, "T_camera_board"),
        lighting._args(),
        None if laser is None else instance_of(laser, Laser, "laser", "binpick.sim.Laser()")._args(),
        number(angle, "angle", -np.pi, np.pi, unit="rad"),
        noise._args(),
        count(supersample, "supersample", 1, MAX_SUPERSAMPLE),
        count(seed, "seed"),
        None
        if window is None
        else pixel_window(window, "window", camera.width, camera.height, span=1, whole="draw the whole image"),
    )


def _noise(noise: Any) -> SensorNoise:
    return instance_of(noise, SensorNoise, "noise", "binpick.sim.SensorNoise()")
