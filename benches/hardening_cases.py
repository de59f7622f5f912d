"""What every class of benches/hardening.py builds on: the case base class, the wrong-answer
exception an oracle raises, and the bad scalars a careless or hostile caller passes."""

from __future__ import annotations

import math
import random
from pathlib import Path


class WrongAnswer(Exception):
    """A call returned, but its result fails the oracle."""


# --------------------------------------------------------------------------- values


def _bad_scalar(rng: random.Random):
    """A value a careless or hostile caller might pass for any integer or float argument."""
    # fmt: off
    return rng.choice([
        -1, 0, 1, 2, 3, 7, 255, 256, 257, 2000, 10**9, 10**12, 2**31, 2**63, 2**64, 2**64 - 1, 2**70, -(2**64),
        10**400, -0.0, 1e-300, 1e-6, 0.5, 1.5, 1e16, 1e300, math.nan, math.inf, -math.inf, True, False, None,
        "6", "", "nan", b"1", [1], (1, 2), {}, 1 + 2j, object(), rng.uniform(-100, 100), rng.randint(-50, 500),
    ])
    # fmt: on


class Cases:
    """One class's cases: ``run(i)`` builds case ``i`` from the seed and calls the API under test;
    it returns normally (ok), raises WrongAnswer, or lets the API's exception out."""

    def __init__(self, seed: int, tmp: Path):
        import binpick

        self.seed, self.tmp, self.bp = seed, tmp, binpick

    def rng(self, i: int) -> random.Random:
        return random.Random(f"{self.seed}:{type(self).__name__}:{i}")
