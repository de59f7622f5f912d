"""Grasps for any part: antipodal parallel-jaw grasps sampled from a mesh without declared grasps or
branches, and a user's STL part picked with them in the simulated cell (issue 14 item 2)."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from _geometry import write_stl_ascii
from binpick.cell import GripperGeometry
from binpick.cell.grasp import mesh_grasps
from binpick.sim import SimulatedCell


def extruded_l(height: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """An L profile (60 × 45 mm, arms 18 mm wide, counter-clockwise) extruded ``height`` mm, outward-wound."""
    ring = [(0, 0), (60, 0), (60, 18), (18, 18), (18, 45), (0, 45), (0, 18)]
    n = len(ring)
    v = np.array([(x, y, z) for z in (0.0, height) for x, y in ring], dtype=float)
    caps = [(0, 1, 2), (0, 2, 3), (0, 3, 6), (6, 3, 4), (6, 4, 5)]
    f = [(c, b, a) for a, b, c in caps] + [(a + n, b + n, c + n) for a, b, c in caps]
    for a in range(n):
        b = (a + 1) % n
        f += [(a, b, b + n), (a, b + n, a + n)]
    return v, np.array(f)


@pytest.fixture(scope="module")
def ell(tmp_path_factory):
    path = tmp_path_factory.mktemp("part") / "ell.stl"
    v, f = extruded_l()
    write_stl_ascii(path, (v - v.mean(axis=0)) / 1000.0, f)  # a user's part, in metres
    return binpick.Model.from_mesh(path, unit="m")


def test_mesh_grasps_close_across_the_part_within_the_stroke(ell):
    g = GripperGeometry()
    grasps = mesh_grasps(ell, g)
    assert grasps and all(name.startswith("mesh") for name in grasps)
    pts = np.asarray(ell.points)
    for T_go in list(grasps.values())[:: max(1, len(grasps) // 40)]:
        local = pts @ T_go[:3, :3].T + T_go[:3, 3]
        inside = local[g.between_fingers(local) & (np.abs(local[:, 0]) < g.open_width_mm / 2)]
        # Material on both sides of the TCP within the open stroke: the fingers close on the part.
        assert (inside[:, 0] > 1.0).any() and (inside[:, 0] < -1.0).any()
        x = T_go[:3, :3].T[:, 0]  # the closing direction in the part's frame: along a face normal
        assert np.isclose(np.abs(x).max(), 1.0, atol=1e-6)


def test_an_stl_part_without_grasps_is_picked_with_generated_grasps(ell):
    with SimulatedCell(ell, count=1, seed=0, frames=60, estimate_options={"d_star": 12.0, "min_points": 500}) as sim:
        assert all(name.startswith("mesh") for name in sim.cell.config.grasps)
        report = sim.cell.run(1)
        assert sim.emulator_failures == []
        remaining = len(sim.pile.ids)
    record = report.records[0]
    assert record.success, record.error
    assert record.held is True and remaining == 0


def test_a_plate_lying_on_the_floor_is_pinched_from_above_by_its_edges():
    """A plate 10 mm thick lying flat: a grasp with the TCP at its middle reaches the fingertips
    5 mm through the floor; each mesh grasp's shallow variant bites SHALLOW_BITE_MM past the
    contacts, and the simulated cell lifts the plate with one."""
    from binpick.cell.grasp_sets import SHALLOW_BITE_MM

    plate, g = binpick.parts.cut_plate(), GripperGeometry()
    grasps = mesh_grasps(plate, g)
    shallow = {n: T for n, T in grasps.items() if n.endswith("/shallow")}
    assert len(shallow) == len(grasps) // 2
    for name, T_go in shallow.items():
        full = grasps[name.removesuffix("/shallow")]
        # The same closing and approach, the TCP drawn back along the approach by tip - bite.
        np.testing.assert_allclose(T_go[:3, :3], full[:3, :3], atol=1e-12)
        np.testing.assert_allclose(T_go[2, 3] - full[2, 3], g.tip_depth_mm - SHALLOW_BITE_MM, atol=1e-9)
    with SimulatedCell(plate, count=1, seed=0, frames=60) as sim:
        report = sim.cell.run(1)
        remaining = len(sim.pile.ids)
    record = report.records[0]
    assert record.held is True and remaining == 0, record.error
    assert record.grasp.endswith("/shallow")


def test_a_shaft_standing_steeper_than_the_tool_may_tilt_is_gripped_end_on():
    """A keyed shaft (150 mm) leaning 60° up from the floor with its keyway out of view (a free
    axis): across its body the tool would tilt 60°, past the 45° limit; the mesh grasps keep pairs
    near its ends, and one of them, closing square to the axis with the TCP on it (valid at any
    turn of the shaft), comes down along the shaft within the limit."""
    from types import SimpleNamespace

    from binpick.cell.grasp import grasp_filter, plan_grasp
    from binpick.transforms import rotation_about

    shaft = binpick.parts.keyed_shaft()
    with SimulatedCell(shaft, count=1, seed=0, frames=4) as sim:
        cfg, here = sim.cell.config, sim.robot_emulator.pose()
    g = cfg.gripper
    # Pairs within reach of the fingers from each end (the shaft runs along z, centred).
    mids = np.array([-(T[:3, :3].T @ T[:3, 3]) for T in cfg.grasps.values()])
    half = float(np.ptp(np.asarray(shaft.points)[:, 2])) / 2
    assert (mids[:, 2] > half - g.finger_length_mm + 10.0).any() and (
        mids[:, 2] < -half + g.finger_length_mm - 10.0
    ).any()
    lo, hi = cfg.bin_bounds
    T = np.eye(4)
    T[:3, :3] = rotation_about(np.array([1.0, 0.0, 0.0]), np.radians(30.0))  # the axis 30° off vertical
    T[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] + 12.0 + 75.0 * np.cos(np.radians(30.0))]
    axis = T[:3, 2]
    result = SimpleNamespace(T_scene_model=T, ambiguous=False, alternatives=(), free_axis=axis, confidence=0.03)
    plan, _ = plan_grasp(cfg, T, np.zeros((0, 3)), here, grasp_filter(cfg, result), free_turn=True)
    assert plan.tilt_deg <= 45.0 + 1e-6
    T_bg = plan.T_base_gripper
    assert abs(T_bg[:3, 0] @ axis) < 0.1  # closing square to the shaft
    assert abs(T_bg[:3, 2] @ axis) > 0.85  # coming down along it, end-on
