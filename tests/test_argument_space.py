"""Issue 16: every integer and float argument of the public API is validated once
(binpick._validate), with InvalidInputError naming it (InvalidTypeError, also a TypeError, for
a wrong type); counts that set allocations or threads meet a documented ceiling; units share
one vocabulary; Ctrl-C stops a long native call; and a property test per public function over
its argument space finds no outcome outside a valid result or a BinpickError."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import binpick
from _properties import PROPERTY, anything, finite, ints, mostly, outcome, reals, rigid
from binpick import _core, errors
from binpick.camera import CameraIntrinsics

RNG = np.random.default_rng(16)
CLOUD = RNG.normal(size=(200, 3)) * 10.0
BOX_V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
BOX_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


@pytest.fixture(scope="module")
def model():
    return binpick.parts.elbow(count=300)


# --------------------------------------------------------------------------- integers and floats

BAD_UNSIGNED = [-1, 2**64, 2**70, -(2**64)]


@pytest.mark.parametrize("value", BAD_UNSIGNED)
@pytest.mark.parametrize(
    "call, name",
    [
        (lambda v: binpick.icp(CLOUD, CLOUD, max_correspondence_distance=1.0, max_iterations=v), "max_iterations"),
        (lambda v: binpick.icp(CLOUD, CLOUD, max_correspondence_distance=1.0, num_threads=v), "num_threads"),
        (lambda v: binpick.estimate_normals(CLOUD, k=v), "k"),
        (lambda v: binpick.estimate_normals(CLOUD, num_threads=v), "num_threads"),
        (lambda v: binpick.Model.from_arrays(BOX_V, BOX_F, count=v), "count"),
        (lambda v: binpick.Model.from_arrays(BOX_V, BOX_F, count=10, seed=v), "seed"),
        (lambda v: binpick.PpfParams(angle_bins=v), "angle_bins"),
        (lambda v: binpick.PpfParams(rotation_bins=v), "rotation_bins"),
    ],
)
def test_out_of_range_integers_are_invalid_input_naming_the_argument(call, name, value):
    with pytest.raises(errors.InvalidInputError, match=name) as info:
        call(value)
    assert not isinstance(info.value, OverflowError)


@pytest.mark.parametrize("value", BAD_UNSIGNED + [10**9])
def test_max_instances_has_a_ceiling(model, value):
    with pytest.raises(errors.InvalidInputError, match="max_instances"):
        binpick.estimate_poses(CLOUD, model, max_instances=value)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda v: binpick.icp(CLOUD, CLOUD, max_correspondence_distance=v), "max_correspondence_distance"),
        (lambda v: binpick.icp(CLOUD, CLOUD, max_correspondence_distance=1.0, max_iterations=v), "max_iterations"),
        (lambda v: binpick.voxel_downsample(CLOUD, v), "voxel_size"),
        (lambda v: binpick.estimate_normals(CLOUD, k=v), "k"),
        (lambda v: binpick.PpfParams(angle_bins=v), "angle_bins"),
        (lambda v: binpick.Model.from_arrays(BOX_V, BOX_F, spacing=v), "spacing"),
    ],
)
@pytest.mark.parametrize("value", ["6", True, None, [1]])
def test_wrong_types_are_binpick_type_errors(call, name, value):
    if value is None and name in ("spacing", "angle_bins"):
        return  # None is that argument's documented "use the default"
    with pytest.raises(errors.InvalidTypeError, match=name) as info:
        call(value)
    assert isinstance(info.value, TypeError) and isinstance(info.value, errors.BinpickError)


def test_max_jump_string_is_a_type_error_naming_it():
    """The issue's example: max_jump="6" to the laser-line extraction."""
    image = np.zeros((20, 20, 3), dtype=np.uint8)
    with pytest.raises(errors.InvalidTypeError, match="max_jump.*number"):
        binpick.extract_line(image, max_jump="6")
    with pytest.raises(errors.InvalidTypeError, match="window"):
        binpick.extract_line(image, window=4.0)
    with pytest.raises(errors.InvalidInputError, match="window"):
        binpick.extract_line(image, window=2**64)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 10**400])
def test_floats_must_be_finite(value):
    with pytest.raises(errors.InvalidInputError, match="max_correspondence_distance"):
        binpick.icp(CLOUD, CLOUD, max_correspondence_distance=value)
    with pytest.raises(errors.InvalidInputError, match="voxel_size"):
        binpick.voxel_downsample(CLOUD, value)


# --------------------------------------------------------------------------- ceilings


def test_num_threads_is_clamped_to_the_cores_below_the_ceiling():
    assert _core.IcpConfig(num_threads=200).num_threads == min(200, os.cpu_count())
    assert _core.PoseConfig(num_threads=0).num_threads == 0
    before = len(os.listdir("/proc/self/task"))
    binpick.estimate_normals(CLOUD, k=10, num_threads=256)
    assert len(os.listdir("/proc/self/task")) - before <= os.cpu_count() + 1


@pytest.mark.parametrize("value", [257, 2000, 2**63])
def test_num_threads_beyond_the_ceiling_is_refused_in_the_binding_too(value):
    with pytest.raises(errors.InvalidInputError, match="num_threads"):
        binpick.estimate_normals(CLOUD, num_threads=value)
    with pytest.raises(errors.InvalidInputError, match="num_threads"):
        _core.IcpConfig(num_threads=value) if value < 2**64 else None
    with pytest.raises(errors.InvalidInputError, match="num_threads"):
        _core.estimate_normals(CLOUD, 10, None, None, value)


def test_counts_that_allocate_are_refused_before_the_call():
    with pytest.raises(errors.InvalidInputError, match="k"):
        binpick.estimate_normals(CLOUD, k=len(CLOUD) + 1)
    for bad in (10**12, 2**63):
        with pytest.raises(errors.InvalidInputError, match="count"):
            binpick.Model.from_arrays(BOX_V, BOX_F, count=bad)
    with pytest.raises(errors.InvalidInputError, match="spacing"):
        binpick.Model.from_arrays(BOX_V, BOX_F, spacing=1e-6)


@pytest.mark.parametrize("size", [(200_000, 200_000), (70_000, 10), (1, 100), (True, 100)])
def test_camera_refuses_absurd_image_sizes(size):
    w, h = size
    with pytest.raises(errors.CalibrationError, match="camera"):
        CameraIntrinsics(width=w, height=h, K=np.array([[100.0, 0, 1], [0, 100, 1], [0, 0, 1]]), dist=np.zeros(5))


# --------------------------------------------------------------------------- units


@pytest.mark.parametrize("unit, scale", [("mm", 1.0), ("meters", 1000.0), (" CM ", 10.0), ("inch", 25.4)])
def test_from_mesh_and_from_arrays_share_one_unit_vocabulary(tmp_path, unit, scale):
    path = tmp_path / "box.ply"
    m = binpick.Model.from_arrays(BOX_V, BOX_F, count=50)
    with open(path, "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n")
        f.write("element face 4\nproperty list uchar int vertex_indices\nend_header\n")
        f.writelines(f"{x} {y} {z}\n" for x, y, z in BOX_V)
        f.writelines(f"3 {a} {b} {c}\n" for a, b, c in BOX_F)
    a = binpick.Model.from_arrays(BOX_V, BOX_F, unit=unit, count=50)
    b = binpick.Model.from_mesh(path, unit=unit, count=50)
    np.testing.assert_allclose(a.vertices, BOX_V * scale)
    np.testing.assert_allclose(b.vertices, a.vertices, rtol=1e-6)
    assert m.diameter * scale == pytest.approx(a.diameter)


@pytest.mark.parametrize("unit", ["furlong", "", 3, None])
def test_unknown_units_list_the_accepted_ones(tmp_path, unit):
    for call in (
        lambda: binpick.Model.from_arrays(BOX_V, BOX_F, unit=unit),
        lambda: binpick.Model.from_mesh(tmp_path / "missing.ply", unit=unit),
    ):
        with pytest.raises(errors.UnknownUnitError, match="'mm'.*'meters'.*'inch'"):
            call()


# --------------------------------------------------------------------------- Ctrl-C

INTERRUPTED = textwrap.dedent(
    """
    import signal, sys, time, numpy as np, binpick
    # A shell's background job inherits SIGINT ignored; Ctrl-C at a terminal raises KeyboardInterrupt.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    pts = np.random.default_rng(0).normal(size=(1_000_000, 3))
    print("ready", flush=True)
    t = time.monotonic()
    try:
        binpick.estimate_normals(pts, k=256, num_threads=1)
    except KeyboardInterrupt:
        print(f"interrupted {time.monotonic() - t:.2f}", flush=True)
        # The abandoned work stops at its next check rather than running on to its end.
        t = time.monotonic()
        while binpick._core._running_calls() and time.monotonic() - t < 30:
            time.sleep(0.01)
        print(f"stopped {time.monotonic() - t:.2f} {binpick._core._running_calls()}", flush=True)
        sys.exit(3)
    print("finished", flush=True)
    """
)


def test_ctrl_c_stops_a_long_native_call_and_its_work():
    proc = subprocess.Popen([sys.executable, "-c", INTERRUPTED], stdout=subprocess.PIPE, text=True, env=os.environ)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.5)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=10)
        waited = time.monotonic() - sent
    finally:
        proc.kill()
    assert proc.returncode == 3, out
    interrupted, stopped = out.splitlines()
    # A full run takes tens of seconds on one thread; the call returns, and its worker stops, at
    # their next check. The bounds leave room for a machine busy with the rest of the suite (the
    # worker once took 1.01 s there) and still tell stopping from running on.
    assert interrupted.startswith("interrupted") and waited < 3.0, (out, waited)
    _, seconds, running = stopped.split()
    assert float(seconds) < 3.0 and running == "0", out


# --------------------------------------------------------------------------- property tests

small_int = ints(-3, 40)
real = reals(-10, 100)
cloud = mostly(
    st.one_of(st.just(CLOUD), st.integers(0, 30).map(lambda n: RNG.normal(size=(n, 3)))),
    st.sampled_from([CLOUD[:, :2], CLOUD.astype(np.float32), CLOUD.astype(np.int32), np.full((20, 3), np.nan)]),
    anything,
)


@PROPERTY
@given(pts=cloud, k=small_int, threads=small_int)
def test_property_estimate_normals(pts, k, threads):
    outcome(lambda: binpick.estimate_normals(pts, k=k, num_threads=threads))


@PROPERTY
@given(pts=cloud, size=real)
def test_property_voxel_downsample(pts, size):
    outcome(lambda: binpick.voxel_downsample(pts, size))


@PROPERTY
@given(
    pts=cloud,
    dist=real,
    iters=small_int,
    threads=small_int,
    trim=real,
    method=st.sampled_from(["point_to_point", "point_to_plane", "x", 3]),
)
def test_property_icp(pts, dist, iters, threads, trim, method):
    outcome(
        lambda: binpick.icp(
            pts,
            CLOUD,
            max_correspondence_distance=dist,
            max_iterations=iters,
            num_threads=threads,
            trim_fraction=trim,
            method=method,
        )
    )


@PROPERTY
@given(
    count=small_int,
    spacing=st.one_of(st.none(), real),
    seed=small_int,
    unit=st.one_of(st.sampled_from(["mm", "m", "in", "x"]), anything),
)
def test_property_model_from_arrays(count, spacing, seed, unit):
    outcome(lambda: binpick.Model.from_arrays(BOX_V, BOX_F, count=count, spacing=spacing, seed=seed, unit=unit))


@PROPERTY
@given(sr=real, ab=small_int, rb=small_int)
def test_property_ppf_params(sr, ab, rb):
    outcome(lambda: binpick.PpfParams(sampling_ratio=sr, angle_bins=ab, rotation_bins=rb))


def _view(model, T):
    """The upper half of ``model``'s surface samples posed at ``T``: what a sensor above sees."""
    pts = model.points @ T[:3, :3].T + T[:3, 3]
    return pts[pts[:, 2] > np.median(pts[:, 2])]


@settings(PROPERTY, max_examples=15)
@given(
    scene=mostly(st.floats(-math.pi, math.pi).map(lambda a: rigid(a, offset=(10.0, 20.0, 300.0))), st.just(CLOUD)),
    inst=small_int,
    threads=small_int,
    hyp=st.one_of(st.none(), small_int),
    fit=reals(0.0, 1.0),
    method=mostly(st.sampled_from(["auto", "ppf", "centroid"]), st.sampled_from(["ccp", "?"]), anything),
)
def test_property_estimate_poses_and_estimate_pose(model, scene, inst, threads, hyp, fit, method):
    """estimate_pose is estimate_poses(...)[0] for the same options, over the same argument space."""
    pts = _view(model, scene) if isinstance(scene, np.ndarray) and scene.shape == (4, 4) else scene
    options = dict(num_threads=threads, max_hypotheses=hyp, min_fitness=fit, method=method)
    poses = outcome(lambda: binpick.estimate_poses(pts, model, max_instances=inst, **options), "estimate_poses")
    pose = outcome(lambda: binpick.estimate_pose(pts, model, **options), "estimate_pose")
    for result in [r for r in (pose, *(poses or ())) if r is not None]:
        T = result.T_scene_model
        assert T.shape == (4, 4) and finite(T) and np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-9)
        assert 0.0 <= result.score <= 1.0 and 0.0 <= result.confidence <= 1.0 and len(result.indices) > 0
    if poses is not None and pose is not None:
        np.testing.assert_allclose(pose.T_scene_model, poses[0].T_scene_model, atol=1e-9)
        assert pose.method == poses[0].method and pose.score == poses[0].score
    elif poses is not None:  # what estimate_poses found, estimate_pose finds: only max_instances may differ
        pytest.fail(f"estimate_poses found {len(poses)} but estimate_pose failed with the same options")


@PROPERTY
@given(w=small_int, h=small_int, f=st.floats())
def test_property_camera(w, h, f):
    outcome(
        lambda: CameraIntrinsics(width=w, height=h, K=np.array([[f, 0, 1], [0, 100, 1], [0, 0, 1]]), dist=np.zeros(5))
    )
