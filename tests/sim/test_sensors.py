"""Depth sensors: each noise term measured on rendered geometry against its model (axial σ on a
plate at two depths, quantisation steps, grazing holes, projector shadows against a ray-box
oracle, flying pixels only along depth edges, multipath only in concave corners), the ideal
sensor equal to the renderer, seeded frames reproducible, and bad arguments named."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given

import binpick
from _properties import PROPERTY, finite, outcome, reals, variations, vectors
from binpick import errors, sim
from binpick.camera import CameraIntrinsics
from binpick.sim import DepthCamera, DepthNoise, render_depth
from binpick.transforms import look_down, rotation_about, translation

#: Small cameras keep each render to milliseconds: a wide one, and a long lens for steep plates.
WIDE = CameraIntrinsics.pinhole(160, 120, 200.0, 200.0, 79.5, 59.5)
NARROW = CameraIntrinsics.pinhole(160, 120, 600.0, 600.0, 79.5, 59.5)
FLOOR_ID, BOX_ID = 0, 1
BOX_HALF, BOX_HEIGHT = 50.0, 80.0


def _plate(world: sim.World, T_base_plate: np.ndarray, half: float, id: int) -> None:
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], dtype=float)
    world.add_instance(world.add_mesh(v, np.array([[0, 1, 2], [0, 2, 3]])), T_base_plate, id)


def _plate_world(T_base_plate: np.ndarray, half: float = 5000.0) -> sim.World:
    w = sim.World()
    _plate(w, T_base_plate, half, FLOOR_ID)
    return w


@pytest.fixture(scope="module")
def box_world() -> sim.World:
    """A 100 × 100 × 80 mm box standing on a floor at z = 0, centred on the base origin."""
    w = _plate_world(np.eye(4), 2000.0)
    lo, hi = (-BOX_HALF, -BOX_HALF, 0.0), (BOX_HALF, BOX_HALF, BOX_HEIGHT)
    v = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]] for i in range(8)])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    f = np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])
    w.add_instance(w.add_mesh(v, f), np.eye(4), BOX_ID)
    return w


def _camera(noise: DepthNoise, T_base_camera: np.ndarray, intrinsics: CameraIntrinsics = WIDE) -> DepthCamera:
    return DepthCamera(intrinsics=intrinsics, noise=noise, T_base_camera=T_base_camera)


def _rays(K: CameraIntrinsics) -> np.ndarray:
    v, u = np.mgrid[0 : K.height, 0 : K.width]
    return np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=2)


def _edges(depth: np.ndarray, jump: float, grow: int) -> np.ndarray:
    """Pixels within ``grow`` pixels of a 4-neighbour depth step above ``jump`` (or of no surface)."""
    d = np.where(np.isfinite(depth), depth, 1e9)
    edge = np.zeros(d.shape, bool)
    edge[:, 1:] |= np.abs(np.diff(d, axis=1)) > jump
    edge[:, :-1] |= np.abs(np.diff(d, axis=1)) > jump
    edge[1:] |= np.abs(np.diff(d, axis=0)) > jump
    edge[:-1] |= np.abs(np.diff(d, axis=0)) > jump
    for _ in range(grow):
        e = edge.copy()
        e[1:] |= edge[:-1]
        e[:-1] |= edge[1:]
        e[:, 1:] |= edge[:, :-1]
        e[:, :-1] |= edge[:, 1:]
        edge = e
    return edge


@pytest.mark.parametrize("z", [600.0, 1200.0])
def test_axial_noise_on_a_plate_matches_the_model(z):
    # A plate square to the optical axis: depth is z everywhere, so the residuals of a fitted plane
    # are the axial noise alone (lateral noise reads the same depth beside the ray).
    noise = replace(DepthNoise.kinect(), disparity_step_px=0.0)
    frame = render_depth(_plate_world(translation(0, 0, z)), _camera(noise, np.eye(4)), seed=1)
    pts = frame.points[frame.valid]
    assert len(pts) > 0.99 * WIDE.width * WIDE.height
    centred = pts - pts.mean(axis=0)
    normal = np.linalg.svd(centred, full_matrices=False)[2][2]
    measured = float((centred @ normal).std())
    incidence = np.arccos(1.0 / np.linalg.norm(_rays(WIDE), axis=2))
    expected = float(np.sqrt(np.mean(noise.axial_sigma(z, incidence) ** 2)))
    assert expected == pytest.approx(1.2 + 1.9 * (z / 1000 - 0.4) ** 2, rel=0.02)  # Nguyen et al. 2012
    assert measured == pytest.approx(expected, rel=0.15)


def test_depth_snaps_to_the_predicted_disparity_steps():
    # A plate tilted 40° spans a range of depths; with disparity quantisation alone, every depth is
    # f·b/(k·q) and neighbouring levels are Δz = z²·q/(f·b) apart.
    noise = replace(DepthNoise.ideal(), baseline=75.0, disparity_step_px=1.0 / 8.0)
    T_plate = translation(0, 0, 1000.0)
    T_plate[:3, :3] = rotation_about([1, 0, 0], math.radians(40.0))
    frame = render_depth(_plate_world(T_plate), _camera(noise, np.eye(4)))
    levels = np.unique(np.round(frame.depth[frame.valid], 6))  # one level, rounded differently along rays
    assert len(levels) > 20
    k = WIDE.fx * 75.0 / (levels * noise.disparity_step_px)
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    middle = (levels[1:] + levels[:-1]) / 2
    np.testing.assert_allclose(np.diff(levels), noise.depth_step(middle, WIDE.fx), rtol=0.01)
    assert noise.depth_step(1000.0, 525.0) == pytest.approx(1000.0**2 / 8 / (525.0 * 75.0))
    unquantised = render_depth(_plate_world(T_plate), _camera(replace(noise, disparity_step_px=0.0), np.eye(4)))
    k = WIDE.fx * 75.0 / (unquantised.depth[unquantised.valid] * noise.disparity_step_px)
    assert (np.abs(k - np.round(k)) > 0.05).mean() > 0.8


def test_holes_appear_exactly_beyond_the_grazing_limit():
    limit = math.radians(70.0)
    noise = replace(DepthNoise.ideal(), max_incidence=limit)
    T_plate = translation(0, 0, 800.0)
    T_plate[:3, :3] = rotation_about([1, 0, 0], math.radians(60.0))
    frame = render_depth(_plate_world(T_plate), _camera(noise, np.eye(4)))
    rays = _rays(WIDE)
    cos = np.abs(rays @ T_plate[:3, 2]) / np.linalg.norm(rays, axis=2)
    incidence = np.arccos(cos)
    hit = np.isfinite(frame.true_depth)
    clear = hit & (np.abs(incidence - limit) > 1e-3)
    assert (~frame.valid[clear] == (incidence[clear] > limit)).all()
    assert 0.1 < (incidence[hit] > limit).mean() < 0.9  # both sides of the limit are in view


@pytest.mark.parametrize(("tilt_deg", "kept"), [(60.0, 1.0), (82.0, 0.0)])
def test_a_plate_tilted_past_the_kinect_limit_loses_its_points(tilt_deg, kept):
    T_plate = translation(0, 0, 800.0)
    T_plate[:3, :3] = rotation_about([1, 0, 0], math.radians(tilt_deg))
    camera = _camera(replace(DepthNoise.kinect(), baseline=0.0, disparity_step_px=0.0), np.eye(4), NARROW)
    frame = render_depth(_plate_world(T_plate), camera, seed=2)
    interior = np.isfinite(frame.true_depth) & ~_edges(frame.true_depth, 10.0, 3)
    assert interior.sum() > 1000
    assert frame.valid[interior].mean() == pytest.approx(kept, abs=0.01)


def _shadow_oracle(frame, K: CameraIntrinsics, projector: np.ndarray) -> np.ndarray:
    """Floor pixels whose segment to the projector (base frame) passes through the box."""
    lo, hi = np.array([-BOX_HALF, -BOX_HALF, 0.0]), np.array([BOX_HALF, BOX_HALF, BOX_HEIGHT])
    R, t = frame.T_base_camera[:3, :3], frame.T_base_camera[:3, 3]
    rays = _rays(K) @ R.T
    floor = t + rays * ((0.0 - t[2]) / rays[..., 2])[..., None]
    d = projector - floor
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (lo - floor) / d, (hi - floor) / d
    enter = np.minimum(a, b).max(axis=2)
    leave = np.maximum(a, b).min(axis=2)
    return (frame.ids == FLOOR_ID) & (enter < leave) & (leave > 0) & (enter < 1)


def test_projector_shadow_falls_behind_the_box_away_from_the_projector(box_world):
    K = CameraIntrinsics.pinhole(160, 120, 400.0, 400.0, 79.5, 59.5)
    T = look_down(0.0, 0.0, 700.0)
    frame = render_depth(box_world, _camera(replace(DepthNoise.ideal(), baseline=75.0), T, K))
    shadow = np.isfinite(frame.true_depth) & ~frame.valid
    oracle = _shadow_oracle(frame, K, (T @ [75.0, 0.0, 0.0, 1.0])[:3])
    assert oracle.sum() > 100  # about 5 px wide along the box's 57 rows
    assert (shadow != oracle).sum() <= 0.1 * oracle.sum()
    box_u = np.nonzero((frame.ids == BOX_ID).any(axis=0))[0]
    cols = np.nonzero(shadow.any(axis=0))[0]
    assert cols.max() < box_u.min()  # the projector is at the camera's +x: shadows fall towards −x
    assert (frame.ids[shadow] == FLOOR_ID).all()
    none = render_depth(box_world, _camera(DepthNoise.ideal(), T, K))
    assert (none.valid == np.isfinite(none.true_depth)).all()


def test_lateral_noise_frays_edges_by_sigma_pixels(box_world):
    # Box top and floor square to the axis: lateral noise alone changes a depth only where a pixel
    # reads across the box's outline. Across a straight edge the pixel k + ½ pixels from it does so
    # when its displacement δ ~ N(0, σ_L²) exceeds that: 2·Σ_k P(δ > k + ½) per outline pixel.
    K = CameraIntrinsics.pinhole(160, 120, 400.0, 400.0, 79.5, 59.5)
    sigma = 0.8
    frame = render_depth(
        box_world, _camera(replace(DepthNoise.ideal(), lateral_sigma_px=sigma), look_down(0.0, 0.0, 700.0), K), seed=5
    )
    moved = np.abs(frame.depth - frame.true_depth) > 1.0
    assert not (moved & ~_edges(frame.true_depth, 10.0, 4)).any()
    assert np.isin(np.round(frame.depth[moved]), [620.0, 700.0]).all()  # read from the other surface
    outline = 4 * 2 * BOX_HALF * K.fx / (700.0 - BOX_HEIGHT)
    expected = 2 * sum(0.5 * math.erfc((k + 0.5) / sigma / math.sqrt(2)) for k in range(10))
    assert moved.sum() / outline == pytest.approx(expected, rel=0.2)


@pytest.mark.parametrize("preset", ["kinect", "tof"])
def test_flying_pixels_only_along_depth_edges(box_world, preset):
    noise = getattr(DepthNoise, preset)()
    frame = render_depth(box_world, _camera(noise, look_down(0.0, 0.0, 700.0)), seed=4)
    true = frame.true_depth
    off = frame.valid & (np.abs(frame.depth - true) > 15.0)  # 10σ of the axial noise here
    near = _edges(true, noise.edge_jump, 3)
    assert off.sum() > 10
    assert not (off & ~near).any()
    # Some depths lie between the box top (620 mm) and the floor (700 mm): mixed, not moved.
    between = frame.valid & (frame.depth > 620.0 + 10.0) & (frame.depth < 700.0 - 10.0)
    assert between.sum() > 5
    ideal = render_depth(box_world, _camera(DepthNoise.ideal(), look_down(0.0, 0.0, 700.0)), seed=4)
    assert not (ideal.valid & (np.abs(ideal.depth - true) > 0)).any()


def test_multipath_lengthens_range_in_concave_corners_only():
    # Inside a bin seen from above: the floor meets the walls in concave corners, the rim is convex;
    # multipath alone, so depth − truth is the bias.
    world = sim.World()
    world.add_bin(sim.Bin(size=(300.0, 200.0, 80.0), center=(0.0, 0.0)), table=False)
    K = CameraIntrinsics.pinhole(160, 120, 150.0, 150.0, 79.5, 59.5)
    T = look_down(0.0, 0.0, 600.0)
    noise = replace(DepthNoise.ideal(), multipath_bias=30.0, multipath_radius=40.0)
    frame = render_depth(world, _camera(noise, T, K))
    truth = render_depth(world, _camera(DepthNoise.ideal(), T, K)).points_base
    bias = frame.depth - frame.true_depth
    assert (bias[frame.valid] >= 0).all()
    floor = (frame.ids == sim.BIN_ID) & (np.abs(truth[..., 2]) < 1e-3)
    to_wall = np.minimum(150.0 - np.abs(truth[..., 0]), 100.0 - np.abs(truth[..., 1]))
    corner = floor & (to_wall < 10.0)
    open_floor = floor & (to_wall > 45.0)
    rim = np.abs(truth[..., 2] - 80.0) < 1e-3
    assert corner.sum() > 50 and open_floor.sum() > 800 and rim.sum() > 500
    assert np.mean(bias[corner]) > 0.15 * noise.multipath_bias  # F: 0.5 at a wall's foot, less away from it
    assert np.max(bias[open_floor]) == 0.0
    assert np.max(bias[rim]) == 0.0
    preset = DepthNoise.tof()
    tof = replace(DepthNoise.ideal(), multipath_bias=preset.multipath_bias, multipath_radius=preset.multipath_radius)
    tof_frame = render_depth(world, _camera(tof, T, K))
    assert 3.0 < np.mean(tof_frame.depth[corner] - tof_frame.true_depth[corner]) < 15.0  # several mm


def test_multipath_ignores_a_surface_far_in_front():
    # A plate hovering 200 mm above a floor hides part of it: beside its silhouette the floor's
    # hemisphere projects onto the plate, which stands far in front, not around the point.
    world = _plate_world(np.eye(4), 2000.0)
    _plate(world, translation(-1000.0, 0.0, 200.0), 1000.0, BOX_ID)
    noise = replace(DepthNoise.ideal(), multipath_bias=30.0, multipath_radius=40.0)
    frame = render_depth(world, _camera(noise, look_down(0.0, 0.0, 600.0)))
    assert (frame.ids == FLOOR_ID).sum() > 1000 and (frame.ids == BOX_ID).sum() > 1000
    assert np.max(np.abs(frame.depth - frame.true_depth)) == 0.0


def test_ideal_reproduces_the_renderer(box_world):
    tee = binpick.parts.tee()
    world = sim.World()
    world.add_bin(sim.Bin())
    T = translation(400.0, 0.0, 13.0)
    world.add_parts(tee, [0, 1], np.stack([T, translation(330.0, 40.0, 13.0) @ np.diag([1.0, -1.0, -1.0, 1.0])]))
    camera = DepthCamera(intrinsics=WIDE, noise=DepthNoise.ideal()).looking_at(
        (400.0, 0.0, 40.0), distance=800.0, tilt_deg=30.0, azimuth_deg=20.0
    )
    frame = render_depth(world, camera)
    seen = world.surfaces(WIDE, camera.T_base_camera)
    np.testing.assert_array_equal(frame.points, seen.points.astype(np.float64))
    np.testing.assert_array_equal(frame.true_depth, seen.depth.astype(np.float64))
    np.testing.assert_array_equal(frame.ids, seen.ids)
    assert {0, 1} <= set(np.unique(frame.ids))
    R, t = camera.T_base_camera[:3, :3], camera.T_base_camera[:3, 3]
    np.testing.assert_allclose(frame.points_base, frame.points @ R.T + t)
    np.testing.assert_array_equal(frame.viewpoint, camera.viewpoint)
    assert frame.cloud.shape == (int(frame.valid.sum()), 3)
    assert not frame.points.flags.writeable


def test_looking_at_places_the_camera_on_its_tilt_and_distance():
    target = np.array([400.0, 0.0, 40.0])
    cam = DepthCamera.kinect().looking_at(target, distance=900.0, tilt_deg=30.0, azimuth_deg=90.0)
    T = cam.T_base_camera
    assert np.linalg.norm(cam.viewpoint - target) == pytest.approx(900.0)
    assert math.degrees(math.acos(-T[2, 2])) == pytest.approx(30.0)
    assert cam.viewpoint[1] > target[1] + 400.0  # azimuth 90°: on the target's +y side
    local = np.linalg.inv(T) @ np.append(target, 1.0)
    K = cam.intrinsics
    assert (K.fx * local[0] / local[2] + K.cx, K.fy * local[1] / local[2] + K.cy) == pytest.approx((K.cx, K.cy))


def test_seeded_frames_are_reproducible(box_world):
    camera = _camera(DepthNoise.kinect(), look_down(20.0, 10.0, 800.0))
    a, b = (render_depth(box_world, camera, seed=7) for _ in range(2))
    np.testing.assert_array_equal(a.points, b.points)
    c = render_depth(box_world, camera, seed=8)
    assert not np.array_equal(a.points, c.points, equal_nan=True)


def test_presets_follow_their_published_numbers():
    kinect, tof, sl = DepthNoise.kinect(), DepthNoise.tof(), DepthNoise.structured_light()
    assert kinect.axial_sigma(1000.0) == pytest.approx(1.2 + 1.9 * 0.6**2)  # Nguyen et al. 2012
    assert kinect.lateral_sigma(math.radians(45.0)) == pytest.approx(0.8 + 0.035 * 1.0)
    assert tof.axial_sigma(2000.0) == pytest.approx(1.5 - 1.0 + 1.2)  # Fankhauser et al. 2015
    assert 0.1 <= sl.axial_sigma(600.0) < sl.axial_sigma(1200.0) <= 0.3
    assert kinect.axial_sigma(2000.0) > 2 * kinect.axial_sigma(1000.0)
    assert DepthCamera.kinect().intrinsics.shape == (480, 640)
    assert DepthCamera.tof().noise == tof and DepthCamera.structured_light().noise == sl


@pytest.mark.parametrize(
    ("build", "error", "name"),
    [
        (lambda: DepthNoise(axial_sigma_0=-1.0), errors.InvalidInputError, "axial_sigma_0"),
        (
            lambda: DepthNoise(axial_sigma_1=-5.0, axial_sigma_0=1.0, axial_sigma_2=1.0),
            errors.InvalidInputError,
            "axial_sigma_1",
        ),
        (lambda: DepthNoise(lateral_sigma_px="0.8"), errors.InvalidTypeError, "lateral_sigma_px"),
        (lambda: DepthNoise(flying_pixel_rate=1.5), errors.InvalidInputError, "flying_pixel_rate"),
        (lambda: DepthNoise(max_incidence=2.0), errors.InvalidInputError, "max_incidence"),
        (lambda: DepthNoise(axial_sigma_grazing=0.1), errors.InvalidInputError, "max_incidence"),
        (lambda: DepthNoise(disparity_step_px=0.125), errors.InvalidInputError, "disparity_step_px"),
        (lambda: DepthNoise(edge_jump=0.0), errors.InvalidInputError, "edge_jump"),
        (lambda: DepthNoise(multipath_radius=float("nan")), errors.InvalidInputError, "multipath_radius"),
        (lambda: DepthCamera(intrinsics="kinect"), errors.InvalidTypeError, "intrinsics"),
        (lambda: DepthCamera(noise=DepthNoise), errors.InvalidTypeError, "noise"),
        (lambda: DepthCamera(T_base_camera=np.eye(3)), errors.ShapeError, "T_base_camera"),
        (lambda: DepthCamera.kinect().looking_at((0, 0, 0), distance=-5.0), errors.InvalidInputError, "distance"),
        (
            lambda: DepthCamera.kinect().looking_at((0, 0, 0), distance=500.0, tilt_deg=95.0),
            errors.InvalidInputError,
            "tilt_deg",
        ),
        (lambda: DepthCamera.kinect().looking_at((0, 0), distance=500.0), errors.ShapeError, "target"),
        (lambda: render_depth("world", DepthCamera.kinect()), errors.InvalidTypeError, "world"),
        (lambda: render_depth(sim.World(), DepthNoise.kinect()), errors.InvalidTypeError, "camera"),
        (lambda: render_depth(sim.World(), DepthCamera.kinect(), seed=-1), errors.InvalidInputError, "seed"),
    ],
)
def test_bad_arguments_name_themselves(build, error, name):
    with pytest.raises(error, match=name):
        build()


#: The Kinect preset's fields, the valid side of the property below.
KINECT_FIELDS = {f: getattr(DepthNoise.kinect(), f) for f in DepthNoise.__dataclass_fields__}
TINY = CameraIntrinsics.pinhole(32, 24, 40.0, 40.0, 15.5, 11.5)


@PROPERTY
@given(
    kw=variations(
        KINECT_FIELDS,
        dict(
            axial_sigma_0=reals(-1, 5),
            axial_sigma_1=reals(-5, 5),
            axial_sigma_2=reals(-1, 5),
            axial_sigma_grazing=reals(-1, 1),
            axial_grazing_exponent=reals(-5, 5),
            lateral_sigma_px=reals(-1, 3),
            lateral_sigma_grazing_px=reals(-1, 1),
            baseline=reals(-10, 300),
            disparity_step_px=reals(-1, 1),
            max_incidence=reals(-1, 2),
            edge_jump=reals(-1, 50),
            flying_pixel_rate=reals(-1, 2),
            multipath_bias=reals(-1, 50),
            multipath_radius=reals(-1, 100),
        ),
    ),
    target=vectors(3, -200, 200),
    distance=reals(-100, 3000),
    tilt_deg=reals(-10, 100),
)
def test_property_depth_noise_and_camera(box_world, kw, target, distance, tilt_deg):
    """Any noise model and placement ends in a frame or an InvalidInputError naming the argument;
    a frame's measured points are finite, its holes NaN, its shapes the camera's."""
    noise = outcome(lambda: DepthNoise(**kw), "DepthNoise")
    if noise is None:
        return
    assert (noise.axial_sigma([300.0, 1000.0, 3000.0], [0.0, 0.5, noise.max_incidence]) >= 0).all()
    camera = outcome(
        lambda: DepthCamera(TINY, noise).looking_at(target, distance=distance, tilt_deg=tilt_deg), "looking_at"
    )
    if camera is None:
        return
    frame = render_depth(box_world, camera, seed=3)
    assert frame.points.shape == (24, 32, 3) and frame.ids.shape == (24, 32)
    valid = frame.valid
    assert finite(frame.points[valid]) and finite(frame.points_base[valid])
    assert np.isnan(frame.points[~valid]).all()
