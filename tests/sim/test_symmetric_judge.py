"""The simulated cell judges a located pose modulo the part's proper symmetries: an elbow or a
cross located turned by one of its symmetries (180° about the elbow's diagonal, 90° or 180°
about the cross's axes) is pick-grade; turned by a rotation that is no symmetry it is not."""

import json
import math

import numpy as np
import pytest

import binpick
from binpick.cli import main
from binpick.sim import SimulatedCell
from binpick.transforms import pose_error, rotation_about

DIAGONAL = (1.0, 1.0, 0.0)  # the elbow's two branches lie along x and y: the 180° turn swaps them


@pytest.fixture(scope="module")
def piles():
    return {
        name: SimulatedCell(getattr(binpick.parts, name)(), count=2, seed=0, frames=4) for name in ("elbow", "cross")
    }


def _turned(model, axis, degrees: float) -> np.ndarray:
    """The map turning ``model`` by ``degrees`` about ``axis`` through its symmetry centre."""
    c = model.symmetries.center
    S = np.eye(4)
    S[:3, :3] = rotation_about(axis, math.radians(degrees))
    S[:3, 3] = c - S[:3, :3] @ c
    return S


@pytest.mark.parametrize(
    "part,axis,degrees,symmetry",
    [
        ("elbow", DIAGONAL, 180.0, True),
        ("elbow", (0.0, 0.0, 1.0), 90.0, False),
        ("elbow", (0.0, 0.0, 1.0), 180.0, False),
        ("cross", (0.0, 0.0, 1.0), 90.0, True),
        ("cross", (0.0, 0.0, 1.0), 180.0, True),
        ("cross", (1.0, 0.0, 0.0), 180.0, True),
        ("cross", (0.0, 0.0, 1.0), 45.0, False),
        ("cross", (1.0, 0.0, 0.0), 90.0, False),
    ],
)
def test_judge_is_modulo_the_part_symmetries(piles, part, axis, degrees, symmetry):
    sim = piles[part]
    T_true = np.asarray(sim.pile.poses[0])
    truth = sim.judge(T_true @ _turned(sim.model, axis, degrees))
    assert truth.instance == int(sim.pile.ids[0])
    if symmetry:
        assert truth.pick_grade, f"a {part} turned {degrees}° by a symmetry judged {truth}"
        assert truth.rotation_error_deg < 0.5 and truth.translation_error_mm < 0.5
    else:
        assert not truth.pick_grade, f"a {part} turned {degrees}° (no symmetry) judged pick-grade"
        assert truth.rotation_error_deg > 40.0


@pytest.mark.parametrize("part,seed,picks", [("elbow", 1, 2), ("cross", 1, 1)])
def test_demo_counts_symmetric_picks_as_picked(tmp_path, capsys, monkeypatch, part, seed, picks):
    # In these piles the estimator locates parts turned by a symmetry (180° about the elbow's
    # diagonal, 180° about an axis of the cross); the demo must count those picks as picked.
    raw: list[float] = []
    judge = SimulatedCell.judge

    def noting_judge(self, T_base_object, **kw):
        truth = judge(self, T_base_object, **kw)
        T_true = dict(zip(map(int, self.pile.ids), self.pile.poses))[truth.instance]
        raw.append(pose_error(T_base_object, T_true)[0])  # no symmetries: the pose as located
        return truth

    monkeypatch.setattr(SimulatedCell, "judge", noting_judge)
    out = tmp_path / part
    argv = ["demo", "--part", part, "--picks", str(picks), "--count", "3", "--frames", "60", "--seed", str(seed)]
    code = main([*argv, "--out", str(out), "--d-star", "12", "--min-points", "500"])
    text = capsys.readouterr().out
    assert code == 0, text
    records = json.loads((out / "picks.json").read_text())["picks"]
    assert [r["success"] for r in records] == [True] * picks, text
    for r in records:
        assert r["truth"]["pick_grade"] and r["truth"]["rotation_error_deg"] < 5.0
    assert max(raw) > 80.0, f"no pose was located turned by a symmetry (raw errors {raw}); the test pile changed"
    assert f"{picks} of {picks} picks succeeded" in text
