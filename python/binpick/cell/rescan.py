"""Rescanning only what a pick changed (``CellConfig.rescan = "changed"``).

After a clean pick — the gripper held the part, it left, nothing was nudged or touched on the
way — the bin differs from the last scan around the part that left: its place, and what leaned
on it. The next scan then sweeps only the laser angles whose sheets cross that region (the
part's box at its located pose, grown by half its size on every side: a neighbour that leaned
on it settles within that), and keeps the last scan's points lit by the other angles.

A sheet crosses the whole bin, so the fresh lines also show the bin outside the region. Where
those lines and the last scan's points see the same surface (a height map of 2 mm cells), they
must agree: when more than :data:`CHANGED_SHARE` of the shared cells moved by more than
:data:`CHANGED_MM`, something outside the region moved, and the cell scans the whole bin. So it
does after anything but a clean pick, for a look from another pose, for a cell with more than
one scan pose, and when the region's sweep would take more than :data:`MAX_SHARE` of the full one.

A move smaller than that test sees (a part tilted a few degrees as the pile settled) can hide
in the points kept, so no pick is made on them: the sweep also covers the part planned next
(``plan_ahead``), and a part chosen whose points the sweep did not see again (less than
:data:`SEEN_AGAIN` of them, :meth:`ScanResult.seen_again`) makes the cell scan the whole bin
before it picks (:meth:`binpick.cell.Cell.scan`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, Optional

import numpy as np

from ..transforms import sheet_angles
from .records import PickRecord, ScanResult

__all__ = [
    "CHANGED_MM",
    "CHANGED_SHARE",
    "MAX_SHARE",
    "RescanBasis",
    "SEEN_AGAIN",
    "basis_after",
    "band",
    "clean_pick",
    "laser_angles",
    "part_box",
    "rescan",
]

#: A height-map cell whose fresh height differs from the last scan's by more than this, mm,
#: has changed (well above the scan's noise, below any part's thickness).
CHANGED_MM = 3.0
#: Share of the cells both scans see, outside the rescanned region, that may change before the
#: cell trusts no part of the last scan.
CHANGED_SHARE = 0.02
#: A region whose sweep takes more than this share of the full sweep's angles is scanned whole.
MAX_SHARE = 0.6
#: Height-map cell, mm.
CELL_MM = 2.0
#: A part is picked from a rescan only when at least this share of its points are fresh.
SEEN_AGAIN = 0.75


@dataclass(frozen=True)
class RescanBasis:
    """What a partial rescan builds on: the last scan, and the box (base frame, mm) the part
    that left it occupied, grown by half the part's size; ``also``, boxes the sweep must cover
    too, though nothing is expected to change there (the part planned next, whose pose the
    fresh lines must confirm)."""

    scan: ScanResult
    lo: np.ndarray
    hi: np.ndarray
    also: tuple[tuple[np.ndarray, np.ndarray], ...] = ()


def clean_pick(record: PickRecord) -> bool:
    """Whether ``record``'s pick changed the bin only where its part was: it succeeded, the
    gripper did not close on nothing, nothing was nudged or touched, and it took one look."""
    return bool(
        record.success
        and record.held is not False
        and not record.nudges
        and not record.collisions
        and record.looks == 1
        and record.T_base_object is not None
    )


def basis_after(cell: Any, record: PickRecord, scan: Optional[ScanResult]) -> Optional[RescanBasis]:
    """The basis for rescanning only what ``record``'s pick changed, or None when the next scan
    must be whole (see the module docstring)."""
    cfg = cell.config
    if (
        cfg.rescan != "changed"
        or not clean_pick(record)
        or scan is None
        or len(cfg.scan_poses) != 1
        or len(scan.angles) < 2
    ):
        return None
    lo, hi = part_box(cfg.model, record.T_base_object, 0.5)
    return RescanBasis(scan=scan, lo=lo, hi=hi)


def part_box(model: Any, T_base_object: np.ndarray, grow: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The box (base frame, mm) of ``model``'s points at ``T_base_object``, grown on every side
    by ``grow`` times the part's size."""
    pts = np.asarray(model.points, dtype=np.float64)
    T = np.asarray(T_base_object, dtype=np.float64)
    placed = pts @ T[:3, :3].T + T[:3, 3]
    margin = grow * float(np.ptp(pts, axis=0).max())
    return placed.min(axis=0) - margin, placed.max(axis=0) + margin


def laser_angles(cell: Any, T_base_flange: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The motor angle (rad) whose laser sheet passes through each point (base frame) with the
    flange at ``T_base_flange`` (:func:`binpick.transforms.sheet_angles`)."""
    cal = cell.config.calibration
    return sheet_angles(T_base_flange @ cal.T_flange_camera @ cal.T_camera_laser, points)


def band(cell: Any, basis: RescanBasis, wanted: np.ndarray, T_base_flange: np.ndarray) -> Optional[np.ndarray]:
    """The angles of ``wanted`` whose sheets cross the basis's region and its ``also`` boxes
    (one step beyond them on each side), or None when that is most of the sweep."""
    corners = np.array([[x, y, z] for lo, hi in ((basis.lo, basis.hi), *basis.also) for x in (lo[0], hi[0])
                        for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])  # fmt: skip
    theta = laser_angles(cell, T_base_flange, corners)
    step = float(np.abs(np.diff(wanted)).max()) if len(wanted) > 1 else 0.0
    inside = (wanted >= theta.min() - step) & (wanted <= theta.max() + step)
    if not inside.any() or inside.sum() > MAX_SHARE * len(wanted):
        return None
    return wanted[inside]


def rescan(cell: Any, basis: RescanBasis, views: list, around: str = "the part that left") -> ScanResult:
    """The scan of ``views`` (one scan pose) after a clean pick: the band of angles around the
    part that left, merged with the last scan (:func:`merged`); the whole sweep when the band is
    most of it or the fresh lines show something else moved (its time counted with the band's)."""
    T_scan, wanted = views[0]
    angles = band(cell, basis, np.asarray(wanted), T_scan)
    if angles is None:
        cell.progress("scan", f"{around} spans most of the sweep: the whole bin is scanned")
        return cell.sweep_views(views)
    fresh = cell.sweep_views([(T_scan, angles)])
    scan, why = merged(basis, fresh, angles)
    if scan is not None:
        scan = replace(scan, timings=MappingProxyType({**scan.timings, "rescanned_share": len(angles) / len(wanted)}))
    if scan is not None:
        cell.progress("scan", f"rescanned {len(angles)} of {len(wanted)} angles, around {around}; {why}")
        return scan
    cell.progress("scan", f"rescanning the whole bin: {why}")
    whole = cell.sweep_views(views)
    timings = dict(whole.timings)
    for k, v in fresh.timings.items():  # the band's sweep took its time too
        timings[k] = timings.get(k, 0.0) + v
    return ScanResult(
        cloud=whole.cloud,
        angles=whole.angles,
        T_base_flanges=whole.T_base_flanges,
        frames=whole.frames,
        timings=MappingProxyType(timings),
    )


def merged(basis: RescanBasis, fresh: ScanResult, swept: np.ndarray) -> tuple[Optional[ScanResult], str]:
    """The fresh band's points with the last scan's points lit by other angles (each point keeps
    the angle that lit it), or None (and why) when the fresh lines show the bin changed outside
    the region."""
    from ..vision import Cloud

    last = basis.scan.cloud
    step = float(np.abs(np.diff(swept)).max()) if len(swept) > 1 else 0.0
    lit_again = (np.asarray(last.angle) >= float(swept.min()) - 0.5 * step) & (
        np.asarray(last.angle) <= float(swept.max()) + 0.5 * step
    )

    def outside(p: np.ndarray) -> np.ndarray:
        return p[~((p >= basis.lo) & (p <= basis.hi)).all(axis=1)]

    # The same sheets on the same surfaces, outside the region: the last scan's and the fresh points.
    share, cells = _moved_share(outside(last.points[lit_again]), outside(fresh.points))
    if cells and share > CHANGED_SHARE:
        return None, f"{share:.0%} of the {cells} places the fresh lines share with the last scan moved"
    keep = ~lit_again
    kept = ScanResult(
        cloud=Cloud(points=last.points[keep], frame=last.frame[keep], pixels=last.pixels[keep], angle=last.angle[keep]),
        angles=basis.scan.angles,
        T_base_flanges=basis.scan.T_base_flanges,
        frames=MappingProxyType({}),
        timings=MappingProxyType({}),
    )
    return replace(kept.joined(fresh), carried=int(keep.sum())), f"kept {int(keep.sum())} points of the last scan"


def _moved_share(old: np.ndarray, new: np.ndarray) -> tuple[float, int]:
    """The share of the height-map cells both clouds see whose top differs by more than
    :data:`CHANGED_MM`, and how many cells they share."""
    if not len(old) or not len(new):
        return 0.0, 0
    lo = np.minimum(old[:, :2].min(axis=0), new[:, :2].min(axis=0))

    def tops(p: np.ndarray) -> dict[tuple[int, int], float]:
        ij = np.floor((p[:, :2] - lo) / CELL_MM).astype(np.int64)
        key = ij[:, 0] * 1_000_003 + ij[:, 1]
        order = np.lexsort((p[:, 2], key))
        last = np.r_[key[order][1:] != key[order][:-1], True]
        return dict(zip(key[order][last].tolist(), p[order][last, 2].tolist()))

    a, b = tops(old), tops(new)
    shared = a.keys() & b.keys()
    if not shared:
        return 0.0, 0
    moved = sum(abs(a[k] - b[k]) > CHANGED_MM for k in shared)
    return moved / len(shared), len(shared)
