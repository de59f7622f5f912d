"""Built-in parametric parts: the paper's plumbing tee, an elbow and a cross; and five
near-symmetric parts, symmetric but for one small feature that decides the pose.

The fittings are closed meshes in millimetres in the frame of the paper's Fig. 6b: the origin
where the branch axes meet, x along the run, y along the side branch, z = x × y.

The near-symmetric parts (:data:`NEAR_SYMMETRIC`; 35–150 mm) are centred on the origin, each with
its feature and the proper symmetries that remain with it (the symmetry detector refuses a turn
that leaves a patch of the surface where the turned part has none, at any size these take):

=================  ==========================================  ===============================
part               feature (the default sizes)                 proper symmetries left
=================  ==========================================  ===============================
``keyed_shaft``    keyway 2 mm deep on +x, mid-length           the flip about x (2)
``cut_plate``      one corner (+x, +y) cut 3.0 mm deep          the flip about the diagonal (2)
``flange``         a locating notch 3 mm deep in the rim, +x    the flip about x (2)
``notched_hex``    a notch 1.5 mm deep along the +y flat        the flip about y (2)
``bossed_rod``     a boss 2 mm proud on +z, mid-length          the half turn about z (2)
=================  ==========================================  ===============================

Without the feature (``feature=False``, or :func:`base_shape`) each is the symmetric base shape:
a plain shaft (continuous about z), a square plate (8), a flange with six bolt holes (12), a hex
prism (12), a plain rod (continuous about x).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from . import _core, _shapes
from ._validate import count, flag, non_negative, positive
from .errors import InvalidInputError, InvalidTypeError
from .models import Branch, Model

__all__ = [
    "tee",
    "elbow",
    "cross",
    "keyed_shaft",
    "cut_plate",
    "flange",
    "notched_hex",
    "bossed_rod",
    "d_shaft",
    "pinned_flange",
    "base_shape",
    "NEAR_SYMMETRIC",
    "MORE_NEAR_SYMMETRIC",
    "BUILT_IN",
    "built_in",
    "MAX_PART_SIZE_MM",
    "MAX_BOLT_HOLES",
]

#: Largest length argument of a near-symmetric part, mm (the defaults are 35–150 mm). Their mesh
#: grids are 0.25–5 mm, so a size is refused above this before any array is built; the grid as a
#: whole is checked too (:data:`binpick._shapes.MAX_GRID_VERTICES`).
MAX_PART_SIZE_MM = 500.0

#: Most bolt holes a :func:`flange` may have.
MAX_BOLT_HOLES = 64


def _size(value, name: str) -> float:
    """A positive finite length in mm of at most :data:`MAX_PART_SIZE_MM`, or InvalidInputError naming ``name``."""
    v = positive(value, name)
    if v > MAX_PART_SIZE_MM:
        raise InvalidInputError(
            f"{name}: {v:g} mm is over the ceiling of {MAX_PART_SIZE_MM:g} mm for a built-in part; pass its size in mm"
        )
    return v


def _boss(semi_axes, height) -> tuple[tuple[float, float], float]:
    """The tee's boss: two positive finite semi-axes (mm) and a finite height ≥ 0 (0 for none)."""
    if isinstance(semi_axes, (str, bytes)) or not hasattr(semi_axes, "__len__"):
        raise InvalidTypeError(
            f"boss_semi_axes: expected two numbers (mm along x and y), got {type(semi_axes).__name__} {semi_axes!r:.40}"
        )
    if len(semi_axes) != 2:
        raise InvalidInputError(f"boss_semi_axes: expected two numbers (mm along x and y), got {len(semi_axes)}")
    axes = (positive(semi_axes[0], "boss_semi_axes[0]"), positive(semi_axes[1], "boss_semi_axes[1]"))
    return axes, non_negative(height, "boss_height", "mm")


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
    semi_axes, height = _boss(boss_semi_axes, boss_height)
    raw = _core.part_tee(
        positive(outer_diameter, "outer_diameter"),
        positive(run_length, "run_length"),
        positive(branch_length, "branch_length"),
        semi_axes,
        height,
        positive(resolution, "resolution"),
    )
    return _model(raw, "tee", spacing, count, seed, special=(0.0, 0.0, 1.0) if height > 0 else None)


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


def _near_model(mesh: tuple, name: str, spacing: Optional[float], seed: int) -> Model:
    vertices, faces = mesh
    return Model.from_arrays(
        vertices, faces, unit="mm", spacing=1.0 if spacing is None else spacing, seed=seed, name=name
    )


def _slot_radius(bottom: float, width: float, phi: np.ndarray) -> np.ndarray:
    """Radius along angle ``phi`` (about the slot's centre line) to the flat bottom of a slot
    ``width`` wide whose bottom lies ``bottom`` from the axis; inf outside the slot."""
    inside = (np.cos(phi) > 0) & (np.abs(np.tan(phi)) < width / (2 * bottom))
    return np.where(inside, bottom / np.where(inside, np.cos(phi), 1.0), np.inf)


def keyed_shaft(
    *,
    diameter: float = 24.0,
    length: float = 150.0,
    keyway_width: float = 6.0,
    keyway_depth: float = 2.0,
    keyway_length: float = 40.0,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A round shaft along z with a flat-bottomed keyway on +x: ``keyway_depth`` deep (its floor
    ``diameter/2 − keyway_depth`` from the axis), ``keyway_width`` wide, ``keyway_length`` long,
    centred on the length. Without the keyway it is continuously symmetric about z; the keyway
    alone fixes the turn about the axis. Sampled every ``spacing`` mm (1 mm by default)."""
    R = _size(diameter, "diameter") / 2
    L = _size(length, "length")
    d = _size(keyway_depth, "keyway_depth") if flag(feature, "feature") else 0.0
    w, lk = _size(keyway_width, "keyway_width"), _size(keyway_length, "keyway_length")
    if d >= R or lk >= L or w >= 2 * (R - d):
        raise InvalidInputError("keyway_depth/keyway_width/keyway_length: the keyway must fit inside the shaft")
    wall = float(np.arctan(w / (2 * (R - d)))) if d > 0 else 0.0
    phi = _shapes.angle_samples(0.4, R, steps=[wall, -wall] if d > 0 else [])
    s = _shapes.stations(L, 5.0, steps=[(L - lk) / 2, (L + lk) / 2] if d > 0 else []) - L / 2

    def radius(z, p):
        if d == 0:
            return np.full_like(z, R)
        slot = _slot_radius(R - d, w, p)
        return np.where(np.abs(z) < lk / 2, np.minimum(slot, R), R)

    mesh = _shapes.axial_solid(radius, s, phi, what="keyed_shaft: diameter/length")
    return _near_model(mesh, "keyed_shaft", spacing, seed)


def d_shaft(
    *,
    diameter: float = 20.0,
    length: float = 120.0,
    flat_depth: float = 1.5,
    flat_length: float = 50.0,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A round shaft along z with a D-flat on +x at its +z end: the flat ``flat_depth`` deep (its
    plane ``diameter/2 − flat_depth`` from the axis) over the last ``flat_length`` mm, as on a
    motor shaft. Without the flat it is continuously symmetric about z and flips end for end; the
    flat alone fixes both the turn about the axis and which end is which. Sampled every ``spacing``
    mm (1 mm by default)."""
    R = _size(diameter, "diameter") / 2
    L = _size(length, "length")
    d = _size(flat_depth, "flat_depth") if flag(feature, "feature") else 0.0
    lf = _size(flat_length, "flat_length")
    if d >= R or lf >= L:
        raise InvalidInputError("flat_depth/flat_length: the flat must fit on the shaft")
    chord = 2.0 * float(np.sqrt(R * R - (R - d) ** 2)) if d > 0 else 0.0
    wall = float(np.arctan(chord / (2 * (R - d)))) if d > 0 else 0.0
    phi = _shapes.angle_samples(0.4, R, steps=[wall, -wall] if d > 0 else [])
    s = _shapes.stations(L, 5.0, steps=[L - lf] if d > 0 else []) - L / 2

    def radius(z, p):
        if d == 0:
            return np.full_like(z, R)
        flat = _slot_radius(R - d, chord + 1e-9, p)
        return np.where(z > L / 2 - lf, np.minimum(flat, R), R)

    mesh = _shapes.axial_solid(radius, s, phi, what="d_shaft: diameter/length")
    return _near_model(mesh, "d_shaft", spacing, seed)


def cut_plate(
    *,
    side: float = 40.0,
    thickness: float = 10.0,
    cut: float = 4.2,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A square plate ``side`` × ``side`` × ``thickness`` mm (z through its thickness) with its
    (+x, +y) corner cut at 45°, ``cut`` mm along each edge: the cut reaches ``cut / √2`` mm deep
    (3.0 mm by default) into the corner. Without the cut: the square plate's 8 symmetries; with
    it only the flip about the diagonal through the cut corner is left."""
    h = _size(side, "side") / 2
    t = _size(thickness, "thickness")
    c = _size(cut, "cut") if flag(feature, "feature") else 0.0
    if c >= h:
        raise InvalidInputError(f"cut: {c:g} mm must be less than half the side ({h:g} mm)")
    corners = [(-h, -h), (h, -h), (h, h - c), (h - c, h), (-h, h)] if c > 0 else [(-h, -h), (h, -h), (h, h), (-h, h)]
    poly = np.array(corners)
    phi = _shapes.angle_samples(1.0, h, breaks=np.arctan2(poly[:, 1], poly[:, 0]))
    s = _shapes.stations(t, 2.0) - t / 2
    mesh = _shapes.axial_solid(
        lambda z, p: _shapes.polygon_radius(poly, p) + 0 * z, s, phi, cap_rings=12, what="cut_plate: side/thickness"
    )
    return _near_model(mesh, "cut_plate", spacing, seed)


def notched_hex(
    *,
    across_flats: float = 30.0,
    length: float = 30.0,
    notch_width: float = 5.0,
    notch_depth: float = 1.5,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A hexagonal prism along z, ``across_flats`` mm, ``length`` long, corners on ±x, with a
    flat-bottomed notch ``notch_depth`` deep and ``notch_width`` wide along the whole +y flat.
    Without the notch: the hex prism's 12 symmetries (near 60° turns); with it only the flip
    about y is left."""
    a = _size(across_flats, "across_flats") / 2
    L = _size(length, "length")
    d = _size(notch_depth, "notch_depth") if flag(feature, "feature") else 0.0
    w = _size(notch_width, "notch_width")
    if d >= a or w >= a:
        raise InvalidInputError("notch_depth/notch_width: the notch must fit on one flat")
    hexagon = np.array(
        [
            (a / np.cos(np.pi / 6) * np.cos(k * np.pi / 3), a / np.cos(np.pi / 6) * np.sin(k * np.pi / 3))
            for k in range(6)
        ]
    )
    wall = float(np.arctan(w / (2 * (a - d)))) if d > 0 else 0.0
    breaks = np.arange(6) * np.pi / 3
    phi = _shapes.angle_samples(0.4, a, breaks=breaks, steps=[np.pi / 2 - wall, np.pi / 2 + wall] if d > 0 else [])
    s = _shapes.stations(L, 3.0) - L / 2

    def radius(z, p):
        r = _shapes.polygon_radius(hexagon, p)
        if d > 0:
            r = np.minimum(r, _slot_radius(a - d, w, p - np.pi / 2))
        return r + 0 * z

    mesh = _shapes.axial_solid(radius, s, phi, what="notched_hex: across_flats/length")
    return _near_model(mesh, "notched_hex", spacing, seed)


def bossed_rod(
    *,
    diameter: float = 20.0,
    length: float = 90.0,
    boss_diameter: float = 10.0,
    boss_height: float = 2.0,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A solid round run along x, ``diameter`` × ``length``, with a round flat-topped boss of
    ``boss_diameter`` on +z at mid-length whose top stands ``boss_height`` mm proud of the run.
    Without the boss it is continuously symmetric about x (and flips end for end); with it only
    the half turn about z is left: the boss alone tells up from down."""
    R = _size(diameter, "diameter") / 2
    L = _size(length, "length")
    rb = _size(boss_diameter, "boss_diameter") / 2
    hb = _size(boss_height, "boss_height") if flag(feature, "feature") else 0.0
    if rb >= R or rb >= L / 2:
        raise InvalidInputError("boss_diameter: the boss must be narrower than the run")
    walls = [float(np.arcsin(rb / R)), -float(np.arcsin(rb / R))] if hb > 0 else []
    phi = _shapes.angle_samples(0.3, R + hb, steps=walls)
    s = _shapes.stations(L, 0.3 if hb > 0 else 5.0) - L / 2
    if hb > 0:
        far = np.abs(s) > rb + 1.0
        s = np.unique(np.r_[s[~far], _shapes.stations(L, 5.0) - L / 2, [-rb - 1.0, rb + 1.0]])

    def radius(x, p):
        if hb == 0:
            return np.full_like(x, R)
        side = np.sqrt(np.clip(rb * rb - x * x, 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            top = np.where(np.cos(p) > 0, (R + hb) / np.cos(p), np.inf)
            wall = np.where(np.abs(np.sin(p)) > 0, side / np.abs(np.sin(p)), np.inf)
        boss = np.where((np.abs(x) < rb) & (np.cos(p) > 0), np.minimum(top, wall), 0.0)
        return np.maximum(R, np.where(np.isfinite(boss), boss, R))

    v, f = _shapes.axial_solid(radius, s, phi, what="bossed_rod: diameter/length/boss_height")
    v = np.c_[v[:, 2], -v[:, 1], v[:, 0]]  # build axis z -> x, the boss's +x -> +z (a proper rotation)
    return _near_model((v, f), "bossed_rod", spacing, seed)


def flange(
    *,
    diameter: float = 60.0,
    thickness: float = 10.0,
    bolt_holes: int = 6,
    bolt_hole_diameter: float = 7.0,
    bolt_circle_diameter: float = 42.0,
    hole_depth: float = 3.0,
    notch_width: float = 10.0,
    notch_depth: float = 3.0,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A flange disc about z, ``diameter`` × ``thickness`` (z from −thickness/2), with
    ``bolt_holes`` holes of ``bolt_hole_diameter`` on the ``bolt_circle_diameter`` (the first at
    180°/``bolt_holes``), and a locating notch off the pattern: ``notch_depth`` deep and
    ``notch_width`` wide in the rim on +x, through the thickness. The bolt holes are pockets
    ``hole_depth`` deep from each face (the solid keeps the topology of a sphere; from above a
    pocket reads like a hole). Without the notch: the 12 symmetries of the hole pattern; with
    it only the flip about x is left."""
    R = _size(diameter, "diameter") / 2
    T = _size(thickness, "thickness")
    n = count(bolt_holes, "bolt_holes", 1, MAX_BOLT_HOLES)
    rh, rc = (
        _size(bolt_hole_diameter, "bolt_hole_diameter") / 2,
        _size(bolt_circle_diameter, "bolt_circle_diameter") / 2,
    )
    hd = _size(hole_depth, "hole_depth")
    d = _size(notch_depth, "notch_depth") if flag(feature, "feature") else 0.0
    w = _size(notch_width, "notch_width")
    if rc + rh >= R - d - 1.0 or rc - rh <= 1.0 or 2 * hd >= T:
        raise InvalidInputError("bolt_holes/bolt_circle_diameter/hole_depth: the holes must lie inside the flange")
    wall = float(np.arctan(w / (2 * (R - d)))) if d > 0 else 0.0
    phi = _shapes.angle_samples(0.3, rc + rh, steps=[wall, -wall] if d > 0 else [])
    rim = np.minimum(_slot_radius(R - d, w, phi), R) if d > 0 else np.full_like(phi, R)
    band = (rc - rh - 0.5, rc + rh + 0.5)
    fine = np.arange(band[0], band[1], 0.25)
    rho = np.unique(np.r_[np.linspace(0, R, int(np.ceil(R / 2.0)) + 1)[1:], fine]) / R  # as a share of the rim
    _shapes.check_grid(2 * len(rho) + 2, len(phi), "flange: diameter/bolt_hole_diameter/bolt_circle_diameter")
    centres = [(rc * np.cos(np.pi * (2 * k + 1) / n), rc * np.sin(np.pi * (2 * k + 1) / n)) for k in range(n)]

    def face(share, z_face, inward):
        x, y = share * rim * np.cos(phi), share * rim * np.sin(phi)
        hole = np.zeros_like(x, dtype=bool)
        for cx, cy in centres:
            hole |= (x - cx) ** 2 + (y - cy) ** 2 < rh * rh
        return np.c_[x, y, np.where(hole, z_face + inward * hd, z_face)]

    bottom = [face(t, -T / 2, 1.0) for t in rho]
    side = [
        np.c_[rim * np.cos(phi), rim * np.sin(phi), np.full_like(phi, z)] for z in np.linspace(-T / 2, T / 2, 4)[1:-1]
    ]
    top = [face(t, T / 2, -1.0) for t in rho[::-1]]
    mesh = _shapes.ring_solid(np.array(bottom + side + top), (0.0, 0.0, -T / 2), (0.0, 0.0, T / 2))
    return _near_model(mesh, "flange", spacing, seed)


#: The near-symmetric parts by name, each a function taking its keyword sizes and ``feature``.
NEAR_SYMMETRIC = {
    "keyed_shaft": keyed_shaft,
    "cut_plate": cut_plate,
    "flange": flange,
    "notched_hex": notched_hex,
    "bossed_rod": bossed_rod,
}


def pinned_flange(
    *,
    diameter: float = 70.0,
    thickness: float = 10.0,
    pin_diameter: float = 6.0,
    pin_height: float = 5.0,
    pin_circle_diameter: float = 50.0,
    feature: bool = True,
    spacing: Optional[float] = None,
    seed: int = 0,
) -> Model:
    """A flange disc about z, ``diameter`` × ``thickness`` (z from −thickness/2), with one locating
    pin of ``pin_diameter`` standing ``pin_height`` proud of its top face on +x, on the
    ``pin_circle_diameter``. Without the pin it is continuously symmetric about z and flips face
    for face; the pin alone fixes the turn about the axis and which face is up."""
    R = _size(diameter, "diameter") / 2
    T = _size(thickness, "thickness")
    rp, rc = _size(pin_diameter, "pin_diameter") / 2, _size(pin_circle_diameter, "pin_circle_diameter") / 2
    hp = _size(pin_height, "pin_height") if flag(feature, "feature") else 0.0
    if rc + rp >= R - 1.0 or rc - rp <= 1.0:
        raise InvalidInputError("pin_circle_diameter/pin_diameter: the pin must stand inside the flange's face")
    phi = _shapes.angle_samples(0.3, rc + rp)
    fine = np.arange(rc - rp - 0.5, rc + rp + 0.5, 0.25)
    rho = np.unique(np.r_[np.linspace(0, R, int(np.ceil(R / 2.0)) + 1)[1:], fine]) / R
    _shapes.check_grid(2 * len(rho) + 2, len(phi), "pinned_flange: diameter/pin_diameter")

    def face(share, z_face, proud):
        x, y = share * R * np.cos(phi), share * R * np.sin(phi)
        pin = (x - rc) ** 2 + y**2 < rp * rp
        return np.c_[x, y, np.where(pin, z_face + proud, z_face)]

    bottom = [face(t, -T / 2, 0.0) for t in rho]
    side = [np.c_[R * np.cos(phi), R * np.sin(phi), np.full_like(phi, z)] for z in np.linspace(-T / 2, T / 2, 4)[1:-1]]
    top = [face(t, T / 2, hp) for t in rho[::-1]]
    mesh = _shapes.ring_solid(np.array(bottom + side + top), (0.0, 0.0, -T / 2), (0.0, 0.0, T / 2))
    return _near_model(mesh, "pinned_flange", spacing, seed)


#: Near-symmetric parts beyond the bench's five, for the cell's bin clearing (issue 39).
MORE_NEAR_SYMMETRIC = {"d_shaft": d_shaft, "pinned_flange": pinned_flange}


#: Every built-in part by the name ``binpick demo --part``, ``binpick validate`` and
#: :func:`built_in` take: the fittings, then the near-symmetric parts.
BUILT_IN = {"tee": tee, "elbow": elbow, "cross": cross, **NEAR_SYMMETRIC, **MORE_NEAR_SYMMETRIC}


def built_in(name: str) -> Model:
    """The built-in part ``name`` (:data:`BUILT_IN`) at its default sizes, in mm."""
    if not isinstance(name, str):
        raise InvalidTypeError(f"name: expected a built-in part's name (str), got {type(name).__name__}")
    if name not in BUILT_IN:
        raise InvalidInputError(f"name: {name!r} is not a built-in part; one of {', '.join(BUILT_IN)}")
    return BUILT_IN[name]()


def base_shape(name: str, **sizes) -> Model:
    """The symmetric base shape of the near-symmetric part ``name`` (:data:`NEAR_SYMMETRIC`):
    the same part, the same sizes and mesh grid, without its feature."""
    if name not in NEAR_SYMMETRIC:
        raise InvalidInputError(f"name: {name!r} is not one of {sorted(NEAR_SYMMETRIC)}")
    return NEAR_SYMMETRIC[name](**sizes, feature=False)
