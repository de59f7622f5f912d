"""Depth cameras as integrators bring them — an industrial structured-light camera, a Kinect-like
structured-light/stereo depth camera, a time-of-flight camera — each the one pinhole model
(:class:`binpick.camera.CameraIntrinsics`) at a fixed pose with a noise model from published
measurements, and :func:`render_depth`: one frame of a :class:`~binpick.sim.World` as the real
camera delivers it (an organised cloud with NaN holes), the renderer's ground truth beside it.

A frame forms in this order (each term off when its parameters are zero, as in :meth:`DepthNoise.ideal`):

1. Holes: pixels that see nothing, pixels whose ray meets the surface beyond ``max_incidence``
   (the pattern or the returned light is lost at grazing angles), and pixels the projector does
   not light (a pinhole ``baseline`` mm along the camera's +x: a second ray cast from there).
2. Lateral noise: each pixel reads the surface at a point displaced across its ray by
   σ_L(θ) pixels (Nguyen et al. 2012), so depth edges fray; its point stays on its own ray.
3. Flying pixels: along depth discontinuities a pixel mixes the depths of the foreground and the
   background its footprint straddles.
4. Multipath: a positive range bias where nearby surfaces close the point's hemisphere (concave corners).
5. Axial noise along the ray, σ_z(z, θ) growing with depth and incidence.
6. Disparity quantisation (triangulating sensors): depth snaps to the steps Δz = z²·q / (f·b).

Lengths in mm, angles in radians (``_deg`` names are degrees), transforms 4×4 ``T_to_from``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._validate import as_transform, as_vector, count, frozen_copy, instance_of, non_negative, number, positive
from ..camera import CameraIntrinsics
from ..errors import InvalidInputError
from ..transforms import looking_at, translation
from .camera import _pixel_rays
from .render import World

__all__ = ["DepthNoise", "DepthCamera", "DepthFrame", "render_depth"]

#: Depth (mm) the noise polynomials take their metres from.
_MM_PER_M = 1000.0

#: How far beyond the projector's depth (mm) a point still counts as lit: the renderer's float32
#: depths, not geometry (a shadow's occluder stands millimetres to metres nearer).
_LIT_TOLERANCE = 0.5


@dataclass(frozen=True)
class DepthNoise:
    """What a depth sensor does to the geometry it sees; every field ≥ 0, zero turns its term off.

    Axial noise, along the pixel's ray, as a standard deviation of depth z (mm) at incidence θ
    (the angle between the ray and the surface normal) with z in metres:

        σ_z(z, θ) = axial_sigma_0 + axial_sigma_1·z + axial_sigma_2·z² + axial_sigma_grazing·z^k·θ² / (π/2 − θ)²

    with k = ``axial_grazing_exponent``. Nguyen, Izadi & Lovell (2012, Kinect v1) fitted
    σ_z = 1.2 + 1.9 (z − 0.4)² + 0.1 z^−½ θ²/(π/2 − θ)² mm; Fankhauser et al. (2015, Kinect v2
    time of flight) σ_z = 1.5 − 0.5 z + 0.3 z² + 0.1 z^{3/2} θ²/(π/2 − θ)² mm; a triangulating
    sensor's random error grows as z² σ_d / (f b) (Khoshelham & Elberink 2012).

    Lateral noise, across the ray, in pixels (Nguyen et al. 2012, 0.8 and 0.035 for Kinect v1):

        σ_L(θ) = lateral_sigma_px + lateral_sigma_grazing_px·θ / (π/2 − θ)

    i.e. σ_L(θ)·z/f mm at depth z, growing with depth.
    """

    #: Constant term of σ_z, mm.
    axial_sigma_0: float = 0.0
    #: Linear term of σ_z, mm per metre of depth (may be negative while σ_z stays ≥ 0 at every depth).
    axial_sigma_1: float = 0.0
    #: Quadratic term of σ_z, mm per square metre of depth.
    axial_sigma_2: float = 0.0
    #: Grazing term of σ_z at 1 m depth, mm; multiplied by θ²/(π/2 − θ)² and by z^``axial_grazing_exponent``.
    axial_sigma_grazing: float = 0.0
    #: Exponent of the depth (metres) in the grazing term: −0.5 for Kinect v1, 1.5 for Kinect v2.
    axial_grazing_exponent: float = 0.0
    #: Lateral σ at normal incidence, pixels.
    lateral_sigma_px: float = 0.0
    #: Growth of the lateral σ with incidence, pixels per unit of θ/(π/2 − θ).
    lateral_sigma_grazing_px: float = 0.0
    #: Projector (or second camera) offset along the camera's +x, mm: it casts shadows (points it
    #: cannot see are holes) and sets the disparity quantisation. 0: none (time of flight).
    baseline: float = 0.0
    #: Disparity resolution q, pixels (1/8 for Kinect v1): depth snaps to f·b / (k·q). 0: none.
    disparity_step_px: float = 0.0
    #: Largest incidence θ (rad) at which the sensor still measures; beyond it a hole. π/2: no limit.
    max_incidence: float = math.pi / 2
    #: Depth step between neighbouring pixels that makes a discontinuity (mm): where flying pixels
    #: form, and across which lateral noise reads the other surface. Keep it above the step on the
    #: steepest surface measured, z/f·tan(max_incidence).
    edge_jump: float = 10.0
    #: Share of the pixels along a discontinuity that mix the two depths (0..1).
    flying_pixel_rate: float = 0.0
    #: Range bias (mm) of a point whose whole hemisphere is closed by nearby surfaces, scaled by the
    #: closed share (cosine-weighted): 0.5 at the foot of a wall, 0 on a plane or a convex surface.
    #: Light that reaches the point by a second bounce travels further (time of flight). 0: none.
    multipath_bias: float = 0.0
    #: Radius within which surfaces send a second bounce to a point, mm.
    multipath_radius: float = 30.0

    def __post_init__(self) -> None:
        for name in ("axial_sigma_0", "axial_sigma_2", "axial_sigma_grazing", "baseline", "multipath_bias"):
            non_negative(getattr(self, name), name, "mm")
        for name in ("lateral_sigma_px", "lateral_sigma_grazing_px", "disparity_step_px"):
            non_negative(getattr(self, name), name, "px")
        a0, a1, a2 = self.axial_sigma_0, number(self.axial_sigma_1, "axial_sigma_1", unit="mm/m"), self.axial_sigma_2
        number(self.axial_grazing_exponent, "axial_grazing_exponent", -4.0, 4.0)
        if a1 < 0 and (a2 <= 0 or a0 - a1 * a1 / (4 * a2) < 0):
            raise InvalidInputError(
                f"axial_sigma_1: {a1:g} mm/m makes σ_z = {a0:g} + {a1:g}·z + {a2:g}·z² negative at some depth; "
                "raise axial_sigma_0 or axial_sigma_2, or make axial_sigma_1 less negative"
            )
        number(self.max_incidence, "max_incidence", 1e-3, math.pi / 2, "rad")
        if self.max_incidence == math.pi / 2 and (self.axial_sigma_grazing > 0 or self.lateral_sigma_grazing_px > 0):
            raise InvalidInputError(
                "max_incidence: π/2 leaves the grazing terms unbounded (θ/(π/2 − θ) grows without limit); "
                "pass the incidence beyond which the sensor loses the surface, e.g. math.radians(80)"
            )
        positive(self.edge_jump, "edge_jump")
        number(self.flying_pixel_rate, "flying_pixel_rate", 0.0, 1.0)
        positive(self.multipath_radius, "multipath_radius")
        if self.disparity_step_px > 0 and self.baseline == 0:
            raise InvalidInputError(
                f"disparity_step_px: {self.disparity_step_px:g} px needs a baseline; a sensor without one "
                "(time of flight) has no disparity: pass disparity_step_px=0 or a baseline > 0 mm"
            )

    @classmethod
    def ideal(cls) -> DepthNoise:
        """No noise, no holes but where nothing is hit: the renderer's exact depth."""
        return cls()

    @classmethod
    def structured_light(cls) -> DepthNoise:
        """An industrial structured-light camera (phase shift or coded light, 150 mm baseline):
        σ_z = 0.05 + 0.15 z² mm (the z² law of triangulation, 0.10 mm at 0.6 m, 0.27 mm at 1.2 m)
        growing at grazing incidence by 0.01 z² θ²/(π/2 − θ)² mm (0.12 mm at 1 m and 70°), lateral
        σ 0.3 px, projector shadows, holes beyond 70° incidence, disparity steps of 1/32 px
        (0.13 mm at 1 m with f = 1600 px)."""
        return cls(
            axial_sigma_0=0.05,
            axial_sigma_2=0.15,
            axial_sigma_grazing=0.01,
            axial_grazing_exponent=2.0,
            lateral_sigma_px=0.3,
            baseline=150.0,
            disparity_step_px=1.0 / 32.0,
            max_incidence=math.radians(70.0),
        )

    @classmethod
    def kinect(cls) -> DepthNoise:
        """A Kinect-v1-like structured-light depth camera: Nguyen et al. (2012)'s axial and lateral
        noise (1.3 mm at 0.6 m, 1.9 mm at 1 m, 6.1 mm at 2 m), disparity steps of 1/8 px over a
        75 mm baseline (Khoshelham & Elberink 2012: 3.2 mm at 1 m with f = 525 px), projector
        shadows, holes beyond 75° incidence, flying pixels on a third of the depth edges."""
        return cls(
            axial_sigma_0=1.2 + 1.9 * 0.4**2,
            axial_sigma_1=-2.0 * 1.9 * 0.4,
            axial_sigma_2=1.9,
            axial_sigma_grazing=0.1,
            axial_grazing_exponent=-0.5,
            lateral_sigma_px=0.8,
            lateral_sigma_grazing_px=0.035,
            baseline=75.0,
            disparity_step_px=1.0 / 8.0,
            max_incidence=math.radians(75.0),
            edge_jump=10.0,
            flying_pixel_rate=0.3,
        )

    @classmethod
    def tof(cls) -> DepthNoise:
        """A time-of-flight camera (Kinect v2 / Azure Kinect class): Fankhauser et al. (2015)'s axial
        noise (1.3 mm at 1 m, 2.7 mm at 3 m), lateral σ 0.5 px, holes beyond 80° incidence,
        flying pixels on most depth edges, a multipath bias of 30 mm times the share of the
        hemisphere that surfaces within 50 mm close (15 mm at the foot of a wall, fading over
        50 mm); no projector shadow, no disparity."""
        return cls(
            axial_sigma_0=1.5,
            axial_sigma_1=-0.5,
            axial_sigma_2=0.3,
            axial_sigma_grazing=0.1,
            axial_grazing_exponent=1.5,
            lateral_sigma_px=0.5,
            max_incidence=math.radians(80.0),
            edge_jump=20.0,
            flying_pixel_rate=0.8,
            multipath_bias=30.0,
            multipath_radius=50.0,
        )

    def axial_sigma(self, depth: Any, incidence: Any = 0.0) -> Any:
        """σ_z (mm) at ``depth`` (mm) and ``incidence`` (rad, at most ``max_incidence``), elementwise."""
        z = np.asarray(depth, dtype=np.float64) / _MM_PER_M
        sigma = self.axial_sigma_0 + self.axial_sigma_1 * z + self.axial_sigma_2 * z * z
        if self.axial_sigma_grazing > 0:
            t = np.minimum(np.asarray(incidence, dtype=np.float64), self.max_incidence)
            sigma = sigma + self.axial_sigma_grazing * z**self.axial_grazing_exponent * (t / (math.pi / 2 - t)) ** 2
        return sigma

    def lateral_sigma(self, incidence: Any = 0.0) -> Any:
        """σ_L (pixels) at ``incidence`` (rad, at most ``max_incidence``), elementwise."""
        t = np.minimum(np.asarray(incidence, dtype=np.float64), self.max_incidence)
        if self.lateral_sigma_grazing_px == 0:
            return self.lateral_sigma_px + 0.0 * t
        return self.lateral_sigma_px + self.lateral_sigma_grazing_px * t / (math.pi / 2 - t)

    def depth_step(self, depth: Any, focal_px: float) -> Any:
        """The quantisation step Δz = z²·q / (f·b) (mm) at ``depth`` (mm) for a camera of focal
        length ``focal_px``; 0 without quantisation."""
        z = np.asarray(depth, dtype=np.float64)
        if self.disparity_step_px == 0:
            return 0.0 * z
        return z * z * self.disparity_step_px / (positive(focal_px, "focal_px", "px") * self.baseline)


def _kinect_intrinsics() -> CameraIntrinsics:
    return CameraIntrinsics.pinhole(640, 480, 525.0, 525.0, 319.5, 239.5)


@dataclass(frozen=True, eq=False)
class DepthCamera:
    """A depth camera at a fixed pose: its ``intrinsics`` (the one camera model; the depth image's
    pixels), its ``noise`` model and ``T_base_camera`` (camera frame: +z along the optical axis,
    +x along the image's rows, the projector along +x). Place it with :meth:`looking_at`."""

    intrinsics: CameraIntrinsics = field(default_factory=_kinect_intrinsics)
    noise: DepthNoise = field(default_factory=DepthNoise.kinect)
    T_base_camera: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        instance_of(self.intrinsics, CameraIntrinsics, "intrinsics", "CameraIntrinsics.pinhole(640, 480, ...)")
        instance_of(self.noise, DepthNoise, "noise", "binpick.sim.DepthNoise.kinect()")
        object.__setattr__(self, "T_base_camera", frozen_copy(as_transform(self.T_base_camera, "T_base_camera")))

    @classmethod
    def kinect(cls, T_base_camera: Any = None) -> DepthCamera:
        """A Kinect-v1-like camera: 640 × 480, f = 525 px (57° × 49°), :meth:`DepthNoise.kinect`."""
        return cls(_kinect_intrinsics(), DepthNoise.kinect(), _pose(T_base_camera))

    @classmethod
    def structured_light(cls, T_base_camera: Any = None) -> DepthCamera:
        """An industrial structured-light camera: 1280 × 1024, f = 1600 px (44° × 35°: a 300 × 200 mm
        bin fills most of the view at 0.6 m), :meth:`DepthNoise.structured_light`."""
        intrinsics = CameraIntrinsics.pinhole(1280, 1024, 1600.0, 1600.0, 639.5, 511.5)
        return cls(intrinsics, DepthNoise.structured_light(), _pose(T_base_camera))

    @classmethod
    def tof(cls, T_base_camera: Any = None) -> DepthCamera:
        """A time-of-flight camera (Azure Kinect narrow mode class): 640 × 576, f = 504 px
        (65° × 59°), :meth:`DepthNoise.tof`."""
        intrinsics = CameraIntrinsics.pinhole(640, 576, 504.0, 504.0, 319.5, 287.5)
        return cls(intrinsics, DepthNoise.tof(), _pose(T_base_camera))

    def looking_at(
        self, target: Any, *, distance: float, tilt_deg: float = 0.0, azimuth_deg: float = 0.0, roll_deg: float = 0.0
    ) -> DepthCamera:
        """This camera placed ``distance`` mm from ``target`` (base frame, mm), its optical axis
        through it, tilted ``tilt_deg`` from looking straight down (at most 85°) towards
        ``azimuth_deg`` (the side it stands on: 0 = +x of the target, 90 = +y) and rolled
        ``roll_deg`` about its axis (:func:`binpick.transforms.looking_at`)."""
        T = looking_at(
            as_vector(target, "target", 3),
            distance=positive(distance, "distance"),
            tilt=math.radians(number(tilt_deg, "tilt_deg", 0.0, 85.0, "deg")),
            azimuth=math.radians(number(azimuth_deg, "azimuth_deg", -360.0, 360.0, "deg")),
            roll=math.radians(number(roll_deg, "roll_deg", -360.0, 360.0, "deg")),
        )
        return replace(self, T_base_camera=T)

    @property
    def viewpoint(self) -> np.ndarray:
        """The camera's optical centre in the base frame, mm (the sensor origin pose estimation takes)."""
        return self.T_base_camera[:3, 3].copy()


def _pose(T_base_camera: Any) -> np.ndarray:
    return np.eye(4) if T_base_camera is None else T_base_camera


@dataclass(frozen=True, eq=False)
class DepthFrame:
    """One depth frame and its ground truth. Arrays are read-only.

    ``points`` (H, W, 3) float64 the organised cloud in the camera frame, mm, NaN at holes (as the
    camera delivers it); ``points_base`` the same in the base frame; ``ids`` (H, W) int32 the
    renderer's instance id of the surface each pixel's ray meets (parts ≥ 0, bin −2, table −3,
    nothing −1), holes included; ``true_depth`` (H, W) float64 that surface's exact depth, mm (NaN
    where none); ``T_base_camera`` the camera's pose."""

    points: np.ndarray
    points_base: np.ndarray
    ids: np.ndarray
    true_depth: np.ndarray
    T_base_camera: np.ndarray

    @property
    def depth(self) -> np.ndarray:
        """(H, W) measured depth (z in the camera frame), mm; NaN at holes."""
        return self.points[..., 2]

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: pixels with a measurement."""
        return np.isfinite(self.points[..., 2])

    @property
    def cloud(self) -> np.ndarray:
        """(N, 3) the measured points in the base frame, holes left out (row-major pixel order)."""
        return self.points_base[self.valid]

    @property
    def viewpoint(self) -> np.ndarray:
        """The sensor origin in the base frame, mm: the ``viewpoint`` of :func:`binpick.estimate_pose`."""
        return self.T_base_camera[:3, 3].copy()

    def __repr__(self) -> str:
        h, w = self.ids.shape
        return f"DepthFrame({w}×{h}, {int(self.valid.sum())} points, viewpoint={np.round(self.viewpoint, 1).tolist()})"


def render_depth(world: World, camera: DepthCamera, *, seed: int = 0, num_threads: int = 0) -> DepthFrame:
    """One frame of ``world`` through ``camera``: the rays cast by the renderer (and from the
    projector, for shadows), then the camera's noise model applied with a numpy generator seeded
    by ``seed`` (the same seed, the same frame). ``num_threads`` for the ray casts (0 = all cores)."""
    instance_of(world, World, "world", "binpick.sim.World.of_pile(pile)")
    instance_of(camera, DepthCamera, "camera", "binpick.sim.DepthCamera.kinect()")
    rng = np.random.default_rng(count(seed, "seed"))
    noise, K = camera.noise, camera.intrinsics
    seen = world.surfaces(K, camera.T_base_camera, num_threads=num_threads)
    P = seen.points.astype(np.float64)
    normals = seen.normals.astype(np.float64)
    true = P[..., 2].copy()
    hit = np.isfinite(true)
    with np.errstate(invalid="ignore"):
        along = np.abs((normals * P).sum(axis=2)) / np.linalg.norm(P, axis=2)
    incidence = np.where(hit, np.arccos(np.clip(along, 0.0, 1.0)), 0.0)

    depth = true.copy()
    if noise.lateral_sigma_px > 0 or noise.lateral_sigma_grazing_px > 0:
        depth = _lateral(depth, noise.lateral_sigma(incidence), noise.edge_jump, rng)
    if noise.flying_pixel_rate > 0:
        depth = _flying(true, depth, noise.edge_jump, noise.flying_pixel_rate, rng)
    rays = np.where(hit[..., None], P / np.where(hit, true, 1.0)[..., None], _pixel_rays(K).reshape(P.shape))
    if noise.multipath_bias > 0:
        F = _enclosure(P, normals, K, noise.multipath_radius)
        depth = depth * (1.0 + noise.multipath_bias * F / (depth * np.linalg.norm(rays, axis=2)))
    depth = depth + noise.axial_sigma(depth, incidence) * rng.standard_normal(depth.shape)  # σ = 0 adds ±0.0
    if noise.disparity_step_px > 0:
        fb = K.fx * noise.baseline
        with np.errstate(divide="ignore", invalid="ignore"):
            steps = np.maximum(np.round(fb / depth / noise.disparity_step_px), 1.0)
        depth = fb / (steps * noise.disparity_step_px)

    holes = ~np.isfinite(depth) | (depth <= 0) | (incidence > noise.max_incidence)
    if noise.baseline > 0 and hit.any():
        holes |= hit & ~_lit(world, camera, P, num_threads)
    depth[holes] = np.nan
    # Scaling the rendered point keeps it on its ray, and exact where the depth is untouched.
    points = rays * depth[..., None]
    points[hit] = P[hit] * (depth[hit] / true[hit])[:, None]
    R, t = camera.T_base_camera[:3, :3], camera.T_base_camera[:3, 3]
    return DepthFrame(
        points=_read_only(points),
        points_base=_read_only(points @ R.T + t),
        ids=_read_only(seen.ids),
        true_depth=_read_only(true),
        T_base_camera=camera.T_base_camera,
    )


def _read_only(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def _lateral(depth: np.ndarray, sigma_px: np.ndarray, edge_jump: float, rng: np.random.Generator) -> np.ndarray:
    """Each pixel's depth read at its pixel displaced by N(0, σ_L²) along u and v: interpolated
    (bilinear in 1/z, exact on a plane) where the four pixels around that point lie on one surface,
    else that of the nearest (an edge frays); the result belongs to the pixel's own ray."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    qu = np.clip(u + sigma_px * rng.standard_normal((h, w)), 0, w - 1)
    qv = np.clip(v + sigma_px * rng.standard_normal((h, w)), 0, h - 1)
    u0 = np.minimum(np.floor(qu).astype(np.intp), w - 2)
    v0 = np.minimum(np.floor(qv).astype(np.intp), h - 2)
    fu, fv = qu - u0, qv - v0
    corners = np.stack([depth[v0, u0], depth[v0, u0 + 1], depth[v0 + 1, u0], depth[v0 + 1, u0 + 1]])
    with np.errstate(invalid="ignore"):
        smooth = np.isfinite(corners).all(axis=0) & (corners.max(axis=0) - corners.min(axis=0) <= edge_jump)
        inverse = (
            (1 - fu) * (1 - fv) / corners[0]
            + fu * (1 - fv) / corners[1]
            + (1 - fu) * fv / corners[2]
            + fu * fv / corners[3]
        )
        nearest = depth[np.rint(qv).astype(np.intp), np.rint(qu).astype(np.intp)]
        return np.where(smooth, 1.0 / inverse, nearest)


def _flying(true: np.ndarray, depth: np.ndarray, edge_jump: float, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Pixels beside a depth discontinuity (a 4-neighbour's true depth differs by more than
    ``edge_jump``) take, at ``rate``, a depth mixed uniformly between the nearest and the farthest
    surface of their neighbourhood: the pixel's footprint straddles both."""
    pad = np.pad(true, 1, constant_values=np.nan)
    around = np.stack([true, pad[1:-1, 2:], pad[1:-1, :-2], pad[2:, 1:-1], pad[:-2, 1:-1]])
    near, far = np.fmin.reduce(around, axis=0), np.fmax.reduce(around, axis=0)
    with np.errstate(invalid="ignore"):
        edge = np.isfinite(true) & (far - near > edge_jump)
    mixed = edge & (rng.random(true.shape) < rate)
    return np.where(mixed, near + rng.random(true.shape) * (far - near), depth)


#: Directions and distances at which :func:`_enclosure` probes a point's hemisphere: cosine-
#: weighted directions on a golden-angle spiral (local x, y along the surface, z along its normal),
#: at distances between a quarter of the radius and all of it (shares of the radius).
_PROBES = 16
_GOLDEN = math.pi * (3.0 - math.sqrt(5.0))
_PROBE_DIRECTIONS = [
    (math.sqrt(s) * math.cos(i * _GOLDEN), math.sqrt(s) * math.sin(i * _GOLDEN), math.sqrt(1.0 - s))
    for i, s in ((i, (i + 0.5) / _PROBES) for i in range(_PROBES))
]
_PROBE_DISTANCES = [0.25 + 0.75 * ((i * 0.618034) % 1.0) for i in range(_PROBES)]


def _enclosure(P: np.ndarray, normals: np.ndarray, K: CameraIntrinsics, radius: float) -> np.ndarray:
    """The share of each seen point's hemisphere (cosine-weighted, within ``radius`` mm) that the
    seen surfaces close: 0 on a plane and on a convex surface, 0.5 at the foot of a wall, near 1
    deep in a narrow slot — the form factor through which a second bounce reaches the point.
    Probed as screen-space ambient occlusion: a point of the hemisphere is closed when the depth
    image holds a surface in front of it (by a tenth of its distance, against the image's
    discretisation) that lies less than ``radius`` in front (farther, it only hides it)."""
    h, w = P.shape[:2]
    p = np.moveaxis(P, 2, 0).astype(np.float32)  # planar layers: sums over a last axis of 3 are slower
    n = np.moveaxis(normals, 2, 0).astype(np.float32)
    depth = np.where(np.isfinite(p[2]), p[2], np.inf)
    closed = np.zeros((h, w), dtype=np.float32)
    with np.errstate(invalid="ignore", divide="ignore"):  # pixels that see nothing have no normal
        # A tangent t1 = a × n with a = the camera's x (its y where n is near x), and t2 = n × t1.
        a = (np.abs(n[0]) < 0.9).astype(np.float32)
        t1 = np.stack([(1 - a) * n[2], -a * n[2], a * n[1] - (1 - a) * n[0]])
        t1 /= np.sqrt((t1 * t1).sum(axis=0))
        t2 = np.stack([n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0]])
        for (lx, ly, lz), share in zip(_PROBE_DIRECTIONS, _PROBE_DISTANCES):
            rho = np.float32(share * radius)
            sx, sy, sz = (p[k] + rho * (lx * t1[k] + ly * t2[k] + lz * n[k]) for k in range(3))
            u = np.rint(K.fx * sx / sz + K.skew * sy / sz + K.cx)
            v = np.rint(K.fy * sy / sz + K.cy)
            inside = (sz > 0) & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
            seen = depth[np.where(inside, v, 0).astype(np.intp), np.where(inside, u, 0).astype(np.intp)]
            gap = sz - seen
            closed += inside & (gap > 0.1 * rho) & (gap < radius)
    return np.where(np.isfinite(p[2]), closed / _PROBES, 0.0).astype(np.float64)


def _lit(world: World, camera: DepthCamera, P: np.ndarray, num_threads: int) -> np.ndarray:
    """Which seen points (camera frame, (H, W, 3)) the projector lights: its pinhole stands
    ``baseline`` mm along the camera's +x, parallel to it, its image widened towards −x so that it
    covers every pixel the camera sees; a point is lit where the projector's first surface along the
    ray to it (the farthest of the four projector pixels around that ray) is not nearer."""
    K, b = camera.intrinsics, camera.noise.baseline
    h, w = K.height, K.width
    X = P - np.array([b, 0.0, 0.0])
    # A point at depth z lies f·b/z pixels further towards −x in the projector's image.
    margin = min(math.ceil(K.fx * b / float(np.nanmin(P[..., 2]))) + 2, 4 * w)
    proj = CameraIntrinsics.pinhole(w + margin, h, K.fx, K.fy, K.cx + margin, K.cy, skew=K.skew)
    reach = world.surfaces(proj, camera.T_base_camera @ translation(b, 0.0, 0.0), num_threads=num_threads).depth
    reach = np.where(np.isfinite(reach), reach, np.inf).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        up = proj.fx * X[..., 0] / X[..., 2] + proj.skew * X[..., 1] / X[..., 2] + proj.cx
        vp = proj.fy * X[..., 1] / X[..., 2] + proj.cy
        # A pixel's footprint reaches half a pixel beyond its centre (rows 0 and h − 1 included).
        inside = (X[..., 2] > 0) & (up > -0.5) & (up < w + margin - 0.5) & (vp > -0.5) & (vp < h - 0.5)
    u0 = np.clip(np.floor(np.where(inside, up, 0)).astype(np.intp), 0, w + margin - 2)
    v0 = np.clip(np.floor(np.where(inside, vp, 0)).astype(np.intp), 0, h - 2)
    farthest = np.maximum.reduce([reach[v0, u0], reach[v0, u0 + 1], reach[v0 + 1, u0], reach[v0 + 1, u0 + 1]])
    return inside & (X[..., 2] <= farthest + _LIT_TOLERANCE)
