"""Part models from CAD meshes, point-cloud files, normals and downsampling."""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from . import _core, _step
from ._paths import check_file, no_such_file
from ._validate import (
    MAX_UNSIGNED,
    as_faces,
    as_points,
    as_transform,
    as_vector,
    count,
    number,
    positive,
    thread_count,
    unit_scale,
    write_atomic,
)
from .errors import DegenerateModelWarning, InvalidInputError, InvalidTypeError, MeshFileNotFoundError
from .transforms import pose_error, rotation_about

__all__ = [
    "Model",
    "Branch",
    "PpfParams",
    "Symmetries",
    "FreeMotion",
    "NearSymmetry",
    "read_ply",
    "write_ply",
    "estimate_normals",
    "scan_noise",
    "voxel_downsample",
]


@dataclass(frozen=True)
class Branch:
    """A cylindrical branch of a pipe fitting, in the model frame (what CCP needs).

    ``direction`` is the unit vector from the junction (the model origin) to the open end,
    ``length`` the distance from the junction to the end face (mm), ``radius`` the outer radius (mm).
    """

    direction: tuple[float, float, float]
    length: float
    radius: float


PpfParams = _core.PpfParams
"""Parameters of a model's point-pair-feature table (Drost et al. 2010), keyword-only, frozen;
an argument left out takes the core's default.

``sampling_ratio``: model and scene sampling distance, and the distance quantisation step, as
a fraction of the model's diameter. ``angle_bins``: bins of each of the three angle features
over [0, π]. ``rotation_bins``: bins of the rotation about the reference normal over a turn.
"""


@dataclass(frozen=True)
class Symmetries:
    """A part's proper symmetries, detected from its surface (rotations that map it onto itself).

    Attributes:
        center: (3,) the point the symmetry axes pass through (the surface centroid), mm.
        continuous_axis: (3,) unit axis of a continuous rotational symmetry, or None.
        rotations: (K, 3, 3) the discrete symmetry rotations about ``center``, identity first
            (with a continuous axis: those beyond the turns about it, e.g. a shaft's end-for-end flip).
    """

    center: np.ndarray
    continuous_axis: Optional[np.ndarray]
    rotations: np.ndarray

    @property
    def is_trivial(self) -> bool:
        """True for a part without symmetry."""
        return self.continuous_axis is None and len(self.rotations) == 1

    def __repr__(self) -> str:
        axis = "none" if self.continuous_axis is None else np.array2string(self.continuous_axis, precision=3)
        return f"Symmetries(discrete={len(self.rotations)}, continuous_axis={axis})"


@dataclass(frozen=True, eq=False)
class FreeMotion:
    """A rigid motion of a part that its surface hardly constrains and that is no symmetry of it:
    a scan cannot locate the part along it (see :attr:`Model.degenerate`).

    Attributes:
        kind: ``"slide"`` or ``"turn"``.
        axis: (3,) unit direction of the slide, or axis of the turn, model frame.
        point: (3,) a point on a turn's axis, model frame, mm; None for a slide.
    """

    kind: str
    axis: np.ndarray
    point: Optional[np.ndarray] = None

    def __str__(self) -> str:
        axis = np.array2string(self.axis, precision=2)
        if self.kind == "slide":
            return f"slides along {axis}"
        return f"turns about {axis} through {np.array2string(self.point, precision=1)} mm"


@dataclass(frozen=True, eq=False)
class NearSymmetry:
    """A rotation that maps most of a part's surface onto itself without being a symmetry: the
    poses it relates look alike to a scan that does not show the feature.

    Attributes:
        center: (3,) the point the axis passes through, model frame, mm.
        axis: (3,) unit axis, model frame.
        angle: the turn, radians; None for a continuous near axis (a shaft with a keyway: every
            turn about it nearly maps the part onto itself).
        agreement: fraction of the surface the turn maps onto the surface.
        feature: (M, 3) model points that break it (the feature and where the turn moves it).
    """

    center: np.ndarray
    axis: np.ndarray
    angle: Optional[float]
    agreement: float
    feature: np.ndarray

    @property
    def transform(self) -> np.ndarray:
        """(4, 4) the turn about ``center`` as a model-frame transform (identity for a
        continuous axis, whose turns are all near-symmetries)."""
        T = np.eye(4)
        if self.angle is not None:
            T[:3, :3] = rotation_about(self.axis, self.angle)
            T[:3, 3] = self.center - T[:3, :3] @ self.center
        return T

    def __repr__(self) -> str:
        turn = "continuous" if self.angle is None else f"{np.degrees(self.angle):.1f}°"
        axis = np.array2string(self.axis, precision=3)
        return f"NearSymmetry({turn} about {axis}, agreement={self.agreement:.3f}, feature={len(self.feature)} points)"


def cache_dir() -> Optional[Path]:
    """Where prepared PPF tables are cached: ``$BINPICK_CACHE_DIR``, else ``~/.cache/binpick``
    (``$XDG_CACHE_HOME/binpick``). Setting ``BINPICK_CACHE_DIR`` to an empty string disables it."""
    env = os.environ.get("BINPICK_CACHE_DIR")
    if env is not None:
        return Path(env) if env else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "binpick"


class Model:
    """A rigid part: its triangle mesh in millimetres and an even surface sample with normals.

    Build one with :meth:`from_mesh` (STL, PLY, OBJ, STEP files) or :meth:`from_arrays`, or take a
    built-in part from :mod:`binpick.parts`. The model frame is the mesh file's frame.

    The samples drive detection and the coarse pose; the final refinement of
    :func:`binpick.estimate_pose` registers onto them too, unless they are sparser than 1.5 ×
    1/100 of the mesh's bounding-box diagonal (a paper-style 300-point model cloud): then it
    registers onto the mesh surface sampled at that 1/100, so accuracy does not depend on how
    sparse the samples are. The samples must lie on the mesh, in its frame.

    Attributes:
        vertices: (V, 3) mesh vertices, mm.
        faces: (F, 3) triangle vertex indices.
        points: (N, 3) surface samples, mm.
        normals: (N, 3) outward unit normals of the samples.
        spacing: nominal sample spacing, mm (None when sampled by count).
        diameter: largest vertex-to-vertex distance, mm.
        area: surface area, mm².
        name: a label for reports.
        branches: cylindrical branches for CCP, or empty when the part has none declared.
        special_direction: direction of a distinguishing feature (the tee's boss) for CCP, or None.
        grasps: named gripper poses ``T_gripper_object`` declared with :meth:`add_grasp`.
    """

    def __init__(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        points: np.ndarray,
        normals: np.ndarray,
        *,
        spacing: Optional[float],
        diameter: float,
        area: float,
        name: str,
        branches: Sequence[Branch] = (),
        special_direction: Optional[Sequence[float]] = None,
    ) -> None:
        self.vertices = vertices
        self.faces = faces
        self.points = points
        self.normals = normals
        self.spacing = spacing
        self.diameter = float(diameter)
        self.area = float(area)
        self.name = name
        self.branches: tuple[Branch, ...] = tuple(branches)
        self.special_direction = None if special_direction is None else tuple(float(v) for v in special_direction)
        self.grasps: dict[str, np.ndarray] = {}
        self._prepared = None
        for arr in (self.vertices, self.faces, self.points, self.normals):
            arr.setflags(write=False)

    @classmethod
    def from_mesh(
        cls,
        path: str | os.PathLike[str],
        *,
        unit: str = "mm",
        spacing: Optional[float] = None,
        count: Optional[int] = None,
        seed: int = 0,
        name: Optional[str] = None,
    ) -> Model:
        """Reads a mesh (binary/ASCII STL, ASCII/binary PLY, OBJ, or STEP), converts ``unit`` (mm,
        cm, m, in) to millimetres and samples its surface: evenly at ``spacing`` mm, or ``count``
        points. With neither, the spacing is 1/100 of the bounding-box diagonal.

        A STEP file (``.step``/``.stp``; needs the optional extra ``pip install "binpick[step]"``)
        is tessellated by OpenCASCADE to within 0.01 mm of its exact surface. A STEP file declares
        its length unit and OpenCASCADE converts it to millimetres, so ``unit`` is a check there:
        a unit other than the declared one is refused, naming the one to pass (``unit="in"`` for
        a file in inches); it scales only a file that declares no length unit."""
        path = os.fspath(path)
        unit_scale(unit)  # an unknown unit is refused before the file is read
        label = name if name is not None else os.path.splitext(os.path.basename(path))[0]
        if os.path.lexists(path):  # a missing file's name is judged first (its extension), then told missing
            check_file(path, "mesh file", fix_empty="export the part from CAD again")
        try:
            if path.lower().endswith(_step.STEP_SUFFIXES):
                vertices, faces = _step.read_step(path, unit)
                unit = "mm"
            else:
                vertices, faces = _core.read_mesh(path, "mm")
        except MeshFileNotFoundError:
            if os.path.lexists(path):
                raise
            raise MeshFileNotFoundError(no_such_file(path, "mesh file")) from None
        return cls.from_arrays(vertices, faces, unit=unit, spacing=spacing, count=count, seed=seed, name=label)

    @classmethod
    def from_arrays(
        cls,
        vertices: Any,
        faces: Any,
        *,
        unit: str = "mm",
        spacing: Optional[float] = None,
        count: Optional[int] = None,
        seed: int = 0,
        name: str = "part",
        branches: Sequence[Branch] = (),
        special_direction: Optional[Sequence[float]] = None,
    ) -> Model:
        """A model from a vertex array (V, 3) in ``unit`` (those of :meth:`from_mesh`) and a face
        index array (F, 3). At most :data:`MAX_SAMPLES` samples are drawn: a larger ``count``,
        or a ``spacing`` so fine that it would ask for more, is refused before any allocation."""
        v = as_points(vertices, "vertices", min_points=3)
        f = as_faces(faces, "faces", len(v))
        branches, special_direction = _branches(branches), _special(special_direction)
        v = v * unit_scale(unit)
        if spacing is not None and count is not None:
            raise InvalidInputError("spacing/count: give one of them, not both")
        if spacing is None and count is None:
            spacing = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) / 100.0
        if spacing is not None:
            spacing = number(spacing, "spacing", MIN_SPACING, MAX_SPACING, unit="mm")
            _check_spacing(v, f, spacing)
        if count is not None:
            count = _count(count)
        pts, nrm, diameter, area = _core.sample_mesh(v, f, spacing, count, _seed(seed))
        return cls(
            v,
            f,
            pts,
            nrm,
            spacing=spacing,
            diameter=diameter,
            area=area,
            name=name,
            branches=branches,
            special_direction=special_direction,
        )

    def declare_branches(self, branches: Sequence[Branch], special_direction: Optional[Sequence[float]] = None) -> None:
        """Declares the part's cylindrical branches (and special feature) so that CCP can be used.

        CCP needs: the branch axes meeting at the model origin, each as a unit direction from
        the origin to the open end with its length and outer radius (mm); optionally the
        direction of one feature that breaks the branches' symmetry (the tee's boss).
        """
        rows, special = _branches(branches), _special(special_direction)  # checked before the model changes
        self.branches = rows
        self.special_direction = special
        self._prepared = None

    def prepared(self, ppf: Optional[PpfParams] = None):
        """The native pose-estimation structure of this model: search structures, symmetries and
        the point-pair-feature table (``ppf``; default: the parameters last used, else
        :class:`PpfParams`), built once and kept until other parameters are asked for.
        The table is cached on disk (:func:`cache_dir`), keyed by the mesh, its sampling and the
        parameters; a missing, stale or corrupt cache file is rebuilt."""
        if ppf is None and self._prepared is not None:
            return self._prepared[1]
        params = PpfParams() if ppf is None else ppf
        if not isinstance(params, PpfParams):
            raise InvalidInputError(f"ppf: expected binpick.PpfParams, got {type(params).__name__}")
        if self._prepared is None or self._prepared[0] != params:
            rows = np.array([[*b.direction, b.length, b.radius] for b in self.branches], dtype=np.float64).reshape(
                -1, 5
            )
            special = None if self.special_direction is None else np.asarray(self.special_direction, dtype=np.float64)
            key = (float(params.sampling_ratio), int(params.angle_bins), int(params.rotation_bins))
            path = self._cache_path(key)
            cached = None if path is None else _read_cache(path)
            native = _core.PreparedModel(
                self.points,
                self.normals,
                self.diameter,
                self.area,
                rows if len(rows) else None,
                special,
                params,
                cached,
                (self.vertices, self.faces),
            )
            if path is not None and not native.ppf_from_cache():
                _write_cache(path, native.ppf_bytes())
            if self._prepared is None and native.degenerate():
                free = "; ".join(str(m) for m in _free_motions(native))
                warnings.warn(
                    f"{self.name}: its surface cannot locate it along some motions ({free}); no scan can fix its pose "
                    "there, and its poses come back with confidence 0. Is this the whole part, with its edges?",
                    DegenerateModelWarning,
                    stacklevel=2,
                )
            self._prepared = (params, native)
        return self._prepared[1]

    @property
    def degenerate(self) -> tuple[FreeMotion, ...]:
        """The motions the part's surface hardly constrains and that are no symmetry of it (one face
        of a box slides in its plane and turns about its normal; a tube without ends slides along
        its axis): a scan cannot locate the part along them, so its poses carry confidence 0.
        Empty for a part that can be located."""
        return _free_motions(self.prepared())

    def _cache_path(self, key: tuple) -> Optional[Path]:
        root = cache_dir()
        if root is None:
            return None
        h = hashlib.sha256()
        for arr in (self.vertices, self.faces, self.points, self.normals):
            h.update(np.ascontiguousarray(arr).tobytes())
        h.update(repr(key).encode())
        return root / "ppf" / f"{h.hexdigest()[:32]}.bin"

    @property
    def symmetries(self) -> Symmetries:
        """The part's proper symmetries, detected from its surface samples."""
        raw = self.prepared().symmetries()
        axis = raw["continuous_axis"]
        return Symmetries(
            center=np.asarray(raw["center"], dtype=np.float64),
            continuous_axis=None if axis is None else np.asarray(axis, dtype=np.float64),
            rotations=np.asarray(raw["rotations"], dtype=np.float64).reshape(-1, 3, 3),
        )

    @property
    def near_symmetries(self) -> list[NearSymmetry]:
        """Rotations that map most (at least 80 %) of the surface onto itself without being
        symmetries, strongest first, each with the model points that break it: the poses a scan
        must tell apart by the feature."""
        return [
            NearSymmetry(
                center=np.asarray(n["center"], dtype=np.float64),
                axis=np.asarray(n["axis"], dtype=np.float64),
                angle=n["angle"],
                agreement=float(n["agreement"]),
                feature=np.asarray(n["feature"], dtype=np.float64),
            )
            for n in self.prepared().near_symmetries()
        ]

    def canonical_pose(self, T_scene_model: Any) -> np.ndarray:
        """The canonical form of a pose under the part's symmetries: the same (4, 4) for any two
        poses that differ only by a symmetry (the one whose rotation is nearest the identity)."""
        return self.prepared().canonical(as_transform(T_scene_model, "T_scene_model"))

    def pose_error(self, T_estimate: Any, T_truth: Any, *, turn_about: Any = None) -> tuple[float, float]:
        """Rotation (degrees) and translation (mm) error of a pose against the truth, minimised
        over the part's symmetries (as the BOP benchmark judges): :func:`binpick.transforms.pose_error`
        with this part's symmetry group (its continuous axis, if any, exactly). ``turn_about``
        (centre, unit axis; model frame), for a part without a continuous symmetry, minimises over
        the turns about that axis too: the error of a pose whose turn about a free axis the scan
        left open (``PoseResult.free_axis``), as a grasp across the axis sees it."""
        sym = self.symmetries
        axis, center = sym.continuous_axis, sym.center
        if turn_about is not None and axis is None:
            center, axis = (as_vector(v, "turn_about", 3) for v in turn_about)
        maps = []
        for R in sym.rotations:
            S = np.eye(4)
            S[:3, :3] = R
            S[:3, 3] = sym.center - R @ sym.center
            maps.append(S)
        return pose_error(T_estimate, T_truth, maps, continuous_axis=axis, center=center)

    def add_grasp(self, name: str, T_gripper_object: Any) -> None:
        """Declares a grasp: the object's pose in the gripper frame when the gripper holds it."""
        self.grasps[str(name)] = as_transform(T_gripper_object, "T_gripper_object")

    def __repr__(self) -> str:
        return (
            f"Model(name={self.name!r}, vertices={len(self.vertices)}, faces={len(self.faces)}, "
            f"points={len(self.points)}, diameter={self.diameter:.2f} mm, branches={len(self.branches)})"
        )


def _branches(branches: Any) -> tuple[Branch, ...]:
    """``branches`` as a tuple of :class:`Branch` with float fields: each a Branch whose direction is
    three finite numbers and whose length and radius are positive finite mm, or InvalidInputError
    (InvalidTypeError for a wrong type) naming ``branches[i]``. Their geometry (distinct axes
    meeting at the origin) is checked when the model is prepared."""
    if isinstance(branches, (str, bytes, Branch)) or not hasattr(branches, "__iter__"):
        raise InvalidTypeError(
            f"branches: expected a sequence of binpick.Branch, got {type(branches).__name__} {branches!r:.40}"
        )
    rows = []
    for i, b in enumerate(branches):
        if not isinstance(b, Branch):
            raise InvalidTypeError(
                f"branches[{i}]: expected a binpick.Branch(direction=(x, y, z), length=mm, radius=mm), "
                f"got {type(b).__name__} {b!r:.40}"
            )
        direction = as_vector(b.direction, f"branches[{i}].direction")
        rows.append(
            Branch(
                direction=(float(direction[0]), float(direction[1]), float(direction[2])),
                length=positive(b.length, f"branches[{i}].length"),
                radius=positive(b.radius, f"branches[{i}].radius"),
            )
        )
    return tuple(rows)


def _special(direction: Any) -> Optional[tuple[float, float, float]]:
    """None, or ``direction`` as three finite floats (InvalidInputError naming ``special_direction``)."""
    if direction is None:
        return None
    d = as_vector(direction, "special_direction")
    return (float(d[0]), float(d[1]), float(d[2]))


#: Bytes of the digest that closes a cache file: the SHA-256 of the table's bytes before it.
_DIGEST = 32


def _read_cache(path: Path) -> Optional[bytes]:
    """The table's bytes in the cache file ``path``, or None when there is none, it cannot be
    read or its digest does not match: a damaged file (a flipped byte in a point the core's
    structural checks cannot see) is rebuilt, never loaded."""
    try:
        data = path.read_bytes() if path.is_file() else b""
    except OSError:
        return None
    table, digest = data[:-_DIGEST], data[-_DIGEST:]
    if len(data) <= _DIGEST or hashlib.sha256(table).digest() != digest:
        return None
    return table


def _write_cache(path: Path, data: Optional[bytes]) -> None:
    """Writes a cache file (the table, then its digest) through a temporary name; a cache that
    cannot be written is skipped."""
    if data is None:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, data + hashlib.sha256(data).digest())
    except OSError as exc:
        warnings.warn(
            f"binpick: cannot write the PPF cache {path} ({exc}); set BINPICK_CACHE_DIR to a writable folder",
            RuntimeWarning,
            stacklevel=3,
        )


#: Most surface samples a model may have (by ``count`` or ``spacing``): ten million points,
#: far beyond any part's needs, so a mistyped count cannot allocate the machine's memory.
MAX_SAMPLES = 10_000_000


def _count(value: Any) -> int:
    return count(value, "count", 1, MAX_SAMPLES)


def _seed(value: Any) -> int:
    return count(value, "seed", 0, MAX_UNSIGNED)


#: The sample spacing :meth:`Model.from_arrays` takes, mm: a micrometre to a kilometre.
MIN_SPACING, MAX_SPACING = 1e-3, 1e6


def _check_spacing(v: np.ndarray, f: np.ndarray, spacing: float) -> None:
    """Refuses a spacing that would sample more than :data:`MAX_SAMPLES` points (area / spacing²)."""
    if len(f) == 0 or f.min() < 0 or f.max() >= len(v):
        return  # the binding names the bad face
    tri = v[f]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    if area / spacing**2 > MAX_SAMPLES:
        raise InvalidInputError(
            f"spacing: {spacing:g} mm over {area:.4g} mm² would take about {area / spacing**2:.3g} samples, more "
            f"than the {MAX_SAMPLES} binpick draws; pass a spacing of at least {np.sqrt(area / MAX_SAMPLES):.3g} mm"
        )


def read_ply(path: str | os.PathLike[str]) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """Reads a PLY point cloud (ASCII or binary): ``(points, normals or None)``, in the file's units."""
    return _core.read_ply(os.fspath(path))


def _free_motions(native: Any) -> tuple[FreeMotion, ...]:
    return tuple(
        FreeMotion(
            kind=m["kind"],
            axis=np.asarray(m["axis"], dtype=np.float64),
            point=None if m["point"] is None else np.asarray(m["point"], dtype=np.float64),
        )
        for m in native.degenerate()
    )


def write_ply(path: str | os.PathLike[str], points: Any, normals: Any = None, *, ascii: bool = False) -> None:
    """Writes points (and normals) as PLY that MeshLab and CloudCompare open (binary by default)."""
    pts = as_points(points, "points", min_points=0)
    nrm = None if normals is None else as_points(normals, "normals", min_points=0)
    if nrm is not None and len(nrm) != len(pts):
        raise InvalidInputError(f"normals: has {len(nrm)} rows but points has {len(pts)}")
    _core.write_ply(os.fspath(path), pts, nrm, bool(ascii))


def scan_noise(points: Any, *, viewpoint: Any = None, direction: Any = (0.0, 0.0, 1.0)) -> Optional[float]:
    """The standard deviation (mm) of a scan's depth noise along its sensor's rays, read from the
    scan alone (no model): height fields fitted along the direction toward the sensor —
    ``viewpoint`` (its optical centre) when given, else ``direction`` (+z) — over small patches,
    the median of their residuals. It is what pose estimation reads when no noise is declared
    (:class:`binpick.SensorModel`). None with too few points (under 80) or fitted patches (20), or no
    surface facing the sensor."""
    pts = as_points(points, "points", min_points=0)
    vp = None if viewpoint is None else as_vector(viewpoint, "viewpoint")
    d = None if viewpoint is not None else as_vector(direction, "direction")
    return _core.scan_noise(pts, vp, d)


def estimate_normals(
    points: Any,
    *,
    k: int = 20,
    viewpoint: Any = None,
    direction: Any = (0.0, 0.0, 1.0),
    num_threads: int = 0,
) -> np.ndarray:
    """Unit normals from the PCA of each point's ``k`` nearest neighbours (3 ≤ k ≤ the number of
    points), flipped to face ``viewpoint`` (a point, e.g. the camera centre) when given, else
    ``direction`` (+z by default). ``num_threads``: 0 = all cores, at most 256 (clamped to the cores)."""
    pts = as_points(points, "points", min_points=3)
    k = count(k, "k", 3, len(pts))
    vp = None if viewpoint is None else as_vector(viewpoint, "viewpoint")
    d = None if viewpoint is not None else as_vector(direction, "direction")
    return _core.estimate_normals(pts, k, vp, d, thread_count(num_threads))


def nearest_distances(points: Any, reference: Any, *, num_threads: int = 1) -> np.ndarray:
    """The distance (mm) from each of ``points`` (N, 3) to the nearest of ``reference`` (M, 3),
    (N,): a KD-tree over the reference (infinity everywhere when it is empty). ``num_threads``:
    0 = all cores (the cell's planners keep to one)."""
    pts = as_points(points, "points", min_points=0)
    ref = as_points(reference, "reference", min_points=0)
    return _core.nearest_distances(pts, ref, thread_count(num_threads))


def voxel_downsample(
    points: Any, voxel_size: float, normals: Any = None
) -> tuple[np.ndarray, Optional[np.ndarray], np.ndarray]:
    """One point per occupied ``voxel_size`` mm cube (the mean of its points):
    ``(points, normals or None, index of each voxel's first input point)``."""
    pts = as_points(points, "points", min_points=0)
    nrm = None if normals is None else as_points(normals, "normals", min_points=0)
    return _core.voxel_downsample(pts, nrm, positive(voxel_size, "voxel_size"))
