"""STEP parts through the optional ``step`` extra: OpenCASCADE (packaged as ``cascadio``)
tessellates the file into an OBJ, which binpick's own mesh reader reads.

The conversion runs in a child Python process, so a STEP file that crashes or hangs OpenCASCADE
becomes a :class:`~binpick.errors.MeshFileError` naming the file, not a dead or frozen caller.
OpenCASCADE converts the length unit the file declares into millimetres.
"""

from __future__ import annotations

import importlib.util
import os
import re
import signal
import subprocess
import sys
import tempfile
import warnings
from typing import Optional

import numpy as np

from . import _core
from ._validate import edge_use_counts, unit_scale
from .errors import MeshFileError, MeshFileNotFoundError, UnitError

__all__ = ["STEP_SUFFIXES", "read_step", "declared_length_unit"]

#: File name endings read as STEP (case ignored).
STEP_SUFFIXES = (".step", ".stp")

#: Tessellation: the largest distance from a triangle to the exact surface (mm, OpenCASCADE's
#: working unit), far below a laser scan's noise, and the largest angle between neighbouring
#: facets on a curved face (radians).
CHORD_TOLERANCE = 0.01
ANGLE_TOLERANCE = 0.5

#: The longest the converter may take, seconds: minutes for the largest real parts, then it is
#: stopped, so a file that makes OpenCASCADE loop cannot hang the caller.
TIMEOUT_S = 600.0

_INSTALL = 'pip install "binpick[step]"'

_CONVERT = """
import sys
try:
    import cascadio
except ImportError as exc:
    print(exc, file=sys.stderr)
    sys.exit(3)
src, out, chord, angle = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
sys.exit(1 if cascadio.step_to_obj(src, out, tol_linear=chord, tol_angular=angle, use_colors=False) else 0)
"""


def read_step(path: str, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """The tessellated surface of the STEP file ``path``: ``(vertices in mm, faces)``, coincident
    vertices merged. ``unit`` must be the length unit the file declares (InvalidInputError naming
    the one to pass otherwise); the file is read in it when it declares none, and OpenCASCADE's
    conversion is taken when binpick cannot work the declared unit out."""
    if importlib.util.find_spec("cascadio") is None:
        raise MeshFileError(f"{path}: reading STEP files needs the optional extra: {_INSTALL} (OpenCASCADE)")
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise MeshFileNotFoundError(f"{path}: cannot read the STEP file ({exc.strerror or exc})") from None
    scale = _scale(path, unit, declared_length_unit(data))
    with tempfile.TemporaryDirectory(prefix="binpick-step-") as tmp:
        obj = os.path.join(tmp, "part.obj")
        complaints = _convert(path, obj)
        vertices, faces = _core.read_mesh(obj, "mm")
    if len(faces) == 0:
        raise MeshFileError(f"{path}: the STEP file has no surface to tessellate (no solid, shell or face)")
    welded, index = np.unique(vertices, axis=0, return_inverse=True)
    faces = np.ascontiguousarray(index.reshape(-1)[faces], dtype=np.int64)
    _check_closed(path, faces, complaints)
    return welded * scale, faces


def _check_closed(path: str, faces: np.ndarray, complaints: str) -> None:
    """Refuses a damaged file whose solid lost faces (OpenCASCADE skips what it cannot read and
    says so); warns of an open surface in a file it read without complaint (a surface model)."""
    open_edges = int(np.count_nonzero(edge_use_counts(faces) != 2))
    if open_edges and complaints:
        raise MeshFileError(
            f"{path}: the STEP file is damaged: OpenCASCADE skipped what it could not read ({complaints}) and "
            f"the surface left is open ({open_edges} edges); export the part again"
        )
    if open_edges or complaints:
        problem = f"its surface is open ({open_edges} edges bound one triangle only)" if open_edges else complaints
        warnings.warn(f"binpick: {path}: read, but {problem}", RuntimeWarning, stacklevel=4)


def _scale(path: str, unit: str, declared: Optional[tuple[str, Optional[float]]]) -> float:
    """What OpenCASCADE's millimetres are multiplied by: ``unit``'s size for a file that declares
    no length unit, else 1 when ``unit`` is the declared one (or the declared one is unknown)."""
    scale = unit_scale(unit)
    if declared is None:
        return scale
    name, mm = declared
    if mm is None or abs(mm / scale - 1.0) <= 1e-6:
        return 1.0
    known = [u for u in ("mm", "cm", "m", "in") if abs(unit_scale(u) / mm - 1.0) <= 1e-6]
    problem = f"unit: {path} declares its lengths in {name} ({mm:g} mm), not {unit!r}; "
    error = UnitError(problem + (f"pass unit={known[0]!r}" if known else "export the part in mm, cm, m or inches"))
    if known:
        error.cli_message = f'{problem}pass `--unit {known[0]}` (in a cell file: unit = "{known[0]}" in [part])'
    raise error


def _convert(path: str, obj: str) -> str:
    """Runs OpenCASCADE on ``path`` into ``obj`` in a child process: its complaints about a file
    it could read (empty when none), or MeshFileError when it could not, crashed or hung."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    args = [sys.executable, "-c", _CONVERT, path, obj, repr(CHORD_TOLERANCE), repr(ANGLE_TOLERANCE)]
    try:
        done = subprocess.run(args, capture_output=True, env=env, timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise MeshFileError(
            f"{path}: OpenCASCADE did not finish tessellating the STEP file in {TIMEOUT_S:g} s and was stopped"
        ) from None
    if done.returncode == 3:
        why = done.stderr.decode("utf-8", "replace").strip()[-300:]
        raise MeshFileError(
            f"{path}: reading STEP files needs the optional extra: {_INSTALL} (OpenCASCADE; "
            f"the converter could not import it: {why or 'no reason given'})"
        )
    if done.returncode < 0:
        raise MeshFileError(
            f"{path}: OpenCASCADE crashed on the STEP file ({_signal_name(-done.returncode)}); is the file damaged?"
        )
    errors, everything = _said(done.stdout + done.stderr, path)
    if done.returncode != 0 or not os.path.isfile(obj):
        raise MeshFileError(f"{path}: not a STEP file OpenCASCADE can read ({errors or everything or 'no message'})")
    return errors


def _signal_name(number: int) -> str:
    try:
        return f"signal {number}, {signal.Signals(number).name}"
    except ValueError:
        return f"signal {number}"


def _said(output: bytes, path: str) -> tuple[str, str]:
    """What OpenCASCADE printed, without terminal colours: ``(its error lines, all of it)``."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", output.decode("utf-8", "replace")).replace(f'"{path}"', "the file")
    lines = [line.strip(" *") for line in text.splitlines() if line.strip(" *")]
    errors = [line for line in lines if "ERR" in line or "rror" in line]
    return "; ".join(errors)[:400], "; ".join(lines)[:400]


_SI_PREFIX = {
    "$": 1e3,
    ".KILO.": 1e6,
    ".HECTO.": 1e5,
    ".DECA.": 1e4,
    ".DECI.": 1e2,
    ".CENTI.": 10.0,
    ".MILLI.": 1.0,
    ".MICRO.": 1e-3,
    ".NANO.": 1e-6,
}
_SI_NAME = {"$": "m", ".CENTI.": "cm", ".MILLI.": "mm", ".MICRO.": "µm", ".KILO.": "km"}


def declared_length_unit(data: bytes) -> Optional[tuple[str, Optional[float]]]:
    """The length unit the geometry contexts of a STEP file (its bytes) declare: ``(name,
    millimetres per unit)``, the size None when binpick cannot work it out or the contexts
    disagree; None when the file declares no length unit."""
    refs = set()
    for m in re.finditer(rb"GLOBAL_UNIT_ASSIGNED_CONTEXT\s*\(\s*\(([^)]*)\)", data):
        refs.update(int(r) for r in re.findall(rb"#(\d+)", m.group(1)))
    units = {_length_unit(data, r, 0) for r in sorted(refs) if re.search(rb"\bLENGTH_UNIT\s*\(", _entity(data, r))}
    if not units:
        return None
    if len(units) > 1:
        return " and ".join(sorted(name for name, _ in units)), None
    return units.pop()


def _entity(data: bytes, ref: int) -> bytes:
    """The text of entity ``#ref`` (empty when the file has none): up to its ``;``, strings whole."""
    m = re.search(rb"#%d\s*=\s*((?:'[^']*'|[^;'])*);" % ref, data)
    return m.group(1) if m else b""


def _length_unit(data: bytes, ref: int, depth: int) -> tuple[str, Optional[float]]:
    value = _entity(data, ref)
    si = re.search(rb"SI_UNIT\s*\(\s*(\$|\.\w+\.)\s*,\s*\.METRE\.\s*\)", value)
    if si:
        prefix = si.group(1).decode("ascii")
        return _SI_NAME.get(prefix, f"{prefix.strip('.').lower()}metre"), _SI_PREFIX.get(prefix)
    conv = re.search(rb"CONVERSION_BASED_UNIT\s*\(\s*'([^']*)'\s*,\s*#(\d+)", value)
    if not conv or depth > 4:
        return f"entity #{ref}", None
    name = conv.group(1).decode("latin-1").strip().lower() or f"entity #{ref}"
    factor = _entity(data, int(conv.group(2)))
    measure = re.search(rb"MEASURE_WITH_UNIT\s*\(\s*(?:\w+\s*\()?\s*([-+0-9.Ee]+)\s*\)?\s*,\s*#(\d+)", factor)
    if not measure:
        return name, None
    _, base = _length_unit(data, int(measure.group(2)), depth + 1)
    try:
        size = float(measure.group(1))
    except ValueError:
        return name, None
    return name, None if base is None else size * base
