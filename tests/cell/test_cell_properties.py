"""Property tests of the cell's public API over its argument space (issue 16 item 6): the
gripper geometry, the cell configuration, grasp generation and symmetry maps, and the cell file
read from hostile TOML each end in a result or a BinpickError (TypeError for a wrong Python
type), within seconds, and what they return is what they promise.

What they found in cell/* (FOUND) is fixed and kept as plain refusal tests."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import binpick
from _files import small_calibration
from _properties import PROPERTY, anything, finite, ints, outcome, reals, transforms, variations, vectors
from binpick import errors
from binpick.cell import (
    CELL_FILE_EXAMPLE,
    CellConfig,
    GripperGeometry,
    branch_grasps,
    config_from_file,
    load_cell_file,
    sweep_angles,
    symmetry_maps,
)
from binpick.transforms import look_down

SIZES = ("open_width_mm", "finger_length_mm", "finger_width_mm", "finger_thickness_mm")
SIZES += ("tip_depth_mm", "body_radius_mm", "body_length_mm")


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee(resolution=2.0, spacing=2.0)


@pytest.fixture(scope="module")
def cell_dir(tmp_path_factory, tee):
    """A cell folder whose part "tee" is the module's (built once, not per file read)."""
    root = tmp_path_factory.mktemp("cell")
    small_calibration().save(root / "calibration.toml")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(binpick.parts, "tee", lambda: tee)
        yield root


@PROPERTY
@given(kw=variations({}, {"T_flange_gripper": transforms, **{name: reals(-5, 200) for name in SIZES}}))
def test_property_gripper_geometry(kw):
    g = outcome(lambda: GripperGeometry(**kw), "GripperGeometry")
    if g is not None:
        assert all(np.isfinite(float(getattr(g, name))) and getattr(g, name) >= 0 for name in SIZES)
        np.testing.assert_allclose(g.T_flange_gripper[:3, :3].T @ g.T_flange_gripper[:3, :3], np.eye(3), atol=1e-6)


def _valid_config(tee):
    return dict(
        calibration=small_calibration(),
        model=tee,
        bin_bounds=((250.0, -100.0, 0.0), (550.0, 100.0, 80.0)),
        scan_poses=(look_down(400.0, 0.0, 450.0),),
        drop_pose=look_down(400.0, -250.0, 350.0),
        frames=4,
    )


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(
    data=st.data(),
    wild=st.fixed_dictionaries(
        {},
        optional=dict(
            bin_bounds=st.one_of(st.tuples(vectors(3, -500, 500), vectors(3, -500, 800)), anything),
            scan_poses=st.one_of(st.lists(transforms, max_size=2), anything),
            drop_pose=transforms,
            frames=ints(-1, 200),
            scan_angles=st.one_of(st.none(), st.lists(vectors(3, -1, 1), max_size=2), anything),
            approach_distance_mm=reals(-10, 200),
            clearance_z_mm=st.one_of(st.none(), reals(-100, 800)),
            max_collision_points=ints(-1, 100),
            floor_clearance_mm=reals(-10, 50),
            min_confidence=reals(-1, 2),
            ambiguity_tolerance_deg=reals(-1, 90),
            ambiguity_tolerance_mm=reals(-1, 50),
            max_candidates=ints(-1, 20),
            min_score=reals(-1, 2),
            keep_frames=ints(-1, 20),
            num_threads=ints(-1, 300),
            calibration=anything,
            model=anything,
            gripper=anything,
            limits=anything,
        ),
    ),
)
def test_property_cell_config(tee, data, wild):
    keys = data.draw(st.lists(st.sampled_from(sorted(wild)), max_size=2, unique=True)) if wild else []
    kw = {**_valid_config(tee), **{k: wild[k] for k in keys}}
    c = outcome(lambda: CellConfig(**kw), "CellConfig")
    if c is not None:
        assert 1 <= c.frames and c.approach_distance_mm >= 0 and c.max_candidates >= 1
        assert 0 <= c.num_threads and finite(np.asarray(c.bin_bounds, float))


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 20))
@given(width=reals(-5, 100), steps=ints(-1, 400))
def test_property_branch_grasps(tee, width, steps):
    grasps = outcome(lambda: branch_grasps(tee, finger_width_mm=width, steps=steps), "branch_grasps")
    if grasps is not None:
        # Two closing sides per step and branch, each in every pitch (and raised variants).
        per_pose = 2 * steps * len(tee.branches)
        assert len(grasps) >= per_pose and len(grasps) % per_pose == 0
        assert all(T.shape == (4, 4) and finite(T) for T in grasps.values())


@PROPERTY
@given(symmetries=st.one_of(st.just("tee"), anything))
def test_property_symmetry_maps(tee, symmetries):
    sym = tee.symmetries if symmetries == "tee" else symmetries
    maps = outcome(lambda: symmetry_maps(sym), "symmetry_maps")
    if maps is not None:
        assert all(np.allclose(S[:3, :3].T @ S[:3, :3], np.eye(3)) for S in maps)


@PROPERTY
@given(frames=ints(-1, 300), margin=reals(-50, 50))
def test_property_sweep_angles(tee, frames, margin):
    c = _valid_config(tee)
    angles = outcome(
        lambda: sweep_angles(c["calibration"], c["scan_poses"][0], c["bin_bounds"], frames, margin=margin),
        "sweep_angles",
    )
    if angles is not None:
        assert len(angles) == frames and finite(angles)


hostile = st.one_of(
    st.builds(
        lambda i, t: CELL_FILE_EXAMPLE[:i] + t + CELL_FILE_EXAMPLE[i:],
        st.integers(0, len(CELL_FILE_EXAMPLE)),
        st.one_of(st.text(max_size=8), st.sampled_from(["[" * 3000, "1e999", "-1", "9" * 5000, '"', "\n[cell]\n"])),
    ),
    st.builds(
        lambda key, value: CELL_FILE_EXAMPLE.replace(key + " = ", f"{key} = {value}\n_{key} = ", 1),
        st.sampled_from(["frames", "bin_min_mm", "scan_pose", "drop_pose", "tool", "calibration", "model"]),
        st.sampled_from(
            ["-1", "1e999", "nan", "[]", "[[1]]", '"x"', "2e19", "true", "{a = 1}", "18446744073709551616"]
        ),
    ),
)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(text=hostile)
def test_property_cell_file_from_hostile_toml(cell_dir, text):
    path = cell_dir / "cell.toml"
    path.write_text(text)
    config = outcome(lambda: config_from_file(load_cell_file(path)), "config_from_file")
    if config is not None:
        assert config.frames >= 1 and finite(config.drop_pose) and finite(np.asarray(config.bin_bounds, float))


@pytest.mark.parametrize("path", ["/nonexistent/cell.toml", "/", "\x00", 3, None])
def test_load_cell_file_refuses_unreadable_paths(path):
    with pytest.raises((errors.BinpickError, TypeError)):
        load_cell_file(path)


#: What the properties found in cell/*.
FOUND = [
    (lambda: symmetry_maps(None), "symmetries"),
    (lambda: symmetry_maps(3), "symmetries"),
]


@pytest.mark.parametrize("call, name", FOUND)
def test_cell_arguments_found_by_the_properties(call, name):
    with pytest.raises(errors.InvalidInputError, match=name):
        call()


@pytest.mark.parametrize("name, value", [("min_confidence", 10**400)])
def test_cell_config_numbers_found_by_the_bench(tee, name, value):
    """benches/hardening.py (class cell): OverflowError from float() of an integer beyond the float range."""
    with pytest.raises(errors.InvalidInputError, match=name):
        CellConfig(**_valid_config(tee), **{name: value})
