"""Property tests of the cell's public API over its argument space (issue 16 item 6): the
gripper geometry, the cell configuration, grasp generation, matching and symmetry maps, grasp and
nudge planning, the static poses' check, and the cell file read from hostile TOML (and turned
into a cell on emulated ports) each end in a result or a BinpickError (TypeError for a wrong
Python type), within seconds, and what they return is what they promise: a plan's whole motion
passes the cell's motion rules, a declared grasp matches itself modulo the part's symmetries.

What they found in cell/* (FOUND, PLANNING_FOUND) is fixed and kept as plain refusal tests."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import binpick
from _files import small_calibration
from _properties import PROPERTY, anything, finite, ints, mostly, outcome, reals, rigid, transforms, variations, vectors
from binpick import errors
from binpick.cell import (
    CELL_FILE_EXAMPLE,
    CellConfig,
    FolderReplay,
    GraspMatcher,
    GripperGeometry,
    branch_grasps,
    cell_from_file,
    check_static_poses,
    config_from_file,
    load_cell_file,
    plan_grasp,
    plan_nudge,
    sweep_angles,
    symmetry_maps,
)
from binpick.devices import CellLimits, safety
from binpick.devices.emulators import DynamixelEmulator, GripperEmulator, RobotEmulator
from binpick.transforms import inverse, look_down

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


# --------------------------------------------------------------------------- planning

BIN_CENTRE = (400.0, 0.0)
HERE = look_down(400.0, 0.0, 450.0)


@pytest.fixture(scope="module")
def config(tee):
    return CellConfig(**_valid_config(tee))


#: The tee lying in the bin (turned about z, anywhere on the floor) three times in four.
lying = mostly(
    st.builds(
        lambda yaw, x, y: rigid(yaw, (0.0, 0.0, 1.0), (BIN_CENTRE[0] + x, BIN_CENTRE[1] + y, 13.0)),
        st.floats(-math.pi, math.pi),
        st.floats(-100.0, 100.0),
        st.floats(-60.0, 60.0),
    ),
    transforms,
)
scenes = mostly(
    st.integers(0, 200).map(lambda n: np.random.default_rng(n).uniform((250, -100, 0), (550, 100, 60), (n, 3))),
    st.sampled_from([np.zeros((5, 2)), np.full((3, 3), np.nan), np.zeros(6)]),
    anything,
)
flange_poses = mostly(st.builds(lambda z: look_down(400.0, 0.0, z), st.floats(250.0, 500.0)), transforms)


def _assert_safe(config, T_start, waypoints, *, push=False):
    """The whole motion of a plan passes the cell's motion rules from ``T_start``."""
    poses, linear = [T for _, T, _ in waypoints], [lin for _, _, lin in waypoints]
    safety.check_sequence(T_start, poses, linear, config.limits, push=push)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(
    T=lying,
    scene=scenes,
    here=flange_poses,
    accept=mostly(st.sampled_from([None, lambda T: True, lambda T: T[0, 3] < 400.0]), st.just(lambda T: False)),
    which=mostly(st.just("config")),
)
def test_property_plan_grasp(config, T, scene, here, accept, which):
    cfg = config if which == "config" else which
    planned = outcome(lambda: plan_grasp(cfg, T, scene, here, accept), "plan_grasp")
    if planned is not None:
        plan, hits = planned
        assert plan.grasp in config.grasps and 0 <= hits <= config.max_collision_points
        np.testing.assert_allclose(plan.T_base_gripper, T @ inverse(config.grasps[plan.grasp]), atol=1e-9)
        assert plan.tilt_deg <= math.degrees(config.limits.max_tool_tilt_rad) + 1e-9
        assert accept is None or accept(plan.T_base_gripper)
        _assert_safe(config, here, plan.waypoints)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(T=lying, scene=scenes, T_now=flange_poses, which=mostly(st.just("config")))
def test_property_plan_nudge(config, T, scene, T_now, which):
    cfg = config if which == "config" else which
    plan = outcome(lambda: plan_nudge(cfg, T, scene, T_now), "plan_nudge")
    if plan is not None:
        np.testing.assert_array_equal(plan.T_base_object, T)
        assert plan.tip_z_mm > config.bin_bounds[0][2] + config.floor_clearance_mm
        _assert_safe(config, T_now, plan.waypoints, push=True)


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 30))
@given(
    wild=st.fixed_dictionaries(
        {},
        optional=dict(
            scan_poses=st.lists(flange_poses, min_size=1, max_size=2),
            drop_pose=flange_poses,
            clearance_z_mm=st.one_of(st.none(), reals(100.0, 600.0)),
            look_again_poses=st.one_of(st.none(), st.lists(flange_poses, max_size=2)),
            limits=st.builds(
                CellLimits, approach_height_mm=st.floats(100.0, 400.0), workspace_max_mm=st.just((700.0, 400.0, 700.0))
            ),
        ),
    ),
    which=mostly(st.just("config")),
)
def test_property_check_static_poses(tee, wild, which):
    def check():
        cfg = CellConfig(**{**_valid_config(tee), **wild}) if which == "config" else which
        check_static_poses(cfg)
        return cfg

    cfg = outcome(check, "check_static_poses")
    if cfg is not None:
        lim = cfg.limits
        for T in (*cfg.scan_poses, *cfg.look_again_poses, cfg.drop_pose):
            safety.check_pose(T, lim)
            assert T[2, 3] >= lim.approach_height_mm
        assert lim.approach_height_mm <= cfg.clearance_z_mm <= lim.workspace_max_mm[2]


@PROPERTY
@given(
    picks=st.lists(st.integers(0, 4319), min_size=1, max_size=5, unique=True),
    wild=variations(
        {},
        {
            "grasps": st.one_of(st.lists(transforms, max_size=2), st.dictionaries(st.text(max_size=2), transforms)),
            "symmetries": st.one_of(st.lists(transforms, max_size=2), anything),
            "tolerance_deg": reals(0.1, 30.0),
            "tolerance_mm": reals(0.1, 20.0),
        },
    ),
    T=transforms,
)
def test_property_grasp_matcher(config, tee, picks, wild, T):
    names = list(config.grasps)
    valid = {
        "grasps": {names[i]: config.grasps[names[i]] for i in picks},
        "symmetries": symmetry_maps(tee.symmetries),
        "tolerance_deg": 12.0,
        "tolerance_mm": 6.0,
    }
    kw = {**valid, **wild}
    matcher = outcome(lambda: GraspMatcher(kw.pop("grasps"), kw.pop("symmetries"), **kw), "GraspMatcher")
    if matcher is None:
        return
    error = outcome(lambda: matcher.error(T), "GraspMatcher.error")
    if error is not None:
        assert all(math.isfinite(v) and v >= 0 for v in error) and matcher.cost(error) >= 0
    if "grasps" not in wild and "symmetries" not in wild:  # a declared grasp, turned by a symmetry or not, matches
        for S in (np.eye(4), *valid["symmetries"]):
            deg, mm = matcher.error(valid["grasps"][names[picks[0]]] @ S)
            assert deg < 1e-4 and mm < 1e-6 and matcher.within((deg, mm))


# --------------------------------------------------------------------------- the cell from its file


@pytest.fixture(scope="module")
def emulated_ports(cell_dir):
    """The robot, laser-motor and gripper emulators on ptys, and a recorded scan for the replay camera."""
    from _files import small_scan

    small_scan(cell_dir / "scan")
    emulators = [RobotEmulator().start(), DynamixelEmulator().start(), GripperEmulator().start()]
    yield [e.slave_path for e in emulators]
    for e in emulators:
        e.close()
    assert all(e.failures == [] for e in emulators)


def _on_emulators(text: str, ports: list) -> str:
    """The cell file ``text`` with its ports the emulators' and its camera a replay of the scan."""
    for old, new in zip(("/dev/ttyUSB0", "/dev/ttyUSB1", "/dev/ttyUSB2"), ports):
        text = text.replace(old, new)
    return text.replace('source = "opencv"', 'source = "replay"\nfolder = "scan"')


@settings(PROPERTY, max_examples=min(PROPERTY.max_examples, 25))
@given(
    text=mostly(st.just(CELL_FILE_EXAMPLE), hostile),
    progress=mostly(st.sampled_from([None, print]), anything),
    threads=ints(0, 300),
    which=mostly(st.just("file")),
)
def test_property_cell_from_file(cell_dir, emulated_ports, text, progress, threads, which):
    path = cell_dir / "cell.toml"
    path.write_text(_on_emulators(text, emulated_ports))

    def build():
        return cell_from_file(
            load_cell_file(path) if which == "file" else which, progress=progress, num_threads=threads
        )

    cell = outcome(build, "cell_from_file")
    if cell is not None:
        try:
            assert isinstance(cell.camera, FolderReplay) and cell.robot.limits == cell.config.limits
            assert cell.config.num_threads == threads
        finally:
            for close in (cell.robot.close, cell.motor.close, cell.gripper.close_port, cell.camera.close):
                close()


#: What the planning and cell-file properties found (AttributeError, IndexError, ValueError from
#: deep inside, or a wrong answer), refused now with an InvalidInputError naming the argument.
PLANNING_FOUND = [
    (lambda cfg: plan_grasp(None, np.eye(4), np.zeros((0, 3)), HERE), "config"),
    (lambda cfg: plan_grasp(cfg, None, np.zeros((0, 3)), HERE), "T_base_object"),
    (lambda cfg: plan_grasp(cfg, np.eye(4) * 2, np.zeros((0, 3)), HERE), "T_base_object"),  # was planned
    (lambda cfg: plan_grasp(cfg, np.eye(4), np.zeros((5, 2)), HERE), "scene"),
    (lambda cfg: plan_grasp(cfg, np.eye(4), np.zeros((0, 3)), HERE, accept=3), "accept"),
    (lambda cfg: plan_nudge(cfg, 3, np.zeros((0, 3)), HERE), "T_base_object"),
    (lambda cfg: plan_nudge(cfg, np.eye(4), [1, 2], HERE), "scene"),
    (lambda cfg: check_static_poses(None), "config"),
    (lambda cfg: GraspMatcher([], tolerance_deg=5.0, tolerance_mm=3.0), "grasps"),
    (lambda cfg: GraspMatcher({"a": "x"}, tolerance_deg=5.0, tolerance_mm=3.0), r"grasps\['a'\]"),
    (lambda cfg: GraspMatcher([np.eye(4)], [None], tolerance_deg=5.0, tolerance_mm=3.0), r"symmetries\[0\]"),
    (lambda cfg: GraspMatcher([np.eye(4)], tolerance_deg=5.0, tolerance_mm=3.0).error(None), "T_gripper_object"),
    (lambda cfg: cell_from_file("cell.toml"), "cell_file"),
    (lambda cfg: branch_grasps(cfg.model, steps=10**9), "steps"),  # would have built 2e10 grasps
]


@pytest.mark.parametrize("call, name", PLANNING_FOUND)
def test_planning_arguments_found_by_the_properties(config, call, name):
    with pytest.raises(errors.InvalidInputError, match=name):
        call(config)


def test_branch_grasps_finer_than_a_degree_keep_every_direction(tee):
    """Grasps were named by the whole degree: with 400 steps, 40 directions shared a name with their
    neighbour and were silently dropped (21600 grasps instead of 24000)."""
    grasps = branch_grasps(tee, steps=400)
    # per direction: 5 pitches and 2 end pitches, both wrist ways, and the end-on one, each raised or not
    assert len(grasps) == 400 * (5 * 2 + 2 * 2 + 1) * 2 * len(tee.branches)
    assert "branch0/0.9°/flipped" in grasps and "branch0/5°" in branch_grasps(tee, steps=72)


def test_a_cell_whose_progress_is_not_a_function_is_refused_and_its_ports_closed(cell_dir, emulated_ports):
    path = cell_dir / "cell.toml"
    path.write_text(_on_emulators(CELL_FILE_EXAMPLE, emulated_ports))
    with pytest.raises(errors.InvalidTypeError, match="progress"):
        cell_from_file(load_cell_file(path), progress="verbose")
    cell = cell_from_file(load_cell_file(path))  # the ports were closed: they open again
    for close in (cell.robot.close, cell.motor.close, cell.gripper.close_port, cell.camera.close):
        close()
