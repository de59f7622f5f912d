"""Typed stub of ``binpick._core``, the native module (crate ``binpick-python``).

Thin wrappers over the Rust core: every function copies its numpy input into owned data and
works with the GIL released; core errors raise the classes of :mod:`binpick.errors`, and a Rust
panic raises ``binpick.errors.InternalError``. Units: mm and radians; transforms are 4×4
``T_to_from`` float64 arrays. The public, validated API is :mod:`binpick`; call these directly
only from inside the package.
"""

from os import PathLike
from typing import Any, Union

import numpy as np
import numpy.typing as npt

_F64 = npt.NDArray[np.float64]
_F32 = npt.NDArray[np.float32]
_I64 = npt.NDArray[np.int64]
_I32 = npt.NDArray[np.int32]
_U8 = npt.NDArray[np.uint8]
_Path = Union[str, "PathLike[str]"]

# The one camera model, for the renderer and triangulation alike (binpick.camera.camera_args):
# (width px, height px, K (3, 3) with skew K[0, 1], dist [k1, k2, p1, p2, k3] (5,))
_CameraArgs = tuple[int, int, _F64, _F64]
# (ambient DN, lamp DN, lamp direction in the base frame, background DN)
_LightingArgs = tuple[float, float, list[float], float]
# (read_noise, shot_noise, speckle, reflections, blur)
_NoiseArgs = tuple[float, float, float, float, float]
# (T_camera_laser0, sheet_sigma, power, fan_angle, color, reference_distance)
_LaserArgs = tuple[_F64, float, float, float, list[float], float]
# (steps, simulated_time s, settled, max_speed mm/s)
_SettleReport = tuple[int, float, bool, float]

__version__: str

def _panic_for_test() -> None:
    """Panics inside the guarded region (raises InternalError); for the tests."""

def _running_calls() -> int:
    """How many native calls are still running, those interrupted by Ctrl-C included; for the tests."""

# --- geometry -------------------------------------------------------------------------------

def estimate_normals(points_in: _F64, k: int, viewpoint: _F64 | None, direction: _F64 | None, num_threads: int) -> _F64:
    """(N, 3) unit normals by k-NN PCA, facing ``viewpoint`` (a point) or else ``direction`` (default +z)."""

def scan_noise(points_in: _F64, viewpoint: _F64 | None, direction: _F64 | None) -> float | None: ...
def voxel_downsample(points_in: _F64, normals: _F64 | None, voxel_size: float) -> tuple[_F64, _F64 | None, _I64]:
    """One point per ``voxel_size`` voxel: (points, normals or None, index of each voxel's first input point)."""

def nearest_distances(points_in: _F64, reference: _F64, num_threads: int) -> _F64:
    """(N,) distance from each point to its nearest ``reference`` point (infinity for an empty reference)."""

def gripper_occupied(
    points_in: _F64, openings: _F64, shape: tuple[float, ...], margin: float, grow: float
) -> npt.NDArray[np.bool_]:
    """(N,) whether each gripper-frame point lies in the gripper of ``shape`` (tip depth, finger
    length, width, thickness, body radius, body length), its fingers ``openings`` (N,) apart."""

class GripperPoints:
    """Scene points (N, 3, base frame) bucketed once for many ``gripper_hits`` counts."""

    def __new__(cls, points_in: _F64) -> GripperPoints: ...
    def __len__(self) -> int: ...

def gripper_hits(
    points_in: _F64 | GripperPoints,
    poses: _F64,
    openings: _F64,
    closed: _F64 | None,
    shape: tuple[float, ...],
    margin: float,
    grow: float,
    back: float,
    floor: float | None,
    limit: int | None,
    num_threads: int,
) -> _I64:
    """(K,) how many base-frame points the gripper meets at each pose (K, 4, 4), its fingers
    ``openings`` (K,) apart, coming in ``back`` mm along its axis, each point standing for what
    lies straight below it down to ``floor`` (None: itself), its fingers closing from there to
    ``closed`` (K,) (None: not closing); a count stops at ``limit`` (None: every point)."""

def gripper_widest(
    points_in: _F64, grasps: _F64, shape: tuple[float, ...], open_width: float, graze: float, num_threads: int
) -> _F64:
    """(K,) half the part's width between the open fingers at each grasp T_gripper_object (K, 4, 4), −1 for none."""

def read_mesh(path: _Path, unit: str) -> tuple[_F64, _I64]:
    """A triangle mesh from STL (binary/ASCII), PLY or OBJ, scaled from ``unit`` (mm|cm|m|in) to mm:
    (vertices, faces)."""

def sample_mesh(
    vertices: _F64, faces: _I64, spacing: float | None, count: int | None, seed: int
) -> tuple[_F64, _F64, float, float]:
    """Surface samples every ``spacing`` mm or ``count`` of them (exactly one given):
    (points, normals, diameter mm, area mm²)."""

def read_ply(path: _Path) -> tuple[_F64, _F64 | None]:
    """A PLY point cloud: (points, normals or None)."""

def lzf_decompress(data: bytes, size: int) -> tuple[bytes | None, str | None]:
    """LZF-decompresses ``data`` to exactly ``size`` bytes: (bytes, None), or (None, why) for a corrupt stream."""

def write_ply(path: _Path, points_in: _F64, normals: _F64 | None, ascii: bool) -> None:
    """Writes a PLY point cloud (binary little-endian unless ``ascii``)."""

def part_tee(
    outer_diameter: float,
    run_length: float,
    branch_length: float,
    boss_semi_axes: tuple[float, float],
    boss_height: float,
    resolution: float,
) -> tuple[_F64, _I64, _F64]:
    """The paper's tee: (vertices, faces, branches as rows [dx, dy, dz, length, radius])."""

def part_fitting(kind: str, outer_diameter: float, branch_length: float, resolution: float) -> tuple[_F64, _I64, _F64]:
    """An ``"elbow"`` or a ``"cross"``: (vertices, faces, branches as rows [dx, dy, dz, length, radius])."""

# --- registration and pose ------------------------------------------------------------------

class IcpConfig:
    """ICP parameters (the core's ``IcpConfig``), frozen; an argument left out or None takes the
    core's default (``kernel_scale``: a third of ``max_correspondence_distance``)."""

    def __new__(
        cls,
        *,
        method: str | None = None,
        max_correspondence_distance: float | None = None,
        max_iterations: int | None = None,
        rotation_tolerance: float | None = None,
        translation_tolerance: float | None = None,
        kernel: str | None = None,
        kernel_scale: float | None = None,
        trim_fraction: float | None = None,
        num_threads: int | None = None,
    ) -> IcpConfig:
        """``method`` ``"point_to_point"``|``"point_to_plane"``, ``kernel``
        ``"none"``|``"huber"``|``"tukey"``|``"cauchy"``; mm and rad."""
    @property
    def method(self) -> str: ...
    @property
    def max_correspondence_distance(self) -> float: ...
    @property
    def max_iterations(self) -> int: ...
    @property
    def rotation_tolerance(self) -> float: ...
    @property
    def translation_tolerance(self) -> float: ...
    @property
    def kernel(self) -> str: ...
    @property
    def kernel_scale(self) -> float | None: ...
    @property
    def trim_fraction(self) -> float: ...
    @property
    def num_threads(self) -> int: ...

class IcpResult:
    """The outcome of one ICP run."""

    @property
    def T_target_source(self) -> _F64: ...
    @property
    def converged(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    @property
    def fitness(self) -> float: ...
    @property
    def rmse(self) -> float: ...
    @property
    def num_inliers(self) -> int: ...

def icp(source: _F64, target: _F64, target_normals: _F64 | None, init: _F64, config: IcpConfig) -> IcpResult:
    """Registers ``source`` onto ``target`` from ``init`` (point-to-plane needs ``target_normals``)."""

class PpfParams:
    """Parameters of the point-pair-feature table (the core's ``PpfConfig``), frozen; an argument
    left out or None takes the core's default."""

    def __new__(
        cls, *, sampling_ratio: float | None = None, angle_bins: int | None = None, rotation_bins: int | None = None
    ) -> PpfParams:
        """``sampling_ratio`` of the model's diameter; bins over [0, π] and over a turn."""
    @property
    def sampling_ratio(self) -> float: ...
    @property
    def angle_bins(self) -> int: ...
    @property
    def rotation_bins(self) -> int: ...

class PreparedModel:
    """A model prepared for pose estimation: search structures, symmetries and the
    point-pair-feature table, built once."""

    def __new__(
        cls,
        points_in: _F64,
        normals: _F64,
        diameter: float,
        area: float,
        branches: _F64 | None,
        special: _F64 | None,
        ppf: PpfParams | None = None,
        ppf_cache: bytes | None = None,
        mesh: tuple[_F64, _I64] | None = None,
    ) -> PreparedModel:
        """From surface samples (N, 3), their normals, diameter and area; ``branches`` rows
        [dx, dy, dz, length, radius] (None or empty: no branch layout), ``special`` the special
        feature's direction or None; ``ppf`` builds the PPF table, or loads it from ``ppf_cache``
        when that is valid for it; ``mesh`` = (vertices, faces), the samples' surface, on which
        sparse samples are refined."""
    def ppf_from_cache(self) -> bool:
        """Whether the PPF table came from ``ppf_cache``."""
    def ppf_pairs(self) -> int:
        """Model pairs in the PPF table (0 without one)."""
    def ppf_bytes(self) -> bytes | None:
        """The PPF table serialised for the cache, or None without one."""
    def symmetries(self) -> dict[str, Any]:
        """Dict with center (3,), continuous_axis (3,) or None, rotations (K, 3, 3), identity first."""
    def near_symmetries(self) -> list[dict[str, Any]]:
        """Dicts with center (3,), axis (3,), angle (radians or None: continuous), agreement, feature (M, 3)."""
    def degenerate(self) -> list[dict[str, Any]]:
        """Dicts with kind ("slide" or "turn"), axis (3,), point (3,) on a turn's axis or None."""
    def canonical(self, t_scene_model: _F64) -> _F64:
        """The canonical form of a (4, 4) pose under the symmetries."""

class PoseConfig:
    """Parameters of pose estimation (the core's ``PoseConfig``), frozen; an argument left out or
    None takes the core's default. The core checks the values when the estimate runs."""

    def __new__(
        cls,
        *,
        bin: _F64 | None = None,
        up: _F64 | None = None,
        method: str | None = None,
        viewpoint: _F64 | None = None,
        along_rays: bool | None = None,
        light: _F64 | None = None,
        noise_mm: float | None = None,
        noise_per_m2: float | None = None,
        d_star: float | None = None,
        min_points: int | None = None,
        max_normal_angle: float | None = None,
        inlier_distance: float | None = None,
        min_fitness: float | None = None,
        min_coverage: float | None = None,
        ccp_closer_radius: float | None = None,
        ccp_tau: float | None = None,
        reference_fraction: float | None = None,
        max_hypotheses: int | None = None,
        max_instances: int | None = None,
        search_instances: int | None = None,
        num_threads: int | None = None,
    ) -> PoseConfig:
        """``bin`` (2, 3) box corners, ``method`` ``"auto"``|``"ppf"``|``"ccp"``|``"centroid"``; mm and rad."""
    @property
    def bin(self) -> _F64 | None: ...
    @property
    def up(self) -> tuple[float, float, float] | None: ...
    @property
    def along_rays(self) -> bool: ...
    @property
    def noise_mm(self) -> float | None: ...
    @property
    def noise_per_m2(self) -> float: ...
    @property
    def method(self) -> str: ...
    @property
    def viewpoint(self) -> tuple[float, float, float] | None: ...
    @property
    def light(self) -> tuple[float, float, float] | None: ...
    @property
    def d_star(self) -> float | None: ...
    @property
    def min_points(self) -> int | None: ...
    @property
    def max_normal_angle(self) -> float: ...
    @property
    def inlier_distance(self) -> float | None: ...
    @property
    def min_fitness(self) -> float: ...
    @property
    def min_coverage(self) -> float: ...
    @property
    def ccp_closer_radius(self) -> float | None: ...
    @property
    def ccp_tau(self) -> float | None: ...
    @property
    def reference_fraction(self) -> float: ...
    @property
    def max_hypotheses(self) -> int: ...
    @property
    def max_instances(self) -> int: ...
    @property
    def search_instances(self) -> int: ...
    @property
    def num_threads(self) -> int: ...

class PoseEstimate:
    """A verified pose; the fractions are None where not judged, pickability None when not ranked."""

    @property
    def T_scene_model(self) -> _F64: ...
    @property
    def T_scene_model_coarse(self) -> _F64: ...
    @property
    def score(self) -> float: ...
    @property
    def rmse(self) -> float: ...
    @property
    def indices(self) -> _I64: ...
    @property
    def timings(self) -> dict[str, float]: ...
    @property
    def iterations(self) -> int: ...
    @property
    def method(self) -> str: ...
    @property
    def visible_fraction(self) -> float | None: ...
    @property
    def occluded_fraction(self) -> float | None: ...
    @property
    def pickability(self) -> float | None: ...
    @property
    def confidence(self) -> float: ...
    @property
    def confidence_any(self) -> float: ...
    @property
    def ambiguous(self) -> bool: ...
    @property
    def alternatives(self) -> list[dict[str, Any]]: ...
    @property
    def free_axis(self) -> list[float] | None: ...
    @property
    def feature_evidence(self) -> dict[str, Any] | None: ...
    @property
    def fit(self) -> dict[str, float] | None: ...

#: The largest depth noise pose estimation takes, mm.
MAX_NOISE_MM: float

def estimate_poses(
    scene: _F64, model: PreparedModel, config: PoseConfig, exclude: npt.NDArray[np.bool_] | None = None
) -> list[PoseEstimate]:
    """Up to ``config.max_instances`` verified instances, most pickable first; the search leaves
    out the points ``exclude`` flags, which the judge still reads."""

def verify_pose(scene: _F64, model: PreparedModel, config: PoseConfig, t_scene_model: _F64) -> PoseEstimate:
    """The verdict on a given pose, judged as found ones are (unrefined)."""

# --- triangulation --------------------------------------------------------------------------

def pixel_rays(camera_args: _CameraArgs, pixels: _F64) -> _F64:
    """Undistorted rays (x, y, 1) through pixels (N, 2) of (u, v); NaN rows where the distortion cannot be inverted."""

def triangulate_scan(
    camera_args: _CameraArgs,
    t_camera_laser0: _F64,
    t_flange_camera: _F64,
    angles: _F64,
    t_base_flanges: _F64,
    pixels: _F64,
    frame_index: _I64,
    num_threads: int,
) -> tuple[_F64, _U8, _F64, int]:
    """Laser pixels of a scan to base-frame points: (points (N, 3), status (N,): 0 valid,
    1 ray parallel to the sheet, 2 behind the camera, 3 not undistortable; pixels (N, 2);
    kept). The first ``kept`` rows of points and pixels are those that triangulated."""

# --- simulated cell -------------------------------------------------------------------------

class SimPile:
    """A physics pile (rapier3d): ``count`` instances of a mesh dropped into a bin and settled."""

    def __new__(
        cls,
        vertices: _F64,
        faces: _I64,
        count: int,
        bin_center: tuple[float, float],
        bin_size: tuple[float, float, float],
        floor_z: float,
        wall_thickness: float,
        seed: int,
        friction: float,
        restitution: float,
        time_step: float,
        max_settle_time: float,
        skin: float,
        decomposition_resolution: int,
        max_convex_hulls: int,
    ) -> SimPile:
        """Drops the parts (deterministic for ``seed``) and lets them settle."""
    @staticmethod
    def placed(
        vertices: _F64,
        faces: _I64,
        poses: _F64,
        bin_center: tuple[float, float],
        bin_size: tuple[float, float, float],
        floor_z: float,
        wall_thickness: float,
        friction: float,
        restitution: float,
        time_step: float,
        max_settle_time: float,
        skin: float,
        decomposition_resolution: int,
        max_convex_hulls: int,
    ) -> SimPile:
        """Places the parts at ``poses`` (T_base_object (N, 4, 4)) and lets them settle."""
    def set_poses(self, poses: _F64) -> _SettleReport:
        """Moves the remaining parts (in id order) to ``poses``, at rest, and settles."""
    def poses(self) -> tuple[_I64, _F64]:
        """(ids (N,), T_base_object (N, 4, 4)) of the parts still in the bin."""
    def remove(self, id: int) -> _SettleReport:
        """Takes part ``id`` out and settles the rest."""
    def settle(self) -> _SettleReport:
        """Steps until every part is at rest."""
    def push(
        self, half_extents: _F64, box_poses: _F64, path: _F64, speed: float
    ) -> tuple[int, _SettleReport, list[int]]:
        """Moves a kinematic tool of boxes along ``path`` (T_base_tool) at ``speed`` mm/s, then settles:
        (push_steps, settle report, ids of the parts that moved)."""
    def last_settle(self) -> _SettleReport:
        """The report of the last settling."""
    def remaining(self) -> int:
        """Parts left in the bin."""
    def max_contact_penetration(self) -> float:
        """Deepest overlap of the convex collision pieces, mm."""
    def collision_hulls(self) -> list[tuple[_F64, _I64]]:
        """The convex pieces (vertices, faces) a part collides with, model frame."""

class SimScene:
    """Meshes and their placed instances in the base frame, ray-cast by :meth:`view`."""

    def __new__(cls) -> SimScene:
        """An empty scene."""
    def add_mesh(self, vertices: _F64, faces: _I64, albedo: list[float], specular: float, shininess: float) -> int:
        """Adds a mesh (mm, its own frame) with its material; returns the mesh index."""
    def add_instance(self, mesh: int, t_base_object: _F64, id: int) -> None:
        """Places mesh ``mesh`` at ``t_base_object`` as instance ``id`` (−1 is reserved)."""
    def set_pose(self, id: int, t_base_object: _F64) -> None:
        """Moves instance ``id``."""
    def remove_instance(self, id: int) -> None:
        """Removes instance ``id``."""
    def instance_ids(self) -> list[int]:
        """Ids of the placed instances, in insertion order."""
    def nearest_surface(self, points_base: _F64) -> tuple[_F64, _I32]:
        """Exact distance (mm) from each base-frame point (N, 3) to the nearest surface and that
        surface's instance id; (inf, −1) in an empty scene."""
    def view(
        self, camera_args: _CameraArgs, t_base_camera: _F64, lighting_args: _LightingArgs, num_threads: int
    ) -> SimView:
        """Casts one ray per pixel from ``t_base_camera``."""

class SimView:
    """The ray-cast geometry of one robot pose; frames are lit from it per laser angle."""

    def depth(self) -> _F32:
        """(H, W) z of the seen surface in the camera frame, mm; NaN where none."""
    def ids(self) -> _I32:
        """(H, W) instance ids, −1 where nothing is hit."""
    def points(self) -> _F32:
        """(H, W, 3) surface points in the camera frame, mm; NaN where none."""
    def normals(self) -> _F32:
        """(H, W, 3) camera-facing unit normals in the camera frame (0 where none)."""
    def ambient_frame(self, noise_args: _NoiseArgs, seed: int) -> _U8:
        """(H, W, 3) RGB frame without the laser."""
    def frames(
        self,
        t_camera_laser0: _F64,
        sheet_sigma: float,
        power: float,
        fan_angle: float,
        color: list[float],
        reference_distance: float,
        angles: list[float],
        noise_args: _NoiseArgs,
        seed: int,
        num_threads: int,
    ) -> npt.NDArray[np.uint8]:
        """(K, H, W, 3) RGB frames, one per motor angle (rad); frame k's noise is seeded by ``seed + k``."""

def sim_convex_decomposition(
    vertices: _F64, faces: _I64, decomposition_resolution: int, max_convex_hulls: int
) -> list[tuple[_F64, _I64]]:
    """Convex pieces (vertices, faces) enclosing a mesh, as piles collide with them."""

def sim_max_interpenetration(vertices: _F64, faces: _I64, poses: _F64, samples: _F64) -> float:
    """Deepest interpenetration (mm) of mesh instances at ``poses`` (N, 4, 4), from surface ``samples`` (M, 3)."""

def sim_bin_mesh(
    center: tuple[float, float], size: tuple[float, float, float], floor_z: float, wall_thickness: float
) -> tuple[_F64, _I64]:
    """The bin's render mesh (vertices, faces) in the base frame."""

def sim_default_laser() -> _LaserArgs:
    """The core's default projector (the one definition ``binpick.sim.Laser`` reads):
    (T_camera_laser0, sheet_sigma mm, power DN, fan_angle rad, color [R, G, B], reference_distance mm)."""

def sim_render_checkerboard(
    camera_args: _CameraArgs,
    board: tuple[int, int, float, float],
    t_camera_board: _F64,
    lighting_args: _LightingArgs,
    laser_args: _LaserArgs | None,
    angle: float,
    noise_args: _NoiseArgs,
    supersample: int,
    seed: int,
    window: tuple[int, int, int, int] | None = None,
) -> _U8:
    """(H, W, 3) RGB image of a checkerboard (board = squares along x, squares along y, square mm,
    margin mm) at ``t_camera_board``, with the laser line at ``angle`` if ``laser_args``; with
    ``window`` (u0, v0, u1, v1), only those pixels drawn (the rest the background)."""
