"""The near-symmetric built-in parts (binpick.parts.NEAR_SYMMETRIC): closed outward meshes of the
documented sizes and feature depths, the symmetries their geometry has, the feature-in-view test
of the near-symmetry bench, and the plain ray-cast it renders with."""

from __future__ import annotations

import numpy as np
import pytest

from _geometry import box_mesh
from binpick import _shapes, parts
from binpick.transforms import rotation_about

NAMES = sorted(parts.NEAR_SYMMETRIC)

#: name -> (extent (x, y, z) mm, axis of the one symmetry left besides the identity)
EXPECTED = {
    "keyed_shaft": ((24.0, 24.0, 150.0), (1.0, 0.0, 0.0)),
    "cut_plate": ((40.0, 40.0, 10.0), (1.0, 1.0, 0.0)),
    "flange": ((59.497, 60.0, 10.0), (1.0, 0.0, 0.0)),
    "notched_hex": ((34.64, 30.0, 30.0), (0.0, 1.0, 0.0)),
    "bossed_rod": ((90.0, 20.0, 22.0), (0.0, 0.0, 1.0)),
}

#: name -> (discrete rotations, continuous axis or None) of the base shape
BASE = {
    "keyed_shaft": (2, (0.0, 0.0, 1.0)),
    "cut_plate": (8, None),
    "flange": (12, None),
    "notched_hex": (12, None),
    "bossed_rod": (2, (1.0, 0.0, 0.0)),
}


@pytest.fixture(scope="module")
def built():
    return {name: (parts.NEAR_SYMMETRIC[name](), parts.base_shape(name)) for name in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_closed_outward_mesh(built, name):
    for model in built[name]:
        assert _shapes.signed_volume(model.vertices, model.faces) > 0
        counts = _shapes.edge_use_counts(model.faces)
        assert (counts == 2).all(), f"{name}: {int((counts != 2).sum())} edges not shared by two faces"


@pytest.mark.parametrize("name", NAMES)
def test_size(built, name):
    part, base = built[name]
    extent = EXPECTED[name][0]
    assert np.allclose(np.ptp(part.vertices, axis=0), extent, atol=0.02)  # chords of 0.3 mm arcs
    assert part.name == name and base.name == name


def test_feature_depths(built):
    shaft = built["keyed_shaft"][0].vertices
    lateral = shaft[np.abs(shaft[:, 2]) < 74.0]
    assert np.hypot(lateral[:, 0], lateral[:, 1]).min() == pytest.approx(12.0 - 2.0, abs=1e-6)
    plate = built["cut_plate"][0].vertices
    assert (40.0 - (plate[:, 0] + plate[:, 1]).max()) / np.sqrt(2) == pytest.approx(4.2 / np.sqrt(2), abs=1e-6)
    hexagon = built["notched_hex"][0].vertices
    assert hexagon[np.abs(hexagon[:, 0]) < 1.0, 1].min() == pytest.approx(-15.0, abs=1e-6)  # the plain flat
    rim = hexagon[(np.abs(hexagon[:, 0]) < 1.0) & (np.abs(hexagon[:, 2]) < 14.0)]
    assert rim[rim[:, 1] > 0, 1].max() == pytest.approx(15.0 - 1.5, abs=1e-6)
    flange = built["flange"][0].vertices
    assert flange[np.abs(flange[:, 1]) < 1.0, 0].max() == pytest.approx(30.0 - 3.0, abs=1e-3)
    faces_z = set(np.round(flange[np.hypot(flange[:, 0], flange[:, 1]) < 26.0, 2], 6).tolist())
    assert faces_z == {-5.0, -2.0, 2.0, 5.0}  # the two faces and the floors of the 3 mm bolt-hole pockets
    rod = built["bossed_rod"][0].vertices
    assert rod[:, 2].max() == pytest.approx(10.0 + 2.0, abs=1e-6)
    assert np.ptp(rod[rod[:, 2] > 11.0, 0]) == pytest.approx(10.0, abs=0.5)


@pytest.mark.parametrize("name", NAMES)
def test_symmetries(built, name):
    part, base = built[name]
    sym = part.symmetries
    assert sym.continuous_axis is None and len(sym.rotations) == 2, f"{name}: {sym}"
    a = np.asarray(EXPECTED[name][1]) / np.linalg.norm(EXPECTED[name][1])
    assert np.allclose(sym.rotations[1], 2 * np.outer(a, a) - np.eye(3), atol=0.02)
    count, axis = BASE[name]
    bsym = base.symmetries
    assert len(bsym.rotations) == count, f"{name} base: {bsym}"
    if axis is None:
        assert bsym.continuous_axis is None
    else:
        assert abs(float(np.dot(bsym.continuous_axis, axis))) > 0.999


def _scan(model, T, rng):
    v = _shapes.posed(model.vertices, T)
    lo, hi = v.min(axis=0)[:2] - 2, v.max(axis=0)[:2] + 2
    return _shapes.scan_down(v, model.faces, lo, hi, 0.5, 0.15, rng)[0]


def test_feature_in_view(built):
    part, base = built["notched_hex"]
    rng = np.random.default_rng(3)
    for angle, expected in ((np.pi / 2, True), (-np.pi / 2, False)):
        T = np.eye(4)
        T[:3, :3] = rotation_about((1.0, 0.0, 0.0), angle)  # the notched +y flat turned up, then down
        T[:3, 3] = (5.0, -3.0, 40.0)
        seen = _shapes.feature_in_view(
            (part.vertices, part.faces), (base.vertices, base.faces), T, _scan(part, T, rng), _scan(base, T, rng)
        )
        assert seen is expected


def test_raycast_box_depth_matches_the_analytic_depth():
    v, f = box_mesh((20.0, 30.0, 40.0))
    T = np.eye(4)
    T[:3, :3] = rotation_about((1.0, 2.0, 0.5), 0.7)
    T[:3, 3] = (3.0, -4.0, 10.0)
    depth, face, xs, ys = _shapes.raycast_down(_shapes.posed(v, T), f, (-40.0, -40.0), (40.0, 40.0), 0.5)
    X, Y = np.meshgrid(xs, ys)
    # The ray (x, y, z0 − t) in the box frame: slabs 0 <= p <= size along each box axis.
    origin = np.stack([X, Y, np.full_like(X, 100.0)], axis=-1) - T[:3, 3]
    o = origin @ T[:3, :3]
    d = np.array([0.0, 0.0, -1.0]) @ T[:3, :3]
    t0 = (np.zeros(3) - o) / d
    t1 = (np.array([20.0, 30.0, 40.0]) - o) / d
    enter = np.minimum(t0, t1).max(axis=-1)
    leave = np.maximum(t0, t1).min(axis=-1)
    hit = enter <= leave
    assert (np.isfinite(depth) != hit).sum() <= 2  # at most pixel centres on the silhouette itself
    both = hit & np.isfinite(depth)
    assert np.abs(depth[both] - (100.0 - enter[both])).max() < 1e-6
    assert (face[both] >= 0).all() and (face[~np.isfinite(depth)] == -1).all()


@pytest.mark.parametrize("name", NAMES)
def test_the_expected_flip_maps_the_surface_onto_itself(built, name):
    part = built[name][0]
    a = np.asarray(EXPECTED[name][1]) / np.linalg.norm(EXPECTED[name][1])
    R = 2 * np.outer(a, a) - np.eye(3)
    assert _shapes.surface_distance(part.vertices, part.faces, part.points @ R.T).max() < 0.05


def test_every_built_in_part_is_taken_by_name_and_a_wrong_name_is_refused_with_the_list():
    from binpick._cli_parts import _model, _Usage
    from binpick.errors import InvalidInputError, InvalidTypeError

    assert list(parts.BUILT_IN)[:3] == ["tee", "elbow", "cross"]
    assert set(parts.NEAR_SYMMETRIC) | set(parts.MORE_NEAR_SYMMETRIC) <= set(parts.BUILT_IN)
    flange = parts.built_in("pinned_flange")
    assert flange.name == "pinned_flange" and np.allclose(np.ptp(flange.points, axis=0)[:2], 70.0, atol=1.0)
    # The commands take the same names (demo --part, validate PART, simulate, emulate cell).
    assert _model("keyed_shaft").name == "keyed_shaft"
    with pytest.raises(_Usage, match="did you mean pinned_flange"):
        _model("pinned_flang")
    with pytest.raises(InvalidInputError, match=r"'nut' is not a built-in part; one of tee, elbow, cross, .*d_shaft"):
        parts.built_in("nut")
    with pytest.raises(InvalidTypeError, match="name: expected a built-in part's name"):
        parts.built_in(3)
