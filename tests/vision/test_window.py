"""The laser window: every pixel whose ray meets the sheet inside the volume lies in it, the
rectangle is no larger than that, and extraction inside it finds the same line."""

from __future__ import annotations

import numpy as np
import pytest

from binpick.errors import InvalidInputError
from binpick.transforms import inverse
from binpick.vision import LaserWindow, extract_line
from binpick.vision import _synthetic as syn

#: A box around the cylinder lying on the tilted floor, base frame, mm.
VOLUME = np.array([[-120.0, -150.0, -30.0], [140.0, 110.0, 110.0]])


def _pixels_in_volume(cell, angle: float, volume: np.ndarray) -> np.ndarray:
    """The pixels (u, v) whose ray (the renderer's own ray model) meets the sheet inside ``volume``."""
    T_base_camera = cell.T_base_flange @ cell.calibration.T_flange_camera
    n, d = syn.laser_plane_base(cell.calibration, angle, cell.T_base_flange)
    dirs = cell.rays @ T_base_camera[:3, :3].T
    origin = T_base_camera[:3, 3]
    t = (d - n @ origin) / (dirs @ n)
    hit = origin + t[:, None] * dirs
    inside = (t > 0) & np.all((hit > volume[0]) & (hit < volume[1]), axis=1)
    v, u = np.divmod(np.flatnonzero(inside), cell.calibration.camera.width)
    return np.stack([u, v], axis=1)


@pytest.mark.parametrize("column", [200.0, 520.0, 1000.0])
def test_window_holds_exactly_the_pixels_whose_ray_meets_the_sheet_in_the_volume(cell, column):
    angle = cell.angle_for_column(column)
    inside = _pixels_in_volume(cell, angle, VOLUME)
    assert len(inside) > 1000
    u0, v0, u1, v1 = LaserWindow(cell.calibration, cell.T_base_flange, VOLUME, pad=0).roi(angle)
    lo, hi = inside.min(axis=0), inside.max(axis=0)
    # Sound: every such pixel is inside; tight: the rectangle ends within 2 px of them.
    assert u0 <= lo[0] and v0 <= lo[1] and hi[0] < u1 and hi[1] < v1
    assert lo[0] - u0 <= 2 and lo[1] - v0 <= 2 and u1 - 1 - hi[0] <= 2 and v1 - 1 - hi[1] <= 2
    assert (u1 - u0) < 0.5 * cell.calibration.camera.width, "a sheet crossing a box is a band, not the frame"


def test_the_line_extracted_inside_the_window_is_the_line_extracted_in_the_whole_frame(cell):
    surfaces = [cell.floor, cell.cylinder]
    window = LaserWindow(cell.calibration, cell.T_base_flange, VOLUME)
    for column in (300.0, 700.0):
        angle = cell.angle_for_column(column)
        img = syn.render(
            cell.calibration, surfaces, cell.T_base_flange, angle=angle, rng=np.random.default_rng(5), rays=cell.rays
        )
        u0, v0, u1, v1 = roi = window.roi(angle)
        whole, part = extract_line(img), extract_line(img, roi=roi)
        assert len(part) > 300
        assert np.array_equal(window.extract(img, angle), part)
        in_roi = (whole[:, 0] >= u0 + 8) & (whole[:, 0] < u1 - 8) & (whole[:, 1] >= v0) & (whole[:, 1] < v1)
        # Matched by row: the same sub-pixel centre, in the whole frame's coordinates.
        rows = dict(zip(part[:, 1].tolist(), part[:, 0].tolist()))
        assert all(r in rows for r in whole[in_roi, 1].tolist())
        assert np.allclose([rows[r] for r in whole[in_roi, 1].tolist()], whole[in_roi, 0], atol=1e-9)


def test_a_sheet_that_misses_the_volume_or_a_volume_out_of_view_gives_no_window(cell):
    T_base_camera = cell.T_base_flange @ cell.calibration.T_flange_camera
    T_laser_base = inverse(T_base_camera @ cell.calibration.T_camera_laser)

    def through(point: np.ndarray) -> float:
        """The motor angle whose sheet (x cos θ − z sin θ = 0 in the laser frame) holds ``point``."""
        x, _, z = (T_laser_base @ [*point, 1.0])[:3]
        return float(np.arctan2(x, z))

    window = LaserWindow(cell.calibration, cell.T_base_flange, VOLUME)
    # Turned far aside, the sheet passes beside the box.
    assert window.roi(cell.angle_for_column(520.0) + 1.2) is None
    blank = np.zeros((*cell.calibration.camera.shape, 3), np.uint8)
    assert window.extract(blank, cell.angle_for_column(520.0) + 1.2).shape == (0, 2)
    # A sheet through a box behind the camera, and through one far outside its view.
    for in_camera in ([0.0, 0.0, -100.0], [3000.0, 0.0, 480.0]):
        centre = (T_base_camera @ [*in_camera, 1.0])[:3]
        box = LaserWindow(cell.calibration, cell.T_base_flange, (centre - 20, centre + 20))
        assert box.roi(through(centre)) is None
    # The same sheet construction finds a box in view.
    centre = (T_base_camera @ [0.0, 0.0, 480.0, 1.0])[:3]
    assert LaserWindow(cell.calibration, cell.T_base_flange, (centre - 20, centre + 20)).roi(through(centre))


def test_bad_windows_and_rois_are_named(cell):
    img = np.zeros((40, 50, 3), np.uint8)
    for roi, what in (((0, 0, 60, 40), "roi"), ((10, 0, 5, 40), "roi"), ((0, 0, 50), "roi"), ((0.5, 0, 5, 5), "roi")):
        with pytest.raises(InvalidInputError, match=what):
            extract_line(img, roi=roi)
    with pytest.raises(InvalidInputError, match="volume"):
        LaserWindow(cell.calibration, cell.T_base_flange, [[0, 0, 0], [0, 10, 10]])
    with pytest.raises(InvalidInputError, match="calibration"):
        LaserWindow("cal", cell.T_base_flange, VOLUME)
    with pytest.raises(InvalidInputError, match="angle"):
        LaserWindow(cell.calibration, cell.T_base_flange, VOLUME).roi(float("nan"))
