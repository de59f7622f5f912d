"""Defects the hardening bench (benches/hardening.py) found, each pinned by its minimal case."""

from __future__ import annotations

import numpy as np
import pytest

import binpick


@pytest.mark.parametrize(
    "header",
    [
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (4k[0, 3), }",  # an unclosed bracket
        b"{'descr': '<f8', 'fortran_order': (False, 'shape': (40, 3), }",  # an unclosed parenthesis
    ],
)
def test_an_npy_scene_with_a_broken_header_is_a_mesh_file_error(tmp_path, header):
    """numpy tokenizes the header and raises tokenize.TokenError or SyntaxError, neither a ValueError."""
    path = tmp_path / "scene.npy"
    good = tmp_path / "good.npy"
    np.save(good, np.zeros((40, 3)))
    data = good.read_bytes()
    size = int.from_bytes(data[8:10], "little")
    body = header.ljust(size - 1) + b"\n"
    path.write_bytes(data[:10] + body + data[10 + size :])
    with pytest.raises(binpick.MeshFileError, match="NumPy"):
        binpick.read_scene(path)
