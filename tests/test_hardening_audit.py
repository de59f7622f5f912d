"""Issue 16 audit: what the bad-input measurement did not reach. The built-in parts' sizes and
counts meet a ceiling before any mesh is built; the tee's boss, a model's branches and a serial
line's parity are checked like every other argument (a model is left unchanged by a refused
declaration); and property tests over the arguments of the functions that had none (the parts,
declare_branches, write_ply/read_ply, grasp_pose, extract_line)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import binpick
from _properties import PROPERTY, anything, ints, outcome, reals, transforms, variations, vectors
from binpick.devices import SerialSettings
from binpick.errors import InvalidInputError, InvalidTypeError

PARTS = binpick.parts


# --------------------------------------------------------------------------- the tee's boss


@pytest.mark.parametrize(
    "kw, error, match",
    [
        ({"boss_height": float("nan")}, InvalidInputError, "boss_height"),
        ({"boss_height": -5.0}, InvalidInputError, "boss_height"),
        ({"boss_height": "x"}, InvalidTypeError, "boss_height"),
        ({"boss_semi_axes": (float("inf"), 8.0)}, InvalidInputError, r"boss_semi_axes\[0\]"),
        ({"boss_semi_axes": ("a", "b")}, InvalidTypeError, r"boss_semi_axes\[0\]"),
        ({"boss_semi_axes": (11.0, 8.0, 3.0)}, InvalidInputError, "boss_semi_axes"),
        ({"boss_semi_axes": 5}, InvalidTypeError, "boss_semi_axes"),
    ],
)
def test_the_tees_boss_is_checked_not_silently_dropped(kw, error, match):
    with pytest.raises(error, match=match):
        PARTS.tee(**kw)


def test_a_tee_without_a_boss_is_still_built():
    assert PARTS.tee(boss_height=0.0, resolution=2.0).special_direction is None


# --------------------------------------------------------------------------- near-symmetric parts


@pytest.mark.parametrize(
    "make, kw, match",
    [
        (PARTS.keyed_shaft, {"length": 1e9}, "length"),
        (PARTS.flange, {"diameter": 1e7}, "diameter"),
        (PARTS.flange, {"bolt_holes": 10**9}, "bolt_holes"),
        (PARTS.cut_plate, {"side": 1e300}, "side"),
        (PARTS.notched_hex, {"length": 1e12}, "length"),
        (PARTS.bossed_rod, {"diameter": 1e8, "length": 1e8}, "diameter"),
        # sizes under the ceiling whose mesh grid would still take the machine's memory
        (
            PARTS.flange,
            {"diameter": 500, "thickness": 50, "bolt_circle_diameter": 250, "bolt_hole_diameter": 200},
            "mesh grid",
        ),
        (PARTS.bossed_rod, {"diameter": 500, "length": 500, "boss_diameter": 200, "boss_height": 200}, "mesh grid"),
    ],
)
def test_part_sizes_that_would_allocate_without_bound_are_refused_at_once(make, kw, match):
    t = time.perf_counter()
    with pytest.raises(InvalidInputError, match=match):
        make(**kw)
    assert time.perf_counter() - t < 1.0


@pytest.mark.parametrize("holes", [2.5, "6", True])
def test_a_bolt_hole_count_must_be_an_integer(holes):
    with pytest.raises(InvalidTypeError, match="bolt_holes"):
        PARTS.flange(bolt_holes=holes)


@pytest.mark.parametrize("make", list(PARTS.NEAR_SYMMETRIC.values()))
def test_feature_must_be_a_bool(make):
    with pytest.raises(InvalidTypeError, match="feature"):
        make(feature="no")


# --------------------------------------------------------------------------- branches


def _branch(direction=(1.0, 0.0, 0.0), length=40.0, radius=13.0):
    return binpick.Branch(direction=direction, length=length, radius=radius)


@pytest.mark.parametrize(
    "branches, special, error, match",
    [
        ([1, 2, 3], None, InvalidTypeError, r"branches\[0\]"),
        ("abc", None, InvalidTypeError, "branches"),
        ([_branch(direction="xyz")], None, InvalidInputError, r"branches\[0\]\.direction"),
        ([_branch(length=float("nan"))], None, InvalidInputError, r"branches\[0\]\.length"),
        ([_branch(radius=-1.0)], None, InvalidInputError, r"branches\[0\]\.radius"),
        ([_branch()], ("a", "b", "c"), InvalidInputError, "special_direction"),
        ([_branch()], (0.0, 1.0), InvalidInputError, "special_direction"),
    ],
)
def test_a_refused_branch_declaration_leaves_the_model_as_it_was(branches, special, error, match):
    tee = PARTS.tee(resolution=2.0, spacing=2.0)
    before = (tee.branches, tee.special_direction)
    with pytest.raises(error, match=match):
        tee.declare_branches(branches, special_direction=special)
    assert (tee.branches, tee.special_direction) == before
    tee.prepared()  # still usable


def test_from_arrays_checks_branches_too():
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    with pytest.raises(InvalidTypeError, match="branches"):
        binpick.Model.from_arrays(v, f, count=10, branches="abc")
    with pytest.raises(InvalidInputError, match="special_direction"):
        binpick.Model.from_arrays(v, f, count=10, special_direction="abc")


# --------------------------------------------------------------------------- serial settings


@pytest.mark.parametrize("kw", [{"parity": {}}, {"parity": ["E"]}, {"stopbits": True}, {"stopbits": "2"}])
def test_serial_settings_of_the_wrong_type_are_invalid_input(kw):
    with pytest.raises(InvalidInputError):
        SerialSettings(**kw)


# --------------------------------------------------------------------------- property tests

_SIZES = {
    "keyed_shaft": {"diameter": 24.0, "length": 150.0, "keyway_width": 6.0, "keyway_depth": 2.0, "keyway_length": 40.0},
    "cut_plate": {"side": 40.0, "thickness": 10.0, "cut": 4.2},
    "flange": {
        "diameter": 60.0,
        "thickness": 10.0,
        "bolt_holes": 6,
        "bolt_hole_diameter": 7.0,
        "bolt_circle_diameter": 42.0,
        "hole_depth": 3.0,
        "notch_width": 10.0,
        "notch_depth": 3.0,
    },
    "notched_hex": {"across_flats": 30.0, "length": 30.0, "notch_width": 5.0, "notch_depth": 1.5},
    "bossed_rod": {"diameter": 20.0, "length": 90.0, "boss_diameter": 10.0, "boss_height": 2.0},
}


@st.composite
def _part_args(draw):
    name = draw(st.sampled_from(sorted(_SIZES)))
    valid = {**_SIZES[name], "spacing": 3.0}
    wild = {k: (ints(0, 20) if k == "bolt_holes" else reals(0.5, 1e4)) for k in _SIZES[name]}
    wild.update(feature=st.one_of(st.booleans(), anything), spacing=st.one_of(st.none(), reals(0.5, 5.0)))
    wild["seed"] = ints(0, 5)
    return name, draw(variations(valid, wild))


@settings(PROPERTY, max_examples=25)
@given(args=_part_args())
def test_property_near_symmetric_parts(args):
    name, kw = args
    m = outcome(lambda: PARTS.NEAR_SYMMETRIC[name](**kw), f"{name}({kw})")
    if m is not None:
        assert np.isfinite(m.points).all() and len(m.points) > 0


@settings(PROPERTY, max_examples=15)
@given(
    kw=variations(
        {"resolution": 2.0, "spacing": 3.0},
        {
            "boss_semi_axes": st.one_of(vectors(2, 0.5, 20.0), anything),
            "boss_height": reals(0.0, 30.0),
            "outer_diameter": reals(5.0, 40.0),
            "resolution": reals(1.0, 4.0),
        },
    )
)
def test_property_tee(kw):
    outcome(lambda: PARTS.tee(**kw), f"tee({kw})")


_TEE = None


def _tee():
    global _TEE
    if _TEE is None:
        _TEE = PARTS.tee(resolution=2.0, spacing=2.0)
    return _TEE


@PROPERTY
@given(
    rows=st.one_of(
        st.lists(
            st.builds(
                binpick.Branch, direction=vectors(3, -1.0, 1.0), length=reals(1.0, 80.0), radius=reals(1.0, 20.0)
            ),
            max_size=4,
        ),
        anything,
    ),
    special=st.one_of(st.none(), vectors(3, -1.0, 1.0)),
)
def test_property_declare_branches(rows, special):
    tee = _tee()
    before = (tee.branches, tee.special_direction)
    if outcome(lambda: tee.declare_branches(rows, special_direction=special) or True, "declare_branches") is None:
        assert (tee.branches, tee.special_direction) == before
    tee.declare_branches(before[0], special_direction=before[1])


_CLOUD = np.random.default_rng(3).normal(size=(30, 3)) * 10.0

_clouds = st.one_of(
    st.just(_CLOUD),
    st.integers(0, 20).map(lambda n: np.random.default_rng(n).normal(size=(n, 3)) * 10),
    st.sampled_from([_CLOUD[:, :2], _CLOUD.astype(np.float32), np.full((4, 3), np.nan), _CLOUD * 1e13]),
    anything,
)


@PROPERTY
@given(points=_clouds, normals=st.one_of(st.none(), _clouds), ascii_=st.booleans())
def test_property_write_ply_then_read_ply(tmp_path_factory, points, normals, ascii_):
    path = tmp_path_factory.mktemp("ply") / "c.ply"
    written = outcome(lambda: binpick.write_ply(path, points, normals, ascii=ascii_) or True, "write_ply")
    if written:
        pts, nrm = outcome(lambda: binpick.read_ply(path), "read_ply")
        np.testing.assert_allclose(pts, np.asarray(points, dtype=np.float64), rtol=1e-6, atol=1e-5)
        assert (nrm is None) == (normals is None)


@PROPERTY
@given(a=transforms, b=transforms)
def test_property_grasp_pose(a, b):
    T = outcome(lambda: binpick.grasp_pose(a, b), "grasp_pose")
    if T is not None:
        assert np.isfinite(T).all() and np.allclose(T[3], [0, 0, 0, 1])


_IMAGE = np.zeros((24, 32, 3), np.uint8)
_IMAGE[:, 16, 2] = 255


@PROPERTY
@given(
    kw=variations(
        {},
        {
            "threshold": reals(0.0, 255.0),
            "window": ints(1, 15),
            "max_jump": st.one_of(st.none(), reals(0.5, 20.0)),
            "method": st.one_of(st.sampled_from(["cog", "gaussian", "x"]), anything),
        },
    )
)
def test_property_extract_line(kw):
    uv = outcome(lambda: binpick.extract_line(_IMAGE, **kw), f"extract_line({kw})")
    if uv is not None and len(uv):
        assert np.isfinite(np.asarray(uv)).all()
