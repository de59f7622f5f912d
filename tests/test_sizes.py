"""One sanity check of sizes before any work (issue 38 item 2): a part, a scene, a bin or a gripper
in the wrong unit is named with the unit it is probably in and the flag (``--unit m``,
``--scene-unit m``), the keyword (``unit="m"``) or the cell file's key that fixes it, with exit
code 2 — before a pile drops, a scan renders or a port opens."""

from __future__ import annotations

import time

import numpy as np
import pytest

import binpick
from _files import small_calibration
from _geometry import write_obj
from binpick import sim
from binpick._sizes import check_part, check_scene
from binpick.cell import CELL_FILE_EXAMPLE, config_from_file, load_cell_file
from binpick.cli import main
from binpick.errors import InvalidInputError, UnitError


def box(lx: float, ly: float, lz: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed box, lx × ly × lz, centred on the origin, outward-wound."""
    v = np.array([(x, y, z) for x in (-lx, lx) for y in (-ly, ly) for z in (-lz, lz)], dtype=float) / 2.0
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return v, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """A 150 × 40 × 20 mm bar written in metres and in millimetres."""
    folder = tmp_path_factory.mktemp("meshes")
    v, f = box(150.0, 40.0, 20.0)
    write_obj(folder / "bar_m.obj", v / 1000.0, f)
    write_obj(folder / "bar_mm.obj", v, f)
    return folder


@pytest.fixture
def no_pile(monkeypatch):
    """Any pile dropped fails the test: the check must come first."""

    def dropped(*args, **kwargs):
        raise AssertionError("a pile was dropped before the sizes were checked")

    monkeypatch.setattr(sim.twin, "Pile", dropped)
    monkeypatch.setattr(sim.dataset, "Pile", dropped)


def _run(argv, capsys):
    t0 = time.perf_counter()
    code = main(argv)
    seconds = time.perf_counter() - t0
    out = capsys.readouterr()
    return code, out.err, out.out, seconds


@pytest.mark.parametrize(
    "argv",
    [
        ["demo", "--part", "{m}"],
        ["simulate", "--part", "{m}", "--out", "{tmp}/scan"],
        ["estimate", "{tmp}/scene.xyz", "{m}", "--png", "{tmp}/e.png"],
        ["emulate", "cell", "--part", "{m}", "--out", "{tmp}/twin"],
    ],
    ids=["demo", "simulate", "estimate", "emulate-cell"],
)
def test_a_metre_mesh_read_as_mm_names_unit_m_before_any_work(argv, meshes, tmp_path, capsys, no_pile):
    np.savetxt(tmp_path / "scene.xyz", np.random.default_rng(0).uniform(0, 300, (500, 3)))
    argv = [a.format(m=meshes / "bar_m.obj", tmp=tmp_path) for a in argv]
    code, err, out, seconds = _run(argv, capsys)
    assert code == 2, err
    assert "the part 'bar_m' is 0.16 mm across" in err and "probably in metres (157 mm)" in err
    assert err.rstrip().endswith("pass `--unit m`"), err
    assert "unit=" not in err and "add_grasp" not in err  # the flag, not the Python keyword
    assert "pile" not in out and seconds < 2.0, (out, seconds)


def test_a_mm_mesh_read_as_metres_names_unit_mm(meshes, capsys, no_pile):
    code, err, _, seconds = _run(["demo", "--part", str(meshes / "bar_mm.obj"), "--unit", "m"], capsys)
    assert code == 2 and seconds < 2.0
    assert "is 156525 mm across, larger than any part an arm picks from a bin" in err
    assert "probably in millimetres (157 mm), read as metres: pass `--unit mm`" in err


@pytest.mark.parametrize("command", [["demo"], ["simulate", "--out", "x"], ["emulate", "cell", "--out", "x"]])
@pytest.mark.parametrize("unit", ["m", "in"])
def test_unit_with_a_built_in_part_is_refused(command, unit, capsys, no_pile):
    code = main([*command, "--part", "tee", "--unit", unit])
    err = capsys.readouterr().err
    assert code == 2 and f"--unit {unit}: the built-in part 'tee' is in mm" in err and "leave it out" in err


def test_unit_with_a_built_in_part_is_refused_by_estimate(tmp_path, capsys):
    np.savetxt(tmp_path / "scene.xyz", np.random.default_rng(0).uniform(0, 300, (500, 3)))
    code = main(["estimate", str(tmp_path / "scene.xyz"), "tee", "--unit", "m"])
    assert code == 2 and "--unit m: the built-in part 'tee' is in mm" in capsys.readouterr().err


def _bin_scene(scale: float) -> np.ndarray:
    """A 400 × 300 mm bin floor with a bump, in mm times ``scale``."""
    rng = np.random.default_rng(1)
    xy = rng.uniform((0, 0), (400, 300), (3000, 2))
    z = np.where(np.hypot(xy[:, 0] - 200, xy[:, 1] - 150) < 40, 20.0, 0.0)
    return np.column_stack([xy, z]) * scale


@pytest.mark.parametrize(
    "scale, header, flags, fix",
    [
        (1e-3, "", [], "read as millimetres: pass `--scene-unit m`"),  # in metres, read as mm
        (1.0, "# unit: m\n", [], "read as metres: pass `--scene-unit mm`"),  # in mm, declared metres
        (1.0, "", ["--scene-unit", "m"], "read as metres: pass `--scene-unit mm`"),  # in mm, passed as metres
    ],
)
def test_a_scene_in_the_wrong_unit_names_scene_unit(tmp_path, capsys, scale, header, flags, fix):
    path = tmp_path / "scene.xyz"
    with open(path, "w") as f:
        f.write(header)
        np.savetxt(f, _bin_scene(scale))
    code, err, _, seconds = _run(["estimate", str(path), "tee", *flags, "--png", str(tmp_path / "e.png")], capsys)
    assert code == 2 and seconds < 2.0
    assert "the scene is" in err and "but the part 'tee' is 84 mm" in err and err.rstrip().endswith(fix), err
    assert "multiply" not in err and not (tmp_path / "e.png").exists()


def test_the_python_api_names_the_keyword(meshes, no_pile):
    bar = binpick.Model.from_mesh(meshes / "bar_m.obj")
    for make in (lambda: sim.SimulatedCell(bar), lambda: sim.simulate_scan(bar, 2)):
        with pytest.raises(UnitError, match=r'^model: .*read its mesh with unit="m"') as info:
            make()
        assert isinstance(info.value, InvalidInputError)
        assert info.value.cli_message.endswith("pass `--unit m`")
    with pytest.raises(UnitError, match=r'read it with unit="m" \(binpick.read_scene'):
        check_scene(_bin_scene(1e-3), binpick.parts.tee())
    # The bands: a plausible part, bin and scene pass; a part larger than a given bin does not.
    check_part(binpick.parts.tee(), bin_bounds=sim.Bin().bounds, opening_mm=50.0)
    check_scene(_bin_scene(1.0), binpick.parts.tee())
    big = binpick.Model.from_mesh(meshes / "bar_mm.obj", unit="in")  # 4 m
    with pytest.raises(UnitError, match=r"larger than the bin .*probably in millimetres \(157 mm\), read as inches"):
        check_part(big, unit="in", bin_bounds=sim.Bin().bounds)


# --------------------------------------------------------------------------- cell files


@pytest.fixture
def cell_dir(tmp_path, meshes):
    small_calibration().save(tmp_path / "calibration.toml")
    for name in ("bar_m.obj", "bar_mm.obj"):
        (tmp_path / name).write_bytes((meshes / name).read_bytes())
    return tmp_path


@pytest.mark.parametrize(
    "edits, match",
    [
        (
            {'model = "tee"': 'model = "bar_m.obj"'},
            r"\[part\] the part 'bar_m' is 0.16 mm across.*probably in metres.*set unit = \"m\" in \[part\]",
        ),
        (
            {'model = "tee"': 'model = "bar_mm.obj"', 'unit = "mm"': 'unit = "m"'},
            r"\[part\] the part 'bar_mm' is 156525 mm across, larger than the bin.*set unit = \"mm\" in \[part\]",
        ),
        (
            {"[250.0, -100.0, 0.0]": "[0.25, -0.1, 0.0]", "[550.0, 100.0, 80.0]": "[0.55, 0.1, 0.08]"},
            r"\[cell\] bin_min_mm, bin_max_mm: the bin is 0.3 × 0.2 × 0.08 mm inside.*probably written in metres: "
            r"write them in mm \(\[250.0, -100.0, 0.0\] and \[550.0, 100.0, 80.0\]\)",
        ),
        (
            {"open_width_mm = 50.0": "open_width_mm = 0.05"},
            r"\[gripper\] open_width_mm = 0.05: the gripper opens 0.05 mm.*probably written in metres.*\(50\)",
        ),
        ({'unit = "mm"': 'unit = "m"'}, r"\[part\] unit = 'm': the built-in part 'tee' is in mm; leave unit out"),
    ],
    ids=["part-in-m", "part-in-mm-read-as-m", "bin-in-m", "gripper-in-m", "unit-with-tee"],
)
def test_a_cell_file_whose_sizes_disagree_names_the_key(cell_dir, edits, match):
    text = CELL_FILE_EXAMPLE
    for old, new in edits.items():
        assert old in text
        text = text.replace(old, new, 1)
    (cell_dir / "cell.toml").write_text(text)
    with pytest.raises(InvalidInputError, match=match) as info:
        config_from_file(load_cell_file(cell_dir / "cell.toml"))
    assert str(info.value).startswith(str(cell_dir / "cell.toml"))


def test_binpick_pick_names_the_cell_files_key_and_exits_2(cell_dir, capsys):
    (cell_dir / "cell.toml").write_text(CELL_FILE_EXAMPLE.replace('model = "tee"', 'model = "bar_m.obj"'))
    code = main(["pick", str(cell_dir / "cell.toml")])
    err = capsys.readouterr().err
    assert code == 2 and err.rstrip().endswith('set unit = "m" in [part]') and "--unit" not in err


def test_a_part_no_grasp_fits_says_why_and_the_command_names_the_cell_files_key(cell_dir, capsys):
    # A 100 mm cube: no two facing sides fit in the example gripper's 50 mm opening.
    v, f = box(100.0, 100.0, 100.0)
    write_obj(cell_dir / "cube.obj", v, f)
    (cell_dir / "cell.toml").write_text(CELL_FILE_EXAMPLE.replace('model = "tee"', 'model = "cube.obj"'))
    with pytest.raises(InvalidInputError, match=r"no two facing sides of it lie 1 to 48 mm apart.*model.add_grasp"):
        config_from_file(load_cell_file(cell_dir / "cell.toml"))
    assert main(["pick", str(cell_dir / "cell.toml")]) == 2
    err = capsys.readouterr().err
    assert "has no grasps" in err and "[gripper] open_width_mm" in err and "add_grasp" not in err


def test_a_step_files_declared_unit_is_named_as_the_flag():
    from binpick import _step

    with pytest.raises(UnitError, match=r"declares its lengths in INCH.*pass unit='in'") as info:
        _step._scale("part.step", "mm", ("INCH", 25.4))
    assert "pass `--unit in`" in info.value.cli_message
