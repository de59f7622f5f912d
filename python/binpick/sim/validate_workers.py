"""What a validation run (:func:`binpick.validate`) runs in its workers: one pile of the
simulated cell (:func:`run_pile`), its cycles as JSON records (:func:`cycle_record`), and the two
ways of running piles side by side — worker processes here (:class:`Pool`) and Ray tasks
(:class:`RayTasks`).

A pile runs in a process of its own with one thread for rendering and binpick, on a fresh copy
of the part, so that what it records depends on its seed alone: the same seeds give the same
records with one worker, N workers or Ray, but for the measurements (:data:`MEASURED`).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import tempfile
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..cell.records import cycle_stages_s
from ..errors import BinpickError, InvalidInputError

__all__ = [
    "ATTEMPTS_PER_PART",
    "FLAGS",
    "MEASURED",
    "PILE_MEASURED",
    "PileSpec",
    "Pool",
    "RayTasks",
    "cycle_record",
    "pile_size",
    "run_pile",
]

#: A pile is given up after this many attempts per part (plus the look that finds the bin empty).
ATTEMPTS_PER_PART = 2
#: Fields of a cycle record that are measurements (wall clock, CPU time, and the cycle time
#: derived from the wall clock): they vary between runs of the same seed; everything else is
#: the seed's alone.
MEASURED = ("cycle_time_s", "stage_s", "cpu_s", "binpick_cpu_s", "wall_s")
#: Fields of a pile record that are measurements.
PILE_MEASURED = ("setup_cpu_s", "cpu_s", "wall_s")
#: The keyword of :func:`binpick.validate` each ``binpick validate`` flag sets (for the command's messages).
FLAGS = {
    "part": "PART",
    "seeds": "--seeds",
    "first_seed": "--first-seed",
    "cycles": "--cycles",
    "count": "--count",
    "frames": "--frames",
    "workers": "--workers",
    "ray": "--ray",
    "out": "--out",
    "cell": "--cell",
    "estimate_options": "--d-star/--min-points",
    "parquet": "--parquet",
}


def bad(message: str, cli: Optional[str] = None) -> InvalidInputError:
    """InvalidInputError(``message``) whose command-line message is ``cli``, by default the
    message with the keyword it starts with spelled as its ``binpick validate`` flag."""
    exc = InvalidInputError(message)
    name, _, rest = message.partition(":")
    exc.cli_message = cli if cli is not None else (f"{FLAGS[name]}:{rest}" if name in FLAGS else None)
    return exc


@dataclass(frozen=True)
class PileSpec:
    """What one pile is run with (the part travels beside it, pickled once per worker): its
    ``seed`` and ``pile_size``, the cell's settings (``frames`` None: the simulated cell's
    default; ``gripper`` None: the simulated gripper; ``overrides``: CellConfig fields), and the
    failure kinds to draw a picture of (``pictures``: those no earlier seed has drawn)."""

    seed: int
    pile_size: int
    frames: Optional[int] = None
    estimate_options: Mapping[str, Any] = field(default_factory=dict)
    gripper: Any = None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    pictures: frozenset = frozenset()


def pile_size(seed: int, sizes: Sequence[int]) -> int:
    """The parts in seed ``seed``'s pile: ``lo + seed mod (hi − lo + 1)`` for ``sizes = (lo, hi)``
    (each size in turn, as the bin-clearing bench has them)."""
    lo, hi = sizes
    return lo + seed % (hi - lo + 1)


def _binpick_cpu_s(timings: Mapping[str, float]) -> float:
    """binpick's own CPU time in a cycle, s: the stages it times on its thread (line extraction,
    pose, planning, grasp widths, nudge planning), and the planning done ahead for it during the last carry
    (:mod:`binpick.cell.ahead`, whose time is hidden in the carry's)."""
    keys = ("cpu.", "scan.cpu.", "ahead.compute.")
    return round(sum(float(v) for k, v in timings.items() if k.startswith(keys)) / 1e3, 4)


def cycle_record(seed: int, pile_size: int, record: Any, *, cpu_s: Optional[float], wall_s: Optional[float]) -> dict:
    """The JSON record of one cycle (see the module docstring) from its :class:`binpick.cell.PickRecord`."""
    t = record.truth
    stages = cycle_stages_s(record.timings) or {}
    T = record.T_base_object
    return {
        "seed": seed,
        "pile_size": pile_size,
        "cycle": record.index,
        "outcome": "picked" if record.success else (record.failure or "failed"),
        "error": record.error,
        "rotation_error_deg": None if t is None else t.rotation_error_deg,
        "translation_error_mm": None if t is None else t.translation_error_mm,
        "pick_grade": None if t is None else t.pick_grade,
        "grasp_fits_truth": record.grasp_fits_truth,
        "confidence": record.confidence,
        "confidence_any": record.confidence_any,
        "orientation_decided": record.orientation_decided,
        "score": record.score,
        "rmse_mm": record.rmse,
        "method": record.method,
        "points": record.points,
        "grasp": record.grasp,
        "held": record.held,
        "picked_instance": record.picked_instance,
        "looks": record.looks,
        "planned_ahead": bool(record.timings.get("ahead.used")),
        "skipped": len(record.skipped),
        "nudges": len(record.nudges),
        "collisions": [str(c["with"]) for c in record.collisions],
        "T_base_object": None if T is None else np.round(T, 4).tolist(),
        "cycle_time_s": round(sum(stages.values()), 4) if stages else None,
        "stage_s": {k: round(v, 4) for k, v in stages.items()},
        "cpu_s": None if cpu_s is None else round(cpu_s, 4),
        "binpick_cpu_s": _binpick_cpu_s(record.timings),
        "wall_s": None if wall_s is None else round(wall_s, 4),
    }


class _CycleClock:
    """The pick loop's progress callback that notes the process's CPU time and the wall clock
    where each cycle starts (the loop's ``— pick i of n —`` line)."""

    def __init__(self) -> None:
        self.starts: dict[int, tuple[float, float]] = {}

    def __call__(self, stage: str, message: str) -> None:
        if stage == "pick" and message.startswith("— pick "):
            try:
                self.starts[int(message.split()[2])] = (time.process_time(), time.perf_counter())
            except (IndexError, ValueError):
                pass

    def spans(self, end: tuple[float, float]) -> dict[int, tuple[float, float]]:
        """Cycle → (CPU s, wall s) from its start to the next one's (the last one's to ``end``)."""
        marks = sorted(self.starts.items())
        nexts = [m for _, m in marks[1:]] + [end]
        return {i: (b[0] - a[0], b[1] - a[1]) for (i, a), b in zip(marks, nexts)}


def run_pile(model: Any, spec: PileSpec) -> dict:
    """Runs one pile in this process (one thread for rendering and binpick): ``{"pile": …,
    "records": [cycle records], "pictures": {kind: {"cycle", "png" (bytes)}}}``."""
    from ..cell.records import FAILURE_KINDS
    from .twin import SimulatedCell

    cpu0, wall0 = time.process_time(), time.perf_counter()
    clock = _CycleClock()
    kwargs: dict[str, Any] = dict(spec.overrides)
    if spec.frames is not None:
        kwargs["frames"] = spec.frames
    if spec.gripper is not None:
        kwargs["gripper"] = spec.gripper
    with SimulatedCell(
        model,
        count=spec.pile_size,
        seed=spec.seed,
        num_threads=1,
        progress=clock,
        estimate_options=dict(spec.estimate_options),
        **kwargs,
    ) as sim:
        dropped = len(sim.pile)
        setup_cpu = time.process_time() - cpu0
        report = sim.cell.run(ATTEMPTS_PER_PART * dropped + 1)
        left = sim.parts_left()
        lost = len(sim.lost)
        end = (time.process_time(), time.perf_counter())
        spans = clock.spans(end)
        bin_bounds = sim.cell.config.bin_bounds
        emulator_failures = list(sim.emulator_failures)
    cycles = [r for r in report.records if not r.bin_empty]
    records = [
        cycle_record(
            spec.seed,
            spec.pile_size,
            r,
            cpu_s=spans.get(r.index, (None, None))[0],
            wall_s=spans.get(r.index, (None, None))[1],
        )
        for r in cycles
    ]
    pictures: dict[str, dict] = {}
    picture_errors: list[str] = []
    for r in cycles:
        kind = r.failure
        if kind in spec.pictures and kind not in pictures and r.scan is not None:
            try:
                pictures[kind] = {"cycle": r.index, "png": _failure_png(model, r, bin_bounds, spec.seed)}
            except BinpickError as exc:  # a picture is not worth the pile's records: say why it is missing
                picture_errors.append(f"seed {spec.seed} cycle {r.index} ({kind}): {type(exc).__name__}: {exc}")
    pile = {
        "seed": spec.seed,
        "pile_size": spec.pile_size,
        "dropped": dropped,
        "removed": dropped - left - lost,
        # Thrown out of the bin by a push (a collision of the cycle that pushed): not removed.
        "lost": lost,
        "emptied": left == 0 and lost == 0,
        "cycles": len(cycles),
        "picked": sum(r.success for r in cycles),
        "failures": {
            k: sum(r.failure == k for r in cycles) for k in FAILURE_KINDS if any(r.failure == k for r in cycles)
        },
        "stopped": report.stopped,
        "emulator_failures": emulator_failures,
        "picture_errors": picture_errors,
        "setup_cpu_s": round(setup_cpu, 4),
        "cpu_s": round(time.process_time() - cpu0, 4),
        "wall_s": round(time.perf_counter() - wall0, 4),
    }
    return {"pile": pile, "records": records, "pictures": pictures}


def _failure_png(model: Any, record: Any, bin_bounds: Any, seed: int) -> bytes:
    """The picture of a failed cycle (:func:`binpick.viz.save_failure`) as PNG bytes, so that it
    travels back from a worker on another machine."""
    from .. import viz

    title = f"seed {seed}, cycle {record.index}: {record.failure} — {record.error or ''}"
    with tempfile.TemporaryDirectory() as folder:
        path = viz.save_record_failure(
            Path(folder) / "failure.png", record, model=model, bin_bounds=bin_bounds, title=title
        )
        return path.read_bytes()


_WORKER_MODEL: Optional[bytes] = None


def _init_worker(model: bytes) -> None:
    global _WORKER_MODEL
    _WORKER_MODEL = model


def _pool_task(spec: PileSpec) -> dict:
    """A pile in a worker process: a fresh copy of the part for each pile, so that no pile
    sees what an earlier one in the same process left in it."""
    assert _WORKER_MODEL is not None, "the worker was started without the part"
    return run_pile(pickle.loads(_WORKER_MODEL), spec)


def _ray_task(model: bytes, spec: PileSpec) -> dict:
    return run_pile(pickle.loads(model), spec)


#: The thread-count variables of the numeric libraries a worker loads (numpy's OpenBLAS, or MKL,
#: and OpenMP), each worker one thread as a pile runs on one (Ray sets OMP_NUM_THREADS so too).
_LIBRARY_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def _one_library_thread() -> Iterator[None]:
    """The numeric libraries' thread counts set to 1 in this process's environment (the one a
    spawned worker inherits) where the user set none, and restored after. With a BLAS thread per
    core in each worker, the idle ones spun after every small matrix product: 7 % of a worker's
    CPU on a tee cycle."""
    unset = [k for k in _LIBRARY_THREADS if k not in os.environ]
    for k in unset:
        os.environ[k] = "1"
    try:
        yield
    finally:
        for k in unset:
            os.environ.pop(k, None)


class Pool:
    """Local worker processes (spawned: the parent runs threads, which a fork would copy
    half-way), one pile per task."""

    def __init__(self, workers: int, model: bytes) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.slots = workers
        self.name = f"{workers} worker process{'es' if workers != 1 else ''}"
        self._executor = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(model,),
        )

    def submit(self, spec: PileSpec) -> Any:
        # A worker process starts during a submit: it starts with one thread for numpy's BLAS.
        with _one_library_thread():
            return self._executor.submit(_pool_task, spec)

    def wait(self, handles: Iterable[Any]) -> list[Any]:
        from concurrent.futures import FIRST_COMPLETED
        from concurrent.futures import wait as wait_futures

        return list(wait_futures(list(handles), return_when=FIRST_COMPLETED).done)

    def result(self, handle: Any) -> dict:
        return handle.result()

    def close(self, cancel: bool = False) -> None:
        if cancel:
            # Stop the piles under way too: the finished ones are on disk, and the same call resumes.
            terminate = getattr(self._executor, "terminate_workers", None)  # Python 3.14
            if terminate is not None:
                terminate()
            else:
                processes = list((getattr(self._executor, "_processes", None) or {}).values())
                self._executor.shutdown(wait=False, cancel_futures=True)
                for p in processes:
                    p.terminate()
                for p in processes:  # reaped, so that their CPU time counts in the run's
                    p.join()
        self._executor.shutdown(wait=True)


class RayTasks:
    """Ray tasks, one pile each: a local Ray instance (``address`` ``"local"``) with ``workers``
    CPUs, or the cluster at ``address`` (a Ray that this process runs already is used as it is);
    the part is put in Ray's object store once."""

    def __init__(self, address: str, workers: Optional[int], model: bytes) -> None:
        address = None if address == "local" else address
        try:
            import ray
        except ImportError:
            raise bad('ray: running on Ray needs Ray: pip install "binpick[ray]"') from None
        self.ray = ray
        self._started = False
        if not ray.is_initialized():
            if address is not None:
                _reachable(address)
            try:
                if address is None:
                    ray.init(num_cpus=workers or cores(), include_dashboard=False, logging_level="warning")
                else:
                    ray.init(address=address, include_dashboard=False, logging_level="warning")
            # Ray raises ConnectionError, ValueError, RuntimeError, … for an address it cannot join.
            except Exception as exc:
                where = "a local Ray instance" if address is None else f"the Ray cluster at {address!r}"
                raise bad(
                    f"ray: cannot start or join {where} ({type(exc).__name__}: {str(exc)[:300]}); give the address "
                    "`ray start --head` printed (host:port), or leave it out to start a local instance",
                    f"--ray: cannot start or join {where} ({type(exc).__name__}: {str(exc)[:300]}); give the "
                    "address `ray start --head` printed (host:port), or `--ray` alone to start a local instance",
                ) from None
            self._started = True
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.slots = workers or max(1, cpus)
        tasks = f"{self.slots} task{'' if self.slots == 1 else 's'} at a time"
        self.name = f"Ray ({'local' if address is None else address}, {tasks})"
        self._model = ray.put(model)
        self._task = ray.remote(num_cpus=1, max_retries=0)(_ray_task)
        self._pending: set = set()

    def submit(self, spec: PileSpec) -> Any:
        ref = self._task.remote(self._model, spec)
        self._pending.add(ref)
        return ref

    def wait(self, handles: Iterable[Any]) -> list[Any]:
        done, _ = self.ray.wait(list(handles), num_returns=1)
        return done

    def result(self, handle: Any) -> dict:
        self._pending.discard(handle)
        return self.ray.get(handle)

    def close(self, cancel: bool = False) -> None:
        if cancel:
            for ref in self._pending:
                self.ray.cancel(ref, force=True)
        if self._started:
            self.ray.shutdown()


#: How long joining a Ray cluster waits for its address to answer, s (Ray itself retries for minutes).
RAY_CONNECT_S = 10.0


def _reachable(address: str) -> None:
    """InvalidInputError naming ``--ray`` when ``address`` (host:port, or ray://host:port) is not
    one or nothing answers there within :data:`RAY_CONNECT_S`; ``auto`` is left to Ray."""
    import socket

    if address == "auto":
        return
    host, sep, port = address.split("://", 1)[-1].rpartition(":")
    if not sep or not host or not port.isdigit():
        raise bad(
            f"ray: {address!r:.80} is not a Ray cluster's address; give host:port, as `ray start --head` prints it"
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_S).close()
    except (OSError, OverflowError) as exc:
        raise bad(
            f"ray: nothing answers at {address!r:.80} ({exc}); start the cluster's head (`ray start --head`) and "
            "give the address it prints, or leave the address out to start a local instance",
            f"--ray: nothing answers at {address!r:.80} ({exc}); start the cluster's head (`ray start --head`) and "
            "give the address it prints, or give --ray alone to start a local instance",
        ) from None


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
