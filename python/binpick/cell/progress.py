"""What the cell says as it works: a callback ``(stage, message)`` the pick loop calls at each stage."""

from __future__ import annotations

import sys
import time
from typing import Optional, TextIO

__all__ = ["ProgressPrinter", "quiet"]


class ProgressPrinter:
    """Prints one line per stage: elapsed time, the pick, the stage and what it did."""

    def __init__(self, stream: Optional[TextIO] = None) -> None:
        self.stream = stream
        self._t0 = time.perf_counter()

    def __call__(self, stage: str, message: str) -> None:
        stream = self.stream if self.stream is not None else sys.stdout
        print(f"[{time.perf_counter() - self._t0:7.2f} s] {stage:<10} {message}", file=stream, flush=True)


def quiet(stage: str, message: str) -> None:
    """A progress callback that prints nothing."""
    return None
