"""Laser speckle and one-bounce reflections: off by default, on by `binpick simulate --speckle /
--reflections`; each changes the frame as `SensorNoise` documents it, and the laser line stays
extractable by binpick.vision."""

from dataclasses import replace

import numpy as np
import pytest

import binpick
from binpick import sim
from binpick.scan import load_scan
from binpick.sim import cli as sim_cli
from binpick.sim import dataset
from binpick.vision import extract_line, reconstruct

CAM = sim.Camera(width=320, height=240, fx=500.0, fy=500.0, cx=159.5, cy=119.5, dist=(0, 0, 0, 0, 0))
# Camera at the base origin looking along +z, the laser 130 mm to its side (the default projector).
CELL = sim.Cell(
    camera=CAM, T_flange_camera=np.eye(4), T_base_flange=np.eye(4), laser=sim.Laser(sheet_sigma=1.0, power=150.0)
)
IDEAL = sim.SensorNoise.none()
SQUARE = np.array([[0, 1, 2], [0, 2, 3]])


def _square(half):
    return np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], dtype=float)


def _floor_world(z=500.0):
    w = sim.World()
    m = w.add_mesh(_square(2000.0), SQUARE, albedo=(0.8, 0.8, 0.8))
    T = np.eye(4)
    T[2, 3] = z
    w.add_instance(m, T, 0)
    return w


def _bgr(rgb):
    return np.ascontiguousarray(rgb[:, :, ::-1])


def _same_rows(a, b):
    """Rows where both extractions found the line, and |Δu| there."""
    common, ia, ib = np.intersect1d(a[:, 1], b[:, 1], return_indices=True)
    return common, np.abs(a[ia, 0] - b[ib, 0])


def test_both_are_off_by_default():
    for noise in (sim.SensorNoise(), sim.Cell().noise, sim.SensorNoise.none()):
        assert noise.speckle == 0.0 and noise.reflections == 0.0
    args = sim_cli._parser().parse_args(["--out", "x"])
    assert args.speckle == 0.0 and args.reflections == 0.0


@pytest.mark.parametrize("contrast", [0.2, 0.5])
def test_speckle_scales_the_laser_light_by_its_contrast(contrast):
    view = _floor_world().view(CELL)
    ambient = view.ambient_frame(noise=IDEAL).astype(float)
    clean = view.frame(0.02, noise=IDEAL).astype(float)
    speckled = view.frame(0.02, noise=replace(IDEAL, speckle=contrast), seed=4).astype(float)
    # Documented: speckle contrast = σ / mean of the laser's brightness per pixel. Where the line
    # is bright (quantisation then adds < 2% to the ratio) the per-pixel gain has that spread.
    laser_clean, laser_speckled = clean[..., 0] - ambient[..., 0], speckled[..., 0] - ambient[..., 0]
    bright = laser_clean > 30
    assert bright.sum() > 500
    gain = laser_speckled[bright] / laser_clean[bright]
    assert abs(gain.mean() - 1.0) < 0.06, gain.mean()
    assert abs(gain.std() / contrast - 1.0) < 0.15, gain.std()
    # Only the laser's light is modulated: away from the line (u ≈ 175) nothing changes.
    assert np.array_equal(speckled[:, :150], clean[:, :150]) and np.array_equal(speckled[:, 200:], clean[:, 200:])


def test_the_line_stays_extractable_under_speckle():
    view = _floor_world().view(CELL)
    clean = extract_line(_bgr(view.frame(0.02, noise=IDEAL)))
    speckled = extract_line(_bgr(view.frame(0.02, noise=replace(sim.SensorNoise(), speckle=0.3), seed=7)))
    assert len(clean) == CAM.height
    rows, du = _same_rows(clean, speckled)
    # Measured: 95% of the rows keep the line (a dark speckle grain can sink a row's peak below
    # the threshold), their centres within 0.13 px median, 0.36 px at the 95th percentile.
    assert len(rows) == len(speckled) >= 0.9 * CAM.height
    assert np.median(du) < 0.2 and np.percentile(du, 95) < 0.5


class _Mirror:
    """A glossy plate leaning 75° into the laser's light, 70 mm in front of a matte floor 500 mm
    from the camera: the sheet lit on the plate is mirrored onto the floor beside the line."""

    tilt, centre, half, floor_z = np.radians(-75.0), np.array([22.0, 0.0, 430.0]), 25.0, 500.0

    def world(self, specular):
        w = _floor_world(self.floor_z)
        m = w.add_mesh(_square(self.half), SQUARE, albedo=(0.5, 0.5, 0.5), specular=specular, shininess=50.0)
        w.add_instance(m, self.pose(), 1)
        return w

    def pose(self):
        T = sim.rot_y(self.tilt)
        T[:3, 3] = self.centre
        return T

    def landing(self, angle):
        """Pixels (u, v) where the sheet's mirror image off the plate meets the floor."""
        T_laser, T_plate = CELL.laser.T_camera_laser(angle), self.pose()
        o, xl, n, c = T_laser[:3, 3], T_laser[:3, 0], T_plate[:3, 2], T_plate[:3, 3]
        out = []
        for y in np.linspace(-self.half, self.half, 201):
            # The point of the plate on the sheet at this y: xl·(p − o) = 0 and n·(p − c) = 0.
            x, z = np.linalg.solve([[xl[0], xl[2]], [n[0], n[2]]], [xl @ o - xl[1] * y, n @ c - n[1] * y])
            p = np.array([x, y, z])
            local = T_plate[:3, :3].T @ (p - c)
            if np.abs(local[:2]).max() > self.half:
                continue
            d = (p - o) / np.linalg.norm(p - o)
            mirrored = d - 2 * (d @ n) * n
            q = p + mirrored * (self.floor_z - p[2]) / mirrored[2]
            out.append((CAM.fx * q[0] / q[2] + CAM.cx, CAM.fy * q[1] / q[2] + CAM.cy))
        return np.array(out)


def test_reflections_mirror_the_line_off_glossy_surfaces_only():
    scene, angle = _Mirror(), 0.0
    view = scene.world(specular=1.0).view(CELL)
    clean = view.frame(angle, noise=IDEAL).astype(float)
    mirrored = view.frame(angle, noise=replace(IDEAL, reflections=1.0)).astype(float)
    stray = (mirrored - clean)[..., 0]
    assert (stray >= 0).all() and stray.sum() > 1000
    # Documented: the light mirrored once off the glossy plate shows where it lands on the floor.
    expected = scene.landing(angle)
    assert len(expected) > 50
    cols = np.arange(CAM.width)
    centre_u = (stray.sum(axis=0) * cols).sum() / stray.sum()
    assert abs(centre_u - expected[:, 0].mean()) < 1.0, (centre_u, expected[:, 0].mean())
    lit_rows = np.nonzero(stray.sum(axis=1))[0]
    assert abs(lit_rows.min() - expected[:, 1].min()) <= 2 and abs(lit_rows.max() - expected[:, 1].max()) <= 2
    # The strength scales the stray light linearly (to within the 8-bit rounding).
    half = (view.frame(angle, noise=replace(IDEAL, reflections=0.5)).astype(float) - clean)[..., 0]
    assert abs(half.sum() / stray.sum() - 0.5) < 0.03
    # A matte plate mirrors nothing.
    matte = _Mirror().world(specular=0.0).view(CELL)
    assert np.array_equal(matte.frame(angle, noise=replace(IDEAL, reflections=1.0)), matte.frame(angle, noise=IDEAL))
    # The line itself is untouched: the same rows, the same centres.
    rows, du = _same_rows(extract_line(_bgr(clean.astype(np.uint8))), extract_line(_bgr(mirrored.astype(np.uint8))))
    assert len(rows) > 150 and du.max() < 0.01


def test_a_glossy_pile_with_speckle_and_reflections_stays_measurable(tmp_path):
    cell = sim.Cell()
    cell = replace(cell, noise=replace(cell.noise, speckle=0.2, reflections=1.0))
    scan = sim.simulate_scan(binpick.parts.tee(), 4, seed=1, frames=15, cell=cell)
    without = scan.view.frames(scan.angles, seed=1, noise=replace(cell.noise, reflections=0.0))
    changed = (scan.frames != without).any(axis=-1).sum(axis=(1, 2))
    # The parts are glossy (simulate_scan does that when reflections are on): frames whose sheet
    # crosses a part carry stray light (measured: 360-1200 pixels in 9 of 15 frames).
    assert (changed > 100).sum() >= 5, changed
    line_rows = agreeing = extra = 0
    for k in range(len(scan.frames)):
        a, b = extract_line(_bgr(without[k])), extract_line(_bgr(scan.frames[k]))
        rows, du = _same_rows(a, b)
        line_rows += len(a)
        agreeing += int((du < 0.3).sum())
        extra += len(b) - len(rows)
    # Measured: 99.8% of the line's rows unchanged; strays add 34 rows to 7 726.
    assert agreeing >= 0.98 * line_rows and extra <= 0.02 * line_rows
    cloud = reconstruct(load_scan(sim.write_scan(scan, tmp_path)))
    dist, _ = scan.world.nearest_surface(cloud.points)
    # Stray rows triangulate to false points (as on a real shiny part); the rest stays accurate.
    # Measured: median 0.15 mm, 0.55% of the points further than 1 mm.
    assert np.median(dist) < 0.2 and np.mean(dist < 1.0) > 0.98


def test_cli_flags_turn_them_on(tmp_path, monkeypatch):
    seen = []
    real = dataset.simulate_scan

    def small(model, count_, **kw):
        seen.append(kw["cell"])
        # A small camera keeps the run short; everything else is the CLI's cell.
        kw["cell"] = replace(
            kw["cell"], camera=sim.Camera(width=240, height=180, fx=300.0, fy=300.0, cx=119.5, cy=89.5)
        )
        return real(model, 1, **kw)

    monkeypatch.setattr(dataset, "simulate_scan", small)
    frames = {}
    for name, flags in (("plain", []), ("noisy", ["--speckle", "0.4", "--reflections", "0.7"])):
        out = tmp_path / name
        assert sim_cli.simulate_main(["--count", "1", "--frames", "3", "--seed", "2", "--out", str(out), *flags]) == 0
        frames[name] = np.stack(list(load_scan(out).images()))
    assert (seen[0].noise.speckle, seen[0].noise.reflections) == (0.0, 0.0)
    assert (seen[1].noise.speckle, seen[1].noise.reflections) == (0.4, 0.7)
    # The same pile and sensor noise seed: only the laser's light differs.
    assert frames["plain"].shape == frames["noisy"].shape and not np.array_equal(frames["plain"], frames["noisy"])
