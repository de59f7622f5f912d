"""Any CAD part (issue 7): point-pair-feature detection, verification, symmetry and piles, on
meshes and scenes the tests make themselves (rendered by binpick's own ray caster)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import binpick
from _geometry import (
    camera_cloud,
    extruded_mesh,
    pile_view,
    random_rotation,
    rendered_view,
    revolved_mesh,
    rot,
    symmetric_pose_error,
)
from binpick import sim

# An L-bracket with unequal legs: no proper symmetry.
L_BRACKET = [(0, 0), (80, 0), (80, 12), (12, 12), (12, 50), (0, 50)]
# A stepped shaft: continuous symmetry about z only (the steps tell its ends apart).
SHAFT = [(0, 0), (15, 0), (15, 40), (9, 40), (9, 95), (0, 95)]
# A hexagonal prism: 6-fold about z and six half-turns about axes in the mid-plane.
HEXAGON = [(30 * np.cos(a), 30 * np.sin(a)) for a in np.linspace(0, 2 * np.pi, 6, endpoint=False)]


def make_part(name: str) -> binpick.Model:
    if name == "bracket":
        v, f = extruded_mesh(L_BRACKET, 30.0)
    elif name == "shaft":
        v, f = revolved_mesh(SHAFT, segments=128)
    else:
        v, f = extruded_mesh(HEXAGON, 24.0)
    return binpick.Model.from_arrays(v, f, spacing=1.0, name=name)


@pytest.fixture(scope="module")
def parts():
    return {name: make_part(name) for name in ("bracket", "shaft", "hexagon")}


def known_symmetries(name: str, model: binpick.Model):
    """The symmetry group the test built into each part (not the detector's answer)."""
    c = model.points.mean(axis=0)
    if name == "bracket":
        return dict(rotations=[np.eye(3)], center=c)
    if name == "shaft":
        return dict(rotations=[np.eye(3)], center=c, continuous_axis=(0, 0, 1))
    six = [rot((0, 0, 1), k * np.pi / 3) for k in range(6)]
    flips = [rot((np.cos(a), np.sin(a), 0), np.pi) for a in np.arange(6) * np.pi / 6]
    return dict(rotations=six + flips, center=c)


def random_pose(rng: np.random.Generator) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    T[:3, 3] = [rng.uniform(330, 470), rng.uniform(-60, 60), rng.uniform(20, 60)]
    return T


@pytest.mark.parametrize("name", ["bracket", "shaft", "hexagon"])
def test_ppf_recovers_random_poses_of_meshes_the_test_makes(parts, name):
    model = parts[name]
    rng = np.random.default_rng({"bracket": 1, "shaft": 2, "hexagon": 3}[name])
    truth_group = known_symmetries(name, model)
    trials, ok = 8, 0
    for _ in range(trials):
        T = random_pose(rng)
        scene = rendered_view(model, T, rng)
        try:
            res = binpick.estimate_pose(scene, model, method="ppf", viewpoint=sim.Cell().T_base_camera[:3, 3])
        except binpick.NoObjectFound:
            continue  # a miss: no pose rather than a guess
        rot_err, trans_err = symmetric_pose_error(res.T_scene_model, T, **truth_group)
        ok += rot_err < 5 and trans_err < 3
        assert res.method == "ppf" and 0.6 <= res.score <= 1.0
    # Measured: every trial pick-grade for each part; one miss in eight is allowed for the
    # views that show a single face. (The bracket's sixth view shows only its L-shaped face,
    # which point pairs of one plane cannot place: its hypotheses confirm pieces of that face
    # and the continuation test refuses them, so the answer is NoObjectFound.)
    assert ok >= trials - 1, f"{name}: {ok}/{trials} pick-grade"


def test_detected_symmetries_match_the_built_ones(parts):
    bracket, shaft, hexagon = parts["bracket"].symmetries, parts["shaft"].symmetries, parts["hexagon"].symmetries
    assert bracket.is_trivial
    assert shaft.continuous_axis is not None and abs(abs(shaft.continuous_axis[2]) - 1) < 1e-3
    assert len(shaft.rotations) == 1  # the steps break the end-for-end flip
    assert hexagon.continuous_axis is None and len(hexagon.rotations) == 12


@pytest.mark.parametrize("name", ["shaft", "hexagon"])
def test_poses_that_differ_by_a_symmetry_have_one_canonical_form(parts, name):
    model = parts[name]
    rng = np.random.default_rng(4)
    group = known_symmetries(name, model)
    c = model.symmetries.center
    for _ in range(5):
        T = random_pose(rng)
        turns = list(group["rotations"])
        if "continuous_axis" in group:
            # About the detected axis (within 1e-3 rad of z): the canonical form is exact for it.
            axis = model.symmetries.continuous_axis
            assert abs(abs(axis[2]) - 1) < 1e-3
            turns = [rot(axis, a) for a in rng.uniform(0, 2 * np.pi, 6)]
        for s in turns:
            S = np.eye(4)
            S[:3, :3] = s
            S[:3, 3] = c - s @ c
            np.testing.assert_allclose(model.canonical_pose(T @ S), model.canonical_pose(T), atol=1e-6)
            assert max(model.pose_error(T @ S, T)) < 1e-6
    # A turn that is no symmetry stays an error.
    off = np.eye(4)
    off[:3, :3] = rot((1, 0, 0), 0.3)
    assert model.pose_error(T @ off, T)[0] > 10


def part_in_bin(model: binpick.Model, seed: int):
    """One part dropped into the cell's bin, seen with the bin and the table (a real cell's view)."""
    cell, pile, scene, _ = pile_view(model, 1, seed=seed, step=2, noise_seed=seed)
    return cell, pile, scene


@pytest.mark.parametrize(
    "shown,asked",
    [("hexagon", "bracket"), ("bracket", "hexagon"), ("shaft", "bracket"), ("bracket", "shaft"), ("hexagon", "shaft")],
)
def test_a_scene_without_the_part_gives_no_object_found(parts, shown, asked):
    for seed in range(2):
        cell, _, scene = part_in_bin(parts[shown], seed)
        # Another part's flat faces fit pieces of the asked part; the depth test (surface over the
        # visible floor, over empty cells) and the bin (no pose through its floor) reject them.
        for box in (cell.bin.bounds, None):
            with pytest.raises(binpick.NoObjectFound):
                binpick.estimate_poses(scene, parts[asked], bin=box, method="ppf")
    # The same scenes hold the shown part, found pick-grade.
    cell, pile, scene = part_in_bin(parts[shown], 0)
    res = binpick.estimate_pose(scene, parts[shown], bin=cell.bin.bounds, method="ppf")
    rot_err, trans_err = symmetric_pose_error(res.T_scene_model, pile.poses[0], **known_symmetries(shown, parts[shown]))
    assert rot_err < 5 and trans_err < 3


def test_an_empty_bin_gives_no_object_found(parts):
    cell = sim.Cell()
    world = sim.World()
    world.add_bin(cell.bin)
    scene = camera_cloud(world.view(cell), cell, step=2)[0]
    for box in (cell.bin.bounds, None):
        with pytest.raises(binpick.NoObjectFound):
            binpick.estimate_poses(scene, parts["bracket"], bin=box, method="ppf")


@pytest.fixture(scope="module")
def bracket_pile(parts):
    """Eight brackets dropped into the cell's bin by the physics engine, seen from the scan pose."""
    model = parts["bracket"]
    return (model, *pile_view(model, 8, seed=5, step=2))


def test_estimate_poses_finds_distinct_instances_most_pickable_first(bracket_pile):
    model, cell, pile, scene, ids = bracket_pile
    found = binpick.estimate_poses(scene, model, bin=cell.bin.bounds, max_instances=4, method="ppf")
    assert 2 <= len(found) <= 4
    picks = [r.pickability for r in found]
    assert picks == sorted(picks, reverse=True)
    heights = {int(i): pile.pose(int(i))[2, 3] for i in pile.ids}
    top3 = sorted(heights, key=heights.get, reverse=True)[:3]
    matched = []
    for r in found:
        errs = {i: symmetric_pose_error(r.T_scene_model, pile.pose(i), rotations=[np.eye(3)]) for i in heights}
        best = min(errs, key=lambda i: sum(errs[i]))
        matched.append((best, errs[best]))
    # The first is pick-grade on one of the three highest parts; every instance is a different part.
    first, (r0, t0) = matched[0]
    assert r0 < 5 and t0 < 3 and first in top3, (matched, top3)
    assert len({m[0] for m in matched}) == len(matched)
    # Its points are that part's.
    labels = ids[found[0].indices]
    assert (labels == first).mean() > 0.9


def test_points_set_aside_are_not_searched_but_stay_in_the_scan(bracket_pile):
    model, cell, pile, scene, ids = bracket_pile
    first = binpick.estimate_poses(scene, model, bin=cell.bin.bounds, max_instances=1, method="ppf")[0]
    part = np.bincount(ids[first.indices][ids[first.indices] >= 0]).argmax()
    aside = ids == part  # every point of the part found first, as a cell that tried it sets them aside
    found = binpick.estimate_poses(scene, model, bin=cell.bin.bounds, max_instances=4, method="ppf", exclude=aside)
    assert found
    for r in found:
        assert not aside[r.indices].any()
        rot, shift = symmetric_pose_error(r.T_scene_model, pile.pose(int(part)), rotations=[np.eye(3)])
        assert rot > 5 or shift > 3, "the part set aside was found again"
    # Everything set aside: nothing is left to search, and the error says why.
    with pytest.raises(binpick.NoObjectFound, match="excluded"):
        binpick.estimate_poses(scene, model, bin=cell.bin.bounds, method="ppf", exclude=np.ones(len(scene), bool))
    with pytest.raises(binpick.DTypeError, match="exclude"):
        binpick.estimate_poses(scene, model, exclude=aside.astype(np.int8))
    with pytest.raises(binpick.ShapeError, match="exclude"):
        binpick.estimate_poses(scene, model, exclude=aside[:-1])


def test_the_feature_table_is_cached_on_disk_and_a_corrupt_cache_is_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("BINPICK_CACHE_DIR", str(tmp_path))
    a = make_part("bracket")
    first = a.prepared()
    assert not first.ppf_from_cache() and first.ppf_pairs() > 10_000
    files = list((tmp_path / "ppf").glob("*.bin"))
    assert len(files) == 1
    b = make_part("bracket")
    assert b.prepared().ppf_from_cache()
    assert b.prepared().ppf_bytes() == first.ppf_bytes()
    # Other parameters: another file.
    b.prepared(binpick.PpfParams(sampling_ratio=0.06))
    assert len(list((tmp_path / "ppf").glob("*.bin"))) == 2
    # A corrupt file is rebuilt (and rewritten), never an error.
    files[0].write_bytes(files[0].read_bytes()[:1000])
    c = make_part("bracket")
    assert not c.prepared().ppf_from_cache()
    table = first.ppf_bytes()
    assert files[0].read_bytes() == table + hashlib.sha256(table).digest()  # the table, then its digest


def test_bad_requests_raise_clear_errors(parts):
    model = parts["bracket"]
    scene = np.random.default_rng(0).uniform(0, 100, (500, 3))
    with pytest.raises(binpick.InvalidInputError, match="max_instances"):
        binpick.estimate_poses(scene, model, max_instances=0)
    with pytest.raises(binpick.InvalidInputError, match="method"):
        binpick.estimate_poses(scene, model, method="fpfh")
    with pytest.raises(binpick.InvalidInputError, match="reference_fraction"):
        binpick.estimate_poses(scene, model, reference_fraction=1.5)
    with pytest.raises(binpick.InvalidInputError, match="viewpoint"):
        binpick.estimate_poses(scene, model, viewpoint=(0, 0))
    for light in ((0, 0), (0, np.nan, 500)):
        with pytest.raises(binpick.InvalidInputError, match="light"):
            binpick.estimate_poses(scene, model, light=light)
    with pytest.raises(binpick.InvalidInputError, match="sampling_ratio"):
        model.prepared(ppf=binpick.PpfParams(sampling_ratio=0.9))


def test_estimate_command_reads_a_mesh_file_and_reports_instances(parts, tmp_path, capsys):
    import json

    from _geometry import write_stl_binary
    from binpick.cli import main

    v, f = extruded_mesh(L_BRACKET, 30.0)
    write_stl_binary(tmp_path / "bracket.stl", v, f)
    rng = np.random.default_rng(8)
    T = random_pose(rng)
    np.save(tmp_path / "scene.npy", rendered_view(parts["bracket"], T, rng))
    png = tmp_path / "estimate.png"
    code = main(
        [
            "estimate",
            str(tmp_path / "scene.npy"),
            str(tmp_path / "bracket.stl"),
            "--method",
            "ppf",
            "--instances",
            "2",
            "--png",
            str(png),
        ]
    )
    assert code == 0
    docs = json.loads(capsys.readouterr().out)
    assert isinstance(docs, list) and 1 <= len(docs) <= 2 and docs[0]["method"] == "ppf"
    rot_err, trans_err = symmetric_pose_error(np.array(docs[0]["T_scene_model"]), T, rotations=[np.eye(3)])
    assert rot_err < 5 and trans_err < 3
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
