"""The same seed gives the same run: the simulated cell picks the same parts in the same order,
with the same poses, twice."""

import binpick
from binpick.sim import SimulatedCell

ESTIMATE = {"d_star": 12.0, "min_points": 500}


def _run(seed: int) -> tuple[list[dict], list[int], str]:
    with SimulatedCell(binpick.parts.tee(), count=3, seed=seed, frames=60, estimate_options=ESTIMATE) as sim:
        report = sim.cell.run(2)
        assert sim.emulator_failures == []
        removed = list(sim.removed)
    picks = []
    for r in report.records:
        d = r.as_dict()
        del d["timings_ms"]  # measured durations, not what the run did
        # The cycle's time holds binpick's compute as measured; its hardware stages are the seed's.
        del d["cycle_time_s"]
        d["stage_s"] = {k: round(v, 6) for k, v in d["stage_s"].items() if k != "compute"}
        picks.append(d)
    return picks, removed, str(report.stopped)


def test_the_same_seed_twice_gives_the_same_picks():
    first, second = _run(1), _run(1)
    assert first[1], "the run removed no part; the test pile should be pickable"
    assert first[1] == second[1], "the parts removed differ"
    for a, b in zip(first[0], second[0]):
        assert a == b, f"pick {a['index']} differs:\n{a}\n{b}"
    assert first == second
