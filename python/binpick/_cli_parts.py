"""What the ``binpick`` commands share about the part: the built-in names, a part by name or
mesh file, and the usage error (exit code 2). A leaf of the command modules, so that
``binpick.cli`` and ``binpick.devices.cli`` need not import each other."""

from __future__ import annotations

import os
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
