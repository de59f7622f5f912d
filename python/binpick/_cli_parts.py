"""What the ``binpick`` commands share about the part: the built-in names, a part by name or
mesh file, and the usage error (exit code 2); and ``binpick bench``. A leaf of the command modules, so that
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
    from . import parts
    from .models import Model

    if part in PARTS:
        return getattr(parts, part)()
    if not os.path.exists(part):
        raise _Usage(f"--part: {part!r} is neither a built-in part ({', '.join(PARTS)}) nor a mesh file")
    return Model.from_mesh(part, unit=unit)


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
