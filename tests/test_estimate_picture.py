"""What `binpick estimate` shows of the instances it finds: its picture draws every one asked
for (numbered, with its confidence and whether it is ambiguous), its JSON gives each one's
confidence, ambiguity, alternatives, fit and the depth noise the judge used; and the demo's
summary picture scales its pose-error axis to the errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

import binpick
from binpick import viz
from binpick.cell import PickRecord, PoseTruth
from binpick.cli import main

BIN = ["--bin", "250", "-100", "0", "550", "100", "80"]


@pytest.fixture(scope="module")
def pile_scene(tmp_path_factory):
    """Four tees seen by a simulated depth camera, as a PCD file that states the camera's position."""
    from binpick import sim

    tee = binpick.parts.tee()
    camera = sim.DepthCamera.kinect().looking_at((400, 0, 40), distance=900, tilt_deg=30, azimuth_deg=0)
    frame = sim.render_depth(sim.World.of_pile(sim.Pile(tee, 4, seed=3)), camera, seed=1)
    path = tmp_path_factory.mktemp("pile") / "pile.pcd"
    binpick.write_scene(path, frame.cloud, viewpoint=frame.viewpoint)
    return path


def test_estimate_draws_and_reports_every_instance_asked_for(pile_scene, tmp_path, monkeypatch, capsys):
    figures = []
    drawn = viz._instances_figure

    def keep(*args, **kwargs):
        figures.append(drawn(*args, **kwargs))
        return figures[-1]

    monkeypatch.setattr(viz, "_instances_figure", keep)
    png = tmp_path / "estimate.png"
    assert main(["estimate", str(pile_scene), "tee", "--instances", "3", "--png", str(png), *BIN]) == 0
    docs = json.loads(capsys.readouterr().out)
    assert len(docs) == 3 and png.read_bytes()[:4] == b"\x89PNG"
    scene = binpick.read_scene(pile_scene)
    sigma = binpick.scan_noise(scene.points, viewpoint=scene.viewpoint)
    for doc in docs:
        assert {"confidence", "confidence_any", "ambiguous", "alternatives", "fit", "free_axis"} <= set(doc)
        assert doc["noise_mm"] == pytest.approx(sigma) and doc["noise_source"] == "read from the scan"
        assert doc["fit"]["noise_floor_mm"] >= doc["noise_mm"] - 1e-9  # the fit's floor is no lower
    (fig,) = figures
    top = fig.axes[0]
    labels = [t.get_text() for t in top.get_legend().get_texts()]
    for i, doc in enumerate(docs, 1):
        decided = f"ambiguous ({len(doc['alternatives'])} alternative" if doc["ambiguous"] else "decided"
        assert any(label.startswith(f"{i}: confidence {doc['confidence']:.2f}, {decided}") for label in labels), labels
    assert sorted(t.get_text() for t in top.texts) == ["1", "2", "3"]  # each numbered where it lies


def test_a_declared_noise_is_the_one_reported(pile_scene, tmp_path, capsys):
    argv = ["estimate", str(pile_scene), "tee", "--noise-mm", "2.5", "--png", str(tmp_path / "e.png"), *BIN]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["noise_mm"] == 2.5 and doc["noise_source"] == "declared (--noise-mm)"


def test_the_pose_error_axis_fits_the_errors_with_the_pick_grade_lines_on_it(tmp_path, monkeypatch):
    assert viz.error_axis_top([0.1, 0.05, float("nan")]) == pytest.approx(1.25 * 5.0)  # was 25 for any errors
    assert viz.error_axis_top([12.0, 2.0]) == pytest.approx(15.0)
    assert viz.error_axis_top([300.0]) == pytest.approx(25.0)  # bars are cut at 20 and labelled
    assert viz.error_axis_top([float("nan")]) == pytest.approx(6.25)
    figures = []
    monkeypatch.setattr(viz, "_save", lambda fig, path: figures.append(fig) or path)
    good = PoseTruth(instance=0, rotation_error_deg=0.1, translation_error_mm=0.08)
    viz.save_pick_summary(tmp_path / "summary.png", [PickRecord(index=1, success=True, truth=good, score=0.9)])
    errors = figures[0].axes[1]
    assert errors.get_ylim()[1] == pytest.approx(6.25)
    assert sorted(line.get_ydata()[0] for line in errors.get_lines()) == [3.0, 5.0]  # the limits stay in view
    assert np.all(np.array([bar.get_height() for bar in errors.patches]) < 1.0)
