"""Renderer: the laser line where the geometry puts it, depth/ids/points consistent with the
camera model, checkerboards OpenCV finds, and a scan binpick reads like a real one."""

import numpy as np
import pytest

import binpick
from binpick import sim

CAM = sim.Camera(width=320, height=240, fx=500.0, fy=500.0, cx=159.5, cy=119.5, dist=(0, 0, 0, 0, 0))


def _plane_world(T_base_plane, half=2000.0):
    w = sim.World()
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    m = w.add_mesh(v, f, albedo=(0.8, 0.8, 0.8))
    w.add_instance(m, T_base_plane, 0)
    return w


@pytest.mark.parametrize("tilt", [0.0, 0.35])
def test_line_lands_where_the_sheet_meets_a_known_plane(tilt):
    # Camera at the base origin looking along +z (T_base_flange = I, T_flange_camera = I); a plane
    # 500 mm out, tilted about the camera's x axis.
    T_plane = np.eye(4)
    c, s = np.cos(tilt), np.sin(tilt)
    T_plane[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    T_plane[2, 3] = 500.0
    cell = sim.Cell(
        camera=CAM, T_flange_camera=np.eye(4), T_base_flange=np.eye(4), laser=sim.Laser(sheet_sigma=1.0, power=150.0)
    )
    view = _plane_world(T_plane).view(cell)
    angle = 0.03
    on = view.frame(angle, noise=sim.SensorNoise.none()).astype(float)
    off = view.ambient_frame(noise=sim.SensorNoise.none()).astype(float)
    excess = on[:, :, 0] - off[:, :, 0]
    # Analytic: the pixel ray r(u) = ((u-cx)/fx, (v-cy)/fy, 1) meets the plane n·X = h at
    # X = h r / (n·r); on the sheet xl·(X − o) = 0, i.e. h (xl·r) = (n·r)(xl·o): linear in u.
    T = cell.laser.T_camera_laser(angle)
    o, xl = T[:3, 3], T[:3, 0]
    n, h = T_plane[:3, 2], T_plane[:3, 2] @ T_plane[:3, 3]
    errors = []
    for v in range(20, 220, 10):
        y = (v - CAM.cy) / CAM.fy
        # (h xl − (xl·o) n) · (x, y, 1) = 0 → solve for x
        g = h * xl - (xl @ o) * n
        x = -(g[1] * y + g[2]) / g[0]
        u_true = CAM.fx * x + CAM.cx
        row = excess[v]
        assert row.sum() > 100, f"no line in row {v}"
        u = (row * np.arange(CAM.width)).sum() / row.sum()
        errors.append(u - u_true)
    assert np.abs(errors).max() < 0.05, errors


def test_depth_points_and_ids_agree_with_the_camera_model():
    cam = sim.Camera(width=200, height=150, fx=300.0, fy=300.0, cx=99.5, cy=74.5, dist=(-0.2, 0.05, 0.001, -0.001, 0.0))
    tee = binpick.parts.tee(resolution=1.5)
    w = sim.World()
    w.add_bin(sim.Bin())
    T = np.eye(4)
    T[:3, 3] = (400, 0, 13)
    w.add_parts(tee, [7], T[None])
    cell = sim.Cell(camera=cam)
    view = w.view(cell)
    ids, depth, pts = view.ids, view.depth, view.points
    assert set(np.unique(ids)) <= {7, sim.BIN_ID, sim.TABLE_ID, sim.NO_SURFACE}
    assert (ids == 7).sum() > 50
    hit = ids != sim.NO_SURFACE
    np.testing.assert_allclose(depth[hit], pts[hit][:, 2])
    # Every surface point projects back to its own pixel through OpenCV's camera model.
    import cv2

    vv, uu = np.nonzero(hit)
    sel = np.arange(0, len(vv), 37)
    proj, _ = cv2.projectPoints(
        pts[vv[sel], uu[sel]].astype(np.float64), np.zeros(3), np.zeros(3), cam.K, np.array(cam.dist)
    )
    err = proj[:, 0, :] - np.stack([uu[sel], vv[sel]], axis=1)
    assert np.abs(err).max() < 1e-2
    # The part's top, seen in the base frame, is where it was placed (tee axis at z = 13, radius 13 + boss to 17).
    T_bc = cell.T_base_camera
    top = (pts[ids == 7] @ T_bc[:3, :3].T + T_bc[:3, 3])[:, 2].max()
    assert abs(top - (13 + 17)) < 0.5


def test_parts_placed_again_render_as_a_world_built_for_them():
    # A world whose parts were moved, removed and added (place_parts, as the simulated camera
    # does after a pick) sees exactly what a world built afresh for the new poses sees.
    tee = binpick.parts.tee(resolution=1.5)
    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, :3, 3] = [(360, -40, 13), (420, 30, 13), (460, -20, 13)]
    w = sim.World()
    w.add_bin(sim.Bin())
    w.add_parts(tee, [0, 1, 2], poses)
    moved = poses[[1, 2]].copy()
    moved[0, :3, 3] += (-15, 5, 0)
    w.place_parts(tee, [1, 2], moved)
    T_new = np.eye(4)
    T_new[:3, 3] = (330, 40, 13)
    w.place_parts(tee, [1, 2, 5], np.concatenate([moved, T_new[None]]))
    fresh = sim.World()
    fresh.add_bin(sim.Bin())
    fresh.add_parts(tee, [1, 2, 5], np.concatenate([moved, T_new[None]]))
    assert sorted(w.ids) == sorted(fresh.ids)
    cell = sim.Cell(camera=sim.Camera(width=258, height=195, fx=300.0, fy=300.0, cx=128.5, cy=97.0))
    a, b = w.view(cell), fresh.view(cell)
    np.testing.assert_array_equal(a.ids, b.ids)
    assert {0, 1, 2, 5} & set(np.unique(a.ids)) == {1, 2, 5}
    np.testing.assert_array_equal(a.frame(0.1, seed=3), b.frame(0.1, seed=3))
    with pytest.raises(binpick.InvalidInputError, match="ids/poses"):
        w.place_parts(tee, [1, 2], moved[:1])


def test_laser_shadow_and_determinism():
    tee = binpick.parts.tee(resolution=1.5)
    w = sim.World()
    w.add_bin(sim.Bin())
    T = np.eye(4)
    T[:3, 3] = (400, 0, 13)
    w.add_parts(tee, [0], T[None])
    cam = sim.Camera(width=258, height=195, fx=400.0, fy=400.0, cx=128.5, cy=97.0)
    view = w.view(sim.Cell(camera=cam))
    a = view.frame(0.0, seed=4)
    np.testing.assert_array_equal(a, view.frame(0.0, seed=4))
    assert np.abs(a.astype(int) - view.frame(0.0, seed=5)).max() > 0


def test_checkerboard_corners_are_found_where_they_project():
    import cv2

    cam = sim.Camera(width=640, height=480, fx=800.0, fy=800.0, cx=319.5, cy=239.5, dist=(-0.05, 0.01, 0, 0, 0))
    T = np.eye(4)
    T[:3, 3] = (-80.0, -50.0, 500.0)
    c, s = np.cos(0.2), np.sin(0.2)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    img = sim.render_checkerboard(cam, T, pattern=(9, 6), square=20.0, noise=sim.SensorNoise.none(), supersample=8)
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    found, corners = cv2.findChessboardCorners(gray, (9, 6))
    assert found
    corners = cv2.cornerSubPix(
        gray, corners, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    )
    obj = np.array([[i * 20.0, j * 20.0, 0.0] for j in range(6) for i in range(9)])
    proj, _ = cv2.projectPoints(obj, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], cam.K, np.array(cam.dist))
    d = np.linalg.norm(corners[:, 0, :] - proj[:, 0, :], axis=1)
    d_rev = np.linalg.norm(corners[::-1, 0, :] - proj[:, 0, :], axis=1)
    # Measured 0.15 px worst with 8×8 supersampling (cornerSubPix bias on sharp edges, not yet
    # separated from renderer error).
    assert min(d.max(), d_rev.max()) < 0.2


def test_a_checkerboard_drawn_in_a_window_is_the_whole_images_there():
    # The simulated camera draws the board only over the pixels that see it: those pixels (and
    # their noise) must be what the whole image has there, the laser line on the board included.
    cam = sim.Camera(width=320, height=240, fx=400.0, fy=400.0, cx=159.5, cy=119.5)
    T = np.eye(4)
    T[:3, 3] = (-80.0, -50.0, 500.0)
    kw = dict(pattern=(7, 5), square=20.0, laser=sim.Laser(), angle=0.05, seed=3)
    whole = sim.render_checkerboard(cam, T, **kw)
    u0, v0, u1, v1 = 40, 30, 211, 175
    part = sim.render_checkerboard(cam, T, window=(u0, v0, u1, v1), **kw)
    np.testing.assert_array_equal(part[v0:v1, u0:u1], whole[v0:v1, u0:u1])
    assert np.ptp(whole[v0:v1, u0:u1].astype(int)) > 100, "the window shows the board"
    # Beside it the background, with its noise on the window's rows and none on the others.
    beside = np.ones(part.shape[:2], dtype=bool)
    beside[v0:v1, u0:u1] = False
    beside[:v0] = beside[v1:] = False
    background = sim.render_checkerboard(cam, T @ _far_away(), **kw)
    np.testing.assert_array_equal(part[beside], background[beside])
    quiet = sim.render_checkerboard(cam, T @ _far_away(), **kw, noise=sim.SensorNoise.none())
    np.testing.assert_array_equal(part[:v0], quiet[:v0])
    np.testing.assert_array_equal(part[v1:], quiet[v1:])
    for bad in ((0, 0, 321, 10), (10, 10, 10, 20), (0.0, 0, 5, 5), (1, 2, 3)):
        with pytest.raises(binpick.InvalidInputError, match="window"):
            sim.render_checkerboard(cam, T, window=bad, **kw)


def _far_away() -> np.ndarray:
    """Moves a board out of the picture (behind the camera's view): only the background is left."""
    T = np.eye(4)
    T[:3, 3] = (1e5, 0.0, 0.0)
    return T


def test_bad_render_input_is_rejected():
    with pytest.raises(binpick.InvalidInputError):
        sim.Camera(width=0)
    with pytest.raises(binpick.InvalidInputError):
        sim.Laser(fan_angle=4.0)
    with pytest.raises(binpick.InvalidInputError):
        sim.World().add_instance(3, np.eye(4), 0)
    w = _plane_world(np.eye(4))
    with pytest.raises(binpick.InvalidInputError):
        w.add_instance(0, np.eye(4), 0)  # duplicate id
    with pytest.raises(binpick.InvalidInputError):
        w.set_pose(0, np.diag([2.0, 1, 1, 1]))  # not rigid


def test_surfaces_from_a_fixed_pose_match_the_cells_view():
    # The same camera at the same pose, once through a cell (flange and hand-eye), once alone.
    tee = binpick.parts.tee(resolution=1.5)
    w = sim.World()
    w.add_bin(sim.Bin())
    w.add_parts(tee, [3], binpick.transforms.translation(400.0, 0.0, 13.0)[None])
    cell = sim.Cell(camera=CAM, board=None)
    view = w.view(cell)
    seen = w.surfaces(CAM, cell.T_base_camera)
    np.testing.assert_array_equal(seen.depth, view.depth)
    np.testing.assert_array_equal(seen.ids, view.ids)
    np.testing.assert_array_equal(seen.normals, view.normals)
    np.testing.assert_array_equal(seen.T_base_camera, view.T_base_camera)
    assert (seen.ids == 3).sum() > 50
    with pytest.raises(binpick.errors.InvalidInputError, match="T_base_camera"):
        w.surfaces(CAM, np.eye(3))
    with pytest.raises(binpick.errors.InvalidInputError, match="camera"):
        w.surfaces(cell, cell.T_base_camera)
