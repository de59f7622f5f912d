"""Laser-line extraction against the exact line centre of rendered analytic scenes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from binpick.errors import DTypeError, InvalidInputError, ShapeError
from binpick.vision import _synthetic as syn
from binpick.vision import extract_line, laser_mask


def centre_errors(uv: np.ndarray, truth: np.ndarray, along: int = 1) -> np.ndarray:
    """Extracted minus true centre, matched by scan line (row for along=1, column for along=0).

    Scan lines that cross the sheet twice, or lie within 3 lines of a jump of the true line
    (a depth edge, where a window across the line straddles two surfaces), are left out."""
    across = 1 - along
    keys_true = np.rint(truth[:, along]).astype(int)
    uniq, counts = np.unique(keys_true, return_counts=True)
    single = set(uniq[counts == 1].tolist())
    order = np.argsort(keys_true)
    k, c = keys_true[order], truth[order, across]
    edges = k[1:][(np.abs(np.diff(c)) > 2.0) | (np.diff(k) > 1)]
    near_edge = {int(e) + d for e in edges for d in range(-3, 4)} | {
        int(e) - 1 + d for e in edges for d in range(-3, 4)
    }
    table = {int(key): val for key, val in zip(keys_true, truth[:, across]) if key in single and key not in near_edge}
    keys = np.rint(uv[:, along]).astype(int)
    matched = np.array([key in table for key in keys], dtype=bool)
    assert matched.sum() > 0.9 * len(table), f"lost scan lines: {matched.sum()} of {len(table)} found"
    return uv[matched, across] - np.array([table[key] for key in keys[matched]])


@pytest.fixture(scope="module", params=[(1.0, 1.0, 1.0), (1.35, 1.0, 0.8)], ids=["white-ambient", "reddish-ambient"])
def noisy_frames(request, cell):
    """Three frames of the floor and cylinder, noise σ = 3 grey levels, bright ambient light."""
    surfaces = [cell.floor, cell.cylinder]
    rng = np.random.default_rng(7)
    out = []
    for u in (260.0, 540.0, 820.0):
        angle = cell.angle_for_column(u)
        img = syn.render(
            cell.calibration,
            surfaces,
            cell.T_base_flange,
            angle=angle,
            rng=rng,
            noise=3.0,
            ambient=110.0,
            ambient_tint=request.param,
            rays=cell.rays,
        )
        out.append((img, syn.true_line_centres(cell.calibration, surfaces, cell.T_base_flange, angle)))
    return out


@pytest.mark.parametrize("method", ["cog", "gaussian"])
def test_line_centre_within_a_tenth_of_a_pixel_on_noisy_frames(noisy_frames, method):
    err = np.concatenate([centre_errors(extract_line(img, method=method), truth) for img, truth in noisy_frames])
    assert np.sqrt(np.mean(err**2)) < 0.1
    assert abs(err.mean()) < 0.03, "biased centre"


def test_line_in_any_direction_is_scanned_across(cell):
    # A horizontal line: the sheet turned 90° about the optical axis.
    T90 = cell.calibration.T_camera_laser.copy()
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    laser = np.eye(4)
    laser[:3, :3] = rot @ T90[:3, :3]
    laser[:3, 3] = rot @ T90[:3, 3]
    cal = type(cell.calibration)(cell.calibration.camera, laser, cell.calibration.T_flange_camera)
    angle = 0.25
    img = syn.render(
        cal, [cell.floor], cell.T_base_flange, angle=angle, rng=np.random.default_rng(1), noise=2.0, rays=cell.rays
    )
    uv = extract_line(img)
    assert np.ptp(uv[:, 0]) > 900 and np.ptp(uv[:, 1]) < 200, "expected one point per column"
    # Truth: scan the transposed problem by columns.
    v = uv[:, 1]
    rays = syn.camera_rays(cal.camera, uv)
    T_base_camera = cell.T_base_flange @ cal.T_flange_camera
    n, d = syn.laser_plane_base(cal, angle, cell.T_base_flange)
    dirs = rays @ T_base_camera[:3, :3].T
    pts = T_base_camera[:3, 3] + dirs * cell.floor.intersect(T_base_camera[:3, 3], dirs)[:, None]
    # Distance of each reconstructed floor point from the sheet, in pixels along v: small.
    off_sheet = np.abs(pts @ n - d)
    assert np.sqrt(np.mean(off_sheet**2)) < 0.1 * 480 / 1195, f"{np.sqrt(np.mean(off_sheet**2))} mm off the sheet"
    assert len(v) > 0.9 * 1032


def test_a_stray_brighter_red_spot_does_not_pull_the_line(cell):
    angle = cell.angle_for_column(500.0)
    img = syn.render(
        cell.calibration, [cell.floor], cell.T_base_flange, angle=angle, rng=np.random.default_rng(3), rays=cell.rays
    )
    truth = syn.true_line_centres(cell.calibration, [cell.floor], cell.T_base_flange, angle)
    # A red reflection, wider and brighter than the line, on rows 300–307 only.
    cv2.rectangle(img, (800, 300), (812, 307), (40, 40, 255), thickness=-1)
    err = centre_errors(extract_line(img), truth)
    assert np.abs(err).max() < 0.5
    assert np.abs(centre_errors(extract_line(img, max_jump=None), truth)).max() > 100, (
        "the spot should win without continuity"
    )


def test_no_line_gives_no_points_and_grey_frames_work(cell):
    img = syn.render(cell.calibration, [cell.floor], cell.T_base_flange, angle=None, rays=cell.rays)
    assert extract_line(img).shape == (0, 2)
    assert not laser_mask(img).any()
    grey = np.zeros((50, 60), np.uint8)
    grey[:, 30] = 200
    grey[:, 31] = 200
    uv = extract_line(grey)
    assert len(uv) == 50 and np.allclose(uv[:, 0], 30.5)


def test_bad_input_is_named():
    with pytest.raises(DTypeError, match="uint8"):
        extract_line(np.zeros((10, 10, 3), np.float32))
    with pytest.raises(ShapeError, match="shape"):
        extract_line(np.zeros((10, 10, 4), np.uint8))
    with pytest.raises(InvalidInputError, match="method"):
        extract_line(np.zeros((10, 10, 3), np.uint8), method="mean")
    with pytest.raises(InvalidInputError, match="window"):
        extract_line(np.zeros((10, 10, 3), np.uint8), window=0)
    with pytest.raises(InvalidInputError, match="threshold"):
        extract_line(np.zeros((10, 10, 3), np.uint8), threshold=300)
