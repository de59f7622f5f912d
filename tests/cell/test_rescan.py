"""Rescanning only what a pick changed: after a clean pick the cell sweeps the band of angles
around the part that left and keeps the rest of the last scan — unless the fresh lines show that
something else moved, or the pick was not clean."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _cell_helpers import recording_tee_cell

from binpick.cell import PickRecord
from binpick.cell.rescan import SEEN_AGAIN, RescanBasis, band, basis_after, laser_angles


def _nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Each point of ``a``'s distance to the nearest of ``b`` (brute force, in chunks)."""
    out = np.empty(len(a))
    for i in range(0, len(a), 256):
        d = np.linalg.norm(a[i : i + 256, None, :] - b[None, :, :], axis=2)
        out[i : i + 256] = d.min(axis=1)
    return out


@pytest.fixture(scope="module")
def after_one_pick():
    """A pile of four tees after one clean pick, the cell set to rescan only what changed; the
    messages the cell printed."""
    sim = recording_tee_cell(count=4, seed=1, frames=60, rescan="changed")
    report = sim.cell.run(1)
    assert report.records[0].success, report.records[0].error
    yield sim, report, sim.lines
    sim.close()


def test_after_a_clean_pick_only_the_band_around_it_is_swept_and_the_cloud_is_the_bins(after_one_pick):
    sim, report, lines = after_one_pick
    basis = sim.cell._basis
    assert basis is not None, "a clean pick leaves a basis for the next scan"
    partial = sim.cell.scan()
    share = partial.timings["rescanned_share"]
    assert 0.0 < share < 0.7
    assert any("rescanned" in m and "around the part that left" in m for s, m in lines if s == "scan")
    # The fresh band covers the part that left: no point of the last scan stays where it lay.
    gone = report.records[0].truth.instance
    assert gone not in {int(i) for i in sim.pile.ids}
    # The merged cloud is the bin as a full scan sees it now: each point near the full scan's.
    full = sim.cell.sweep_views([(sim.config.scan_poses[0], sim.config.angles_for(0))])
    rng = np.random.default_rng(0)
    sample = partial.points[rng.choice(len(partial.points), 1500, replace=False)]
    d = _nearest(sample, full.points)
    assert np.quantile(d, 0.98) < 2.0, np.quantile(d, [0.5, 0.9, 0.98, 1.0])
    # ... and no point was lost: each full-scan point has a merged point nearby.
    back = _nearest(full.points[rng.choice(len(full.points), 1500, replace=False)], partial.points)
    assert np.quantile(back, 0.98) < 2.0, np.quantile(back, [0.5, 0.9, 0.98, 1.0])
    # A band takes its share of the sweep's hardware time, not the whole.
    assert partial.timings["phys.sweep"] < 0.75 * full.timings["phys.sweep"]


def test_a_part_that_moved_outside_the_region_makes_the_cell_scan_the_whole_bin(after_one_pick):
    sim, report, lines = after_one_pick
    sim.cell._basis = basis = basis_after(sim.cell, report.records[0], sim.cell._last[0])
    T = sim.config.scan_poses[0]
    swept = band(sim.cell, basis, sim.config.angles_for(0), T)
    assert swept is not None
    # The part outside the region that the band's sheets cross most: taken away, as if the pick
    # had dragged it off.
    pts = np.asarray(sim.model.points)
    crossed = {}
    for pid, P in zip(sim.pile.ids, sim.pile.poses):
        placed = pts @ P[:3, :3].T + P[:3, 3]
        outside = ~((placed >= basis.lo) & (placed <= basis.hi)).all(axis=1)
        theta = laser_angles(sim.cell, T, placed[outside])
        if outside.mean() > 0.8:
            crossed[int(pid)] = float(np.mean((theta >= swept.min()) & (theta <= swept.max())))
    moved = max(crossed, key=crossed.get, default=None)
    assert moved is not None and crossed[moved] > 0.5, f"the pile of seed 1 has no part beside the region: {crossed}"
    sim.pile.remove(moved)
    lines.clear()
    scan = sim.cell.scan()
    assert any(s == "scan" and m.startswith("rescanning the whole bin") for s, m in lines), lines
    assert "rescanned_share" not in scan.timings
    # The whole sweep's time, and the band's before it.
    assert scan.timings["phys.sweep"] > 60 / 15.0


def test_anything_but_a_clean_pick_scans_the_whole_bin_next(after_one_pick):
    sim, report, _ = after_one_pick
    clean = report.records[0]
    scan = sim.cell._last[0]
    assert basis_after(sim.cell, clean, scan) is not None
    for changed in (
        {"success": False, "failure": "wrong pose"},
        {"held": False},
        {"nudges": (object(),)},
        {"collisions": ({"with": "part 2", "points": 3},)},
        {"looks": 2},
    ):
        assert basis_after(sim.cell, replace(clean, **changed), scan) is None, changed
    assert isinstance(clean, PickRecord)
    full = replace(sim.cell.config, rescan="full")
    sim.cell.config, keep = full, sim.cell.config
    try:
        assert basis_after(sim.cell, clean, scan) is None
    finally:
        sim.cell.config = keep


def test_a_part_is_never_picked_on_points_the_sweep_only_carried_over(after_one_pick):
    sim, report, lines = after_one_pick
    assert len(sim.pile), "parts are left to pick"
    last = sim.cell._last[0]
    lo, hi = (np.asarray(b, dtype=np.float64) for b in sim.config.bin_bounds)
    # Sweep again only around an empty strip along the bin's -x wall: every part lies in points
    # the rescan keeps from the last scan, which a part that settled a little may no longer match.
    pts = np.asarray(sim.model.points)
    placed = np.vstack([pts @ P[:3, :3].T + P[:3, 3] for P in sim.pile.poses])
    # (along the -x or the +x wall, whichever is farther from every part)
    if placed[:, 0].min() - lo[0] > hi[0] - placed[:, 0].max():
        strip = (lo.copy(), np.array([lo[0] + 12.0, hi[1], hi[2]]))
        clear = placed[:, 0].min() - strip[1][0]
    else:
        strip = (np.array([hi[0] - 12.0, lo[1], lo[2]]), hi.copy())
        clear = strip[0][0] - placed[:, 0].max()
    assert clear > 20.0, "the strip is clear of every part"
    sim.cell._basis = RescanBasis(scan=last, lo=strip[0], hi=strip[1])
    partial = sim.cell.scan()
    assert 0 < partial.carried < len(partial.points)
    assert partial.seen_again(np.arange(partial.carried)) == 0.0
    assert partial.seen_again(np.arange(partial.carried, len(partial.points))) == 1.0
    # The same in a pick: the part chosen on kept points is swept again before it is picked.
    sim.cell._basis = RescanBasis(scan=last, lo=strip[0], hi=strip[1])
    lines.clear()
    record, _ = sim.cell._look_and_pick(2, None)  # one pick of a run (run() starts with a whole scan)
    said = [m for s, m in lines if s == "scan"]
    assert any("kept the last scan's points: it is swept again" in m for m in said), said
    scan, located = sim.cell._last
    assert scan.seen_again(located.indices) >= SEEN_AGAIN
    assert record.success and record.truth.pick_grade, record.error


def test_the_band_also_sweeps_the_part_planned_next(after_one_pick):
    sim, report, _ = after_one_pick
    last = sim.cell._last[0]
    basis = basis_after(sim.cell, report.records[0], last) or RescanBasis(
        scan=last, lo=np.asarray(sim.config.bin_bounds[0], float), hi=np.asarray(sim.config.bin_bounds[0], float) + 10
    )
    T = sim.config.scan_poses[0]
    wanted = np.asarray(sim.config.angles_for(0))
    lo, hi = (np.asarray(b, dtype=np.float64) for b in sim.config.bin_bounds)
    # A box at the far +x end of the bin, which the region's own band does not reach.
    far = (np.array([hi[0] - 30.0, lo[1], lo[2]]), np.array([hi[0] - 10.0, hi[1], lo[2] + 20.0]))
    corners = [[x, y, z] for x in (far[0][0], far[1][0]) for y in (lo[1], hi[1]) for z in (far[0][2], far[1][2])]
    theta = laser_angles(sim.cell, T, np.array(corners))
    own = band(sim.cell, replace(basis, lo=lo, hi=lo + 10.0), wanted, T)
    assert own is not None and not ((own >= theta.min()) & (own <= theta.max())).any()
    both = band(sim.cell, replace(basis, lo=lo, hi=lo + 10.0, also=(far,)), wanted, T)
    assert both is None or ((both >= theta.min()) & (both <= theta.max())).any()
