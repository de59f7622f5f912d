"""PNG pictures of what the cell saw and did (matplotlib, Agg backend: no display needed).

* :func:`save_cloud` — a scanned cloud from above and in 3-D, coloured by height, with the
  estimated part (the model's points at the found pose) overlaid in red.
* :func:`save_pick_summary` — per pick: score, pose error against ground truth (when known)
  and where the time went.
* :func:`save_contact_sheet` — a few frames of a scan side by side.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._validate import as_points, as_transform
from .errors import FileWriteError, InvalidInputError

__all__ = ["save_cloud", "save_pick_summary", "save_contact_sheet"]

_MAX_POINTS = 60_000


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=110)
    except OSError as exc:
        raise FileWriteError(f"{p}: cannot write the picture ({exc})") from None
    finally:
        _pyplot().close(fig)
    return p


def _thin(points: np.ndarray, limit: int, seed: int = 0) -> np.ndarray:
    if len(points) <= limit:
        return points
    return points[np.random.default_rng(seed).choice(len(points), limit, replace=False)]


def save_cloud(
    path: str | os.PathLike[str],
    points: Any,
    *,
    model: Any = None,
    T_base_object: Any = None,
    highlight: Any = None,
    bin_bounds: Any = None,
    title: str = "",
) -> Path:
    """Writes the cloud (N, 3, mm) seen from above (x, y coloured by z) and in 3-D.

    With ``model`` (a :class:`binpick.Model`) and ``T_base_object``, the model's surface points at
    that pose are drawn in red over the cloud; ``highlight`` (indices into ``points``) marks the
    points the estimate used; ``bin_bounds`` outlines the bin. Returns the path.
    """
    pts = as_points(points, "points", min_points=1)
    overlay = None
    if model is not None:
        if T_base_object is None:
            raise InvalidInputError("T_base_object: give the pose at which to draw the model")
        T = as_transform(T_base_object, "T_base_object")
        overlay = _thin(np.asarray(model.points) @ T[:3, :3].T + T[:3, 3], 4000)
    plt = _pyplot()
    fig = plt.figure(figsize=(13, 5.6))
    shown = _thin(pts, _MAX_POINTS)
    top = fig.add_subplot(1, 2, 1)
    sc = top.scatter(shown[:, 0], shown[:, 1], c=shown[:, 2], s=0.6, cmap="viridis", linewidths=0)
    if highlight is not None:
        idx = np.asarray(highlight, dtype=np.int64)
        idx = idx[(idx >= 0) & (idx < len(pts))]
        h = _thin(pts[idx], 8000)
        top.scatter(h[:, 0], h[:, 1], s=0.8, c="orange", linewidths=0, label="points used")
    if overlay is not None:
        top.scatter(overlay[:, 0], overlay[:, 1], s=0.8, c="red", linewidths=0, label="estimated part")
    if bin_bounds is not None:
        (x0, y0, _), (x1, y1, _) = np.asarray(bin_bounds, dtype=float)
        top.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "k--", linewidth=0.8, label="bin")
    top.set_aspect("equal")
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_title("from above, coloured by height")
    fig.colorbar(sc, ax=top, label="z (mm)", shrink=0.8)
    if overlay is not None or highlight is not None or bin_bounds is not None:
        top.legend(loc="upper right", markerscale=8, fontsize=8)
    ax = fig.add_subplot(1, 2, 2, projection="3d")
    s3 = _thin(pts, 25_000)
    ax.scatter(s3[:, 0], s3[:, 1], s3[:, 2], c=s3[:, 2], s=0.4, cmap="viridis", linewidths=0)
    if overlay is not None:
        ax.scatter(overlay[:, 0], overlay[:, 1], overlay[:, 2], c="red", s=0.6, linewidths=0)
    span = np.ptp(s3, axis=0)
    ax.set_box_aspect((max(span[0], 1), max(span[1], 1), max(span[2], 1)))
    ax.view_init(elev=35, azim=-60)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title("3-D")
    fig.suptitle(title or f"{len(pts)} points")
    fig.tight_layout()
    return _save(fig, path)


def save_pick_summary(path: str | os.PathLike[str], records: Sequence[Any], *, title: str = "") -> Path:
    """Writes a per-pick summary of :class:`binpick.cell.PickRecord` s: score, pose error against
    ground truth where known (with the pick-grade limits 5° and 3 mm), and the time per stage."""
    recs = list(records)
    if not recs:
        raise InvalidInputError("records: no picks to summarise")
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4))
    x = np.arange(1, len(recs) + 1)
    colors = ["tab:green" if r.success else "tab:red" for r in recs]
    scores = [r.score if r.score is not None else 0.0 for r in recs]
    axes[0].bar(x, scores, color=colors)
    axes[0].set_ylim(0, 1.05)
    axes[0].set_xticks(x)
    axes[0].set_xlabel("pick")
    axes[0].set_ylabel("score")
    axes[0].set_title("pose score (green: picked, red: failed)")
    rot = [r.truth.rotation_error_deg if r.truth is not None else np.nan for r in recs]
    tra = [r.truth.translation_error_mm if r.truth is not None else np.nan for r in recs]
    if np.isfinite(rot).any():
        w = 0.38
        axes[1].bar(x - w / 2, np.minimum(rot, 20), w, label="rotation (°)", color="tab:blue")
        axes[1].bar(x + w / 2, np.minimum(tra, 20), w, label="translation (mm)", color="tab:orange")
        axes[1].axhline(5.0, color="tab:blue", linestyle="--", linewidth=0.8)
        axes[1].axhline(3.0, color="tab:orange", linestyle="--", linewidth=0.8)
        axes[1].set_title("pose error vs ground truth (dashed: pick-grade limits)")
        axes[1].legend(fontsize=8)
    else:
        axes[1].text(0.5, 0.5, "no ground truth", ha="center", va="center", transform=axes[1].transAxes)
        axes[1].set_title("pose error")
    axes[1].set_xticks(x)
    axes[1].set_xlabel("pick")
    stages = ["scan.move", "scan.sweep", "scan.extract", "scan.triangulate", "locate+plan", "motion"]
    bottom = np.zeros(len(recs))
    for stage in stages:
        vals = np.array([float(r.timings.get(stage, 0.0)) / 1e3 for r in recs])
        if vals.any():
            axes[2].bar(x, vals, bottom=bottom, label=stage.replace("scan.", "scan: "))
            bottom += vals
    axes[2].set_xticks(x)
    axes[2].set_xlabel("pick")
    axes[2].set_ylabel("seconds")
    axes[2].set_title("time per stage")
    axes[2].legend(fontsize=7)
    fig.suptitle(title or f"{sum(r.success for r in recs)} of {len(recs)} picks succeeded")
    fig.tight_layout()
    return _save(fig, path)


def save_contact_sheet(
    path: str | os.PathLike[str], frames_bgr: Sequence[np.ndarray], *, columns: int = 3, width: int = 1200
) -> Path:
    """Writes frames (uint8 BGR, as grabbed, all of one size) tiled ``columns`` wide."""
    import cv2

    from .sim import contact_sheet

    frames = [np.asarray(f) for f in frames_bgr]
    if not frames or any(
        f.ndim != 3 or f.shape[2] != 3 or f.dtype != np.uint8 or f.shape != frames[0].shape for f in frames
    ):
        raise InvalidInputError("frames_bgr: expected one or more uint8 BGR images (H, W, 3) of one size")
    sheet = contact_sheet(np.stack([f[:, :, ::-1] for f in frames]), picks=len(frames), columns=columns, width=width)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(p), sheet):
        raise FileWriteError(f"{p}: cannot write the contact sheet")
    return p
