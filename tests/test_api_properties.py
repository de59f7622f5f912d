"""Property tests (issue 16 item 6) of the top-level public functions the earlier property tests
left out: Model.from_mesh, canonical_pose, add_grasp and prepared; the scene readers and writers
and the LZF decoder; the pinhole matrix and the camera's native form; save_scan; the pictures of
binpick.viz. Each case ends in a result or a BinpickError (TypeError for a wrong Python type),
within seconds, and a result is checked against what it promises: a file written reads back
equal, an independent LZF compressor's output decodes to its input, a canonical pose is the same
for poses that differ by a symmetry.

What they found is fixed and pinned in FOUND (each case refused with an error naming the argument)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import binpick
from _files import HEIGHT, WIDTH, small_calibration
from _geometry import MESH_WRITERS, box_mesh
from _properties import PROPERTY, anything, finite, ints, mostly, outcome, reals, rigid, transforms, variations, vectors
from binpick import errors, viz
from binpick._validate import LENGTH_UNITS
from binpick.camera import camera_args, pinhole_matrix
from binpick.cell import PickRecord, PoseTruth, symmetry_maps
from binpick.cell.records import Skipped
from binpick.clouds import SCENE_FORMATS, lzf_decompress, read_scene, write_pcd, write_scene
from binpick.scan import load_scan, save_scan
from test_clouds import lzf_compress

BOX_V, BOX_F = box_mesh((20.0, 30.0, 40.0))
CLOUD = np.random.default_rng(6).normal(size=(40, 3)) * 20.0

units = mostly(st.sampled_from(["mm", "m", " CM ", "inch"]), st.sampled_from(["furlong", ""]), anything)
clouds = mostly(
    st.integers(0, 30).map(lambda n: np.random.default_rng(n).normal(size=(n, 3)) * 100.0),
    st.sampled_from([CLOUD[:, :2], CLOUD.astype(np.float32), CLOUD.astype(np.int16), np.full((4, 3), np.nan)]),
    st.sampled_from([CLOUD * 1e13, np.array([["a"] * 3] * 2)]),
    anything,
)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The box as every mesh format, and a scene in every scene format, written once."""
    root = tmp_path_factory.mktemp("files")
    for name, write in MESH_WRITERS.items():
        write(root / name, BOX_V, BOX_F)
    for ext in (".xyz", ".npy", ".pcd", ".ply"):
        write_scene(root / f"scene{ext}", CLOUD)
    (root / "folder").mkdir()
    return root


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    """A small model whose PPF table is cached in the module's own folder."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("BINPICK_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        yield binpick.Model.from_arrays(BOX_V, BOX_F, count=150, name="box")


# --------------------------------------------------------------------------- models

mesh_names = mostly(
    st.sampled_from(list(MESH_WRITERS)), st.sampled_from(["missing.stl", "folder", "scene.xyz"]), anything
)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(
    name=mesh_names,
    kw=variations(
        {"spacing": 3.0},
        {"unit": units, "spacing": mostly(reals(1.0, 20.0), st.none()), "count": ints(1, 300), "seed": ints(0, 9)},
    ),
)
def test_property_model_from_mesh(files, name, kw):
    path = files / name if isinstance(name, str) else name
    m = outcome(lambda: binpick.Model.from_mesh(path, **kw), f"from_mesh({name!r}, {kw})")
    if m is not None:
        scale = LENGTH_UNITS[kw.get("unit", "mm").strip().lower()]
        np.testing.assert_allclose(m.vertices.min(axis=0), BOX_V.min(axis=0) * scale, atol=1e-4 * scale)
        np.testing.assert_allclose(m.vertices.max(axis=0), BOX_V.max(axis=0) * scale, rtol=1e-6)
        assert finite(m.points) and len(m.points) > 0
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-6)


@PROPERTY
@given(T=transforms)
def test_property_canonical_pose(cube, T):
    C = outcome(lambda: cube.canonical_pose(T), "canonical_pose")
    if C is not None:
        assert C.shape == (4, 4) and finite(C) and np.allclose(C[:3, :3].T @ C[:3, :3], np.eye(3), atol=1e-9)
        np.testing.assert_allclose(cube.canonical_pose(C), C, atol=1e-9)  # canonical already
        for S in symmetry_maps(cube.symmetries)[:3]:  # a pose turned by a symmetry: the same canonical form
            np.testing.assert_allclose(cube.canonical_pose(np.asarray(T, dtype=float) @ S), C, atol=1e-6)


@PROPERTY
@given(name=st.one_of(st.text(max_size=6), anything), T=transforms)
def test_property_add_grasp(cube, name, T):
    before = dict(cube.grasps)
    if outcome(lambda: cube.add_grasp(name, T) or True, "add_grasp"):
        np.testing.assert_allclose(cube.grasps[str(name)], np.asarray(T, dtype=float))
    else:
        assert cube.grasps.keys() == before.keys(), "a refused grasp changed the model's grasps"
    cube.grasps.clear()


ppf_options = variations(
    {},
    {"sampling_ratio": reals(0.02, 0.3), "angle_bins": ints(1, 60), "rotation_bins": ints(1, 60)},
)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 20))
@given(ppf=st.one_of(st.none(), ppf_options, anything))
def test_property_prepared(cube, ppf):
    def prepare():
        params = binpick.PpfParams(**ppf) if isinstance(ppf, dict) else ppf
        return params, cube.prepared(params)

    done = outcome(prepare, f"prepared({ppf})")
    if done is not None:
        params, native = done
        assert native.ppf_pairs() > 0
        assert cube.prepared(params) is native and cube.prepared() is native  # kept until others are asked for


# --------------------------------------------------------------------------- scene files

scene_names = mostly(
    st.sampled_from(["scene.xyz", "scene.npy", "scene.pcd", "scene.ply"]),
    st.sampled_from(["binary.stl", "folder", "missing.xyz"]),
    anything,
)


@PROPERTY
@given(name=scene_names, unit=st.one_of(st.none(), units))
def test_property_read_scene(files, name, unit):
    path = files / name if isinstance(name, str) else name
    scene = outcome(lambda: read_scene(path, unit=unit), f"read_scene({name!r}, unit={unit!r})")
    if scene is not None:
        scale = 1.0 if unit is None else LENGTH_UNITS[unit.strip().lower()]
        assert scene.points.dtype == np.float64 and scene.points.shape == CLOUD.shape and finite(scene.points)
        rtol = 1e-6 if name in ("scene.pcd", "scene.ply") else 0.0  # PCD and PLY hold float32, XYZ 6 decimals
        np.testing.assert_allclose(scene.points, CLOUD * scale, rtol=rtol, atol=1e-6 * scale)


suffixes = mostly(st.sampled_from([*SCENE_FORMATS, ".PLY"]), st.sampled_from([".foo", ""]))


@PROPERTY
@given(suffix=suffixes, points=clouds)
def test_property_write_scene_then_read_scene(tmp_path_factory, suffix, points):
    path = tmp_path_factory.mktemp("scene") / f"cloud{suffix}"
    written = outcome(lambda: write_scene(path, points), f"write_scene({suffix!r})")
    if written is not None:
        expected = np.asarray(points, dtype=np.float64)
        back = outcome(lambda: read_scene(written), f"read_scene({suffix!r})")
        float32 = SCENE_FORMATS[suffix.lower()] in ("ply", "pcd")
        np.testing.assert_allclose(back.points, expected, rtol=1e-6 if float32 else 1e-9, atol=1e-6)


@PROPERTY
@given(points=clouds, encoding=mostly(st.sampled_from(["binary", "ascii"]), st.just("binary_compressed"), anything))
def test_property_write_pcd_then_read_scene(tmp_path_factory, points, encoding):
    path = tmp_path_factory.mktemp("pcd") / "cloud.pcd"
    written = outcome(lambda: write_pcd(path, points, encoding=encoding), f"write_pcd({encoding!r})")
    if written is not None:
        expected = np.asarray(points, dtype=np.float64).astype(np.float32)
        back = read_scene(written)
        assert back.file_unit == "mm" and back.points.shape == expected.shape
        np.testing.assert_array_equal(back.points, expected)  # float32 written, float32 read, exactly


@st.composite
def lzf_cases(draw):
    """(data, size, plain): an independent compressor's stream of ``plain`` with its size, or that
    stream or its size damaged (plain None), or anything."""
    plain = draw(st.one_of(st.binary(max_size=300), st.binary(max_size=8).map(lambda b: b * 40)))
    packed = lzf_compress(plain)
    kind = draw(st.sampled_from(["true", "size", "bytes", "wild"]))
    if kind == "true":
        return packed, len(plain), plain
    if kind == "size":
        return packed, draw(ints(0, 400)), None
    if kind == "bytes":
        i = draw(st.integers(0, max(0, len(packed) - 1)))
        return packed[:i] + draw(st.binary(min_size=1, max_size=3)) + packed[i + 1 :], len(plain), None
    return draw(st.one_of(st.binary(max_size=20), anything)), draw(ints(0, 100)), None


@PROPERTY
@given(case=lzf_cases())
def test_property_lzf_decompress(case):
    data, size, plain = case
    out = outcome(lambda: lzf_decompress(data, size), f"lzf_decompress({data!r:.40}, {size!r:.20})")
    if plain is not None:
        assert out == plain, "the independent compressor's stream did not decode to its input"
    elif out is not None:
        assert isinstance(out, bytes) and len(out) == size


# --------------------------------------------------------------------------- camera


@PROPERTY
@given(fx=reals(-10, 1e4), fy=reals(-10, 1e4), cx=reals(-10, 1e3), cy=reals(-10, 1e3), skew=reals(-1, 1))
def test_property_pinhole_matrix(fx, fy, cx, cy, skew):
    K = outcome(lambda: pinhole_matrix(fx, fy, cx, cy, skew), "pinhole_matrix")
    if K is not None:
        assert K.dtype == np.float64 and K.shape == (3, 3) and finite(K)
        np.testing.assert_array_equal(K, [[fx, skew, cx], [0, fy, cy], [0, 0, 1]])


cameras = st.builds(
    binpick.sim.Camera,
    width=st.integers(2, 2000),
    height=st.integers(2, 2000),
    fx=st.floats(1.0, 1e4),
    fy=st.floats(1.0, 1e4),
    cx=st.just(1.0),
    cy=st.just(1.0),
    dist=st.tuples(*[st.floats(-0.5, 0.5)] * 5),
)


@PROPERTY
@given(camera=mostly(cameras))
def test_property_camera_args(camera):
    args = outcome(lambda: camera_args(camera), "camera_args")
    if args is not None:
        w, h, K, dist = args
        assert (w, h) == (camera.width, camera.height) and K.shape == (3, 3) and dist.shape == (5,)
        assert K.flags.c_contiguous and dist.flags.c_contiguous and K.dtype == dist.dtype == np.float64
        np.testing.assert_array_equal(K, camera.K) and np.testing.assert_array_equal(dist, camera.dist)


# --------------------------------------------------------------------------- scans

FRAME = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
FRAME[:, 20, 2] = 255
wild_frames = st.one_of(
    st.sampled_from([[], [FRAME[:, :, 0]], [FRAME.astype(np.float32)], [FRAME[:10]], [FRAME[:, :, :2]]]),
    anything,
)
frame_lists = mostly(st.integers(1, 3).map(lambda n: [np.roll(FRAME, 3 * k, axis=1) for k in range(n)]), wild_frames)


@st.composite
def scans(draw):
    """save_scan's arguments: a valid scan of one to three frames with up to two of its
    arguments replaced by a wild value."""
    n = draw(st.integers(1, 3))
    valid = {
        "frames": [np.roll(FRAME, 3 * k, axis=1) for k in range(n)],
        "angles": draw(st.lists(st.floats(-math.pi, math.pi), min_size=n, max_size=n)),
        "poses": [rigid(draw(st.floats(-3, 3)), offset=(400.0, 0.0, 600.0)) for _ in range(n)],
        "calibration": small_calibration(),
        "truth": draw(st.sampled_from([None, {"ids": [1, 2]}])),
    }
    wild = {
        "frames": wild_frames,
        "angles": st.one_of(vectors(n, -4, 4), st.lists(st.floats(-3, 3), max_size=4)),
        "poses": st.one_of(st.lists(transforms, min_size=n, max_size=n), st.lists(transforms, max_size=4), anything),
        "calibration": anything,
        "truth": st.one_of(st.sampled_from([{"x": object()}, {1j: 1}, {"nan": math.nan}]), anything),
    }
    return draw(variations(valid, wild))


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(kw=scans())
def test_property_save_scan_then_load_scan(tmp_path_factory, kw):
    root = tmp_path_factory.mktemp("scan")
    args = (kw["frames"], kw["angles"], kw["poses"], kw["calibration"])
    written = outcome(lambda: save_scan(root, *args, ground_truth=kw["truth"]), "save_scan")
    if written is None:
        assert not (root / "scan.json").exists(), "a refused scan left a scan.json behind"
        return
    scan = load_scan(written)
    np.testing.assert_allclose(scan.angles, kw["angles"])
    np.testing.assert_allclose(scan.T_base_flanges, np.asarray(kw["poses"], dtype=float))
    assert all(np.array_equal(img, f) for img, f in zip(scan.images(), kw["frames"]))
    assert scan.ground_truth == kw["truth"] or (scan.ground_truth is None and kw["truth"] is None)


# --------------------------------------------------------------------------- pictures

picture_names = st.sampled_from(["p.png", "p.svg", "p.pdf", "p.foo", "p.pgf", "sub/p.png"])
indices = st.one_of(
    st.lists(st.integers(-5, 50), max_size=5).map(np.array),
    st.sampled_from([np.array([1.5]), np.zeros((2, 2), int), np.array([2**63], np.uint64), []]),
    anything,
)
boxes = st.one_of(st.just(((-30.0, -30.0, -10.0), (30.0, 30.0, 40.0))), st.tuples(vectors(3), vectors(3)), anything)
titles = st.one_of(st.just(""), st.text(max_size=10), anything)


def _written(path, result):
    assert result == path and path.read_bytes()[:1] != b""


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 12))
@given(
    name=mostly(st.just("p.png"), picture_names),
    points=clouds,
    kw=variations(
        {},
        {
            "model": st.one_of(st.just("cube"), anything),
            "T_base_object": transforms,
            "highlight": indices,
            "bin_bounds": boxes,
            "title": titles,
        },
    ),
)
def test_property_save_cloud(tmp_path_factory, cube, name, points, kw):
    path = tmp_path_factory.mktemp("picture") / name
    kw = {**kw, "model": cube} if kw.get("model") == "cube" else kw
    result = outcome(lambda: viz.save_cloud(path, points, **kw), f"save_cloud({name}, {kw})")
    if result is not None:
        _written(path, result)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 25))
@given(
    name=mostly(st.sampled_from(["s.png", "s.jpg"]), st.sampled_from(["s.foo", "s"])),
    frames=frame_lists,
    kw=variations(
        {},
        {
            "numbers": st.one_of(st.lists(ints(0, 99), min_size=1, max_size=3), anything),
            "columns": ints(1, 5),
            "width": ints(1, 2000),
        },
    ),
)
def test_property_save_contact_sheet(tmp_path_factory, name, frames, kw):
    path = tmp_path_factory.mktemp("sheet") / name
    result = outcome(lambda: viz.save_contact_sheet(path, frames, **kw), f"save_contact_sheet({name}, {kw})")
    if result is not None:
        _written(path, result)


refused = {"tilt": np.stack([rigid(0.3, offset=(0.0, 0.0, 50.0))] * 2)}
skipped_parts = st.lists(
    st.builds(
        Skipped,
        T_base_object=transforms,
        reason=st.sampled_from(["tilt", "no grasp"]),
        refused=st.sampled_from([{}, refused]),
    ),
    max_size=3,
)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 12))
@given(
    points=clouds,
    model=mostly(st.just("cube")),
    kw=variations(
        {},
        {
            "skipped": st.one_of(skipped_parts, anything),
            "located": st.one_of(st.none(), transforms),
            "bin_bounds": boxes,
            "title": titles,
        },
    ),
)
def test_property_save_failure(tmp_path_factory, cube, points, model, kw):
    path = tmp_path_factory.mktemp("failure") / "f.png"
    m = cube if model == "cube" else model
    result = outcome(lambda: viz.save_failure(path, points, model=m, **kw), f"save_failure({kw})")
    if result is not None:
        _written(path, result)


records = st.lists(
    st.builds(
        PickRecord,
        index=st.integers(1, 9),
        success=st.booleans(),
        score=st.one_of(st.none(), st.floats(0, 1)),
        truth=st.one_of(st.none(), st.builds(PoseTruth, st.integers(0, 5), st.floats(0, 90), st.floats(0, 50))),
        timings=st.sampled_from([{}, {"scan.move": 800.0, "motion": 2500.0}]),
    ),
    min_size=1,
    max_size=3,
)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 12))
@given(recs=mostly(records, st.lists(anything, max_size=2), anything), title=titles)
def test_property_save_pick_summary(tmp_path_factory, recs, title):
    path = tmp_path_factory.mktemp("summary") / "s.png"
    result = outcome(lambda: viz.save_pick_summary(path, recs, title=title), "save_pick_summary")
    if result is not None:
        _written(path, result)


# --------------------------------------------------------------------------- found


def _cube():
    return binpick.Model.from_arrays(BOX_V, BOX_F, count=50)


#: What these properties found (each raised outside BinpickError or returned a wrong answer),
#: refused now with an InvalidInputError naming the argument.
FOUND = [
    (lambda p: pinhole_matrix(None, 1.0, 1.0, 1.0), "fx"),  # was an object array
    (lambda p: pinhole_matrix(1.0, math.nan, 1.0, 1.0), "fy"),  # was a NaN matrix
    (lambda p: pinhole_matrix(1.0, 1.0, "1", 1.0), "cx"),  # was a string array
    (lambda p: write_pcd(p / "a.pcd", CLOUD, encoding=np.zeros(2)), "encoding"),  # ValueError
    (lambda p: lzf_decompress(np.zeros(3), 3), "data"),  # ValueError
    (lambda p: lzf_decompress(b"\x00a", np.zeros(2)), "size"),  # ValueError
    (lambda p: lzf_decompress(b"\x00a", None), "size"),  # TypeError
    (
        lambda p: save_scan(p / "s", [FRAME], [0.0], [np.eye(4)], small_calibration(), ground_truth={"a": object()}),
        "ground_truth",
    ),  # TypeError after the frames and scan.json were written
    (lambda p: save_scan(p / "a\x00b", [FRAME], [0.0], [np.eye(4)], small_calibration()), "directory"),  # ValueError
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, model="box", T_base_object=np.eye(4)), "model"),  # AttributeError
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, highlight=[1.5]), "highlight"),  # silently truncated
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, highlight="x"), "highlight"),  # ValueError
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, bin_bounds=3), "bin_bounds"),  # TypeError
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, bin_bounds=[[0, 0, 0]] * 3), "bin_bounds"),  # ValueError
    (lambda p: viz.save_cloud(p / "c.png", CLOUD, title=np.zeros(2)), "title"),  # ValueError
    (lambda p: viz.save_cloud(p / "c.foo", CLOUD), "path"),  # matplotlib's ValueError
    (lambda p: viz.save_cloud(p / "c\x00.png", CLOUD), "path"),  # ValueError
    (lambda p: viz.save_failure(p / "f.png", CLOUD, model=None), "model"),  # AttributeError
    (lambda p: viz.save_failure(p / "f.png", CLOUD, model=_cube(), skipped="x"), r"skipped\[0\]"),  # AttributeError
    (lambda p: viz.save_pick_summary(p / "s.png", [1]), r"records\[0\]"),  # AttributeError
    (lambda p: viz.save_contact_sheet(p / "s.png", [FRAME], numbers=["x"]), r"numbers\[0\]"),  # ValueError
    (lambda p: viz.save_contact_sheet(p / "s.png", [FRAME[:0, :0]]), r"frames_bgr\[0\]"),  # ZeroDivisionError
    (lambda p: viz.save_contact_sheet(p / "s.png", [FRAME], columns=10**9), "columns"),  # a 3 GB sheet
    (lambda p: viz.save_contact_sheet(p / "s.png", [FRAME], width=10**7), "width"),  # a 220 GB sheet
    (lambda p: viz.save_contact_sheet(p / "s.foo", [FRAME]), "path"),  # cv2.error
]


@pytest.mark.parametrize("call, name", FOUND)
def test_arguments_found_by_the_api_properties(tmp_path, call, name):
    with pytest.raises(errors.InvalidInputError, match=name):
        call(tmp_path)
    assert not (tmp_path / "s" / "scan.json").exists()  # save_scan refuses before writing anything
