"""End to end through the simulated cell: a pile rendered by the default cell (1032 × 778 camera
about 500 mm above the pile, default sensor noise), written as a scan folder, read back like a
real scan, reconstructed by binpick.vision and measured against the exact surfaces it was
rendered from. The issue's target: RMS distance to the true surface ≤ 0.2 mm."""

import numpy as np
import pytest

import binpick
from binpick import sim
from binpick.scan import load_scan, save_scan
from binpick.vision import reconstruct

SEED = 1
PARTS = 4
# 30 sheets across the 320 mm sweep: one every ~11 mm, several across every tee (26 mm tubes).
FRAMES = 30
TARGET_RMS = 0.2  # mm, issue 5


@pytest.fixture(scope="module")
def pile_scan(tmp_path_factory):
    scan = sim.simulate_scan(binpick.parts.tee(), PARTS, seed=SEED, frames=FRAMES)
    root = sim.write_scan(scan, tmp_path_factory.mktemp("tee_scan"))
    loaded = load_scan(root)
    return scan, root, loaded, reconstruct(loaded)


def test_the_scan_folder_round_trips(pile_scan):
    scan, root, loaded, _ = pile_scan
    assert len(loaded) == FRAMES
    assert np.array_equal(loaded.angles, scan.angles)
    assert np.array_equal(loaded.T_base_flanges, np.broadcast_to(scan.T_base_flange, (FRAMES, 4, 4)))
    # PNG is lossless: every pixel comes back (BGR on disk, RGB in memory).
    for k, img in enumerate(loaded.images()):
        assert np.array_equal(img, scan.frames[k][:, :, ::-1]), f"frame {k} changed on disk"
    cal = loaded.calibration
    assert cal == scan.cell.calibration()
    assert np.array_equal(cal.T_camera_laser, scan.cell.laser.T_camera_laser0)
    assert np.array_equal(cal.camera.dist, np.array(scan.cell.camera.dist))
    gt = loaded.ground_truth
    assert gt == scan.ground_truth()
    assert gt["part"] == "tee" and gt["ids"] == list(range(PARTS))
    assert np.array_equal(np.array(gt["T_base_object"]), scan.pile.poses)
    assert np.array_equal(np.array(gt["bin"]), scan.cell.bin.bounds)
    assert (root / "contact_sheet.png").stat().st_size > 0


def test_reconstruction_is_within_0_2_mm_rms_of_the_true_surfaces(pile_scan):
    scan, _, loaded, cloud = pile_scan
    dist, ids = scan.world.nearest_surface(cloud.points)
    rms = float(np.sqrt(np.mean(dist**2)))
    # Measured: 0.124 mm RMS, median 0.060 mm over 15 635 points (seed 1). The larger errors sit
    # where the line crosses an edge (bin rim, a part's silhouette or its laser shadow).
    assert rms <= TARGET_RMS, (
        f"RMS {rms:.3f} mm over {len(dist)} points (median {np.median(dist):.3f}, p99 {np.percentile(dist, 99):.3f})"
    )
    assert np.median(dist) < 0.08
    assert len(cloud) > 10_000
    assert set(np.unique(cloud.frame)) == set(range(FRAMES)), "a frame gave no points"
    # Every part of the pile is measured, not only the bin around it.
    for part in scan.pile.ids:
        on_part = ids == part
        assert on_part.sum() > 200, f"part {part}: only {on_part.sum()} points"
        part_rms = float(np.sqrt(np.mean(dist[on_part] ** 2)))
        assert part_rms < 2 * TARGET_RMS, f"part {part}: RMS {part_rms:.3f} mm"
    # The points are seen where the renderer put each surface: the instance nearest a point is
    # the one the camera saw at its pixel.
    px = np.rint(cloud.pixels).astype(int)
    seen = scan.view.ids[px[:, 1], px[:, 0]]
    assert np.mean(seen == ids) > 0.98


def _cylinder_mesh(radius, length, segments=720):
    """A closed cylinder along y, centred at the origin: side quads and two capped fans."""
    a = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([radius * np.cos(a), np.zeros(segments), radius * np.sin(a)], axis=1)
    v = np.concatenate(
        [ring + [0, -length / 2, 0], ring + [0, length / 2, 0], [[0, -length / 2, 0], [0, length / 2, 0]]]
    )
    i = np.arange(segments)
    j = (i + 1) % segments
    n = segments
    side = np.concatenate([np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1)])
    caps = np.concatenate([np.stack([np.full(n, 2 * n), j, i], 1), np.stack([np.full(n, 2 * n + 1), n + i, n + j], 1)])
    return v, np.concatenate([side, caps])


def _translation(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


class _PlaneAndCylinder:
    """A floor at z = 0 and a cylinder of radius 30 mm, 160 mm long, lying on it along y under the
    default cell's camera; exact distances in closed form."""

    radius, length, centre = 30.0, 160.0, np.array([400.0, 0.0, 30.0])

    def world(self):
        w = sim.World()
        half = 300.0
        floor = w.add_mesh(
            np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]]),
            np.array([[0, 1, 2], [0, 2, 3]]),
        )
        w.add_instance(floor, _translation(400.0, 0.0, 0.0), 0)
        cyl = w.add_mesh(*_cylinder_mesh(self.radius, self.length))
        w.add_instance(cyl, _translation(*self.centre), 1)
        return w

    def distance(self, p):
        q = p - self.centre
        radial = np.hypot(q[:, 0], q[:, 2]) - self.radius
        axial = np.abs(q[:, 1]) - self.length / 2
        outside = np.hypot(np.maximum(radial, 0), np.maximum(axial, 0))
        cylinder = np.abs(outside + np.minimum(np.maximum(radial, axial), 0))
        return np.minimum(np.abs(p[:, 2]), cylinder)


def test_nearest_surface_is_the_closed_form_distance():
    scene = _PlaneAndCylinder()
    rng = np.random.default_rng(5)
    p = scene.centre + rng.uniform([-120, -110, -29], [120, 110, 40], size=(4000, 3))
    dist, ids = scene.world().nearest_surface(p)
    # 720 segments leave the facets 0.3 µm inside the round cylinder; the rest is f32 rounding.
    assert np.abs(dist - scene.distance(p)).max() < 2e-3
    assert set(np.unique(ids)) == {0, 1}
    empty = sim.World().nearest_surface(p[:3])
    assert np.all(np.isinf(empty[0])) and np.all(empty[1] == -1)


def test_a_plane_and_cylinder_scan_reconstructs_within_0_2_mm_rms(tmp_path):
    scene = _PlaneAndCylinder()
    cell = sim.Cell()
    view = scene.world().view(cell)
    angles = cell.sweep(20)
    frames = view.frames(angles, seed=SEED)
    save_scan(tmp_path, [f[:, :, ::-1] for f in frames], angles, [cell.T_base_flange] * len(angles), cell.calibration())
    cloud = reconstruct(load_scan(tmp_path))
    d = scene.distance(cloud.points)
    on_cylinder = np.abs(cloud.points[:, 2]) > 1.0
    rms = float(np.sqrt(np.mean(d**2)))
    # Measured (seed 1): 0.072 mm RMS over 14 700 points, median 0.045 mm; 0.099 mm RMS on the
    # cylinder alone (its silhouette and laser-shadow edges hold the largest errors).
    assert rms <= TARGET_RMS, f"RMS {rms:.3f} mm over {len(d)} points"
    assert np.median(d) < 0.08
    assert on_cylinder.sum() > 1000
    cylinder_rms = float(np.sqrt(np.mean(d[on_cylinder] ** 2)))
    assert cylinder_rms <= TARGET_RMS, f"cylinder RMS {cylinder_rms:.3f} mm"
