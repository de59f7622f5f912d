"""What the property tests over the public API share (issue 16 item 6): the argument values they
draw from, and the one rule every case must meet — a result, a BinpickError subclass, or Python's
own TypeError for an argument of the wrong Python type; never another exception and never a case
slower than :data:`SLOWEST_CASE_S`."""

from __future__ import annotations

import math
import os
import time
from typing import Any, Callable, Optional

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from binpick import errors

#: The outcomes a bad argument may have besides a result.
ALLOWED = (errors.BinpickError, TypeError)

#: Outcomes that are never acceptable, even though they subclass an allowed one.
FORBIDDEN = (errors.InternalError,)

#: The longest one case may take, seconds (a hang shows as a case over it).
SLOWEST_CASE_S = 5.0

#: Examples per property test; BINPICK_PROPERTY_EXAMPLES raises it for a longer run.
EXAMPLES = int(os.environ.get("BINPICK_PROPERTY_EXAMPLES", "40"))

#: Hypothesis settings of a property test: a bounded number of examples, no per-example deadline
#: (the machine is shared; :func:`outcome` bounds each case itself), nothing stored between runs,
#: the same examples every run (a failure found is found again, never a flake).
PROPERTY = settings(
    max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), database=None, derandomize=True
)

#: Any value of a wrong or extreme kind for a scalar argument.
anything = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([10**400, -(10**400), 2**64, -1, 0, 1e300, -1e300, 5e-324, np.float64("nan"), np.int64(3)]),
    st.text(max_size=4),
    st.lists(st.integers(0, 5), max_size=3),
    st.just(object()),
)


def mostly(valid: st.SearchStrategy, *wild: st.SearchStrategy) -> st.SearchStrategy:
    """Draws from ``valid`` three times in four, else from ``wild`` (default: anything), so that a
    test whose arguments must all be valid for a result still reaches one. (Not ``one_of(valid,
    valid, wild)``: one_of flattens a nested one_of such as :data:`anything` into its branches,
    and the valid draws came up once in ten.)"""
    other = st.one_of(*wild) if wild else anything
    return st.sampled_from((True, True, True, False)).flatmap(lambda ok: valid if ok else other)


def ints(low: int, high: int) -> st.SearchStrategy:
    """Integers mostly in [low, high] (where the valid values are), or anything."""
    return mostly(st.integers(low, high))


def reals(low: float, high: float) -> st.SearchStrategy:
    """Finite floats mostly in [low, high], or anything."""
    return mostly(st.floats(low, high))


def vectors(size: int, low: float = -1e3, high: float = 1e3) -> st.SearchStrategy:
    """Sequences of about ``size`` numbers (sometimes the wrong size, type or finiteness), or anything."""
    right = st.lists(st.floats(low, high), min_size=size, max_size=size)
    return mostly(
        st.one_of(right.map(tuple), right.map(np.array)),
        st.lists(mostly(st.floats(low, high)), min_size=max(0, size - 1), max_size=size + 1),
        anything,
    )


def rigid(angle: float, axis: Any = (0.3, -0.5, 0.8), offset: Any = (10.0, -20.0, 30.0)) -> np.ndarray:
    """The rigid transform turning ``angle`` rad about ``axis`` and moving by ``offset`` mm."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    T[:3, 3] = offset
    return T


_BAD_TRANSFORMS = [
    np.eye(3),
    np.eye(4) * 2.0,
    np.diag([1.0, 1.0, -1.0, 1.0]),
    np.full((4, 4), np.nan),
    np.eye(4).astype(np.float32),
    np.zeros((4, 4)),
    [[1, 0, 0, 0]] * 4,
    [[1, 0, 0, 10**400], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
    np.array([["a"] * 4] * 4),
]

#: Rigid transforms (random rotation and offset) three times in four, else matrices that are not
#: one or anything. (The offset is drawn unfiltered: a filter on :func:`vectors` rejected nearly
#: every draw, and the rigid branch came up once in a hundred examples.)
transforms = mostly(
    st.builds(rigid, st.floats(-math.pi, math.pi), st.just((0.1, 0.7, -0.2)), st.tuples(*[st.floats(-500, 500)] * 3)),
    st.sampled_from(_BAD_TRANSFORMS),
    anything,
)


def attempt(call: Callable[[], Any], what: str = "") -> tuple[Any, Optional[Exception]]:
    """``(call()'s result, None)``, or ``(None, the error)`` where it raised an allowed error; an
    AssertionError naming the exception for anything else (or for a case slower than
    :data:`SLOWEST_CASE_S`)."""
    t0 = time.monotonic()
    result, error = None, None
    try:
        result = call()
    except FORBIDDEN as exc:
        raise AssertionError(f"{what}: {type(exc).__name__}: {exc}") from exc
    except ALLOWED as exc:
        error = exc
    except Exception as exc:
        raise AssertionError(f"{what}: {type(exc).__name__} outside BinpickError: {exc}") from exc
    took = time.monotonic() - t0
    assert took < SLOWEST_CASE_S, f"{what}: took {took:.1f} s"
    return result, error


def outcome(call: Callable[[], Any], what: str = "") -> Any:
    """``call()``'s result, or None where it raised an allowed error (see :func:`attempt`)."""
    return attempt(call, what)[0]


def finite(arr: Any) -> bool:
    """Whether every element of ``arr`` is a finite number."""
    return bool(np.isfinite(np.asarray(arr, dtype=np.float64)).all())


def variations(valid: dict, wild: dict) -> st.SearchStrategy:
    """Keyword arguments: ``valid`` with up to two of them replaced by a draw from ``wild``
    (name → strategy), so that both the accepted and the refused side of a many-argument
    constructor are exercised."""
    keys = sorted(wild)
    return (
        st.lists(st.sampled_from(keys), max_size=2, unique=True)
        .flatmap(lambda ks: st.fixed_dictionaries({k: wild[k] for k in ks}))
        .map(lambda d: {**valid, **d})
    )
