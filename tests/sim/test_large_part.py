"""A part too long for the paper's bin gets a cell grown to it (bin, scan pose, lens, arm), and
the simulated cell empties a pile of it — a continuously symmetric shaft whose located turn about
its axis is arbitrary, so the twin's gripper must match grips modulo that turn."""

import itertools

import numpy as np
import pytest

import binpick
from binpick.sim import SIM_ARM, Cell, SimulatedCell, sim_arm
from binpick.transforms import inverse


@pytest.fixture(scope="module")
def shaft():
    # 400 mm long: twice what the default 300 mm bin takes (2/3 of its length).
    return binpick.parts.keyed_shaft(diameter=40.0, length=400.0, feature=False, spacing=3.0)


def test_parts_that_fit_keep_the_papers_cell():
    default = Cell()
    for part in (binpick.parts.tee(), binpick.parts.elbow(), binpick.parts.cross()):
        cell = Cell.for_part(part)
        assert cell.bin == default.bin and cell.camera == default.camera
        assert np.array_equal(cell.T_base_flange, default.T_base_flange)
        assert sim_arm(cell) is SIM_ARM


def test_a_long_part_gets_a_larger_bin_that_the_camera_sees_and_the_arm_reaches(shaft):
    cell = Cell.for_part(shaft)
    (x0, y0, z0), (x1, y1, z1) = cell.bin.bounds
    assert x1 - x0 == pytest.approx(1.5 * 400.0, rel=1e-3)  # the part's length is 2/3 of the bin's
    assert (y1 - y0) / (x1 - x0) == pytest.approx(200.0 / 300.0) and z1 - z0 > 80.0
    assert x0 == pytest.approx(Cell().bin.bounds[0][0])  # the near wall stays where it was
    # Every corner of the bin's rim and floor projects inside the image from the scan pose.
    T_cb = inverse(cell.T_base_camera)
    cam = cell.camera
    for corner in itertools.product((x0, x1), (y0, y1), (z0, z1)):
        p = T_cb[:3, :3] @ np.array(corner) + T_cb[:3, 3]
        u, v = cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy
        assert 0 < u < cam.width and 0 < v < cam.height, f"bin corner {corner} is out of view at ({u:.0f}, {v:.0f})"
    # The calibration board moved aside with the view: none of it is in the scan's image.
    (bx0, by0), (bx1, by1) = cell.board.extent
    for bx, by in itertools.product((bx0, bx1), (by0, by1)):
        corner = (cell.board.T_base_board @ np.array([bx, by, 0.0, 1.0]))[:3]
        p = T_cb[:3, :3] @ corner + T_cb[:3, 3]
        v = cam.fy * p[1] / p[2] + cam.cy
        assert not 0 < v < cam.height, f"board corner {corner} is in view"
    arm = sim_arm(cell)
    assert arm is not SIM_ARM and arm.upper_arm_mm > SIM_ARM.upper_arm_mm


def test_the_simulated_cell_empties_a_pile_of_long_shafts(shaft):
    with SimulatedCell(shaft, count=2, seed=0, frames=40) as sim:
        assert sim.layout.bin.size[0] > 500.0
        report = sim.cell.run(2)
        assert sim.emulator_failures == []
        left = len(sim.pile.ids)
    picked = [r for r in report.records if r.success]
    assert left == 0, f"{left} shafts left: {report.stopped}"
    assert len(picked) == 2 and all(r.failure is None for r in picked)
