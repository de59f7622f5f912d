"""Session fixtures shared by the top-level tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tee_model():
    import binpick

    return binpick.parts.tee(resolution=1.0, spacing=1.0)
