"""Laser-line extraction (paper section 3): BGR → YCrCb, threshold on the red chroma Cr, one
pixel per scan line (the thinning), then a sub-pixel centre across the line."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from .._validate import as_image, choice, count, number, pixel_window, positive
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


def describe_frames(frames: Any, threshold: float = 30.0) -> str:
    """What a scan's frames (BGR or grey images) show, in words, for a scan that gave no points:
    dark (the lens covered, the light off), overexposed (the line drowned), no pixel red enough
    for the line (the laser off or out of the view), or red pixels the extraction could not follow
    as a line."""
    images = [as_image(im, "frames") for im in frames]
    if not images:
        return "the scan kept no frame to look at"
    grey = [im if im.ndim == 2 else cv2.cvtColor(im, cv2.COLOR_BGR2GRAY) for im in images]
    brightness = float(np.median([float(g.mean()) for g in grey]))
    saturated = float(np.median([float((g >= 250).mean()) for g in grey]))
    red = [int((red_excess(im) > threshold).sum()) for im in images]
    seen = f"{len(images)} frames kept: median brightness {brightness:.0f} of 255"
    if brightness < 15.0:
        return f"{seen}; the images are dark: is the lens covered, the light off or the exposure too short?"
    if saturated > 0.25:
        return f"{seen}, {saturated:.0%} of the pixels saturated; the line drowns in it: lower the exposure or gain"
    if max(red) == 0:
        return (
            f"{seen}; no pixel is red enough for the laser line (Cr more than {threshold:g} over grey) in any of "
            "them: is the laser on, and does its line fall in the camera's view?"
        )
    return (
        f"{seen}; up to {max(red)} pixels per frame are red enough for the line, but none could be followed as a "
        "line across the image: is the view blocked close to the camera?"
    )


def _threshold(value: Any) -> float:
    t = number(value, "threshold", unit="grey levels")
    if not 0 <= t < 255:
        raise InvalidInputError(
            f"threshold: {t:g} is outside 0–255; it is the chroma (Cr − 128) or grey level a line pixel must exceed"
        )
    return t


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
        u0, v0, u1, v1 = pixel_window(roi, "roi", img.shape[1], img.shape[0], span=2, whole="search the whole image")
        img = img[v0:v1, u0:u1]
    signal = red_excess(img)
    if direction == "auto":
        lit_rows = np.count_nonzero(cv2.reduce(signal, 1, cv2.REDUCE_MAX) > t)
        # More rows lit than the image has columns: the columns cannot win (a tall window).
        lit_cols = 0 if lit_rows >= signal.shape[1] else np.count_nonzero(signal.max(axis=0) > t)
        direction = "columns" if lit_cols > lit_rows else "rows"
    if direction == "columns":
        signal = cv2.transpose(signal)
    across, along = _centres(signal, t, int(window), method, max_jump)
    uv = np.stack([across, along], axis=1) if direction == "rows" else np.stack([along, across], axis=1)
    if roi is not None:
        uv += (u0, v0)
    return uv


def _centres(
    signal: np.ndarray, threshold: float, window: int, method: str, max_jump: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel peak positions along each row of ``signal``: (position across, row index)."""
    signal = np.ascontiguousarray(signal)
    height, width = signal.shape
    # The strongest peak after a box blur of about the line's width: a wide, bright line wins
    # over a single hot pixel of noise. (The first maximum of each row, found through the row
    # maxima: numpy's row-wise argmax pays a call per row.)
    smooth = cv2.blur(signal, (2 * (window // 2) + 1, 1))
    top = cv2.reduce(smooth, 1, cv2.REDUCE_MAX)
    peak_col = (smooth == top).argmax(axis=1)
    ok = top[:, 0] > 0
    if max_jump is not None and np.count_nonzero(ok) > 2 * _TRACK_HALF:
        _follow_track(smooth, peak_col, np.nonzero(ok)[0], max_jump)
    offsets = np.arange(-window, window + 1)
    flat = signal.reshape(-1)

    def around(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The window's values about ``cols`` on ``rows``, one row per offset: (2·window + 1, N),
        and which of them lie inside the image."""
        idx = cols[None, :] + offsets[:, None]
        inside = (idx >= 0) & (idx < width)
        np.clip(idx, 0, width - 1, out=idx)
        idx += rows * width
        return flat[idx].astype(np.float32), inside

    # The centre is refined about the raw maximum near the blurred peak; that maximum must
    # clear the threshold.
    rows = np.nonzero(ok)[0]
    vals, _ = around(rows, peak_col[rows])
    best = vals.max(axis=0)
    raw_best = np.full(len(rows), window, dtype=np.intp)
    for k in range(2 * window, -1, -1):  # the first offset holding the maximum
        raw_best[vals[k] == best] = k
    keep = best > threshold
    rows, cols = rows[keep], (peak_col[rows] + raw_best - window)[keep]
    vals, inside = around(rows, cols)
    everywhere = bool(inside.all())
    lowest = vals.min(axis=0) if everywhere else np.where(inside, vals, np.inf).min(axis=0)
    if method == "cog":
        # Weights above the window's floor, or a fifth of the peak if higher: ambient light and
        # the noisy tails then carry no weight.
        highest = vals.max(axis=0) if everywhere else np.where(inside, vals, -np.inf).max(axis=0)
        weights = np.maximum(vals - np.maximum(lowest, 0.2 * highest), 0.0)
        if not everywhere:
            weights[~inside] = 0.0
        total = weights.sum(axis=0)
        good = total > 0
        shift = (offsets.astype(np.float32) @ weights[:, good]) / total[good]
        return cols[good] + shift.astype(np.float64), rows[good].astype(np.float64)
    above = vals[window - 1 : window + 2] - lowest
    if not everywhere:
        above[~inside[window - 1 : window + 2]] = np.nan
    logs = np.log(np.maximum(above, 0.5))
    denom = logs[0] - 2 * logs[1] + logs[2]
    good = np.isfinite(denom) & (denom < 0)
    shift = np.clip(0.5 * (logs[0, good] - logs[2, good]) / denom[good], -1, 1)
    return cols[good] + shift.astype(np.float64), rows[good].astype(np.float64)


def _follow_track(smooth: np.ndarray, peak_col: np.ndarray, lit: np.ndarray, max_jump: float) -> None:
    """Moves, in place, each peak of ``peak_col`` on the scan lines ``lit`` that lies further
    than ``max_jump`` from the running median of its neighbours' peaks onto the strongest
    peak of ``smooth`` within ``max_jump`` of that median."""
    cols = peak_col[lit].astype(np.float64)
    half = _TRACK_HALF
    # A peak within max_jump of all its neighbours is within max_jump of their median: only
    # the others need the median. (Running max and min as a dilation and erosion.)
    row = cols.astype(np.float32)[None, :]
    span = np.ones((1, 2 * half + 1), np.uint8)
    highest = cv2.dilate(row, span, borderType=cv2.BORDER_REPLICATE)[0]
    lowest = cv2.erode(row, span, borderType=cv2.BORDER_REPLICATE)[0]
    maybe = np.nonzero(np.maximum(highest - cols, cols - lowest) > max_jump)[0]
    if not len(maybe):
        return
    padded = np.concatenate([np.full(half, cols[0]), cols, np.full(half, cols[-1])])
    neighbours = padded[maybe[:, None] + np.arange(2 * half + 1)]
    predicted = np.partition(neighbours, half, axis=1)[:, half]  # the median of 2·half + 1
    stray = np.abs(cols[maybe] - predicted) > max_jump
    if not stray.any():
        return
    r = lit[maybe[stray]]
    jump = int(np.ceil(max_jump))
    band = np.clip(
        np.rint(predicted[stray]).astype(np.intp)[:, None] + np.arange(-jump, jump + 1), 0, smooth.shape[1] - 1
    )
    peak_col[r] = band[np.arange(len(r)), smooth[r[:, None], band].argmax(axis=1)]
