"""Session fixtures shared by the top-level tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tee_model():
    import binpick

    return binpick.parts.tee(resolution=1.0, spacing=1.0)


#: Test files whose run takes half a minute or more (a pile emptied, a whole commissioning, a
#: calibration capture, the trust stage over piles), longest first (session 33's durations on
#: 2 cores): collected first, so that with `pytest -n auto --dist loadfile` they start at once on
#: their own workers instead of one running alone at the end while the other worker idles.
LONGEST_FIRST = (
    "test_validate.py",
    "test_trust.py",
    "test_commission.py",
    "test_nudge.py",
    "test_eye_to_hand_readme.py",
    "test_capture_solve.py",
    "test_twin_process.py",
    "test_serve_readme.py",
    "test_serve_fixed_camera.py",
    "test_heap.py",
    "test_eye_to_hand.py",
    "test_cell_file.py",
    "test_no_dead_end.py",
)


def pytest_xdist_auto_num_workers(config):
    # `-n auto`: one worker more than the cores. The tests wait part of their time for the
    # emulators, the twin's processes and sockets; a third worker on 2 cores kept them busy
    # (session 33: the suite in 740 s against 808 s with 2).
    from binpick.sim.validate_workers import cores

    return cores() + 1


def pytest_configure(config):
    # pytest-xdist orders the files by how many tests each holds unless told not to, which sends
    # the long files of few tests (a commissioning, a pile emptied) last: keep LONGEST_FIRST's order.
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))  # stable: the rest keep their order
