"""Parts from STEP files (the optional ``step`` extra, OpenCASCADE through cascadio): solids
written here as AP214 text, entity by entity, with known size, volume and area; their units; the
error naming the extra when it is missing; damaged files."""

from __future__ import annotations

import random
import re
import signal
import sys
import time
import warnings

import numpy as np
import pytest

import binpick
from _files import mutate
from _geometry import extruded_mesh, random_rotation, rendered_view
from binpick import _step
from binpick._shapes import edge_use_counts, signed_volume
from binpick.errors import BinpickError, InvalidInputError, MeshFileError, MeshFileNotFoundError, UnknownUnitError

#: An L-shaped plate (mm, counter-clockwise): 1600 mm² of outline, 200 mm around, 15 mm thick.
L_OUTLINE = [(0, 0), (60, 0), (60, 20), (20, 20), (20, 40), (0, 40)]
L_HEIGHT = 15.0
L_VOLUME = 1600.0 * L_HEIGHT
L_AREA = 2 * 1600.0 + 200.0 * L_HEIGHT

#: The length units a STEP file can declare, as the STEP entities that declare them.
UNITS = {
    "mm": ["(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.))"],
    "m": ["(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT($,.METRE.))"],
    "in": [
        "(CONVERSION_BASED_UNIT('INCH',#{1})LENGTH_UNIT()NAMED_UNIT(#{2}))",
        "LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(25.4),#{3})",
        "DIMENSIONAL_EXPONENTS(1.,0.,0.,0.,0.,0.,0.)",
        "(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.))",
    ],
    # No length unit among the context's units: OpenCASCADE reads the numbers as millimetres.
    None: ["(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.))"],
}
MM_PER = {"mm": 1.0, "m": 1000.0, "in": 25.4, None: 1.0}


class StepWriter:
    """Writes the DATA section of an AP214 file one entity at a time, numbering them."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def add(self, text: str) -> str:
        self.lines.append(f"#{len(self.lines) + 1}={text};")
        return f"#{len(self.lines)}"

    def point(self, p) -> str:
        return self.add("CARTESIAN_POINT('',({}))".format(",".join(_real(c) for c in p)))

    def direction(self, d) -> str:
        return self.add("DIRECTION('',({}))".format(",".join(_real(c) for c in d)))

    def placement(self, origin, axis, ref) -> str:
        return self.add(f"AXIS2_PLACEMENT_3D('',{self.point(origin)},{self.direction(axis)},{self.direction(ref)})")

    def line_edge(self, v0: str, v1: str, a, b) -> str:
        d = np.subtract(b, a, dtype=float)
        length = float(np.linalg.norm(d))
        vector = self.add(f"VECTOR('',{self.direction(d / length)},{_real(length)})")
        line = self.add(f"LINE('',{self.point(a)},{vector})")
        return self.add(f"EDGE_CURVE('',{v0},{v1},{line},.T.)")

    def face(self, surface: str, loop) -> str:
        """An outward face on ``surface`` bounded by ``loop``: (edge, forward) pairs, counter-clockwise
        seen from outside."""
        edges = ",".join(self.add(f"ORIENTED_EDGE('',*,*,{e},{'.T.' if fwd else '.F.'})") for e, fwd in loop)
        loop_id = self.add(f"EDGE_LOOP('',({edges}))")
        bound = self.add(f"FACE_OUTER_BOUND('',{loop_id},.T.)")
        return self.add(f"ADVANCED_FACE('',({bound}),{surface},.T.)")

    def plane(self, origin, normal, ref) -> str:
        return self.add(f"PLANE('',{self.placement(origin, normal, ref)})")

    def document(self, faces: list[str], unit) -> str:
        """The whole file: the solid bounded by ``faces``, its units and its product."""
        shell = self.add("CLOSED_SHELL('',({}))".format(",".join(faces)))
        brep = self.add(f"MANIFOLD_SOLID_BREP('part',{shell})")
        origin = self.placement((0, 0, 0), (0, 0, 1), (1, 0, 0))
        first = len(self.lines) + 1
        for text in UNITS[unit]:  # {k}: the k-th entity after the first unit entity
            self.add(text.format(*(first + k for k in range(4))))
        length = f"#{first}"
        angle = self.add("(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.))")
        solid = self.add("(NAMED_UNIT(*)SI_UNIT($,.STERADIAN.)SOLID_ANGLE_UNIT())")
        accuracy = self.add(
            f"UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE(1.E-07),{length},'distance_accuracy_value','confusion')"
        )
        context = self.add(
            f"(GEOMETRIC_REPRESENTATION_CONTEXT(3)GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT(({accuracy}))"
            f"GLOBAL_UNIT_ASSIGNED_CONTEXT(({length},{angle},{solid}))REPRESENTATION_CONTEXT('',''))"
        )
        shape = self.add(f"ADVANCED_BREP_SHAPE_REPRESENTATION('',({brep},{origin}),{context})")
        app = self.add("APPLICATION_CONTEXT('automotive design')")
        self.add(f"APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,{app})")
        product_context = self.add(f"PRODUCT_CONTEXT('',{app},'mechanical')")
        product = self.add(f"PRODUCT('part','part','',({product_context}))")
        formation = self.add(f"PRODUCT_DEFINITION_FORMATION('','',{product})")
        pd_context = self.add(f"PRODUCT_DEFINITION_CONTEXT('part definition',{app},'design')")
        definition = self.add(f"PRODUCT_DEFINITION('design','',{formation},{pd_context})")
        definition_shape = self.add(f"PRODUCT_DEFINITION_SHAPE('','',{definition})")
        self.add(f"SHAPE_DEFINITION_REPRESENTATION({definition_shape},{shape})")
        return (
            "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('binpick test part'),'2;1');\n"
            "FILE_NAME('part.step','2026-01-01T00:00:00',(''),(''),'','','');\n"
            "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\nDATA;\n"
            + "\n".join(self.lines)
            + "\nENDSEC;\nEND-ISO-10303-21;\n"
        )


def _real(x: float) -> str:
    text = repr(float(x))
    return text if ("." in text or "e" in text) else text + "."


def prism_step(outline, height: float, unit="mm") -> str:
    """A STEP solid: the counter-clockwise ``outline`` (mm) extruded by ``height`` (mm), written in
    ``unit``: planes, straight edges, one face per side."""
    s = 1.0 / MM_PER[unit]
    w = StepWriter()
    p = [np.array([x, y, 0.0]) * s for x, y in outline]
    q = [np.array([x, y, height]) * s for x, y in outline]
    n = len(p)
    vp = [w.add(f"VERTEX_POINT('',{w.point(a)})") for a in p]
    vq = [w.add(f"VERTEX_POINT('',{w.point(a)})") for a in q]
    low = [w.line_edge(vp[i], vp[(i + 1) % n], p[i], p[(i + 1) % n]) for i in range(n)]
    high = [w.line_edge(vq[i], vq[(i + 1) % n], q[i], q[(i + 1) % n]) for i in range(n)]
    up = [w.line_edge(vp[i], vq[i], p[i], q[i]) for i in range(n)]
    faces = [
        w.face(w.plane(p[0], (0, 0, -1), (1, 0, 0)), [(low[i], False) for i in reversed(range(n))]),
        w.face(w.plane(q[0], (0, 0, 1), (1, 0, 0)), [(e, True) for e in high]),
    ]
    for i in range(n):
        j = (i + 1) % n
        e = (p[j] - p[i]) / np.linalg.norm(p[j] - p[i])
        side = w.plane(p[i], (e[1], -e[0], 0.0), e)
        faces.append(w.face(side, [(low[i], True), (up[j], True), (high[i], False), (up[i], False)]))
    return w.document(faces, unit)


def cylinder_step(radius: float, height: float) -> str:
    """A STEP cylinder (mm) on the z axis from z = 0: a cylindrical face with a seam, two discs."""
    w = StepWriter()
    v0 = w.add(f"VERTEX_POINT('',{w.point((radius, 0, 0))})")
    v1 = w.add(f"VERTEX_POINT('',{w.point((radius, 0, height))})")
    rims = []
    for v, z in ((v0, 0.0), (v1, height)):
        circle = w.add(f"CIRCLE('',{w.placement((0, 0, z), (0, 0, 1), (1, 0, 0))},{_real(radius)})")
        rims.append(w.add(f"EDGE_CURVE('',{v},{v},{circle},.T.)"))
    seam = w.line_edge(v0, v1, (radius, 0, 0), (radius, 0, height))
    wall = w.add(f"CYLINDRICAL_SURFACE('',{w.placement((0, 0, 0), (0, 0, 1), (1, 0, 0))},{_real(radius)})")
    faces = [
        w.face(wall, [(rims[0], True), (seam, True), (rims[1], False), (seam, False)]),
        w.face(w.plane((0, 0, 0), (0, 0, -1), (1, 0, 0)), [(rims[0], False)]),
        w.face(w.plane((0, 0, height), (0, 0, 1), (1, 0, 0)), [(rims[1], True)]),
    ]
    return w.document(faces, "mm")


@pytest.fixture(scope="module")
def l_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("step") / "plate.step"
    path.write_text(prism_step(L_OUTLINE, L_HEIGHT))
    return path


@pytest.fixture(scope="module")
def l_model(l_file):
    return binpick.Model.from_mesh(l_file, spacing=1.0)


def test_a_prism_reads_as_the_solid_it_describes(l_model):
    m = l_model
    assert m.name == "plate"
    np.testing.assert_allclose(m.vertices.min(axis=0), [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(m.vertices.max(axis=0), [60, 40, L_HEIGHT], atol=1e-6)
    assert len(m.vertices) == 12  # the corners, each once: the faces share them
    assert (edge_use_counts(m.faces) == 2).all()  # closed
    assert signed_volume(m.vertices, m.faces) == pytest.approx(L_VOLUME, rel=1e-9)
    assert m.area == pytest.approx(L_AREA, rel=1e-9)
    # The samples cover the L, not its bounding box: none in the notch.
    notch = (m.points[:, 0] > 20.5) & (m.points[:, 1] > 20.5)
    assert not notch.any()
    assert len(m.points) == pytest.approx(L_AREA, rel=0.1)  # one sample per mm² at 1 mm spacing


def test_a_cylinder_is_tessellated_within_the_chord_tolerance(tmp_path):
    radius, height = 20.0, 30.0
    path = tmp_path / "shaft.stp"
    path.write_text(cylinder_step(radius, height))
    m = binpick.Model.from_mesh(path, spacing=0.5)
    rho = np.hypot(m.vertices[:, 0], m.vertices[:, 1])
    np.testing.assert_allclose(rho, radius, atol=1e-5)  # vertices on the exact surface
    wall = (m.points[:, 2] > 1e-3) & (m.points[:, 2] < height - 1e-3)
    sag = radius - np.hypot(m.points[wall, 0], m.points[wall, 1])
    assert sag.min() > -1e-6 and sag.max() <= _step.CHORD_TOLERANCE + 1e-6
    assert sag.max() > _step.CHORD_TOLERANCE / 4  # the facets are chords, not the circle itself
    assert (edge_use_counts(m.faces) == 2).all()
    volume = np.pi * radius**2 * height
    assert volume * (1 - 2 * _step.CHORD_TOLERANCE / radius) < signed_volume(m.vertices, m.faces) < volume
    assert m.symmetries.continuous_axis is not None
    assert abs(m.symmetries.continuous_axis[2]) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("unit", ["mm", "m", "in", None])
def test_the_file_unit_is_converted_to_millimetres(tmp_path, l_model, unit):
    path = tmp_path / f"plate_{unit}.STEP"
    path.write_text(prism_step(L_OUTLINE, L_HEIGHT, unit))
    m = binpick.Model.from_mesh(path, unit=unit or "mm", spacing=1.0)
    np.testing.assert_allclose(m.vertices.max(axis=0), [60, 40, L_HEIGHT], rtol=1e-6)
    assert signed_volume(m.vertices, m.faces) == pytest.approx(L_VOLUME, rel=1e-6)


def test_the_declared_unit_is_named():
    names = {u: _step.declared_length_unit(prism_step(L_OUTLINE, L_HEIGHT, u).encode()) for u in UNITS}
    assert names == {"mm": ("mm", 1.0), "m": ("m", 1000.0), "in": ("inch", 25.4), None: None}


def test_a_unit_other_than_the_declared_one_is_refused(tmp_path):
    path = tmp_path / "plate_in.step"
    path.write_text(prism_step(L_OUTLINE, L_HEIGHT, "in"))
    refused = r"unit: .*plate_in.step declares its lengths in inch \(25.4 mm\), not '{}'; pass unit='in'"
    with pytest.raises(InvalidInputError, match=refused.format("mm")):
        binpick.Model.from_mesh(path)
    with pytest.raises(InvalidInputError, match=refused.format("cm")):
        binpick.Model.from_mesh(path, unit="cm")
    with pytest.raises(UnknownUnitError, match="unit: unknown unit 'furlong'"):
        binpick.Model.from_mesh(path, unit="furlong")


def test_a_unit_scales_a_file_that_declares_none(tmp_path):
    path = tmp_path / "plate_bare.step"
    path.write_text(prism_step(L_OUTLINE, L_HEIGHT, None))
    m = binpick.Model.from_mesh(path, unit="cm", spacing=10.0)
    np.testing.assert_allclose(m.vertices.max(axis=0), [600, 400, 10 * L_HEIGHT], rtol=1e-6)


def test_without_the_extra_the_error_names_it(l_file, monkeypatch):
    monkeypatch.setitem(sys.modules, "cascadio", None)  # what `import cascadio` meets when it is absent
    named = r'plate.step: reading STEP files needs the optional extra: pip install "binpick\[step\]"'
    with pytest.raises(MeshFileError, match=named):
        binpick.Model.from_mesh(l_file)


def _shadow_cascadio(tmp_path, monkeypatch, source: str) -> None:
    """Puts a module named cascadio first on the path, where the converter process finds it too:
    how these tests make the converter fail to load, crash or hang."""
    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "cascadio.py").write_text(source)
    monkeypatch.delitem(sys.modules, "cascadio", raising=False)
    monkeypatch.syspath_prepend(str(shadow))


def test_an_extra_that_cannot_load_in_the_converter_is_named(l_file, tmp_path, monkeypatch):
    _shadow_cascadio(tmp_path, monkeypatch, "raise ImportError('OpenCASCADE libraries missing')\n")
    named = r'needs the optional extra: pip install "binpick\[step\]" .*: OpenCASCADE libraries missing\)'
    with pytest.raises(MeshFileError, match=named):
        binpick.Model.from_mesh(l_file)


def test_a_converter_that_crashes_leaves_the_caller_alive(l_file, tmp_path, monkeypatch):
    crash = "import os, signal\n\ndef step_to_obj(*args, **kwargs):\n    os.kill(os.getpid(), signal.SIGSEGV)\n"
    _shadow_cascadio(tmp_path, monkeypatch, crash)
    crashed = rf"plate.step: OpenCASCADE crashed on the STEP file \(signal {int(signal.SIGSEGV)}, SIGSEGV\)"
    with pytest.raises(MeshFileError, match=crashed):
        binpick.Model.from_mesh(l_file)


@pytest.mark.timeout(30)
def test_a_converter_that_hangs_is_stopped(l_file, tmp_path, monkeypatch):
    _shadow_cascadio(tmp_path, monkeypatch, "import time\n\ndef step_to_obj(*args, **kwargs):\n    time.sleep(60)\n")
    monkeypatch.setattr(_step, "TIMEOUT_S", 2.0)
    t = time.monotonic()
    with pytest.raises(MeshFileError, match="plate.step: OpenCASCADE did not finish tessellating the STEP file in 2 s"):
        binpick.Model.from_mesh(l_file)
    assert time.monotonic() - t < 10


@pytest.mark.parametrize(
    "damage, reason",
    [
        ("truncated", "unexpected end of file"),
        ("garbage", "Incorrect syntax"),
        ("empty", r"the mesh file is empty \(0 bytes\); export the part from CAD again"),
        ("no geometry", "transfer"),
    ],
)
@pytest.mark.timeout(60)
def test_a_damaged_file_is_a_mesh_file_error_naming_it(l_file, tmp_path, damage, reason):
    text = l_file.read_bytes()
    data = {
        "truncated": text[: len(text) // 2],
        "garbage": bytes(random.Random(1).randrange(256) for _ in range(4000)),
        "empty": b"",
        "no geometry": text.split(b"DATA;")[0] + b"DATA;\nENDSEC;\nEND-ISO-10303-21;\n",
    }[damage]
    path = tmp_path / "broken.step"
    path.write_bytes(data)
    with pytest.raises(MeshFileError, match=rf"broken.step: .*{reason}"):
        binpick.Model.from_mesh(path)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(MeshFileNotFoundError, match="nowhere.stp: no such file, the mesh file does not exist"):
        binpick.Model.from_mesh(tmp_path / "nowhere.stp")


def _variant(text: str, top_face: bool = True, surface_model: bool = False, listed: bool = True) -> str:
    """``text`` (a prism_step file) without its top face, or as a surface model (an open shell),
    whose shell is ``listed`` as the schema wants, or named bare."""
    if not top_face:
        top = re.findall(r"(#\d+)=ADVANCED_FACE", text)[1]
        text = text.replace(f",{top},", ",")
    if surface_model:
        text = text.replace("CLOSED_SHELL", "OPEN_SHELL").replace(
            "ADVANCED_BREP_SHAPE_REPRESENTATION", "MANIFOLD_SURFACE_SHAPE_REPRESENTATION"
        )
        shells = r"(\1)" if listed else r"\1"
        text = re.sub(r"MANIFOLD_SOLID_BREP\('part',(#\d+)\)", rf"SHELL_BASED_SURFACE_MODEL('part',{shells})", text)
    return text


def test_a_solid_that_lost_a_face_is_refused(l_file, tmp_path):
    # OpenCASCADE drops the face whose bound it cannot resolve, says so, and tessellates the rest.
    text = re.sub(r"ADVANCED_FACE\('',\(#\d+\)", "ADVANCED_FACE('',(#99999)", l_file.read_text(), count=1)
    path = tmp_path / "holed.step"
    path.write_text(text)
    damaged = r"holed.step: the STEP file is damaged: .*Unresolved Reference.* the surface left is open \(6 edges\)"
    with pytest.raises(MeshFileError, match=damaged):
        binpick.Model.from_mesh(path)


def test_damage_outside_the_geometry_warns_and_keeps_the_solid(l_file, tmp_path):
    path = tmp_path / "misnamed.step"
    path.write_text(l_file.read_text().replace("PRODUCT('part','part','',(#", "PRODUCT('part','part','',(#9999"))
    with pytest.warns(RuntimeWarning, match="misnamed.step: read, but .*Unresolved Reference"):
        m = binpick.Model.from_mesh(path)
    assert signed_volume(m.vertices, m.faces) == pytest.approx(L_VOLUME, rel=1e-9)


def test_a_surface_model_is_read_open_with_a_warning(l_file, tmp_path):
    path = tmp_path / "tray.step"
    path.write_text(_variant(l_file.read_text(), top_face=False, surface_model=True))
    with pytest.warns(RuntimeWarning, match=r"tray.step: read, but its surface is open \(6 edges bound one triangle"):
        m = binpick.Model.from_mesh(path)
    assert m.area == pytest.approx(L_AREA - 1600.0, rel=1e-9)
    assert m.vertices[:, 2].max() == pytest.approx(L_HEIGHT)


def test_a_file_that_crashes_opencascade_leaves_the_caller_alive(l_file, tmp_path):
    # A surface model whose SHELL_BASED_SURFACE_MODEL names its shell without the list around it:
    # OpenCASCADE 7.x/8.0 in cascadio 0.1.1 dies of SIGSEGV on it, in the converter process.
    path = tmp_path / "unlisted.step"
    path.write_text(_variant(l_file.read_text(), surface_model=True, listed=False))
    with pytest.raises(MeshFileError, match="unlisted.step: "):
        binpick.Model.from_mesh(path)


@pytest.mark.timeout(120)
def test_mutated_files_load_or_raise_binpick_errors(l_file, tmp_path):
    original = l_file.read_bytes()
    rng = random.Random(7)
    path = tmp_path / "mutant.step"
    outcomes = []
    for _ in range(6):
        path.write_bytes(mutate(original, rng))
        try:
            with warnings.catch_warnings(record=True) as warned:
                warnings.simplefilter("always")
                m = binpick.Model.from_mesh(path, spacing=2.0)
            closed = bool((edge_use_counts(m.faces) == 2).all())
            outcomes.append(("valid", closed or bool(warned)))  # an open surface is never silent
        except BinpickError as exc:
            outcomes.append((type(exc).__name__, True))
    assert all(kind in ("valid", "MeshFileError", "InvalidInputError") and ok for kind, ok in outcomes), outcomes


def test_a_step_part_is_found_in_a_scan_of_the_solid(l_model):
    # The scan renders the prism built independently (tests/_geometry), the pose is estimated
    # against the model read from STEP: the two frames must be the same for the pose to be.
    from binpick import sim

    truth = binpick.Model.from_arrays(*extruded_mesh(L_OUTLINE, L_HEIGHT), spacing=1.0)
    rng = np.random.default_rng(5)
    viewpoint = sim.Cell().T_base_camera[:3, 3]
    errors = []
    for _ in range(3):
        T = np.eye(4)
        T[:3, :3] = random_rotation(rng)
        T[:3, 3] = [rng.uniform(350, 450), rng.uniform(-40, 40), rng.uniform(30, 50)]
        res = binpick.estimate_pose(rendered_view(truth, T, rng), l_model, method="ppf", viewpoint=viewpoint)
        errors.append(l_model.pose_error(res.T_scene_model, T))
    assert all(rot < 5.0 and shift < 3.0 for rot, shift in errors), errors
