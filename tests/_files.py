"""Small valid calibration files and scan folders for the file-reader tests, and the seeded byte
mutations the fuzz tests feed them."""

from __future__ import annotations

import random
import time
from collections import Counter
from pathlib import Path
from typing import Any, Callable

import numpy as np

from binpick.calibration import CellCalibration
from binpick.camera import CameraIntrinsics
from binpick.errors import BinpickError
from binpick.scan import save_scan
from binpick.transforms import look_down

WIDTH, HEIGHT = 64, 48

#: Mutations per fuzz run, and the longest one case may take.
CASES = 300
SLOWEST_CASE_S = 2.0


def small_calibration() -> CellCalibration:
    """A 64 × 48 camera, a laser 100 mm to its side, the camera 40 mm below the flange."""
    T_laser = np.eye(4)
    T_laser[0, 3] = 100.0
    T_hand = np.eye(4)
    T_hand[2, 3] = 40.0
    camera = CameraIntrinsics.pinhole(WIDTH, HEIGHT, 80.0, 80.0, 31.5, 23.5, dist=(-0.04, 0.01, 0.0, 0.0, 0.0))
    return CellCalibration(camera=camera, T_camera_laser=T_laser, T_flange_camera=T_hand)


def small_scan(root: Path, frames: int = 2) -> Path:
    """A scan folder of ``frames`` small frames with a red line, written by save_scan."""
    images = []
    for k in range(frames):
        img = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
        img[:, 10 + 5 * k, 2] = 255
        images.append(img)
    angles = np.linspace(-0.1, 0.1, frames)
    return save_scan(root, images, angles, [look_down(400.0, 0.0, 600.0)] * frames, small_calibration())


# Byte strings that tend to break readers: deep nesting, huge or odd numbers, bad UTF-8, quotes.
_TOKENS = [
    b"[" * 3000,
    b"{" * 3000,
    b"1e999",
    b"-1e999",
    b"9" * 5000,
    b"nan",
    b"inf",
    b"\xff\xfe",
    b"\xc3",
    b"\x00",
    b'"',
    b"'",
    b"true",
    b"null",
    b"65537",
    b"4294967296",
    b"-1",
    b"1.5",
    b"[]",
    b"{}",
    b"=",
    b",",
    b"\n",
    b"1979-05-27",
]


def _byte(rng: random.Random) -> int:
    """A random byte, printable ASCII seven times in ten so that most edits reach the parser."""
    return rng.randrange(32, 127) if rng.random() < 0.7 else rng.randrange(256)


def mutate(data: bytes, rng: random.Random) -> bytes:
    """``data`` with one to three random edits: a byte replaced, a slice deleted or duplicated,
    random bytes or a troublesome token inserted."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(len(out) + 1) if out else 0
        op = rng.randrange(5)
        if op == 0 and out:
            out[min(i, len(out) - 1)] = _byte(rng)
        elif op == 1:
            del out[i : i + rng.randint(1, 24)]
        elif op == 2:
            out[i:i] = bytes(_byte(rng) for _ in range(rng.randint(1, 8)))
        elif op == 3:
            j = rng.randrange(len(out) + 1) if out else 0
            out[i:i] = out[j : j + rng.randint(1, 40)]
        else:
            out[i:i] = rng.choice(_TOKENS)
    return bytes(out)


def fuzz(path: Path, original: bytes, load: Callable[[], Any], seed: int, cases: int = CASES) -> tuple[Counter, list]:
    """Writes ``cases`` mutations of ``original`` to ``path`` and calls ``load`` on each; the
    outcome counts (valid, BinpickError, other) and the cases that ended in anything but a load
    or a BinpickError. Fails at once when one case takes longer than ``SLOWEST_CASE_S``."""
    rng = random.Random(seed)
    outcomes: Counter = Counter()
    other = []
    for case in range(cases):
        data = mutate(original, rng)
        path.write_bytes(data)
        t = time.monotonic()
        try:
            load()
            outcomes["valid"] += 1
        except BinpickError:
            outcomes["BinpickError"] += 1
        except Exception as exc:  # the outcome the fuzz exists to catch
            outcomes["other"] += 1
            other.append((case, type(exc).__name__, str(exc)[:120], data[:200]))
        took = time.monotonic() - t
        assert took < SLOWEST_CASE_S, f"case {case} took {took:.1f} s: {data[:200]!r}"
    return outcomes, other


def mesh_and_scene_readers(root: Path) -> list[tuple[str, Path, Callable[[], Any]]]:
    """``(name, file, load)`` for every mesh format :meth:`binpick.Model.from_mesh` reads (the box
    of :func:`_geometry.box_mesh`), PLY clouds by :func:`binpick.read_ply` and XYZ and NPY scenes
    by :func:`binpick.clouds.read_scene`, each written under ``root``; ``load`` reads the file
    and fails (AssertionError) on a result that breaks its promise: non-finite points or normals."""
    import binpick
    from _geometry import MESH_WRITERS, box_mesh
    from binpick.clouds import read_scene, write_scene

    root.mkdir(parents=True, exist_ok=True)
    v, f = box_mesh()
    cloud = np.random.default_rng(5).normal(size=(30, 3)) * 20.0
    out = []
    for name, write in MESH_WRITERS.items():
        write(root / name, v, f)
        out.append(
            (f"mesh {name}", root / name, lambda p=root / name: _finite(binpick.Model.from_mesh(p, count=50).points))
        )
    for name, ascii_ in (("cloud_ascii.ply", True), ("cloud_binary.ply", False)):
        binpick.write_ply(root / name, cloud, cloud / np.linalg.norm(cloud, axis=1)[:, None], ascii=ascii_)
        out.append(
            (
                f"read_ply {name}",
                root / name,
                lambda p=root / name: [_finite(a) for a in binpick.read_ply(p) if a is not None],
            )
        )
    for ext in (".xyz", ".npy"):
        path = write_scene(root / f"scene{ext}", cloud)
        out.append((f"read_scene {ext}", path, lambda p=path: _finite(read_scene(p).points)))
    return out


def _finite(arr: np.ndarray) -> np.ndarray:
    assert arr.ndim == 2 and arr.shape[1] == 3 and np.isfinite(arr).all(), "a reader returned non-finite points"
    return arr


#: A tetrahedron: its prepared model is the cheapest to build (about 50 ms), for the cache fuzz.
_TETRA_V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
_TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def ppf_cache_reader(root: Path) -> tuple[Path, Callable[[], Any]]:
    """The PPF cache file of a small model, written under ``root`` (the caller sets
    ``BINPICK_CACHE_DIR`` to it), and ``load``: prepares the model afresh from whatever the file
    holds. It fails (AssertionError) when the table it ends with differs from the one built from
    the model: a damaged cache must be rebuilt, never loaded."""
    import binpick

    model = binpick.Model.from_arrays(_TETRA_V, _TETRA_F, count=40)
    table = model.prepared().ppf_bytes()
    (path,) = (root / "ppf").glob("*.bin")

    def load() -> Any:
        model._prepared = None
        native = model.prepared()
        assert native.ppf_bytes() == table, "a damaged PPF cache was loaded instead of rebuilt"
        return native

    return path, load
