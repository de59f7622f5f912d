"""Laser-line extraction (paper section 3): BGR → YCrCb, threshold on the red chroma Cr, one
pixel per scan line (the thinning), then a sub-pixel centre across the line."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from .._validate import as_image, choice, count, number, positive
from ..errors import InvalidInputError

__all__ = ["extract_line", "laser_mask", "red_excess"]

_METHODS = ("cog", "gaussian")
_DIRECTIONS = ("auto", "rows", "columns")
#: Half-length, in scan lines, of the running median that predicts where the line should be.
_TRACK_HALF = 8


def red_excess(image: np.ndarray) -> np.ndarray:
    """The red chroma above neutral, ``max(Cr − 128, 0)`` (uint8, H×W), of a BGR frame; a grey
    frame is returned as it is (its brightness is the signal). White or grey ambient light leaves
    Cr at 128, which is why the line is found on Cr and not on brightness."""
    img = as_image(image, "image")
    if img.ndim == 2:
        return img
    cr = cv2.extractChannel(cv2.cvtColor(img, cv2.COLOR_BGR2YCrCb), 1)
    return cv2.subtract(cr, 128)


def laser_mask(image: np.ndarray, threshold: float = 30.0) -> np.ndarray:
    """The paper's binary segmentation: pixels whose Cr exceeds 128 + ``threshold`` (bool H×W)."""
    return red_excess(image) > _threshold(threshold)


def _threshold(value: Any) -> float:
    t = number(value, "threshold", unit="grey levels")
    if not 0 <= t < 255:
        raise InvalidInputError(
            f"threshold: {t:g} is outside 0–255; it is the chroma (Cr − 128) or grey level a line pixel must exceed"
        )
    return t


def _running_median(x: np.ndarray, half: int) -> np.ndarray:
    padded = np.pad(x, half, mode="edge")
    return np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1), axis=1)


def extract_line(
    image: np.ndarray,
    *,
    threshold: float = 30.0,
    window: int = 4,
    method: str = "cog",
    direction: str = "auto",
    max_jump: float | None = 6.0,
    roi: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """The laser line's centre in ``image``, one sub-pixel point per scan line: (M, 2) float64 (u, v).

    - ``image``: uint8 BGR frame (H, W, 3) as grabbed, or a grey (H, W) frame whose brightness is the line.
    - ``threshold``: the red chroma Cr − 128 (grey level for grey frames) a line's peak must exceed.
    - ``window``: half-width in pixels of the window across the line used for the sub-pixel centre.
    - ``method``: ``"cog"`` (centre of gravity above the window's floor, robust to ambient light)
      or ``"gaussian"`` (three-point Gaussian fit at the peak).
    - ``direction``: ``"rows"`` scans each image row (a line running top to bottom), ``"columns"``
      each column (a line running left to right), ``"auto"`` picks the one the line crosses more.
    - ``max_jump``: several candidate peaks on one scan line are resolved by continuity: a peak
      further than this (pixels) from the running median of its neighbours is replaced by the
      strongest peak within ``max_jump`` of that median, or dropped. The median spans 17 scan
      lines, so a stray reflection over fewer than 9 of them is rejected. None keeps the strongest.
    - ``roi``: ``(u0, v0, u1, v1)``, only the pixels ``u0 ≤ u < u1``, ``v0 ≤ v < v1`` are searched
      (:meth:`LaserWindow.roi` gives where the sheet can meet the working volume); None: the whole image.

    Scan lines without a peak above ``threshold`` give no point.
    """
    t = _threshold(threshold)
    window = count(window, "window", 1, 50)
    choice(method, "method", _METHODS)
    choice(direction, "direction", _DIRECTIONS)
    if max_jump is not None:
        max_jump = positive(max_jump, "max_jump", "pixels")
    img = as_image(image, "image")
    if roi is not None:
        u0, v0, u1, v1 = _roi(roi, img.shape)
        img = img[v0:v1, u0:u1]
    signal = red_excess(img)
    if direction == "auto":
        lit_rows = np.count_nonzero(signal.max(axis=1) > t)
        lit_cols = np.count_nonzero(signal.max(axis=0) > t)
        direction = "columns" if lit_cols > lit_rows else "rows"
    if direction == "columns":
        signal = cv2.transpose(signal)
    across, along = _centres(signal, t, int(window), method, max_jump)
    uv = np.stack([across, along], axis=1) if direction == "rows" else np.stack([along, across], axis=1)
    if roi is not None:
        uv += (u0, v0)
    return uv


def _roi(roi: Any, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    """``roi`` as four ints inside an image of ``shape``, or InvalidInputError naming it."""
    r = np.asarray(roi)
    if r.shape != (4,) or r.dtype.kind not in "iu":
        raise InvalidInputError(f"roi: expected four integers (u0, v0, u1, v1) in pixels, got {roi!r}")
    u0, v0, u1, v1 = (int(x) for x in r)
    height, width = shape[:2]
    if not (0 <= u0 <= u1 - 2 and u1 <= width and 0 <= v0 <= v1 - 2 and v1 <= height):
        raise InvalidInputError(
            f"roi: ({u0}, {v0}, {u1}, {v1}) must satisfy 0 ≤ u0 < u1 ≤ {width} and 0 ≤ v0 < v1 ≤ {height} "
            "(the image's width and height) and span at least 2 pixels each way; pass None to search the whole image"
        )
    return u0, v0, u1, v1


def _centres(
    signal: np.ndarray, threshold: float, window: int, method: str, max_jump: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel peak positions along each row of ``signal``: (position across, row index)."""
    height, width = signal.shape
    # The strongest peak after a box blur of about the line's width: a wide, bright line wins
    # over a single hot pixel of noise.
    smooth = cv2.blur(signal, (2 * (window // 2) + 1, 1))
    peak_col = smooth.argmax(axis=1)
    rows = np.arange(height)
    ok = smooth[rows, peak_col] > 0
    if max_jump is not None and np.count_nonzero(ok) > 2 * _TRACK_HALF:
        lit = np.nonzero(ok)[0]
        predicted = _running_median(peak_col[lit].astype(np.float64), _TRACK_HALF)
        stray = np.abs(peak_col[lit] - predicted) > max_jump
        if stray.any():
            r = lit[stray]
            jump = int(np.ceil(max_jump))
            band = np.clip(
                np.rint(predicted[stray]).astype(np.intp)[:, None] + np.arange(-jump, jump + 1), 0, width - 1
            )
            peak_col[r] = band[np.arange(len(r)), smooth[r[:, None], band].argmax(axis=1)]
    offsets = np.arange(-window, window + 1)

    def around(cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = cols[:, None] + offsets
        inside = (idx >= 0) & (idx < width)
        return signal[rows[:, None], np.clip(idx, 0, width - 1)].astype(np.float32), inside

    # The centre is refined about the raw maximum near the blurred peak; that maximum must
    # clear the threshold.
    vals, _ = around(peak_col)
    raw_best = vals.argmax(axis=1)
    keep = ok & (vals[rows, raw_best] > threshold)
    rows, cols = rows[keep], (peak_col + raw_best - window)[keep]
    vals, inside = around(cols)
    vals[~inside] = np.nan
    if method == "cog":
        # Weights above the window's floor, or a fifth of the peak if higher: ambient light and
        # the noisy tails then carry no weight.
        floor = np.maximum(np.nanmin(vals, axis=1, keepdims=True), 0.2 * np.nanmax(vals, axis=1, keepdims=True))
        weights = np.maximum(vals - floor, 0.0)
        weights[~inside] = 0.0
        total = weights.sum(axis=1)
        good = total > 0
        shift = (weights @ offsets.astype(np.float32))[good] / total[good]
        return cols[good] + shift.astype(np.float64), rows[good].astype(np.float64)
    above = vals[:, window - 1 : window + 2] - np.nanmin(vals, axis=1, keepdims=True)
    logs = np.log(np.maximum(above, 0.5))
    denom = logs[:, 0] - 2 * logs[:, 1] + logs[:, 2]
    good = np.isfinite(denom) & (denom < 0)
    shift = np.clip(0.5 * (logs[good, 0] - logs[good, 2]) / denom[good], -1, 1)
    return cols[good] + shift.astype(np.float64), rows[good].astype(np.float64)
