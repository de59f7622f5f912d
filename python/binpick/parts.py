"""Built-in parametric parts: the paper's plumbing tee, an elbow and a cross.

Every part is a closed mesh in millimetres in the frame of the paper's Fig. 6b: the origin
where the branch axes meet, x along the run, y along the side branch, z = x × y.
"""

from __future__ import annotations

from typing import Optional

from . import _core
from ._validate import positive
from .models import Branch, Model

__all__ = ["tee", "elbow", "cross"]


def _model(raw, name: str, spacing: Optional[float], count: Optional[int], seed: int, special=None) -> Model:
    vertices, faces, branches = raw
    rows = [
        Branch(direction=(float(b[0]), float(b[1]), float(b[2])), length=float(b[3]), radius=float(b[4]))
        for b in branches
    ]
    if spacing is None and count is None:
        spacing = 1.0
    return Model.from_arrays(
        vertices, faces, spacing=spacing, count=count, seed=seed, name=name, branches=rows, special_direction=special
    )


def tee(
    *,
    outer_diameter: float = 26.0,
    run_length: float = 80.0,
    branch_length: float = 40.0,
    boss_semi_axes: tuple[float, float] = (11.0, 8.0),
    boss_height: float = 17.0,
    resolution: float = 0.6,
    spacing: Optional[float] = None,
    count: Optional[int] = None,
    seed: int = 0,
) -> Model:
    """The paper's plumbing tee (a ¾-inch fitting by default), all lengths in mm.

    Three cylindrical branches of ``outer_diameter``: the run along x, ``run_length`` end to end,
    and the side branch along +y, ``branch_length`` from the run's axis to its end face; and the
    elliptical boss (semi-axes ``boss_semi_axes`` along x and y) rising to ``boss_height`` on +z
    (0 for none). ``resolution`` is the meshing grid; the model is sampled at ``spacing`` mm
    (1 mm by default) or with ``count`` points.
    """
    raw = _core.part_tee(
        positive(outer_diameter, "outer_diameter"),
        positive(run_length, "run_length"),
        positive(branch_length, "branch_length"),
        (float(boss_semi_axes[0]), float(boss_semi_axes[1])),
        float(boss_height),
        positive(resolution, "resolution"),
    )
    return _model(raw, "tee", spacing, count, seed, special=(0.0, 0.0, 1.0) if boss_height > 0 else None)


def elbow(
    *,
    outer_diameter: float = 26.0,
    branch_length: float = 40.0,
    resolution: float = 0.6,
    spacing: Optional[float] = None,
    count: Optional[int] = None,
    seed: int = 0,
) -> Model:
    """A 90° elbow: branches along +x and +y, ``branch_length`` mm from the corner to each end face."""
    raw = _core.part_fitting(
        "elbow",
        positive(outer_diameter, "outer_diameter"),
        positive(branch_length, "branch_length"),
        positive(resolution, "resolution"),
    )
    return _model(raw, "elbow", spacing, count, seed)


def cross(
    *,
    outer_diameter: float = 26.0,
    branch_length: float = 40.0,
    resolution: float = 0.6,
    spacing: Optional[float] = None,
    count: Optional[int] = None,
    seed: int = 0,
) -> Model:
    """A cross: four branches along ±x and ±y, ``branch_length`` mm from the centre to each end face."""
    raw = _core.part_fitting(
        "cross",
        positive(outer_diameter, "outer_diameter"),
        positive(branch_length, "branch_length"),
        positive(resolution, "resolution"),
    )
    return _model(raw, "cross", spacing, count, seed)
