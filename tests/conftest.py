"""Session fixtures shared by the top-level tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tee_model():
    import binpick

    return binpick.parts.tee(resolution=1.0, spacing=1.0)


#: Test files whose run takes a minute or more (a whole commissioning, a calibration capture, a
#: pile emptied): collected first, so that with `pytest -n auto --dist loadfile` they start at
#: once on their own workers instead of running alone at the end.
LONGEST_FIRST = (
    "test_commission.py",
    "test_capture_solve.py",
    "test_twin_process.py",
    "test_large_part.py",
    "test_nudge.py",
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))  # stable: the rest keep their order
