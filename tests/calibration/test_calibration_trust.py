"""A camera calibration that cannot be trusted is refused (issue 38 item 6): too few views, too
little of the image covered, views too alike, a large residual or an uncertain focal length,
each named with its fix; ``--accept-untrusted`` keeps it with every warning on stderr and in the
output. Checkerboards rendered by binpick's own renderer with a known camera."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from _readme import readme_block
from binpick import errors
from binpick.calibration import CalibrationLimits, calibrate_camera, find_checkerboard
from binpick.camera import CameraIntrinsics
from binpick.cli import main
from binpick.sim import render_checkerboard
from binpick.transforms import rotation_about

CAMERA = CameraIntrinsics.pinhole(640, 480, 540.0, 540.0, 322.0, 236.0, dist=(-0.25, 0.08, 0.0005, -0.0003, 0.0))
PATTERN = (9, 6)
SQUARE = 25.0


def board_at(u: float, v: float, distance: float, tilt_deg: float = 0.0, toward_deg: float = 0.0, roll_deg=0.0):
    """``T_camera_board`` with the board's centre on the ray through pixel (u, v), ``distance`` mm
    away, its plane tilted ``tilt_deg`` about an axis in the image plane at ``toward_deg`` from x,
    and turned ``roll_deg`` about the optical axis."""
    a = math.radians(toward_deg)
    R = rotation_about((0, 0, 1), math.radians(roll_deg)) @ rotation_about(
        (math.cos(a), math.sin(a), 0.0), math.radians(tilt_deg)
    )
    ray = np.array([(u - CAMERA.cx) / CAMERA.fx, (v - CAMERA.cy) / CAMERA.fy, 1.0])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = ray / np.linalg.norm(ray) * distance - R @ np.array([4 * SQUARE, 2.5 * SQUARE, 0.0])
    return T


def render(T: np.ndarray, seed: int) -> np.ndarray:
    return render_checkerboard(CAMERA, T, pattern=PATTERN, square=SQUARE, seed=seed)


#: Fourteen good views: the board tilted 20–35° toward every side, near each image corner and edge.
GOOD = [
    board_at(u, v, d, tilt, toward, roll)
    for u, v, d, tilt, toward, roll in (
        (200, 150, 560, 25, 45, 5),
        (440, 150, 560, 25, 135, -5),
        (200, 330, 560, 25, -45, 5),
        (440, 330, 560, 25, -135, -5),
        (320, 240, 500, 30, 0, 0),
        (320, 240, 500, 30, 90, 10),
        (320, 240, 520, 0, 0, 0),
        (320, 240, 480, 7, 30, 0),
        (230, 240, 560, 35, 90, 0),
        (410, 240, 560, 35, -90, 0),
        (320, 160, 560, 35, 0, -10),
        (320, 320, 560, 35, 180, 10),
        (180, 240, 600, 20, 60, 15),
        (460, 240, 600, 20, 120, -15),
    )
]


@pytest.fixture(scope="module")
def good_images():
    return [render(T, seed=i) for i, T in enumerate(GOOD)]


def _unfindable(images: list[np.ndarray]) -> list[np.ndarray]:
    """The same views as a careless session takes them: out of focus, a hand over the board,
    or the board half out of the picture."""
    out = []
    for i, im in enumerate(images):
        corners = find_checkerboard(im, PATTERN)
        centre, half = corners.mean(axis=0), np.ptp(corners, axis=0) / 4
        if i % 3 == 0:
            im = cv2.GaussianBlur(im, (0, 0), 15.0)
        elif i % 3 == 1:
            im = cv2.rectangle(
                im.copy(), *(tuple(int(v) for v in centre + s * half) for s in (-1, 1)), (90, 80, 70), -1
            )
        else:
            im = im.copy()
            im[:, int(centre[0]) :] = 0
        assert find_checkerboard(im, PATTERN) is None
        out.append(im)
    return out


@pytest.fixture(scope="module")
def three_of_fourteen(good_images):
    """The board findable in 3 of 14 images: the three easy views (little tilt, the image's centre)."""
    easy = (4, 6, 7)
    spoiled = _unfindable([im for i, im in enumerate(good_images) if i not in easy])
    images = [good_images[i] for i in easy] + spoiled
    assert len(images) == 14
    return images


def test_good_spread_is_trusted_and_within_one_percent(good_images):
    result = calibrate_camera(good_images, PATTERN, SQUARE)
    q = result.quality
    assert result.trusted and q.problems == () and q.views == q.images == 14
    assert abs(result.camera.fx / CAMERA.fx - 1) < 0.01 and abs(result.camera.fy / CAMERA.fy - 1) < 0.01
    assert abs(result.camera.cx - CAMERA.cx) < 3 and abs(result.camera.cy - CAMERA.cy) < 3
    assert q.coverage > 0.4 and q.tilt_spread_deg > 40 and q.rms_px < 0.2 and q.focal_sigma_pct < 0.3
    assert len(q.std_intrinsics) == 9 and np.all(q.std_intrinsics[:4] > 0)


def test_three_of_fourteen_is_refused_naming_the_causes(three_of_fourteen):
    with pytest.raises(errors.UntrustedCalibrationError) as caught:
        calibrate_camera(three_of_fourteen, PATTERN, SQUARE)
    text, q = str(caught.value), caught.value.quality
    assert "found in only 3 views; at least 8 are needed" in text and "[--min-views]" in text
    assert "found in 3 of 14 images (21%, less than 50%)" in text and "[--min-found-share]" in text
    assert "--accept-untrusted" in text and "limits=CalibrationLimits" in text
    assert q.views == 3 and q.images == 14 and not q.trusted
    assert caught.value.calibration.quality is q  # the result refused, for a look


def test_cli_refuses_three_of_fourteen_and_keeps_it_on_request(three_of_fourteen, tmp_path, capsys):
    folder = tmp_path / "boards"
    folder.mkdir()
    for i, im in enumerate(three_of_fourteen):
        cv2.imwrite(str(folder / f"view{i:02d}.png"), im)
    args = ["calibrate", str(folder), "--pattern", "9x6", "--square", "25"]
    code = main(args)
    printed = capsys.readouterr()
    assert code == 2 and printed.out == ""
    assert "this camera calibration cannot be trusted" in printed.err
    assert "found in 3 of 14 images" in printed.err and "--min-views" in printed.err
    assert "--accept-untrusted" in printed.err and "NOT TRUSTED" in printed.err
    for line in readme_block("<!-- calibrate-refusal -->").splitlines():  # as README shows it
        assert line in printed.err.splitlines()

    code = main([*args, "--accept-untrusted"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "WARNING: this camera calibration CANNOT BE TRUSTED" in printed.err
    assert "WARNING:   - the board was found in 3 of 14 images" in printed.err
    doc = json.loads(printed.out)
    q = doc["quality"]
    assert q["trusted"] is False and q["views"] == 3 and q["images"] == 14
    assert any("3 of 14 images" in w for w in q["warnings"]) and q["limits"]["min_views"] == 8
    for figure in ("coverage", "tilt_spread_deg", "rms_px", "focal_sigma_pct"):
        assert isinstance(q[figure], float) and q[figure] >= 0
    assert doc["views"] == ["view00.png", "view01.png", "view02.png"]


def test_cli_limit_flags_move_the_limits_knowingly(good_images, three_of_fourteen, tmp_path, capsys):
    folder = tmp_path / "good"
    folder.mkdir()
    for i, im in enumerate(good_images):
        cv2.imwrite(str(folder / f"view{i:02d}.png"), im)
    code = main(["calibrate", str(folder), "--pattern", "9x6", "--square", "25", "--min-views", "15"])
    printed = capsys.readouterr()
    assert code == 2 and "found in only 14 views; at least 15 are needed" in printed.err
    code = main(["calibrate", str(folder), "--pattern", "9x6", "--square", "25", "--max-rms", "0.3"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    doc = json.loads(printed.out)
    assert doc["quality"]["trusted"] is True and doc["quality"]["limits"]["max_rms_px"] == 0.3
    assert "WARNING" not in printed.err and "trusted" in printed.err
    assert main(["calibrate", str(folder), "--min-views", "0"]) == 2
    assert "--min-views: must be at least 1" in capsys.readouterr().err
    assert main(["calibrate", "compare", "a.toml", "b.toml", "--accept-untrusted"]) == 2
    assert "--accept-untrusted: applies to `calibrate FOLDER` and `calibrate solve`" in capsys.readouterr().err


def test_views_all_alike_are_refused_for_the_tilt(good_images):
    """Fourteen fronto-parallel views at one distance: the focal length trades with the distance,
    and OpenCV's deviation does not see it; the tilt test does."""
    images = [render(board_at(u, v, 520), seed=i) for i, (u, v) in enumerate(_grid(14))]
    with pytest.raises(errors.UntrustedCalibrationError, match=r"planes differ by at most \d\.\d°") as caught:
        calibrate_camera(images, PATTERN, SQUARE)
    q = caught.value.quality
    assert q.tilt_spread_deg < 2 and "[--min-tilt-spread]" in str(caught.value)
    assert len(q.problems) == 1  # every other figure looks fine ...
    assert abs(caught.value.calibration.camera.fx / CAMERA.fx - 1) > 0.05  # ... yet fx is far off


def _grid(n: int) -> list[tuple[float, float]]:
    """``n`` pixel positions spread over the image for board centres."""
    return [(170 + 300 * ((i * 5) % n) / (n - 1), 150 + 180 * (i % 4) / 3) for i in range(n)]


def test_views_in_the_middle_only_are_refused_for_the_coverage():
    """A small board far away, always in the image's centre: the distortion is never measured
    where it is large."""
    images = [
        render(board_at(320 + 20 * math.cos(k), 240 + 15 * math.sin(k), 1100, 30, 360 * k / 10), seed=k)
        for k in range(10)
    ]
    with pytest.raises(errors.UntrustedCalibrationError, match=r"cover \d+% of the image") as caught:
        calibrate_camera(images, PATTERN, SQUARE)
    assert caught.value.quality.coverage < 0.25 and "[--min-coverage]" in str(caught.value)


def test_corners_that_do_not_fit_the_camera_are_refused_for_the_residual(good_images):
    """A wavy board (a ±1.5 px ripple no lens model holds): the residual is several times corner noise."""
    h, w = good_images[0].shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    map_x = xs + 1.5 * np.sin(2 * np.pi * ys / 50.0)
    map_y = ys + 1.5 * np.sin(2 * np.pi * xs / 50.0)
    wavy = [cv2.remap(im, map_x, map_y, cv2.INTER_LINEAR) for im in good_images]
    with pytest.raises(errors.UntrustedCalibrationError, match=r"reprojection RMS is \d\.\d+ px") as caught:
        calibrate_camera(wavy, PATTERN, SQUARE)
    assert caught.value.quality.rms_px > 0.5 and "[--max-rms]" in str(caught.value)


def test_little_tilt_is_refused_for_the_focal_length_uncertainty():
    """Boards tilted by ±4°: the focal length's deviation is several percent; refused on that
    even with the tilt limit moved out of the way."""
    images = [render(board_at(u, v, 560, 4, 360 * i / 14), seed=i) for i, (u, v) in enumerate(_grid(14))]
    limits = CalibrationLimits(min_tilt_spread_deg=0.0)
    with pytest.raises(errors.UntrustedCalibrationError, match=r"1-sigma is \d+\.\d\d %") as caught:
        calibrate_camera(images, PATTERN, SQUARE, limits=limits)
    q = caught.value.quality
    assert q.focal_sigma_pct > 0.5 and [p for p in q.problems if "1-sigma" not in p] == []


def test_limits_are_checked_and_named():
    for kwargs, name in (
        ({"min_views": 0}, "min_views"),
        ({"min_found_share": 1.5}, "min_found_share"),
        ({"min_coverage": -0.1}, "min_coverage"),
        ({"min_tilt_spread_deg": math.nan}, "min_tilt_spread_deg"),
        ({"max_rms_px": 0.0}, "max_rms_px"),
        ({"max_focal_sigma_pct": "1"}, "max_focal_sigma_pct"),
    ):
        with pytest.raises(errors.InvalidInputError, match=name):
            CalibrationLimits(**kwargs)
    with pytest.raises(errors.InvalidInputError, match="limits"):
        calibrate_camera([np.zeros((8, 8), np.uint8)], PATTERN, SQUARE, limits={"min_views": 3})
