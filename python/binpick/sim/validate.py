"""``binpick.validate``: what share of picks succeed for a part and a gripper, and how many picks
an hour — seeded pick cycles over many simulated piles, each pile the whole simulated cell
(:class:`binpick.sim.SimulatedCell`) in a worker process of its own, on this machine or on Ray.

Vocabulary (the names are those of :mod:`binpick.sim.validate_workers`). A *pile* is one seed:
a :class:`~binpick.sim.SimulatedCell` of ``pile_size`` parts (``pile_size()``: from the seed,
within the ``count`` range) run until the bin is empty, the cell stops (nothing pickable, a
fault) or ``ATTEMPTS_PER_PART`` attempts per part were made. A *cycle* is one pick attempt of a
pile (one :class:`binpick.cell.PickRecord`); the look that finds the bin empty ends the pile and
is not a cycle.

Records. Every cycle is a JSON object (``cycle_record()``): ``seed``, ``pile_size``, ``cycle``
(1, 2, … within the pile), ``outcome`` (``"picked"`` or the failure's kind, one of
:data:`binpick.cell.FAILURE_KINDS`), the pose error against the truth, confidence, grasp, … —
all of them decided by the seed alone, identical with one worker, N workers or Ray — and the
measurements, which vary from run to run and machine to machine (:data:`MEASURED`):
``cycle_time_s`` and ``stage_s`` (the cell's physical time, :func:`binpick.cell.records.cycle_stages_s`:
the hardware's on the simulated cell's clock, binpick's compute as measured), ``cpu_s`` (the worker process's
CPU time over the cycle: the simulator's renderer, physics and emulators with binpick's own
compute), ``binpick_cpu_s`` (binpick's own compute: line extraction, pose, planning, and the planning done
ahead for the cycle during the last carry) and
``wall_s``. Every pile is a JSON object too (``run_pile()``'s ``pile``).

Files (``out``): ``run.json`` (the settings), ``records.jsonl`` (a line per cycle),
``piles.jsonl`` (a line per pile), written as piles finish, so a run that is killed keeps every
pile it finished and the same call resumes it (a run with other settings in the folder is
refused, naming the difference); at the end ``report.json``, ``summary.png``, one picture per
failure kind (``failure_<kind>.png``, the first cycle of that kind by seed and cycle) and,
asked for, ``records.parquet``.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
import pickle
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from .._validate import count as _count
from .._validate import write_atomic
from ..errors import BinpickError, FileWriteError, InvalidInputError
from . import validate_report as _report
from .validate_report import ValidationReport
from .validate_workers import (
    ATTEMPTS_PER_PART,
    FLAGS,
    MEASURED,
    PileSpec,
    Pool,
    RayTasks,
    bad,
    cores,
    pile_size,
)

__all__ = ["MEASURED", "PILE_SIZES", "ValidationReport", "identical", "validate"]

#: The pile sizes when none are given: each seed's pile has 8 to 12 parts.
PILE_SIZES = (8, 12)
#: The most piles (seeds) one run takes: a million cycles or so.
MAX_SEEDS = 100_000
#: The most cycles ``cycles`` may ask for.
MAX_CYCLES = 1_000_000
#: The most worker processes (or Ray tasks in flight) of one run.
MAX_WORKERS = 64
#: The largest pile: a bin of the default cell holds a dozen parts of the size it was made for.
MAX_PILE = 100
#: The most laser frames per scan.
MAX_FRAMES = 10_000


# --------------------------------------------------------------------------- the run's files


class _Files:
    """The run's folder: settings, records and piles as JSON lines, the failure pictures."""

    def __init__(self, out: Optional[Any]) -> None:
        self.root = None if out is None else Path(os.fspath(out))

    def open(self, settings: dict) -> tuple[dict, list[dict], dict]:
        """Creates the folder, or resumes the run in it: the piles finished (seed → pile record),
        their cycle records, and the pictures drawn (kind → {seed, cycle, file}). A run with other
        settings is refused, naming the difference."""
        if self.root is None:
            return {}, [], {}
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FileWriteError(f"out: cannot create {self.root} ({exc})") from None
        run = self.root / "run.json"
        if run.exists():
            before = _read_json(run)
            diffs = [k for k in sorted(set(before) | set(settings)) if before.get(k) != settings.get(k)]
            if diffs:
                said = "; ".join(f"{k}: {before.get(k)!r} there, {settings.get(k)!r} now" for k in diffs)
                flags = "; ".join(f"{FLAGS.get(k, k)}: {before.get(k)!r} there, {settings.get(k)!r} now" for k in diffs)
                raise bad(
                    f"out: {self.root} holds a run with other settings ({said}); give the same settings to "
                    "resume it, or another out folder",
                    f"--out: {self.root} holds a run with other settings ({flags}); give the same flags to "
                    "resume it, or another --out folder",
                )
        elif (self.root / "records.jsonl").exists():
            raise bad(
                f"out: {self.root} holds records.jsonl but no run.json; give another out folder",
                f"--out: {self.root} holds records.jsonl but no run.json; give another --out folder",
            )
        write_atomic(run, json.dumps(settings, indent=1))
        piles = {p["seed"]: p for p in _read_lines(self.root / "piles.jsonl")}
        records = [r for r in _read_lines(self.root / "records.jsonl") if r["seed"] in piles]
        # A killed run may have left a pile's cycles without its pile line, or half a line: keep what is whole.
        self._rewrite(records, list(piles.values()))
        index = self.root / "failures.json"
        pictures = _read_json(index) if index.exists() else {}
        pictures = {k: v for k, v in pictures.items() if v["seed"] in piles and (self.root / v["file"]).exists()}
        return piles, records, pictures

    def add(self, result: dict) -> None:
        """Appends a finished pile: its cycles, then its pile line (the pile counts as finished
        once that line is there)."""
        if self.root is None:
            return
        with open(self.root / "records.jsonl", "a", encoding="utf-8") as f:
            for r in result["records"]:
                f.write(json.dumps(r) + "\n")
        with open(self.root / "piles.jsonl", "a", encoding="utf-8") as f:
            f.write(json.dumps(result["pile"]) + "\n")

    def picture(self, kind: str, seed: int, cycle: int, png: bytes, pictures: dict) -> None:
        """Keeps ``png`` as the picture of ``kind`` (the earlier one it replaces is removed)."""
        name = "failure_" + kind.replace(" ", "_") + ".png"
        pictures[kind] = {"seed": seed, "cycle": cycle, "file": name}
        if self.root is None:
            return
        write_atomic(self.root / name, png)
        write_atomic(self.root / "failures.json", json.dumps(pictures, indent=1))

    def finish(self, records: list[dict], piles: list[dict]) -> None:
        """The run's records and piles in seed and cycle order (those of the run's seeds only)."""
        if self.root is not None:
            self._rewrite(records, piles)

    def _rewrite(self, records: list[dict], piles: list[dict]) -> None:
        write_atomic(self.root / "records.jsonl", "".join(json.dumps(r) + "\n" for r in records))
        write_atomic(self.root / "piles.jsonl", "".join(json.dumps(p) + "\n" for p in piles))


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"out: {path} cannot be read ({exc}); give another out folder") from None


def _read_lines(path: Path) -> list[dict]:
    """The JSON lines of ``path`` (none when it is missing), without a last line a kill cut short."""
    if not path.exists():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            break
    return out


# --------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class _Plan:
    """A validation run's settings, checked: which seeds, the pile sizes, the cell's settings."""

    model: Any
    part: str
    sizes: tuple[int, int]
    first_seed: int
    seeds: Optional[int]
    cycles: Optional[int]
    frames: Optional[int]
    options: Mapping[str, Any]
    gripper: Any
    overrides: Mapping[str, Any]
    cell: Optional[str]

    def settings(self) -> dict:
        """What decides the run's records (run.json): a resumed run must have the same."""
        from .. import __version__
        from .twin import TwinWorld

        defaults = inspect.signature(TwinWorld.__init__).parameters
        vertices = np.ascontiguousarray(self.model.vertices, dtype=np.float64)
        return {
            "part": self.part,
            "part_geometry": hashlib.sha256(vertices.tobytes()).hexdigest()[:16],
            "count": list(self.sizes),
            "first_seed": self.first_seed,
            "seeds": self.seeds,
            "cycles": self.cycles,
            "frames": self.frames if self.frames is not None else defaults["frames"].default,
            "speed_scale": defaults["speed_scale"].default,
            "estimate_options": dict(self.options),
            "gripper": None if self.gripper is None else _jsonable(asdict(self.gripper)),
            "cell_options": dict(self.overrides),
            "cell": self.cell,
            "attempts_per_part": ATTEMPTS_PER_PART,
            "binpick": __version__,
        }

    def spec(self, seed: int, pictures: Mapping[str, dict]) -> PileSpec:
        """The pile of ``seed``, drawing the failure kinds no earlier seed has a picture of."""
        from ..cell.records import FAILURE_KINDS

        return PileSpec(
            seed=seed,
            pile_size=pile_size(seed, self.sizes),
            frames=self.frames,
            estimate_options=self.options,
            gripper=self.gripper,
            overrides=self.overrides,
            pictures=frozenset(k for k in FAILURE_KINDS if k not in pictures or pictures[k]["seed"] > seed),
        )

    def todo(self, done: Mapping[int, dict]) -> Iterator[int]:
        """The seeds not finished, in the order they are started: with ``cycles`` in seed order
        (as many as it may take), else the largest piles first, so that the last pile to finish,
        running while the other workers have none left, is a small one."""
        if self.cycles is not None:
            return (s for s in range(self.first_seed, self.first_seed + MAX_SEEDS) if s not in done)
        seeds = [s for s in range(self.first_seed, self.first_seed + self.seeds) if s not in done]
        return iter(sorted(seeds, key=lambda s: -pile_size(s, self.sizes)))

    def chosen(self, done: Mapping[int, dict]) -> list[int]:
        """The run's seeds among those finished: all asked for (``seeds``), or those in seed order
        up to the one whose cycles bring the count to ``cycles``."""
        if self.cycles is None:
            return [s for s in range(self.first_seed, self.first_seed + self.seeds) if s in done]
        chosen, total = [], 0
        for s in range(self.first_seed, self.first_seed + MAX_SEEDS):
            if s not in done or total >= self.cycles:
                break
            chosen.append(s)
            total += done[s]["cycles"]
        return chosen

    def enough(self, done: Mapping[int, dict], running: Iterable[int]) -> bool:
        """Whether no more piles need starting: the run is complete, or (``cycles``) every seed
        up to the last one finished is finished or ``running`` and the piles finished hold the
        cycles asked for — so that once those running finish, the seeds in order reach them."""
        if self.cycles is None or self.complete(done):
            return self.complete(done)
        below = set(done) | set(running)
        top = max(done, default=self.first_seed - 1)
        gapless = all(s in below for s in range(self.first_seed, top + 1))
        return gapless and sum(p["cycles"] for p in done.values()) >= self.cycles

    def complete(self, done: Mapping[int, dict]) -> bool:
        """Whether the piles finished make the whole run."""
        if self.cycles is None:
            return len(self.chosen(done)) == self.seeds
        return sum(done[s]["cycles"] for s in self.chosen(done)) >= self.cycles


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def _cell_settings(path: Any) -> tuple[Optional[int], dict, Any, dict]:
    """The cell file's scan and gripper settings: frames, [estimate], the gripper (its [gripper]
    shape and [cell] tool, where it gives them: else the simulated cell's), the options the cell
    judges picks by (orientation_needed, min_confidence), the laser's sweep (``[cell] sweep``,
    ``rescan``), planning ahead (``plan_ahead``) and the arm's speeds (``[limits] max_override_percent`` and
    ``max_linear_speed_mm_s``: the simulated cell runs at them). The simulated cell's bin,
    camera and arm stay the simulator's."""
    from ..cell import cell_file as cf

    f = cf.load_cell_file(path)
    frames = None if f.get("cell", "frames", None) is None else f.integer("cell", "frames")
    # The file's gripper where it describes one; else the simulated cell's, made for the part.
    described = f.get("cell", "tool", None) is not None or any(
        f.get("gripper", k, None) is not None for k in cf.GRIPPER_SHAPE_KEYS
    )
    gripper = cf._gripper_geometry(f, f.pose("cell", "tool", [0, 0, 150, 0, 0, 0])) if described else None
    options = cf._stake(f)
    for key in ("sweep", "rescan"):
        if f.get("cell", key, None) is not None:
            options[key] = f.text("cell", key)
    if f.get("cell", "plan_ahead", None) is not None:
        options["plan_ahead"] = f.boolean("cell", "plan_ahead")
    for key in ("max_override_percent", "max_linear_speed_mm_s"):
        if f.get("limits", key, None) is not None:
            options[key] = f.number("limits", key)
    return frames, cf._estimate_options(f), gripper, options


def _resolve_part(part: Any, unit: str) -> tuple[Any, str]:
    """The part and how run.json names it: a Model, a built-in part's name or a mesh file."""
    from .. import parts
    from .._sizes import check_part
    from ..models import Model

    if isinstance(part, Model):
        model, name = part, part.name
    elif isinstance(part, (str, os.PathLike)):
        name = os.fspath(part)
        if name in parts.BUILT_IN:
            model = parts.built_in(name)
        else:
            model = Model.from_mesh(name, unit=unit)
            name = f"{os.path.abspath(name)} ({unit})"
    else:
        raise InvalidInputError(
            f"part: expected a binpick.Model, a built-in part's name or a mesh file, got {type(part).__name__}"
        )
    check_part(model)
    return model, name


def _named(call: Callable[[], Any]) -> Any:
    """``call()``, its InvalidInputError given the ``binpick validate`` flag of the keyword it names."""
    try:
        return call()
    except InvalidInputError as exc:
        name, _, rest = str(exc).partition(":")
        if exc.cli_message is None and name in FLAGS:
            exc.cli_message = f"{FLAGS[name]}:{rest}"
        raise


def _sizes(count: Any) -> tuple[int, int]:
    if isinstance(count, (int, np.integer)) and not isinstance(count, bool):
        count = (count, count)
    try:
        lo, hi = count
    except (TypeError, ValueError):
        raise InvalidInputError(f"count: expected (lo, hi) parts per pile, got {count!r:.60}") from None
    lo, hi = _count(lo, "count", 1, MAX_PILE), _count(hi, "count", 1, MAX_PILE)
    if hi < lo:
        raise InvalidInputError(f"count: the range {lo}-{hi} is empty; give the smaller number first")
    return lo, hi


def _plan(part, unit, seeds, first_seed, cycles, count, frames, cell, estimate_options) -> _Plan:
    """The run's settings, each checked (InvalidInputError naming the keyword, and the flag)."""
    model, name = _resolve_part(part, unit)
    first_seed = _count(first_seed, "first_seed", 0, 2**32 - 1 - MAX_SEEDS)
    if seeds is not None and cycles is not None:
        raise bad("seeds: give seeds or cycles, not both", "--seeds: give --seeds or --cycles, not both")
    if cycles is not None:
        cycles = _count(cycles, "cycles", 1, MAX_CYCLES)
    else:
        seeds = _count(10 if seeds is None else seeds, "seeds", 1, MAX_SEEDS)
    sizes = _sizes(count)
    cell_frames, cell_options, gripper, overrides = (None, {}, None, {}) if cell is None else _cell_settings(cell)
    if frames is not None:
        frames = _count(frames, "frames", 2, MAX_FRAMES)
    if estimate_options is not None and not isinstance(estimate_options, Mapping):
        raise InvalidInputError(f"estimate_options: expected a dict, got {type(estimate_options).__name__}")
    return _Plan(
        model=model,
        part=name,
        sizes=sizes,
        first_seed=first_seed,
        seeds=seeds,
        cycles=cycles,
        frames=cell_frames if frames is None else frames,
        options={**cell_options, **dict(estimate_options or {})},
        gripper=gripper,
        overrides=overrides,
        cell=None if cell is None else os.path.abspath(os.fspath(cell)),
    )


def validate(
    part: Any,
    *,
    unit: str = "mm",
    seeds: Optional[int] = None,
    first_seed: int = 0,
    cycles: Optional[int] = None,
    count: Sequence[int] = PILE_SIZES,
    frames: Optional[int] = None,
    cell: Any = None,
    estimate_options: Optional[Mapping[str, Any]] = None,
    out: Any = None,
    workers: Optional[int] = None,
    ray: Optional[str] = None,
    parquet: bool = False,
    progress: Optional[Callable[[str], None]] = None,
) -> ValidationReport:
    """Runs seeded pick cycles of ``part`` over many simulated piles and reports the success rate
    (with its 95 % Wilson interval), bins emptied, failures by kind, the cycle time and picks per
    hour (:class:`~binpick.sim.validate_report.ValidationReport`).

    Args:
        part: a :class:`binpick.Model`, a built-in part's name (``"tee"``) or a mesh file read in ``unit``.
        seeds: piles to run, seeds ``first_seed``, ``first_seed + 1``, … (default 10) — or
        cycles: run piles in seed order until this many cycles are done (the run ends with the
            pile in which the count is reached, whatever the workers).
        count: ``(lo, hi)`` parts per pile (:func:`~binpick.sim.validate_workers.pile_size`), or one number.
        frames: laser frames per scan (default: the cell file's, else the simulated cell's).
        cell: a cell file whose frames, ``[estimate]``, gripper (``[gripper]``, ``[cell] tool``),
            ``orientation_needed`` and ``min_confidence`` are used (the bin, camera and arm stay
            the simulated cell's).
        estimate_options: keyword arguments of :func:`binpick.estimate_poses` (over the cell file's).
        out: the run's folder (see the module docstring); None: nothing is written.
        workers: piles run at a time (default: this machine's cores; on a Ray cluster its CPUs).
        ray: None (worker processes here), ``"local"`` (a local Ray instance) or a Ray cluster's address.
        parquet: also write ``records.parquet`` (needs pyarrow).
        progress: called with a line per finished pile.

    Ctrl-C (KeyboardInterrupt) stops the workers; the piles finished are in ``out``.
    """
    plan = _named(lambda: _plan(part, unit, seeds, first_seed, cycles, count, frames, cell, estimate_options))
    if workers is not None:
        workers = _named(lambda: _count(workers, "workers", 1, MAX_WORKERS))
    if ray is not None and (not isinstance(ray, str) or not ray.strip()):
        raise bad(
            f"ray: expected 'local' or a Ray cluster's address (host:port), got {ray!r:.60}",
            f"--ray: expected a Ray cluster's address (host:port), or nothing for a local instance, got {ray!r:.60}",
        )
    settings = plan.settings()
    files = _Files(out)
    done, records, pictures = _named(lambda: files.open(settings))
    t0 = time.perf_counter()
    cpu0 = _cpu_here()
    backend, cycles_run = _run(plan, workers, ray, files, done, records, pictures, progress or (lambda line: None))
    # Ray's worker processes are not this process's children: only the local pool is counted.
    cpu_here = None if cpu0 is None or ray is not None else _cpu_here() - cpu0
    chosen = plan.chosen(done)
    kept = set(chosen)
    records = sorted((r for r in records if r["seed"] in kept), key=lambda r: (r["seed"], r["cycle"]))
    piles = [done[s] for s in chosen]
    files.finish(records, piles)
    pictures = {k: v for k, v in pictures.items() if v["seed"] in kept}
    run = {
        "backend": backend,
        "wall_s": round(time.perf_counter() - t0, 3),
        "cycles_run": cycles_run,
        # Everything this run cost on this machine: this process and every worker process, their
        # start-up included (the local worker processes only).
        "cpu_s_here": None if cpu_here is None else round(cpu_here, 3),
    }
    summary = _report.summarize(records, piles, settings, pictures, run)
    return _named(lambda: _report.write(files.root, summary, records, piles, parquet=parquet))


def _run(
    plan: _Plan,
    workers: Optional[int],
    ray: Optional[str],
    files: _Files,
    done: dict,
    records: list,
    pictures: dict,
    say: Callable[[str], None],
) -> tuple[str, int]:
    """Runs the piles not finished yet, as many at a time as the backend has slots, writing each
    as it finishes; returns the backend's name and the cycles run."""
    if plan.complete(done):
        return "none (every pile was finished before)", 0
    model = pickle.dumps(plan.model)
    backend = Pool(workers or cores(), model) if ray is None else RayTasks(ray, workers, model)
    seeds = plan.todo(done)
    piles = None if plan.cycles is None else 0
    total = plan.seeds - len(done) if plan.cycles is None else None
    lo, hi = plan.sizes
    say(
        f"validate {plan.part}: "
        + (_plural(total, "pile") if total is not None else _plural(plan.cycles, "cycle"))
        + f" of {lo if lo == hi else f'{lo}-{hi}'} parts on {backend.name}"
        + (f" ({_plural(len(done), 'pile')} finished before)" if done else "")
    )
    inflight: dict[Any, int] = {}
    t0, piles, cycles_run = time.perf_counter(), 0, 0
    try:
        while True:
            while len(inflight) < backend.slots and not plan.enough(done, inflight.values()):
                seed = next(seeds, None)
                if seed is None:
                    break
                inflight[backend.submit(plan.spec(seed, pictures))] = seed
            # Done: the piles still running (with ``cycles``, seeds past the one that reached
            # the count) are not the run's, and are stopped.
            if not inflight or plan.complete(done):
                break
            for handle in backend.wait(inflight):
                seed = inflight.pop(handle)
                try:
                    result = backend.result(handle)
                except Exception as exc:
                    raise BinpickError(
                        f"seed {seed}: the pile failed in its worker ({type(exc).__name__}: {str(exc)[:500]}); "
                        "the piles finished are kept, and the same call resumes the run"
                    ) from exc
                files.add(result)
                done[seed] = result["pile"]
                records.extend(result["records"])
                for kind, pic in result["pictures"].items():
                    old = pictures.get(kind)
                    if old is None or (seed, pic["cycle"]) < (old["seed"], old["cycle"]):
                        files.picture(kind, seed, pic["cycle"], pic["png"], pictures)
                piles += 1
                cycles_run += result["pile"]["cycles"]
                say(_progress_line(plan, result["pile"], done, time.perf_counter() - t0, piles, cycles_run, total))
    except BaseException:
        backend.close(cancel=True)
        raise
    backend.close(cancel=bool(inflight))
    return backend.name, cycles_run


def _progress_line(
    plan: _Plan, pile: dict, done: Mapping[int, dict], elapsed: float, piles: int, cycles_run: int, total: Optional[int]
) -> str:
    """A finished pile: seed, parts removed, cycles; the run's progress, elapsed time and ETA."""
    if total is not None:
        left = (total - piles) * elapsed / piles
        where = f"{piles}/{total} piles"
    else:
        reached = sum(done[s]["cycles"] for s in plan.chosen(done))
        left = max(0, plan.cycles - reached) * elapsed / max(1, cycles_run)
        where = f"{min(reached, plan.cycles)}/{plan.cycles} cycles"
    end = "bin emptied" if pile["emptied"] else f"stopped: {pile['stopped'] or 'attempts used up'}"
    return (
        f"seed {pile['seed']}: {pile['removed']} of {_plural(pile['dropped'], 'part')} removed in "
        f"{_plural(pile['cycles'], 'cycle')} "
        f"({pile['picked']} picked), {end[:100]}; {where}, elapsed {_clock(elapsed)}, ETA {_clock(left)}"
    )


def _cpu_here() -> Optional[float]:
    """CPU seconds of this process and its finished child processes so far (None where unknown)."""
    try:
        import resource
    except ImportError:  # not on a Unix
        return None
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _clock(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def identical(a: Sequence[dict], b: Sequence[dict]) -> bool:
    """Whether two runs' cycle records are the same but for the measurements (:data:`MEASURED`)."""
    strip = [[{k: v for k, v in r.items() if k not in MEASURED} for r in rs] for rs in (a, b)]
    return strip[0] == strip[1]
