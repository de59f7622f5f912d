"""The renderer and the measuring chain use one camera model: a known plane rendered through a
camera with realistic distortion and a skew term reprojects to its pixel centres and
triangulates back onto itself, through the exact rays and through the scan path alike; and a
laser line rendered on it, extracted and triangulated, lies on it."""

import numpy as np
import pytest

from binpick import sim, vision
from binpick.calibration import CellCalibration
from binpick.camera import CameraIntrinsics

# A realistic lens (barrel distortion moving the corners by about 15 px, small decentring) and skew.
CAM = CameraIntrinsics.pinhole(
    640, 480, fx=820.0, fy=815.0, cx=322.4, cy=237.1, dist=(-0.12, 0.08, 0.001, -0.0007, -0.01), skew=1.7
)
HALF_THICKNESS = 10.0


def _rot(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _flat_box_scene():
    """A 4 m × 4 m × 20 mm box, tilted, 500 mm in front of the camera (camera = base frame);
    returns the world, the cell and the plane (normal n, offset h: n·X = h) of the face it sees."""
    T = np.eye(4)
    T[:3, :3] = _rot(0.3, -0.2, 0.1)
    T[:3, 3] = [20.0, -10.0, 500.0]
    half = 2000.0
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], dtype=float)
    v = corners * [half, half, HALF_THICKNESS]
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    f = np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])
    world = sim.World()
    world.add_instance(world.add_mesh(v, f, albedo=(0.8, 0.8, 0.8)), T, 0)
    cell = sim.Cell(camera=CAM, T_flange_camera=np.eye(4), T_base_flange=np.eye(4))
    # The box's z axis points away from the camera: it sees the face z = −HALF_THICKNESS.
    n = T[:3, 2]
    return world, cell, n, float(n @ (T[:3, 3] - HALF_THICKNESS * n))


def _opencv_project(points, cam):
    """The test's oracle: the OpenCV pinhole-and-distortion projection written out, with skew."""
    k1, k2, p1, p2, k3 = cam.dist
    x, y = points[:, 0] / points[:, 2], points[:, 1] / points[:, 2]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([cam.fx * xd + cam.skew * yd + cam.cx, cam.fy * yd + cam.cy], axis=1)


@pytest.fixture(scope="module")
def scene():
    world, cell, n, h = _flat_box_scene()
    return world, cell, world.view(cell), n, h


def _sheet_on(n, h):
    """A laser pose whose sheet (x_L = 0 at angle 0) is the plane n·X = h: triangulating against
    it is intersecting each pixel's ray with the plane, through the scan path."""
    x = n / np.linalg.norm(n)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, np.cross(x, y)], axis=1)
    T[:3, 3] = h * x
    return T


def test_rendered_points_reproject_to_their_pixel_centres(scene):
    _, _, view, _, _ = scene
    pts = view.points.reshape(-1, 3).astype(np.float64)
    assert np.isfinite(pts).all(), "the box must fill the view"
    v, u = np.divmod(np.arange(len(pts)), CAM.width)
    err = np.linalg.norm(_opencv_project(pts, CAM) - np.stack([u, v], axis=1), axis=1)
    assert err.max() < 0.05, f"worst reprojection {err.max():.3g} px"


def test_pixel_rays_triangulate_onto_the_rendered_plane(scene):
    _, _, view, n, h = scene
    pts = view.points.reshape(-1, 3).astype(np.float64)
    v, u = np.divmod(np.arange(len(pts)), CAM.width)
    pixels = np.stack([u, v], axis=1).astype(np.float64)
    rays = vision.pixel_rays(pixels, CAM)
    exact = rays * (h / (rays @ n))[:, None]
    assert np.linalg.norm(exact - pts, axis=1).max() < 0.05
    calib = CellCalibration(camera=CAM, T_camera_laser=_sheet_on(n, h), T_flange_camera=np.eye(4))
    cloud = vision.triangulate(pixels, np.zeros(len(pixels), dtype=np.int64), [0.0], [np.eye(4)], calib)
    assert len(cloud) == len(pixels)
    err = np.linalg.norm(cloud.points - pts, axis=1)
    assert err.max() < 0.05, f"worst triangulation {err.max():.3g} mm"


def test_a_rendered_laser_line_triangulates_onto_the_plane(scene):
    _, cell, view, n, h = scene
    angle = 0.02
    rgb = view.frame(angle, noise=sim.SensorNoise.none())
    uv = vision.extract_line(np.ascontiguousarray(rgb[:, :, ::-1]))
    assert len(uv) > 0.9 * CAM.height, "the line must cross the whole image"
    cloud = vision.triangulate(uv, np.zeros(len(uv), dtype=np.int64), [angle], [np.eye(4)], cell.calibration())
    assert len(cloud) == len(uv)
    off_plane = np.abs(cloud.points @ n - h)
    # How far a point moves off the plate per pixel the line centre is off (along the scan line):
    # about 2 mm here, where a pixel spans 0.6 mm and the sheet meets the plate obliquely.
    shifted = vision.triangulate(uv + [1.0, 0.0], cloud.frame, [angle], [np.eye(4)], cell.calibration())
    mm_per_px = np.abs(shifted.points @ n - h - (cloud.points @ n - h))
    # Noise-free, the centre-of-gravity extractor finds the rendered line within about 0.05 px
    # (the renderer's own line test holds it to that): the points are on the plate within that.
    assert np.median(mm_per_px) > 1.0, "the sheet must cut the plate obliquely for this check to bite"
    px_off = off_plane / mm_per_px
    assert px_off.max() < 0.06, f"worst {off_plane.max():.3g} mm = {px_off.max():.3g} px off the plate"
    assert off_plane.mean() < 0.05, f"mean {off_plane.mean():.3g} mm off the plate"
