"""Typed stub of ``binpick._core``, the native module (crate ``binpick-python``).

Thin wrappers over the Rust core: every function copies its numpy input into owned data and
works with the GIL released; core errors raise the classes of :mod:`binpick.errors`, and a Rust
panic raises ``binpick.errors.InternalError``. Units: mm and radians; transforms are 4×4
``T_to_from`` float64 arrays. The public, validated API is :mod:`binpick`; call these directly
only from inside the package.
"""

from os import PathLike
from typing import Any, Optional, Union

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

# --- geometry -------------------------------------------------------------------------------

def estimate_normals(points_in: _F64, k: int, viewpoint: Optional[_F64], direction: Optional[_F64], num_threads: int) -> _F64:
    """(N, 3) unit normals by k-NN PCA, facing ``viewpoint`` (a point) or else ``direction`` (default +z)."""

def voxel_downsample(points_in: _F64, normals: Optional[_F64], voxel_size: float) -> tuple[_F64, Optional[_F64], _I64]:
    """One point per ``voxel_size`` voxel: (points, normals or None, index of each voxel's first input point)."""

def read_mesh(path: _Path, unit: str) -> tuple[_F64, _I64]:
    """A triangle mesh from STL (binary/ASCII), PLY or OBJ, scaled from ``unit`` (mm|cm|m|in) to mm: (vertices, faces)."""

def sample_mesh(vertices: _F64, faces: _I64, spacing: Optional[float], count: Optional[int], seed: int) -> tuple[_F64, _F64, float, float]:
    """Surface samples every ``spacing`` mm or ``count`` of them (exactly one given): (points, normals, diameter mm, area mm²)."""

def read_ply(path: _Path) -> tuple[_F64, Optional[_F64]]:
    """A PLY point cloud: (points, normals or None)."""

def write_ply(path: _Path, points_in: _F64, normals: Optional[_F64], ascii: bool) -> None:
    """Writes a PLY point cloud (binary little-endian unless ``ascii``)."""

def part_tee(
    outer_diameter: float, run_length: float, branch_length: float, boss_semi_axes: tuple[float, float], boss_height: float, resolution: float
) -> tuple[_F64, _I64, _F64]:
    """The paper's tee: (vertices, faces, branches as rows [dx, dy, dz, length, radius])."""

def part_fitting(kind: str, outer_diameter: float, branch_length: float, resolution: float) -> tuple[_F64, _I64, _F64]:
    """An ``"elbow"`` or a ``"cross"``: (vertices, faces, branches as rows [dx, dy, dz, length, radius])."""

# --- registration and pose ------------------------------------------------------------------

def icp(
    source: _F64,
    target: _F64,
    target_normals: Optional[_F64],
    init: _F64,
    method: str,
    max_correspondence_distance: float,
    max_iterations: int,
    rotation_tolerance: float,
    translation_tolerance: float,
    kernel: str,
    kernel_scale: float,
    trim_fraction: float,
    num_threads: int,
) -> dict[str, Any]:
    """Registers ``source`` onto ``target`` (method ``"point_to_point"``|``"point_to_plane"``, kernel
    ``"none"``|``"huber"``|``"tukey"``|``"cauchy"``): dict with T_target_source, converged,
    iterations, fitness, rmse, num_inliers."""

class PreparedModel:
    """A model prepared for pose estimation: search structures, symmetries and the
    point-pair-feature table, built once."""

    def __new__(
        cls,
        points_in: _F64,
        normals: _F64,
        diameter: float,
        area: float,
        branches: Optional[_F64],
        special: Optional[_F64],
        ppf: Optional[tuple[float, int, int]] = None,
        ppf_cache: Optional[bytes] = None,
        mesh: Optional[tuple[_F64, _I64]] = None,
    ) -> "PreparedModel":
        """From surface samples (N, 3), their normals, diameter and area; ``branches`` rows
        [dx, dy, dz, length, radius] (None or empty: no branch layout), ``special`` the special
        feature's direction or None; ``ppf`` = (sampling_ratio, angle_bins, rotation_bins) builds
        the PPF table, or loads it from ``ppf_cache`` when that is valid for it; ``mesh`` =
        (vertices, faces), the samples' surface, on which sparse samples are refined."""
    def ppf_from_cache(self) -> bool:
        """Whether the PPF table came from ``ppf_cache``."""
    def ppf_pairs(self) -> int:
        """Model pairs in the PPF table (0 without one)."""
    def ppf_bytes(self) -> Optional[bytes]:
        """The PPF table serialised for the cache, or None without one."""
    def symmetries(self) -> dict[str, Any]:
        """Dict with center (3,), continuous_axis (3,) or None, rotations (K, 3, 3), identity first."""
    def canonical(self, t_scene_model: _F64) -> _F64:
        """The canonical form of a (4, 4) pose under the symmetries."""
    def pose_error(self, estimate: _F64, truth: _F64) -> tuple[float, float]:
        """(rotation error rad, translation error mm), minimised over the symmetries."""

def estimate_poses(
    scene: _F64,
    model: PreparedModel,
    bin_box: Optional[_F64],
    up: _F64,
    method: str,
    d_star: Optional[float],
    min_points: Optional[int],
    max_normal_angle: float,
    inlier_distance: Optional[float],
    min_fitness: float,
    closer_radius: Optional[float],
    tau: Optional[float],
    num_threads: int,
    max_instances: int = 1,
    viewpoint: Optional[_F64] = None,
    reference_fraction: Optional[float] = None,
    max_hypotheses: Optional[int] = None,
    min_coverage: float = 0.8,
) -> list[dict[str, Any]]:
    """Up to ``max_instances`` verified instances, most pickable first (coarse ``method``
    ``"auto"``|``"ppf"``|``"ccp"``|``"centroid"``, then ICP): dicts with T_scene_model,
    T_scene_model_coarse, score, rmse, indices, timings, iterations, method, visible_fraction,
    occluded_fraction, pickability."""

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
    ) -> "SimPile":
        """Drops the parts (deterministic for ``seed``) and lets them settle."""
    def poses(self) -> tuple[_I64, _F64]:
        """(ids (N,), T_base_object (N, 4, 4)) of the parts still in the bin."""
    def remove(self, id: int) -> _SettleReport:
        """Takes part ``id`` out and settles the rest."""
    def settle(self) -> _SettleReport:
        """Steps until every part is at rest."""
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

    def __new__(cls) -> "SimScene":
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
    def view(self, camera_args: _CameraArgs, t_base_camera: _F64, lighting_args: _LightingArgs, num_threads: int) -> "SimView":
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

def sim_convex_decomposition(vertices: _F64, faces: _I64, decomposition_resolution: int, max_convex_hulls: int) -> list[tuple[_F64, _I64]]:
    """Convex pieces (vertices, faces) enclosing a mesh, as piles collide with them."""

def sim_max_interpenetration(vertices: _F64, faces: _I64, poses: _F64, samples: _F64) -> float:
    """Deepest interpenetration (mm) of mesh instances at ``poses`` (N, 4, 4), from surface ``samples`` (M, 3)."""

def sim_bin_mesh(center: tuple[float, float], size: tuple[float, float, float], floor_z: float, wall_thickness: float) -> tuple[_F64, _I64]:
    """The bin's render mesh (vertices, faces) in the base frame."""

def sim_default_laser() -> _LaserArgs:
    """The core's default projector (the one definition ``binpick.sim.Laser`` reads):
    (T_camera_laser0, sheet_sigma mm, power DN, fan_angle rad, color [R, G, B], reference_distance mm)."""

def sim_render_checkerboard(
    camera_args: _CameraArgs,
    board: tuple[int, int, float, float],
    t_camera_board: _F64,
    lighting_args: _LightingArgs,
    laser_args: Optional[_LaserArgs],
    angle: float,
    noise_args: _NoiseArgs,
    supersample: int,
    seed: int,
) -> _U8:
    """(H, W, 3) RGB image of a checkerboard (board = squares along x, squares along y, square mm,
    margin mm) at ``t_camera_board``, with the laser line at ``angle`` if ``laser_args``."""
