"""What the ``binpick`` commands share about the part: the built-in names, a part by name or
mesh file (its size checked before any work), the usage error (exit code 2) and the message an
error shows on the command line; and ``binpick bench``. A leaf of the command modules, so that
``binpick.cli`` and ``binpick.devices.cli`` need not import each other."""

from __future__ import annotations

import difflib
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from ._paths import close_match, no_such_file
from .parts import BUILT_IN

PARTS = tuple(BUILT_IN)


class _Usage(Exception):
    """A usage error found after parsing (exit code 2)."""


def _model(part: str, unit: str = "mm", flag: str = "--part") -> Any:
    """The part ``part`` names: a built-in part, or a mesh file read in ``unit`` whose size a
    bin-picking cell can mean (binpick._sizes.check_part: UnitError naming ``--unit``); a usage
    error naming ``flag`` for a name that is neither (with the close one meant, if any). A built-in
    part is in mm: ``--unit`` other than mm with it is refused, as it means nothing there (it says
    the unit of a mesh file; scaling a built-in part by it would make a part no cell holds)."""
    from . import _sizes, parts
    from ._validate import unit_scale
    from .models import Model

    if part in PARTS:
        if unit_scale(unit) != 1.0:
            raise _Usage(
                f"--unit {unit}: the built-in part {part!r} is in mm; --unit is the unit of a mesh file: leave it out"
            )
        return parts.built_in(part)
    if not os.path.lexists(part):
        meant = difflib.get_close_matches(part.lower(), PARTS, n=1) or [close_match(part)]
        raise _Usage(
            f"{flag}: {part!r} is neither a built-in part ({', '.join(PARTS)}) nor a mesh file (no such file)"
            + (f"; did you mean {meant[0]}?" if meant[0] else "")
        )
    model = Model.from_mesh(part, unit=unit)
    _sizes.check_part(model, unit=unit)
    return model


def error_text(exc: BaseException) -> str:
    """An error's message as the command shows it: the flag that fixes it where the message names
    a Python keyword (BinpickError.cli_message)."""
    return getattr(exc, "cli_message", None) or str(exc)


def _existing(path: str, flag: str, what: str, *, folder: bool = False, fix: str = "") -> str:
    """``path``, or a usage error naming ``flag`` when it is not there (with ``fix`` and the close
    name meant, :func:`binpick._paths.no_such_file`) or is not a folder (``folder``) or a file."""
    if not os.path.lexists(path):
        raise _Usage(f"{flag}: {no_such_file(path, what, folder=folder, fix=fix)}")
    if folder != os.path.isdir(path):
        raise _Usage(f"{flag}: {path} is {'not a folder' if folder else 'a folder'}; give the {what}")
    return path


def run_bench(args: Any) -> int:
    """``binpick bench``: runs the benches of a source checkout (their scripts in benches/)."""
    root = Path(__file__).resolve().parents[2] / "benches"
    scripts = sorted(root.glob("*.py")) if root.is_dir() else []
    if not scripts:
        print(
            "binpick bench: the benchmarks live in the source repository's benches/ folder (criterion benches: "
            "`cargo bench -p binpick-bench`; Python benches: `python benches/<name>.py`); this installation has none."
        )
        return 0
    if args.list:
        for s in scripts:
            print(s.stem)
        return 0
    chosen = [s for s in scripts if not args.names or s.stem in args.names]
    unknown = set(args.names) - {s.stem for s in scripts}
    if unknown:
        raise _Usage(
            f"bench: unknown bench {', '.join(sorted(unknown))}; available: {', '.join(s.stem for s in scripts)}"
        )
    status = 0
    for s in chosen:
        print(f"== {s.stem}", flush=True)
        status |= subprocess.call([sys.executable, str(s)])
    return 1 if status else 0


#: The exit code of a pick run in which the gripper touched something other than the part it
#: grasped (the simulator's or the twin's physics saw it): the run finished, but it is not clean.
EXIT_COLLISION = 4


def collision_exit(report: Any, command: str) -> int | None:
    """EXIT_COLLISION, with a line on stderr naming the picks, when any pick of ``report`` (a
    :class:`binpick.cell.RunReport`) collided; None otherwise."""
    hit = [str(r.index) for r in report.records if r.failure == "collision"]
    if not hit:
        return None
    print(
        f"binpick {command}: the gripper collided in pick{'s' if len(hit) > 1 else ''} {', '.join(hit)} "
        "(see the table and failure_pick*.png)",
        file=sys.stderr,
    )
    return EXIT_COLLISION
