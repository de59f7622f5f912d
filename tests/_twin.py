"""The digital twin as its own process for a test: `binpick emulate cell` started, waited for,
its true calibrations copied where its cell file looks for solved ones, and stopped after."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def twin_process(out: Path, *options: str) -> Iterator[Path]:
    """``binpick emulate cell --out OUT --speed-scale 10 OPTIONS…`` until the block ends; yields OUT
    once its camera socket is up, with calibration.toml (and eye_to_hand.toml for a fixed camera)
    copied from the twin's truth."""
    cmd = [sys.executable, "-m", "binpick", "emulate", "cell", "--out", str(out), "--speed-scale", "10", *options]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / "camera.sock").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "the twin did not start"
            time.sleep(0.2)
        shutil.copy(out / "true_calibration.toml", out / "calibration.toml")
        if (out / "true_eye_to_hand.toml").exists():
            shutil.copy(out / "true_eye_to_hand.toml", out / "eye_to_hand.toml")
        yield out
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)
