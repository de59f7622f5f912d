"""A user's file that is not there or is empty: binpick says "no such file" and, where a file of a
close name lies beside it, which one was meant; an empty file is called empty (0 bytes), not a
format binpick does not read — for scenes, meshes, cell files and folders given on the command line."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from binpick.cli import main
from binpick.errors import MeshFileError, MeshFileNotFoundError


@pytest.mark.parametrize("name", ["scene.ply", "scene.npy", "scene.pcd", "scene.xyz"])
def test_an_empty_scene_file_is_called_empty(tmp_path, name, capsys):
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(MeshFileError, match=r"the scene file is empty \(0 bytes\); write it again"):
        binpick.read_scene(path)
    assert main(["estimate", str(path), "tee"]) == 2
    err = capsys.readouterr().err
    assert "is empty (0 bytes)" in err and "not a scene format" not in err


@pytest.mark.parametrize("name", ["part.stl", "part.obj", "part.ply"])
def test_an_empty_mesh_file_is_called_empty(tmp_path, name, capsys):
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(MeshFileError, match=r"the mesh file is empty \(0 bytes\); export the part from CAD again"):
        binpick.Model.from_mesh(path)
    assert main(["demo", "--part", str(path)]) == 2
    assert "mesh file is empty (0 bytes)" in capsys.readouterr().err


def test_a_mistyped_scene_path_names_the_file_meant(tmp_path, capsys):
    np.save(tmp_path / "scene.npy", np.zeros((20, 3)))
    typo = tmp_path / "scnee.npy"
    with pytest.raises(MeshFileNotFoundError, match="no such file") as caught:
        binpick.read_scene(typo)
    assert str(caught.value).endswith(f"did you mean {tmp_path / 'scene.npy'}?")
    assert main(["estimate", str(typo), "tee"]) == 2
    assert f"did you mean {tmp_path / 'scene.npy'}?" in capsys.readouterr().err
    with pytest.raises(MeshFileNotFoundError) as caught:  # nothing close: no guess
        binpick.read_scene(tmp_path / "wholly_other.pcd")
    assert "no such file" in str(caught.value) and "did you mean" not in str(caught.value).lower()


def test_a_mistyped_mesh_or_part_name_names_the_one_meant(tmp_path, capsys):
    from _geometry import box_mesh, write_stl_binary

    write_stl_binary(tmp_path / "bracket.stl", *box_mesh())
    with pytest.raises(MeshFileNotFoundError, match=r"no such file.*did you mean .*bracket\.stl\?"):
        binpick.Model.from_mesh(tmp_path / "brakcet.stl")
    np.save(tmp_path / "scene.npy", np.zeros((20, 3)))
    assert main(["estimate", str(tmp_path / "scene.npy"), str(tmp_path / "bracket.st")]) == 2
    err = capsys.readouterr().err
    assert "MODEL:" in err and "no such file" in err and f"did you mean {tmp_path / 'bracket.stl'}?" in err
    assert main(["demo", "--part", "elbw"]) == 2
    err = capsys.readouterr().err
    assert "--part: 'elbw' is neither a built-in part" in err and "did you mean elbow?" in err


def test_a_mistyped_cell_file_or_folder_names_the_one_meant(tmp_path, capsys):
    (tmp_path / "twin").mkdir()
    (tmp_path / "twin" / "cell.toml").write_text("")
    (tmp_path / "checkerboards").mkdir()
    for argv, meant in (
        (["pick", str(tmp_path / "twn" / "cell.toml")], tmp_path / "twin" / "cell.toml"),
        (["pick", str(tmp_path / "twin" / "cel.toml")], tmp_path / "twin" / "cell.toml"),
        (["calibrate", str(tmp_path / "checkerbords")], tmp_path / "checkerboards"),
        (["calibrate", "solve", str(tmp_path / "twinn")], tmp_path / "twin"),
        (["reconstruct", str(tmp_path / "twi")], tmp_path / "twin"),
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "no such" in err and f"did you mean {meant}?" in err, (argv, err)


def test_close_match_mends_each_missing_part_of_a_path(tmp_path):
    from binpick._paths import close_match

    (tmp_path / "scans" / "sweep_001").mkdir(parents=True)
    (tmp_path / "scans" / "sweep_001" / "scan.json").write_text("{}")
    assert close_match(tmp_path / "scan" / "sweep_01" / "scan.jsn") == str(tmp_path / "scans/sweep_001/scan.json")
    assert close_match(tmp_path / "SCANS") == str(tmp_path / "scans")  # case does not count
    assert close_match(tmp_path / "scans") is None  # it exists
    assert close_match(tmp_path / "nothing_like_it" / "x") is None
