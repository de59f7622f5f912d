"""binpick serve with a fixed 3-D camera above the bin (eye-to-hand) on the twin with a UR arm:
`binpick emulate cell --robot ur --camera fixed`, the twin's true eye-to-hand pose (its
calibration is tested in tests/calibration/test_eye_to_hand.py), `binpick serve --brand abb`,
and the robot program of examples/robots/twin_program.py scanning from the park pose — issue
40's target: 5 parts of 5 removed, per world.json."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "robots"))
from twin_program import run  # noqa: E402

from _twin import twin_process  # noqa: E402


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    options = ("--count", "5", "--robot", "ur", "--camera", "fixed")
    with twin_process(tmp_path_factory.mktemp("fixed"), *options) as out:
        server = subprocess.Popen(
            [sys.executable, "-m", "binpick", "serve", str(out / "cell.toml"), "--brand", "abb", "--port", "0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        )
        try:
            first = server.stdout.readline()
            assert first.startswith("binpick serve: listening on 127.0.0.1:"), first
            yield out, int(first.split("127.0.0.1:")[1].split()[0])
        finally:
            os.killpg(server.pid, signal.SIGTERM)
            server.wait(timeout=30)


def test_a_fixed_camera_cell_empties_the_bin_through_the_server(twin):
    out, port = twin
    lines: list[str] = []
    counts = run(str(out / "cell.toml"), "127.0.0.1", port, "abb", 7, out=lines.append)
    assert counts == {"held": 5, "empty": 0, "refused": 0}, lines
    assert lines[-1].startswith("NEXT: code 10")  # the sixth shot found the bin empty
    time.sleep(0.5)  # the twin writes world.json on its next tick
    world = json.loads((out / "world.json").read_text())
    assert sorted(world["removed"]) == [0, 1, 2, 3, 4] and world["in_bin"] == []
    assert all(c["with"].startswith("part ") and int(c["with"][5:]) in world["removed"] for c in world["collisions"])
