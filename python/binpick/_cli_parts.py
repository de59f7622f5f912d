"""What the ``binpick`` commands share about the part: the built-in names, a part by name or
mesh file (its size checked before any work), the usage error (exit code 2) and the message an
error shows on the command line; and ``binpick bench``. A leaf of the command modules, so that
``binpick.cli`` and ``binpick.devices.cli`` need not import each other."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

PARTS = ("tee", "elbow", "cross")


class _Usage(Exception):
    """A usage error found after parsing (exit code 2)."""


def _model(part: str, unit: str = "mm") -> Any:
    """The part ``part`` names: a built-in part, or a mesh file read in ``unit`` whose size a
    bin-picking cell can mean (binpick._sizes.check_part: UnitError naming ``--unit``). A built-in
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
        return getattr(parts, part)()
    if not os.path.exists(part):
        raise _Usage(f"--part: {part!r} is neither a built-in part ({', '.join(PARTS)}) nor a mesh file")
    model = Model.from_mesh(part, unit=unit)
    _sizes.check_part(model, unit=unit)
    return model


def error_text(exc: BaseException) -> str:
    """An error's message as the command shows it: the flag that fixes it where the message names
    a Python keyword (BinpickError.cli_message)."""
    return getattr(exc, "cli_message", None) or str(exc)


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
