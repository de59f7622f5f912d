"""Helpers shared by the cell tests."""

from __future__ import annotations

from types import MappingProxyType, SimpleNamespace
from typing import Any

import numpy as np

from binpick.cell.records import Located, ScanResult


def located(T_base_object: np.ndarray, result: Any) -> Located:
    """A located part at ``T_base_object`` with pose result ``result`` and an empty scan."""
    scan = ScanResult(
        cloud=SimpleNamespace(points=np.zeros((0, 3))),
        angles=np.zeros(0),
        T_base_flanges=np.zeros((0, 4, 4)),
        frames=MappingProxyType({}),
        timings=MappingProxyType({}),
    )
    return Located(scan=scan, result=result, T_base_object=T_base_object, indices=np.zeros(0, dtype=np.int64))
