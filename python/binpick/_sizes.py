"""One sanity check of sizes, run before any work: a part, a scene, a bin and a gripper whose
sizes no bin-picking cell can mean together — most often a file read in the wrong unit — raise
:class:`~binpick.errors.UnitError` naming the size that is off, what it is off against, and,
where a unit explains it, that unit and how to pass it: ``unit="m"`` to Python, ``--unit m`` on
the command line (:attr:`~binpick.errors.BinpickError.cli_message`), ``unit = "m"`` in a cell file.

Without it a part in metres read as millimetres (0.08 mm across) drops into the simulated bin and
then has no grasps, or matches no point pair of a scene; a part in millimetres read as metres
(80 m) asks for a simulated arm that reaches a bin 120 m long. Checked here, before a pile drops,
a scan is rendered or a port opens, with the bands below (physical reasons, not a sample's sizes):

- a part is at least :data:`MIN_PART_MM` across, and at least :data:`GRIPPER_STEP_SHARE` of the
  gripper's opening;
- a part is at most the bin's inner diagonal (it must lie in the bin), and without a bin at most
  :data:`MAX_PART_MM`;
- a scene is at least :data:`SCENE_MIN_SHARE` of the part's diameter across and at most
  :data:`SCENE_MAX_RATIO` times it;
- in a cell file, also: the bin holds the gripper's opening's smallest part, and the gripper
  opens at least :data:`MIN_PART_MM`.

A size off by a unit's factor (1000 for metres, 25.4 for inches, 10 for centimetres) inside its
band is not told from a true one (a 3-inch part read as 3 mm is a plausible part) and passes.
Lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from ._validate import unit_scale
from .errors import UnitError

__all__ = [
    "Fix",
    "PART",
    "SCENE",
    "cell_file_fix",
    "check_part",
    "check_scene",
    "check_cell",
    "MIN_PART_MM",
    "GRIPPER_STEP_SHARE",
    "MAX_PART_MM",
    "SCENE_MIN_SHARE",
    "SCENE_MAX_RATIO",
]

#: The smallest part a bin-picking cell picks, mm: the smallest parts picked from bins (M1 screws,
#: pins, SMD parts) are a few mm; below a millimetre a laser scan's noise (0.1 mm and more)
#: blurs the shape, and two faces of it are closer than a parallel gripper's fingers resolve.
MIN_PART_MM = 1.0

#: The smallest part a gripper picks, as a share of its opening: a parallel gripper's width is
#: set and read in steps of about its stroke / 255 (Robotiq-class: 85 mm in 0.33 mm steps), and
#: holding a part must show as a few steps short of closed; 1/100 of the opening is ~2.5 steps.
GRIPPER_STEP_SHARE = 0.01

#: The largest part picked from a bin when no bin says otherwise, mm: the largest industrial
#: arms reach under 5 m, and a bin they pick from is no longer than that.
MAX_PART_MM = 5000.0

#: The smallest scene, as a share of the part's diameter: the pose estimate confirms a part only
#: where most of its sensor-facing side is seen; a scene a fifth of the part's size cannot hold it.
#: binpick's core refuses such a scene too (with Python's words); checked here first for a command.
SCENE_MIN_SHARE = 0.2

#: The largest scene, as a multiple of the part's diameter: a sensor has at most a few thousand
#: pixels across its view, so a part a thousandth of the view spans a few samples of it, where
#: locating it takes hundreds. Measured between the 0.5th and 99.5th percentiles of each axis, so
#: a few stray points far away do not count.
SCENE_MAX_RATIO = 1000.0

#: The units a length may have been given in, the most common first: millimetres (mechanical
#: CAD), metres (SI, ROS, many mesh exports), inches (US CAD), centimetres.
_COMMON = ("mm", "m", "in", "cm")
_NAMES = {"mm": "millimetres", "m": "metres", "in": "inches", "cm": "centimetres"}


@dataclass(frozen=True)
class Fix:
    """How a reader is told to read a file's lengths in unit ``{u}``: ``python`` for the API's
    message, ``cli`` for the command's (:attr:`~binpick.errors.BinpickError.cli_message`), and
    what each message starts with (the argument, or the file and table)."""

    python: str
    cli: str
    python_prefix: str = ""
    cli_prefix: str = ""
    #: The setting that says the unit, for a message that names no unit: ``unit=`` to Python …
    python_setting: str = "unit= of Model.from_mesh"
    #: … and its flag or key to the command.
    cli_setting: str = "`--unit`"


#: A part's mesh file.
PART = Fix(
    python='read its mesh with unit="{u}" (Model.from_mesh(path, unit="{u}"))',
    cli="pass `--unit {u}`",
    python_prefix="model: ",
)
#: A scene's cloud file.
SCENE = Fix(
    python='read it with unit="{u}" (binpick.read_scene(path, unit="{u}"))',
    cli="pass `--scene-unit {u}`",
    python_prefix="scene: ",
    python_setting="unit= of binpick.read_scene",
    cli_setting="`--scene-unit`",
)


def cell_file_fix(path: str) -> Fix:
    """The part's mesh of the cell file ``path``: its ``[part] unit``, the same to both readers."""
    text = 'set unit = "{u}" in [part]'
    return Fix(text, text, f"{path}: [part] ", f"{path}: [part] ", "[part] unit", "[part] unit")


def _mm(x: float) -> str:
    """A length for a message: three significant figures, never an exponent."""
    x = float(x)
    if x >= 100.0:
        return f"{x:.0f}"
    if x >= 1.0:
        return f"{x:.3g}"
    return f"{x:.2g}" if x >= 1e-4 else f"{x:.1e}"


def _likely(size: float, lo: float, hi: float, unit: Optional[str]) -> Optional[tuple[str, str, float]]:
    """The unit a size read in ``unit`` (None: not known, the readers' default mm when too small)
    was probably in, as ``(true unit, unit it was read in, true size)``: the most common unit
    (:data:`_COMMON`) whose reading puts the size inside [lo, hi]; None when none does."""
    if unit is not None:  # its canonical name ("metres" → "m"): the one the fix names
        unit = next(u for u in _COMMON if unit_scale(u) == unit_scale(unit))
    if size < lo:
        read = "mm" if unit is None else unit
        tries = [(u, read) for u in _COMMON if unit_scale(u) > unit_scale(read)]
    else:
        # Read in too small a unit's place: the file is in a smaller unit, most often mm.
        reads = [u for u in _COMMON if u != "mm"] if unit is None else [unit]
        tries = [(u, r) for r in reads for u in _COMMON if unit_scale(u) < unit_scale(r)]
    for true, read in tries:
        scaled = size * unit_scale(true) / unit_scale(read)
        if lo <= scaled <= hi:
            return true, read, scaled
    return None


def _unit_error(problem: str, fix: Fix, likely: Optional[tuple[str, str, float]], what: str) -> UnitError:
    """The error: ``problem``, then the likely unit and its fix in each reader's words."""
    if likely is None:
        python = f"; check the size and unit of {what} ({fix.python_setting})"
        cli = f"; check the size and unit of {what} ({fix.cli_setting})"
    else:
        true, read, scaled = likely
        said = f"; {what} is probably in {_NAMES[true]} ({_mm(scaled)} mm), read as {_NAMES[read]}: "
        python, cli = said + fix.python.format(u=true), said + fix.cli.format(u=true)
    error = UnitError(fix.python_prefix + problem + python)
    error.cli_message = fix.cli_prefix + problem + cli
    return error


def _inner(bin_bounds: Any) -> Optional[np.ndarray]:
    """A bin's inner size (3,) from its bounds [[min], [max]], or None when they are not a box
    (the bin's own check names that)."""
    try:
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bin_bounds)
    except (TypeError, ValueError):
        return None
    size = hi - lo
    return size if np.isfinite(size).all() and (size > 0).all() else None


def check_part(
    model: Any,
    *,
    unit: Optional[str] = None,
    bin_bounds: Any = None,
    opening_mm: Optional[float] = None,
    fix: Fix = PART,
) -> None:
    """UnitError when the part ``model`` (read in ``unit``; None: not known) is smaller than a
    part a gripper picks (:data:`MIN_PART_MM`, and :data:`GRIPPER_STEP_SHARE` of ``opening_mm``)
    or larger than the bin of ``bin_bounds`` holds (its inner diagonal; without a bin,
    :data:`MAX_PART_MM`). ``fix``: how the message tells the reader to pass a unit."""
    size = float(model.diameter)
    lo, hi = MIN_PART_MM, MAX_PART_MM
    small = "any part a gripper picks"
    if opening_mm is not None and GRIPPER_STEP_SHARE * opening_mm > lo:
        lo, small = GRIPPER_STEP_SHARE * opening_mm, f"any part a gripper opening {_mm(opening_mm)} mm picks"
    big = f"any part an arm picks from a bin ({_mm(MAX_PART_MM)} mm: the largest arms reach less)"
    inner = None if bin_bounds is None else _inner(bin_bounds)
    if inner is not None:
        hi = float(np.linalg.norm(inner))
        big = f"the bin ({' × '.join(_mm(s) for s in inner)} mm inside, {_mm(hi)} mm corner to corner)"
    if lo <= size <= hi:
        return
    name = f"the part {model.name!r}"
    problem = f"{name} is {_mm(size)} mm across, " + (
        f"smaller than {small} (at least {_mm(lo)} mm)" if size < lo else f"larger than {big}"
    )
    raise _unit_error(problem, fix, _likely(size, lo, hi, unit), "its mesh")


def _extent(points: np.ndarray, robust: bool) -> float:
    """The diagonal of a cloud's bounding box; ``robust``: of the box between the 0.5th and 99.5th
    percentiles of each axis."""
    if robust:
        lo, hi = np.percentile(points, [0.5, 99.5], axis=0)
    else:
        lo, hi = points.min(axis=0), points.max(axis=0)
    return float(np.linalg.norm(hi - lo))


def check_scene(points: Any, model: Any, *, unit: Optional[str] = None, fix: Fix = SCENE) -> None:
    """UnitError when a scene (N, 3) read in ``unit`` (None: not known, taken as mm) is less
    than :data:`SCENE_MIN_SHARE` of the part's diameter across, or more than
    :data:`SCENE_MAX_RATIO` times it; check the part first (:func:`check_part`), so that a part in
    the wrong unit is named as such rather than its scene."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    diameter = float(model.diameter)
    if len(pts) < 2 or not diameter > 0:
        return  # nothing to measure: the pose estimate names an empty scene
    small, large = _extent(pts, robust=False), _extent(pts, robust=True)
    ratio = small / diameter if small < SCENE_MIN_SHARE * diameter else large / diameter
    if SCENE_MIN_SHARE <= ratio <= SCENE_MAX_RATIO:
        return
    extent = small if ratio < SCENE_MIN_SHARE else large
    problem = f"the scene is {_mm(extent)} mm across but the part {model.name!r} is {_mm(diameter)} mm: " + (
        f"a scene less than {SCENE_MIN_SHARE:g} times its part's size cannot show it"
        if ratio < SCENE_MIN_SHARE
        else f"no sensor resolves a part {SCENE_MAX_RATIO:g} times smaller than its view"
    )
    likely = _likely(ratio, SCENE_MIN_SHARE, SCENE_MAX_RATIO, unit if unit is not None else "mm")
    if likely is not None:
        true, read, scaled = likely
        likely = (true, read, scaled * diameter)
    raise _unit_error(problem, fix, likely, "the scene")


def check_cell(path: str, model: Any, *, unit: str, bin_bounds: Any, opening_mm: float) -> None:
    """The sizes of the cell file ``path``: its gripper opens (``[gripper] open_width_mm``) at least
    :data:`MIN_PART_MM`; its bin (``[cell] bin_min_mm``, ``bin_max_mm``) is no smaller, corner to
    corner, than the gripper's opening, which must reach into it; its part, read in ``unit``,
    against the gripper and the bin (:func:`check_part`). UnitError naming the file and the key;
    a gripper or a bin a thousand times too small is named as written in metres."""
    if opening_mm < MIN_PART_MM:
        hint = ""
        if MIN_PART_MM <= opening_mm * 1000.0 <= MAX_PART_MM:
            hint = f"; it is probably written in metres: write it in mm ({opening_mm * 1000.0:g})"
        raise UnitError(
            f"{path}: [gripper] open_width_mm = {opening_mm:g}: the gripper opens {_mm(opening_mm)} mm, "
            f"less than any part a gripper picks (at least {_mm(MIN_PART_MM)} mm){hint}"
        )
    inner = _inner(bin_bounds)
    if inner is not None and float(np.linalg.norm(inner)) < opening_mm:
        lo, hi = (np.asarray(b, dtype=np.float64).reshape(3) for b in bin_bounds)
        diagonal = float(np.linalg.norm(inner))
        hint = "; check its corners"
        if opening_mm <= diagonal * 1000.0 <= MAX_PART_MM:
            hint = f"; its corners are probably written in metres: write them in mm ({_corner(lo)} and {_corner(hi)})"
        raise UnitError(
            f"{path}: [cell] bin_min_mm, bin_max_mm: the bin is {' × '.join(_mm(s) for s in inner)} mm inside, "
            f"{_mm(diagonal)} mm corner to corner, smaller than the gripper's {_mm(opening_mm)} mm opening that "
            f"must reach into it{hint}"
        )
    check_part(model, unit=unit, bin_bounds=bin_bounds, opening_mm=opening_mm, fix=cell_file_fix(path))


def _corner(p: np.ndarray) -> str:
    """Corner ``p`` (metres) in mm, as a cell file writes it."""
    return "[" + ", ".join(f"{v * 1000.0:.1f}" for v in p) + "]"
