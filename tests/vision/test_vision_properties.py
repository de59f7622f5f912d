"""Property tests of the measuring chain's public functions over their argument space (issue 16
item 6): red_excess, laser_mask, pixel_rays, triangulate and reconstruct each end in a result or
a BinpickError (TypeError for a wrong Python type), within seconds, and a result is what it
promises: the red chroma of OpenCV's YCrCb, rays and points that project back onto their pixels
through the distorted camera, the scan's laser line found where it was drawn."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _files import HEIGHT, WIDTH, small_calibration, small_scan
from _properties import PROPERTY, anything, finite, ints, mostly, outcome, reals, transforms, variations, vectors
from binpick.scan import load_scan
from binpick.transforms import look_down
from binpick.vision import laser_mask, pixel_rays, reconstruct, red_excess, triangulate

CALIBRATION = small_calibration()
CAMERA = CALIBRATION.camera
T_BASE_FLANGE = look_down(400.0, 0.0, 600.0)

images = mostly(
    st.tuples(st.integers(2, 12), st.integers(2, 12), st.integers(0, 2**32 - 1)).map(
        lambda s: np.random.default_rng(s[2]).integers(0, 256, (s[0], s[1], 3), dtype=np.uint8)
    ),
    st.sampled_from(
        [
            np.full((4, 5), 200, np.uint8),
            np.zeros((4, 5, 1), np.uint8),
            np.zeros((4, 5, 3), np.float32),
            np.zeros((4, 5, 4), np.uint8),
            np.zeros((1, 5, 3), np.uint8),
            np.zeros((0, 0, 3), np.uint8),
        ]
    ),
    anything,
)


def _red_chroma(image: np.ndarray) -> np.ndarray:
    """Cr − 128 of a BGR image from the ITU-R BT.601 formula (OpenCV's YCrCb), clipped at 0."""
    b, g, r = (image[..., k].astype(np.float64) for k in range(3))
    y = 0.299 * r + 0.587 * g + 0.114 * b
    return np.clip((r - y) * 0.713, 0.0, 127.0)


@PROPERTY
@given(image=images)
def test_property_red_excess(image):
    signal = outcome(lambda: red_excess(image), "red_excess")
    if signal is not None:
        assert signal.dtype == np.uint8 and signal.shape == image.shape[:2]
        if image.ndim == 3 and image.shape[2] == 3:
            assert np.abs(signal - _red_chroma(image)).max() <= 1.0  # OpenCV rounds in fixed point
        else:
            np.testing.assert_array_equal(signal, image.reshape(image.shape[:2]))  # grey: its brightness


@PROPERTY
@given(image=images, threshold=reals(0.0, 254.0))
def test_property_laser_mask(image, threshold):
    mask = outcome(lambda: laser_mask(image, threshold), "laser_mask")
    if mask is not None:
        assert mask.dtype == bool and mask.shape == image.shape[:2]
        np.testing.assert_array_equal(mask, red_excess(image) > threshold)


def _project(points_camera: np.ndarray) -> np.ndarray:
    """Pixels of camera-frame points through the distorted camera (OpenCV's projection)."""
    if len(points_camera) == 0:
        return np.zeros((0, 2))
    uv, _ = cv2.projectPoints(points_camera.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), CAMERA.K, CAMERA.dist)
    return uv.reshape(-1, 2)


pixels = mostly(
    st.integers(0, 40).map(lambda n: np.random.default_rng(n).uniform((0.0, 0.0), (WIDTH - 1.0, HEIGHT - 1.0), (n, 2))),
    st.sampled_from([np.zeros((3, 3)), np.full((2, 2), np.nan), np.array([[1e9, 1e9]]), np.array([["a", "b"]])]),
    anything,
)


@PROPERTY
@given(px=pixels, camera=mostly(st.just(CAMERA)))
def test_property_pixel_rays(px, camera):
    rays = outcome(lambda: pixel_rays(px, camera), "pixel_rays")
    if rays is not None:
        assert rays.shape == (len(px), 3) and finite(rays) and (rays[:, 2] == 1.0).all()
        np.testing.assert_allclose(_project(rays), px, atol=1e-6)


@st.composite
def scans(draw):
    """triangulate's arguments: pixels of up to three frames of the small camera, their frame
    indices, angles and flange poses, with up to two replaced by a wild value."""
    frames = draw(st.integers(1, 3))
    n = draw(st.integers(0, 30))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    valid = {
        "pixels": rng.uniform((0.0, 0.0), (WIDTH - 1.0, HEIGHT - 1.0), (n, 2)),
        "frame_index": rng.integers(0, frames, n),
        "angles": rng.uniform(-0.4, 0.4, frames),
        "T_base_flanges": np.stack([T_BASE_FLANGE] * frames),
        "calibration": CALIBRATION,
    }
    wild = {
        "pixels": pixels,
        "frame_index": st.one_of(
            st.lists(ints(-2, 4), min_size=n, max_size=n), st.just(np.full(n, 0.5)), st.just(np.full(n, 2**63 - 1))
        ),
        "angles": st.one_of(vectors(frames, -4, 4), st.just(np.degrees(valid["angles"]))),
        "T_base_flanges": st.one_of(st.lists(transforms, min_size=frames, max_size=frames), anything),
        "calibration": anything,
        "on_singular": mostly(st.sampled_from(["drop", "raise"])),
        "num_threads": ints(0, 300),
    }
    return draw(variations(valid, wild))


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(kw=scans())
def test_property_triangulate(kw):
    cloud = outcome(lambda: triangulate(**kw), "triangulate")
    if cloud is None:
        return
    px = np.asarray(kw["pixels"], dtype=float)
    assert finite(cloud.points) and cloud.points.shape == (len(cloud), 3) and len(cloud) <= len(px)
    assert cloud.frame.shape == (len(cloud),) and cloud.pixels.shape == (len(cloud), 2)
    if kw.get("on_singular") == "raise":
        assert len(cloud) == len(px)
    T_base_camera = np.asarray(kw["T_base_flanges"], dtype=float) @ CALIBRATION.T_flange_camera
    for f in np.unique(cloud.frame):  # each point lies on its pixel's camera ray
        mine = cloud.frame == f
        inv = np.linalg.inv(T_base_camera[f])
        in_camera = cloud.points[mine] @ inv[:3, :3].T + inv[:3, 3]
        np.testing.assert_allclose(_project(in_camera), cloud.pixels[mine], atol=1e-4)


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """Two frames of the small camera with a red line down columns 10 and 15."""
    return load_scan(small_scan(tmp_path_factory.mktemp("scan") / "scan"))


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 25))
@given(
    which=mostly(st.just("scan")),
    threads=ints(0, 300),
    options=variations(
        {},
        {
            "threshold": reals(0.0, 254.0),
            "window": ints(1, 15),
            "method": mostly(st.sampled_from(["cog", "gaussian"])),
            "direction": mostly(st.sampled_from(["auto", "rows"]), st.just("columns"), anything),
            "max_jump": st.one_of(st.none(), reals(0.5, 20.0)),
            "thresold": st.just(10.0),  # a misspelt option: Python's own TypeError
        },
    ),
)
def test_property_reconstruct(scan, which, threads, options):
    s = scan if which == "scan" else which
    cloud = outcome(lambda: reconstruct(s, num_threads=threads, **options), f"reconstruct({options})")
    if cloud is not None:
        assert finite(cloud.points) and set(np.unique(cloud.frame)) <= {0, 1}
        if options.get("direction", "auto") != "columns" and len(cloud):
            # The line was drawn down column 10 + 5 k of frame k: every point's pixel is on it.
            np.testing.assert_allclose(cloud.pixels[:, 0], 10.0 + 5.0 * cloud.frame, atol=0.5)
            assert math.isclose(len(cloud), HEIGHT * len(np.unique(cloud.frame)))
