"""Running a README block word for word: the fenced block after a marker, and an environment
whose `binpick` command is this interpreter running the package under test."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import binpick

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_block(marker: str) -> str:
    """The fenced block right after ``marker`` in README.md."""
    text = README.read_text(encoding="utf-8")
    assert marker in text, f"README.md lost the {marker} marker"
    block = re.match(r"\s*```[^\n]*\n(.*?)```", text[text.index(marker) + len(marker) :], re.S)
    assert block is not None, "the marker must be followed by the fenced block"
    return block.group(1)


def command_shim(folder: Path) -> dict:
    """An environment whose `binpick` (and `python`) is this interpreter running the package under test."""
    folder.mkdir()
    shim = folder / "binpick"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m binpick "$@"\n')
    shim.chmod(0o755)
    python = folder / "python"  # `python` in a block is this interpreter too
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(0o755)
    package_root = str(Path(binpick.__file__).resolve().parents[1])
    env = dict(os.environ, PATH=f"{folder}{os.pathsep}{os.environ['PATH']}")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH")) if p)
    return env


def run_block(marker: str, work: Path, *, timeout_s: float, setup=None) -> tuple[int, str]:
    """Runs the README block after ``marker`` with ``bash -e`` in ``work`` (its `binpick` this
    package); returns (exit code, output). The block's background jobs are stopped with it, also
    when a step fails; a block past ``timeout_s`` fails the test with the output's end."""
    import pytest

    env = command_shim(work / ".bin")
    if setup is not None:
        setup(work)
    script = work / "block.sh"
    script.write_text(readme_block(marker))
    log = work / "block.log"
    with open(log, "w") as sink:
        proc = subprocess.Popen(
            ["bash", "-e", script.name],
            cwd=work,
            env=env,
            stdout=sink,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the README block {marker} did not finish in {timeout_s} s:\n{log.read_text()[-4000:]}")
        finally:
            try:  # a failed step leaves the block's background jobs running: stop them with it
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    return proc.returncode, log.read_text()
