"""README's Python blocks, word for word, each as a script of its own: they say where every name
comes from (the scene a simulated camera's view of a pile) and the pose found is pick-grade."""

from __future__ import annotations

import re
import subprocess
import sys

from _readme import command_shim, readme_block


def _run(marker: str, tmp_path) -> str:
    script = tmp_path / "block.py"
    script.write_text(readme_block(marker))
    env = command_shim(tmp_path / ".bin")
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_the_python_api_block_runs_and_finds_a_pick_grade_pose(tmp_path):
    out = _run("<!-- python-api -->", tmp_path)
    m = re.fullmatch(r"confidence ([\d.]+); ([\d.]+)° and ([\d.]+) mm from the nearest tee\n", out)
    assert m is not None, out
    confidence, deg, mm = (float(v) for v in m.groups())
    assert deg < 5.0 and mm < 3.0 and confidence > 0.5, out


def test_the_depth_camera_block_runs(tmp_path):
    assert _run("<!-- depth-camera-python -->", tmp_path) == ""
