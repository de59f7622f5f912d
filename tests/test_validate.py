"""``binpick validate`` (issue 37, item 1): seeded pick cycles over simulated piles, the same
records from one worker, two workers and Ray; a killed run resumed; the report's figures; the
command's bad input. The piles are tiny (one or two tees, 30 frames) so that a run takes
seconds: the records' identity and the run's mechanics do not depend on the pile's size."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import binpick
from binpick.cell.records import CYCLE_STAGES
from binpick.cli import main
from binpick.errors import InvalidInputError
from binpick.sim import validate as v
from binpick.sim.validate_report import summarize, table, wilson
from binpick.sim.validate_workers import MEASURED, PileSpec, run_pile

ESTIMATE = {"d_star": 12.0, "min_points": 500}
#: Seeds 0 and 1: piles of one and two tees.
RUN = dict(seeds=2, first_seed=0, count=(1, 2), frames=30, estimate_options=ESTIMATE)
FLAGS = ["--seeds", "2", "--count", "1-2", "--frames", "30", "--d-star", "12", "--min-points", "500"]


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    """The reference: seeds 0 and 1 in one worker process, written to a folder (with Parquet)."""
    out = tmp_path_factory.mktemp("validate") / "one"
    lines: list[str] = []
    report = binpick.validate("tee", **RUN, workers=1, out=out, parquet=True, progress=lines.append)
    return report, out, lines


def _without_measurements(records):
    return [{k: x for k, x in r.items() if k not in MEASURED} for r in records]


def test_a_run_records_every_cycle_and_writes_its_files(one_worker):
    report, out, lines = one_worker
    recs = report.records
    assert [r["seed"] for r in recs] == sorted(r["seed"] for r in recs) and {r["seed"] for r in recs} == {0, 1}
    assert [r["pile_size"] for r in recs if r["cycle"] == 1] == [1, 2]  # count 1-2: seed 0 one tee, seed 1 two
    for r in recs:
        assert r["outcome"] == "picked" or r["outcome"] in binpick.cell.FAILURE_KINDS
        assert r["cycle_time_s"] > 0 and r["cpu_s"] > 0 and r["wall_s"] > 0 and r["binpick_cpu_s"] > 0
        assert set(r["stage_s"]) == set(CYCLE_STAGES)  # the hardware clock's stages and binpick's compute
        assert r["stage_s"]["scan.sweep"] >= r["looks"] * 30 / 15.0  # 30 frames a look at 15 fps, at least
        assert r["cycle_time_s"] == pytest.approx(sum(r["stage_s"].values()), abs=1e-3)
    on_disk = [json.loads(x) for x in (out / "records.jsonl").read_text().splitlines()]
    assert on_disk == list(recs)
    piles = [json.loads(x) for x in (out / "piles.jsonl").read_text().splitlines()]
    assert [p["seed"] for p in piles] == [0, 1] and sum(p["cycles"] for p in piles) == len(recs)
    saved = json.loads((out / "report.json").read_text())
    assert saved["cycles"] == len(recs) and saved["success_rate_95"] == list(report.interval)
    assert saved["success_rate"] == sum(r["outcome"] == "picked" for r in recs) / len(recs)
    assert (out / "summary.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "run.json").read_text())["count"] == [1, 2]
    # one progress line per pile after the opening one, the larger pile first
    assert len(lines) == 3 and lines[1].startswith("seed 1: ") and lines[2].startswith("seed 0: ") and "ETA" in lines[2]


def test_the_parquet_table_holds_the_records(one_worker):
    pq = pytest.importorskip("pyarrow.parquet")
    report, out, _ = one_worker
    assert pq.read_table(out / "records.parquet").to_pylist() == list(report.records)


def test_one_and_two_workers_give_the_same_records(one_worker):
    two = binpick.validate("tee", **RUN, workers=2)
    assert len(two.records) >= 3
    assert _without_measurements(two.records) == _without_measurements(one_worker[0].records)
    assert v.identical(two.records, one_worker[0].records)


def test_ray_with_two_workers_gives_the_same_records(one_worker):
    pytest.importorskip("ray")
    on_ray = binpick.validate("tee", **RUN, workers=2, ray="local")
    assert on_ray.summary["run"]["backend"].startswith("Ray (local, 2 tasks")
    assert _without_measurements(on_ray.records) == _without_measurements(one_worker[0].records)


def test_a_killed_run_resumed_finishes_with_the_records_of_an_uninterrupted_one(one_worker, tmp_path):
    out = tmp_path / "killed"
    env = dict(os.environ, PYTHONPATH=str(Path(binpick.__file__).resolve().parents[1]))
    cmd = [sys.executable, "-m", "binpick", "validate", "tee", *FLAGS, "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    piles = out / "piles.jsonl"
    deadline = time.monotonic() + 180
    try:
        while not (piles.exists() and piles.read_text().count("\n") >= 1):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the first pile did not finish in 180 s"
            time.sleep(0.1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the command and its worker process, at once
        proc.wait()
    # the larger pile, seed 1's, runs first
    assert [json.loads(x)["seed"] for x in piles.read_text().splitlines()] == [1], "killed after its first pile"
    resumed = binpick.validate("tee", **RUN, workers=1, out=out)
    first = [r for r in one_worker[0].records if r["seed"] == 1]
    assert resumed.summary["run"]["cycles_run"] == len(one_worker[0].records) - len(first)  # seed 0 alone ran
    assert v.identical(resumed.records, one_worker[0].records)
    assert [json.loads(x) for x in (out / "records.jsonl").read_text().splitlines()] == list(resumed.records)
    assert [json.loads(x)["seed"] for x in piles.read_text().splitlines()] == [0, 1]


def test_a_finished_run_resumed_runs_nothing_and_reports_the_same(one_worker):
    report, out, _ = one_worker
    again = binpick.validate("tee", **RUN, workers=1, out=out)
    assert again.summary["run"]["cycles_run"] == 0 and again.summary["run"]["backend"].startswith("none")
    assert again.records == report.records


def test_a_folder_of_a_run_with_other_settings_is_refused_naming_the_difference(one_worker, capsys):
    _, out, _ = one_worker
    with pytest.raises(InvalidInputError, match=r"frames: 30 there, 31 now"):
        binpick.validate("tee", **{**RUN, "frames": 31}, workers=1, out=out)
    argv = ["validate", "tee", *FLAGS[:4], "--frames", "31", *FLAGS[6:], "--out", str(out)]
    assert main(argv) == 2
    assert "--frames: 30 there, 31 now" in capsys.readouterr().err


def test_a_cut_short_pile_is_dropped_on_resume(tmp_path):
    """A kill between a pile's cycle lines and its pile line, or in the middle of a line: the run
    resumes from the piles whose pile line is whole."""
    settings = {"part": "tee", "frames": 30}
    (tmp_path / "run.json").write_text(json.dumps(settings))
    rec = {"seed": 0, "cycle": 1, "outcome": "picked"}
    (tmp_path / "records.jsonl").write_text(
        json.dumps(rec) + "\n" + json.dumps({**rec, "seed": 1}) + "\n" + json.dumps({**rec, "seed": 1, "cycle": 2})[:20]
    )
    (tmp_path / "piles.jsonl").write_text(json.dumps({"seed": 0, "cycles": 1}) + "\n" + '{"seed": 1, "cyc')
    done, records, pictures = v._Files(tmp_path).open(settings)
    assert list(done) == [0] and records == [rec] and pictures == {}
    assert (tmp_path / "records.jsonl").read_text() == json.dumps(rec) + "\n"


def test_cycles_end_with_the_pile_that_reaches_them_in_seed_order():
    plan = v._plan("tee", "mm", None, 5, 4, (1, 2), None, None, None)
    done = {5: {"cycles": 2}, 7: {"cycles": 3}}  # seed 7 finished before seed 6 (another worker)
    assert plan.chosen(done) == [5] and not plan.complete(done)
    done[6] = {"cycles": 1}
    assert plan.chosen(done) == [5, 6, 7] and plan.complete(done)
    done[8] = {"cycles": 1}  # run beyond the count by a worker: not the run's
    assert plan.chosen(done) == [5, 6, 7]
    assert [s for s, _ in zip(plan.todo({5: {}, 7: {}}), range(3))] == [6, 8, 9]
    # Seeds: the largest piles first (sizes 1 and 2 by turns), the seeds of one size in order.
    assert list(v._plan("tee", "mm", 5, 10, None, (1, 2), None, None, None).todo({12: {}})) == [11, 13, 10, 14]
    # No more piles are started once those finished hold the cycles and every earlier seed is finished or running.
    assert not plan.enough({5: {"cycles": 2}, 7: {"cycles": 3}}, running=[])
    assert plan.enough({5: {"cycles": 2}, 7: {"cycles": 3}}, running=[6])
    assert not plan.enough({5: {"cycles": 2}}, running=[6, 7])


def test_the_report_figures_of_handcrafted_records():
    def rec(seed, cycle, outcome, t, cpu):
        return {"seed": seed, "cycle": cycle, "outcome": outcome, "cycle_time_s": t, "cpu_s": cpu, "binpick_cpu_s": 0.1}

    outcomes = ["picked"] * 8 + ["empty grip", "collision"]
    records = [rec(i // 5, i % 5 + 1, o, float(i + 1), 2.0) for i, o in enumerate(outcomes)]
    for r, looks, nudges in zip(records, [1] * 8 + [4, 3], [0] * 8 + [2, 1]):
        r.update(looks=looks, nudges=nudges, pick_grade=r["outcome"] != "picked" or r["cycle"] != 2)
    piles = [
        {"seed": 0, "dropped": 5, "removed": 5, "emptied": True, "cpu_s": 12.0},
        {"seed": 1, "dropped": 5, "removed": 3, "lost": 1, "emptied": False, "cpu_s": 13.0},
    ]
    s = summarize(records, piles)
    # Two picks on a pose off the truth by what the grasp does not care about (cycle 2 of each pile).
    assert s["picked_off_pose"] == 2
    assert s["looks_per_cycle"] == pytest.approx(15 / 10) and s["nudges_per_cycle"] == pytest.approx(3 / 10)
    assert s["parts_lost"] == 1
    text = table(s)
    assert "1.50 looks, 0.30 nudges" in text and "1 thrown out of the bin by a push" in text
    assert "picked off pose   2" in text
    # Wilson 95 % for 8 of 10, by hand: p = 0.8, z² = 3.8415, centre = (0.8 + 0.19207) / 1.38415 = 0.71682,
    # half-width = 1.95996 · √(0.016 + 0.0096036) / 1.38415 = 0.22657 → 0.4902 .. 0.9434.
    assert s["success_rate"] == 0.8
    assert s["success_rate_95"] == pytest.approx([0.4902, 0.9434], abs=1e-4)
    assert wilson(0, 0) == (0.0, 1.0) and wilson(10, 10)[1] == 1.0
    assert s["failures"] == {"empty grip": 1, "collision": 1}  # in the order of FAILURE_KINDS
    assert s["bins_emptied"] == 1 and s["parts_removed"] == 8 and s["parts_dropped"] == 10
    assert s["cycle_time_s"]["median"] == 5.5 and s["cycle_time_s"]["p90"] == pytest.approx(9.1)
    assert s["picks_per_hour"] == pytest.approx(3600 * 8 / 55)  # the time of every cycle, failed ones too
    assert s["cycles_per_core_hour"] == pytest.approx(3600 * 10 / 25)  # the piles' whole CPU time
    assert s["cpu_s_per_cycle"] == 2.0


# No pose is ever sure enough, nowhere else to look and no nudge: the one cycle is "no grasp".
NO_GRASP = PileSpec(
    seed=0,
    pile_size=1,
    frames=30,
    estimate_options=ESTIMATE,
    overrides={"min_confidence": 1.0, "look_again_poses": (), "max_nudges": 0},
    pictures=frozenset({"no grasp"}),
)


def test_a_failed_cycle_has_its_kind_and_its_picture():
    result = run_pile(binpick.parts.tee(), NO_GRASP)
    assert [r["outcome"] for r in result["records"]] == ["no grasp"]
    assert result["pile"]["emptied"] is False and result["pile"]["failures"] == {"no grasp": 1}
    assert result["pile"]["stopped"]
    assert result["pictures"]["no grasp"]["cycle"] == 1
    assert result["pictures"]["no grasp"]["png"][:8] == b"\x89PNG\r\n\x1a\n"


def test_a_picture_that_cannot_be_drawn_loses_no_record(monkeypatch):
    def broken(*args, **kwargs):
        raise InvalidInputError("collisions.T_base_gripper: not a rotation")

    monkeypatch.setattr(binpick.viz, "save_failure", broken)
    result = run_pile(binpick.parts.tee(), NO_GRASP)
    assert [r["outcome"] for r in result["records"]] == ["no grasp"] and result["pictures"] == {}
    assert result["pile"]["picture_errors"] == [
        "seed 0 cycle 1 (no grasp): InvalidInputError: collisions.T_base_gripper: not a rotation"
    ]
    assert summarize(result["records"], [result["pile"]])["picture_errors"] == result["pile"]["picture_errors"]


def test_a_cell_file_gives_its_frames_estimate_options_and_gripper(tmp_path):
    cell = tmp_path / "cell.toml"
    cell.write_text(
        "[cell]\nframes = 40\ntool = [0, 0, 200, 0, 0, 0]\nmin_confidence = 0.5\n"
        "[gripper]\nopen_width_mm = 70\n[estimate]\nd_star = 11.0\n"
    )
    plan = v._plan("tee", "mm", 1, 0, None, (1, 1), None, str(cell), {"min_points": 400})
    s = plan.settings()
    assert s["frames"] == 40 and s["estimate_options"] == {"d_star": 11.0, "min_points": 400}
    assert s["gripper"]["open_width_mm"] == 70 and s["gripper"]["T_flange_gripper"][2][3] == 200
    assert s["cell_options"] == {"min_confidence": 0.5}
    assert v._plan("tee", "mm", 1, 0, None, (1, 1), 25, str(cell), None).settings()["frames"] == 25


def test_ray_missing_is_named_with_its_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails
    with pytest.raises(InvalidInputError, match=r'pip install "binpick\[ray\]"') as info:
        v.RayTasks("local", 1, b"")
    assert info.value.cli_message.startswith("--ray: ")


@pytest.mark.parametrize(
    "flags, named",
    [
        (["nosuchpart"], "PART"),
        (["tee", "--count", "0"], "--count: must be at least 1"),
        (["tee", "--count", "5-3"], "--count: the range 5-3 is empty"),
        (["tee", "--count", "many"], "--count"),
        (["tee", "--seeds", "0"], "--seeds: must be at least 1"),
        (["tee", "--seeds", "1000000"], "--seeds: must be at most 100000"),
        (["tee", "--cycles", "0"], "--cycles: must be at least 1"),
        (["tee", "--workers", "65"], "--workers: must be at most 64"),
        (["tee", "--frames", "1"], "--frames: must be at least 2"),
        (["tee", "--first-seed", "-1"], "--first-seed: must be at least 0"),
        (["tee", "--unit", "m"], "--unit m"),
        (["tee", "--cell", "no-such-cell.toml"], "no-such-cell.toml"),
        (["tee", "--ray", "127.0.0.1:1", "--seeds", "1", "--count", "1"], "--ray: "),
        (["tee", "--ray", "not an address", "--seeds", "1", "--count", "1"], "--ray: "),
    ],
)
def test_bad_input_exits_2_naming_the_flag(flags, named, tmp_path, capsys):
    assert main(["validate", *flags, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err


def test_seeds_and_cycles_together_are_refused(capsys):
    assert main(["validate", "tee", "--seeds", "2", "--cycles", "5"]) == 2
    assert "--cycles" in capsys.readouterr().err


def test_the_readme_run_works_word_for_word(tmp_path):
    from _readme import run_block

    code, out = run_block("<!-- validate-commands -->", tmp_path, timeout_s=240)
    assert code == 0, out[-4000:]
    assert "seed 0: " in out and "seed 1: " in out and "success rate" in out and "Traceback" not in out
    report = json.loads((tmp_path / "validate-tee" / "report.json").read_text())
    lines = (tmp_path / "validate-tee" / "records.jsonl").read_text().splitlines()
    assert report["piles"] == 2 and report["cycles"] == len(lines) >= 3
    assert 0.0 <= report["success_rate_95"][0] <= report["success_rate"] <= report["success_rate_95"][1] <= 1.0


class _Backwards:
    """A stand-in for the worker pool that finishes its piles out of order (as parallel workers
    may: the newest and the oldest in turn), each pile made up from its seed: two cycles, the
    second an "empty grip" on odd seeds, with its picture."""

    name = "backwards"

    def __init__(self, workers, model):
        self.slots, self.queue, self.waits = workers, [], 0

    def submit(self, spec):
        self.queue.append(spec)
        return spec.seed

    def wait(self, handles):
        self.waits += 1
        return [max(handles) if self.waits % 2 else min(handles)]

    def result(self, seed):
        spec = next(s for s in self.queue if s.seed == seed)
        outcomes = ["picked", "empty grip" if seed % 2 else "picked"]
        records = [
            {"seed": seed, "cycle": i + 1, "outcome": o, "cycle_time_s": 1.0, "cpu_s": 1.0, "binpick_cpu_s": 0.1}
            for i, o in enumerate(outcomes)
        ]
        pictures = (
            {"empty grip": {"cycle": 2, "png": b"png of seed %d" % seed}} if "empty grip" in spec.pictures else {}
        )
        pile = {"seed": seed, "dropped": 2, "removed": 1 + (seed % 2 == 0), "emptied": seed % 2 == 0, "cycles": 2}
        pile.update(picked=outcomes.count("picked"), stopped=None, cpu_s=2.5, emulator_failures=[])
        return {"pile": pile, "records": records, "pictures": pictures if seed % 2 else {}}

    def close(self, cancel=False):
        pass


def test_piles_finished_out_of_order_give_the_records_and_pictures_in_seed_order(tmp_path, monkeypatch):
    monkeypatch.setattr(v, "Pool", _Backwards)
    out = tmp_path / "run"
    report = binpick.validate("tee", seeds=4, first_seed=0, count=2, workers=4, out=out)
    assert [(r["seed"], r["cycle"]) for r in report.records] == [(s, c) for s in range(4) for c in (1, 2)]
    # seed 3 finished first and drew the picture; seed 1's, the first by seed, replaced it
    assert report.summary["failure_pictures"] == {
        "empty grip": {"seed": 1, "cycle": 2, "file": "failure_empty_grip.png"}
    }
    assert (out / "failure_empty_grip.png").read_bytes() == b"png of seed 1"
    assert report.summary["failures"] == {"empty grip": 2} and report.summary["bins_emptied"] == 2
    # cycles: seeds in order up to the one that reaches 5 (2 + 2 + 2); seed 3, run alongside, is not the run's
    five = binpick.validate("tee", cycles=5, count=2, workers=2, out=tmp_path / "five")
    assert [p["seed"] for p in five.piles] == [0, 1, 2] and five.summary["cycles"] == 6
    assert [json.loads(x)["seed"] for x in (tmp_path / "five" / "piles.jsonl").read_text().splitlines()] == [0, 1, 2]


def test_the_readme_cell_file_of_the_papers_hardware_sets_the_scan_and_the_speeds(tmp_path):
    from _readme import readme_block

    path = tmp_path / "paper.toml"
    path.write_text(readme_block("<!-- paper-cell -->"))
    frames, options, gripper, overrides = v._cell_settings(path)
    assert frames == 34 and options == {} and gripper is None  # the simulator's gripper for the part
    assert overrides == {
        "sweep": "continuous",
        "rescan": "changed",
        "plan_ahead": True,
        "max_override_percent": 100.0,
        "max_linear_speed_mm_s": 500.0,
    }


def test_a_worker_process_starts_with_one_thread_for_numpys_blas(monkeypatch):
    # Each pile runs on one thread: a worker spawned from the pool has the numeric libraries'
    # thread counts at 1 where the user set none (a user's own setting is kept), and the parent's
    # environment is as it was afterwards.
    import multiprocessing

    from binpick.sim.validate_workers import _one_library_thread

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    with _one_library_thread():
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            seen = pool.map(os.getenv, ["OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"])
    assert seen == ["1", "1", "3"]
    assert "OPENBLAS_NUM_THREADS" not in os.environ and "MKL_NUM_THREADS" not in os.environ
    assert os.environ["OMP_NUM_THREADS"] == "3"
