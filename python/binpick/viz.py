"""PNG pictures of what the cell saw and did (matplotlib, Agg backend: no display needed).

* :func:`save_cloud` — a scanned cloud from above and in 3-D, coloured by height, with the
  estimated part (the model's points at the found pose) overlaid in red.
* :func:`save_instances` — the same with every instance found drawn, numbered and labelled.
* :func:`save_pick_summary` — per pick: score, pose error against ground truth (when known)
  and where the time went.
* :func:`save_contact_sheet` — a few frames of a scan side by side.
* :func:`save_failure` — a failed pick: the cloud, the parts passed over and the gripper poses
  refused for each, by reason.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ._validate import (
    MAX_IMAGE_PIXELS,
    MAX_IMAGE_SIDE,
    MAX_SHEET_TILES,
    as_box,
    as_image,
    as_indices,
    as_path,
    as_points,
    as_transform,
    count,
    instance_of,
)
from .errors import FileWriteError, InvalidInputError
from .models import Model

__all__ = [
    "save_cloud",
    "save_instances",
    "save_pick_summary",
    "save_contact_sheet",
    "save_failure",
    "save_record_failure",
    "error_axis_top",
]

_MAX_POINTS = 60_000
_CLIP = 20.0
"""Pose-error bars are cut at this height (° or mm) and labelled with their value."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _picture_path(path: str | os.PathLike[str], writable: Any) -> Path:
    """``path`` as a Path (:func:`as_path`), or InvalidInputError naming it when it ends in an
    extension ``writable`` (``Path → bool``) refuses."""
    p = as_path(path)
    if not writable(p):
        raise InvalidInputError(
            f"path: {p} ends in {p.suffix!r:.20}, not a picture format binpick writes; end it in .png"
        )
    return p


def _matplotlib_writes(p: Path) -> bool:
    """Whether matplotlib writes ``p`` by itself (no extension: PNG; .pgf needs LaTeX)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    suffix = p.suffix[1:].lower()
    return not suffix or (suffix != "pgf" and suffix in FigureCanvasAgg.get_supported_filetypes())


def _save(fig: Any, path: str | os.PathLike[str]) -> Path:
    try:
        p = _picture_path(path, _matplotlib_writes)
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=110)
    except OSError as exc:
        raise FileWriteError(f"{path}: cannot write the picture ({exc})") from None
    finally:
        _pyplot().close(fig)
    return p


def _thin(points: np.ndarray, limit: int, seed: int = 0) -> np.ndarray:
    if len(points) <= limit:
        return points
    return points[np.random.default_rng(seed).choice(len(points), limit, replace=False)]


def _scene(points: Any, bin_bounds: Any, title: Any) -> tuple[np.ndarray, Optional[tuple[np.ndarray, np.ndarray]]]:
    """A picture's cloud (N ≥ 1, 3) and bin box (None when not given), the title checked to be text."""
    instance_of(title, str, "title")
    return as_points(points, "points", min_points=1), None if bin_bounds is None else as_box(bin_bounds, "bin_bounds")


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
    pts, box = _scene(points, bin_bounds, title)
    overlays = []
    if model is not None:
        instance_of(model, Model, "model", "binpick.parts.tee()")
        if T_base_object is None:
            raise InvalidInputError("T_base_object: give the pose at which to draw the model")
        overlays = [(_posed(model, T_base_object, "T_base_object"), "red", "estimated part")]
    idx = [] if highlight is None else [as_indices(highlight, "highlight")]
    return _save(_cloud_figure(pts, overlays, idx, box, title), path)


def save_instances(
    path: str | os.PathLike[str],
    points: Any,
    model: Any,
    poses: Sequence[Any],
    *,
    labels: Sequence[str] = (),
    highlights: Sequence[Any] = (),
    bin_bounds: Any = None,
    title: str = "",
) -> Path:
    """Writes the cloud (N, 3, mm) as :func:`save_cloud` does with every instance found of
    ``model`` drawn at its pose (``poses``, 4×4 ``T_scene_model`` each) in a colour of its own,
    numbered from 1 at its centre in the top view and named in the legend with its ``labels``
    entry (one per pose, e.g. its confidence); ``highlights`` (indices into ``points``, one array
    per pose) marks the points each used. Returns the path."""
    return _save(_instances_figure(points, model, poses, labels, highlights, bin_bounds, title), path)


def _instances_figure(
    points: Any,
    model: Any,
    poses: Sequence[Any],
    labels: Sequence[str],
    highlights: Sequence[Any],
    bin_bounds: Any,
    title: str,
) -> Any:
    """The figure of :func:`save_instances`."""
    pts, box = _scene(points, bin_bounds, title)
    poses, labels, highlights = list(poses), list(labels), list(highlights)
    if not poses:
        raise InvalidInputError("poses: give the pose of at least one instance to draw")
    for name, given in (("labels", labels), ("highlights", highlights)):
        if given and len(given) != len(poses):
            raise InvalidInputError(f"{name}: expected one per pose ({len(poses)}), got {len(given)}")
    overlays = [
        (_posed(model, T, f"poses[{i}]"), _INSTANCE_COLORS[i % len(_INSTANCE_COLORS)], f"{i + 1}: {label}".rstrip(": "))
        for i, (T, label) in enumerate(zip(poses, labels or [""] * len(poses)))
    ]
    idx = [as_indices(h, f"highlights[{i}]") for i, h in enumerate(highlights)]
    return _cloud_figure(pts, overlays, idx, box, title, numbered=True)


_INSTANCE_COLORS = ("red", "magenta", "cyan", "blue", "lime", "black", "gold", "brown")
"""The colours of the instances :func:`save_instances` draws (orange marks the points used)."""


def _posed(model: Any, T: Any, name: str) -> np.ndarray:
    """Up to 4000 of ``model``'s surface points at the pose ``T``."""
    instance_of(model, Model, "model", "binpick.parts.tee()")
    T = as_transform(T, name)
    return _thin(np.asarray(model.points) @ T[:3, :3].T + T[:3, 3], 4000)


def _cloud_figure(
    pts: np.ndarray,
    overlays: Sequence[tuple[np.ndarray, str, str]],
    highlights: Sequence[np.ndarray],
    box: Any,
    title: str,
    *,
    numbered: bool = False,
) -> Any:
    """The cloud from above and in 3-D with ``overlays`` (model points, colour, legend label)
    drawn over it, numbered at their centres when ``numbered``, and the points ``highlights``."""
    plt = _pyplot()
    fig = plt.figure(figsize=(13, 5.6))
    shown = _thin(pts, _MAX_POINTS)
    top = fig.add_subplot(1, 2, 1)
    sc = top.scatter(shown[:, 0], shown[:, 1], c=shown[:, 2], s=0.6, cmap="viridis", linewidths=0)
    for k, idx in enumerate(highlights):
        h = _thin(pts[idx[(idx >= 0) & (idx < len(pts))]], 8000)
        top.scatter(h[:, 0], h[:, 1], s=0.8, c="orange", linewidths=0, label=None if k else "points used")
    for number, (body, color, label) in enumerate(overlays, 1):
        top.scatter(body[:, 0], body[:, 1], s=0.8, c=color, linewidths=0, label=label)
        if numbered:
            x, y = body[:, :2].mean(axis=0)
            top.annotate(str(number), (x, y), fontsize=11, weight="bold", color="black", ha="center", va="center")
    if box is not None:
        (x0, y0, _), (x1, y1, _) = box
        top.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "k--", linewidth=0.8, label="bin")
    top.set_aspect("equal")
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_title("from above, coloured by height")
    fig.colorbar(sc, ax=top, label="z (mm)", shrink=0.8)
    if overlays or highlights or box is not None:
        top.legend(loc="upper right", markerscale=8, fontsize=8)
    ax = fig.add_subplot(1, 2, 2, projection="3d")
    s3 = _thin(pts, 25_000)
    ax.scatter(s3[:, 0], s3[:, 1], s3[:, 2], c=s3[:, 2], s=0.4, cmap="viridis", linewidths=0)
    for body, color, _ in overlays:
        ax.scatter(body[:, 0], body[:, 1], body[:, 2], c=color, s=0.6, linewidths=0)
    span = np.ptp(s3, axis=0)
    ax.set_box_aspect((max(span[0], 1), max(span[1], 1), max(span[2], 1)))
    ax.view_init(elev=35, azim=-60)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title("3-D")
    fig.suptitle(title or f"{len(pts)} points")
    fig.tight_layout()
    return fig


#: How far from a rotation (|RᵀR − I|) a pose read back from JSON may be and still be drawn.
_JSON_ROUNDING = 1e-4


def _json_pose(T: Any, name: str) -> np.ndarray:
    """A pose to draw, as :func:`as_transform` checks it, once its rotation block is snapped to the
    nearest rotation when it is within :data:`_JSON_ROUNDING` of one: a pose rounded as the
    records keep it (6 decimals) is a rotation only to about 1e-6, the checks' own tolerance."""
    arr = np.array(T, dtype=np.float64) if isinstance(T, (list, tuple, np.ndarray)) else T
    if isinstance(arr, np.ndarray) and arr.shape == (4, 4) and np.isfinite(arr).all():
        R = arr[:3, :3]
        if float(np.abs(R.T @ R - np.eye(3)).max()) < _JSON_ROUNDING and np.linalg.det(R) > 0:
            u, _, vt = np.linalg.svd(R)
            arr[:3, :3] = u @ vt
    return as_transform(arr, name)


def error_axis_top(errors: Sequence[float]) -> float:
    """The top of the pose-error axis of :func:`save_pick_summary` for ``errors`` (° and mm; NaN
    where a pick has no ground truth): a quarter above the tallest bar (bars are cut at
    :data:`_CLIP`) and never below the pick-grade limits' lines, which are drawn on it."""
    from .cell.records import PICK_GRADE_DEG, PICK_GRADE_MM

    values = np.asarray(errors, dtype=np.float64)
    values = values[np.isfinite(values)]
    tallest = min(float(values.max()), _CLIP) if len(values) else 0.0
    return 1.25 * max(tallest, PICK_GRADE_DEG, PICK_GRADE_MM)


def save_pick_summary(path: str | os.PathLike[str], records: Sequence[Any], *, title: str = "") -> Path:
    """Writes a per-pick summary of :class:`binpick.cell.PickRecord` s: score, pose error against
    ground truth where known (with the pick-grade limits 5° and 3 mm; the axis as tall as
    :func:`error_axis_top` says), and the time per stage."""
    from .cell.records import PICK_GRADE_DEG, PICK_GRADE_MM, PickRecord

    recs = list(records)
    if not recs:
        raise InvalidInputError("records: no picks to summarise")
    for i, r in enumerate(recs):
        instance_of(r, PickRecord, f"records[{i}]", "the records of Cell.run's report")
    instance_of(title, str, "title")
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4))
    x = np.arange(1, len(recs) + 1)
    colors = ["tab:green" if r.success else "tab:gray" if r.bin_empty else "tab:red" for r in recs]
    scores = [r.score if r.score is not None else 0.0 for r in recs]
    axes[0].bar(x, scores, color=colors)
    axes[0].set_ylim(0, 1.05)
    axes[0].set_xticks(x)
    axes[0].set_xlabel("pick")
    axes[0].set_ylabel("score")
    axes[0].set_title(
        "pose score (green: picked, red: failed" + (", grey: bin empty)" if any(r.bin_empty for r in recs) else ")")
    )
    rot = [r.truth.rotation_error_deg if r.truth is not None else np.nan for r in recs]
    tra = [r.truth.translation_error_mm if r.truth is not None else np.nan for r in recs]
    if np.isfinite(rot).any():
        w = 0.38
        for offset, vals, label, color in (
            (-w / 2, rot, "rotation (°)", "tab:blue"),
            (w / 2, tra, "translation (mm)", "tab:orange"),
        ):
            axes[1].bar(x + offset, np.minimum(vals, _CLIP), w, label=label, color=color)
            for xi, v in zip(x, vals):
                if np.isfinite(v) and v > _CLIP:  # the bar is cut at the top: say how tall it is
                    axes[1].text(xi + offset, _CLIP, f"{v:.0f}", ha="center", va="bottom", fontsize=7, rotation=90)
        axes[1].set_ylim(0, error_axis_top(rot + tra))
        axes[1].axhline(PICK_GRADE_DEG, color="tab:blue", linestyle="--", linewidth=0.8)
        axes[1].axhline(PICK_GRADE_MM, color="tab:orange", linestyle="--", linewidth=0.8)
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
    if bottom.any():
        axes[2].legend(fontsize=7)
    fig.suptitle(title or f"{sum(r.success for r in recs)} of {len(recs)} picks succeeded")
    fig.tight_layout()
    return _save(fig, path)


def save_contact_sheet(
    path: str | os.PathLike[str],
    frames_bgr: Sequence[np.ndarray],
    *,
    numbers: Optional[Sequence[int]] = None,
    columns: int = 3,
    width: int = 1200,
) -> Path:
    """Writes frames (uint8 BGR, as grabbed, all of one size) tiled ``columns`` wide, each
    labelled with its frame number in the scan (``numbers``; default 0, 1, …). Each frame goes
    through a maximum filter twice as wide as the shrink factor before it is shrunk, so that the
    laser line, a pixel or two wide, keeps its full brightness in the tile (a plain area average
    would dim it by the shrink factor) and shows about two tile pixels wide."""
    import cv2

    frames = [as_image(f, f"frames_bgr[{i}]", color=True) for i, f in enumerate(frames_bgr)]
    if not frames or any(f.shape != frames[0].shape for f in frames):
        raise InvalidInputError("frames_bgr: expected one or more uint8 BGR images (H, W, 3) of one size")
    labels = list(range(len(frames))) if numbers is None else [count(n, f"numbers[{i}]") for i, n in enumerate(numbers)]
    if len(labels) != len(frames):
        raise InvalidInputError(f"numbers: expected one frame number per frame ({len(frames)}), got {len(labels)}")
    cols = count(columns, "columns", 1, MAX_SHEET_TILES)
    h, w = frames[0].shape[:2]
    tw = max(1, count(width, "width", cols, MAX_IMAGE_SIDE) // cols)
    th = max(1, int(round(h * tw / w)))
    k = 2 * max(1, int(np.ceil(w / tw))) + 1  # wide enough to cover a whole tile pixel wherever it falls
    kernel = np.ones((k, k), dtype=np.uint8)
    rows = int(np.ceil(len(frames) / cols))
    if rows * th * cols * tw > MAX_IMAGE_PIXELS:
        raise InvalidInputError(
            f"width: {len(frames)} frames of {w}×{h} tiled {cols} wide at {width} px make a sheet of "
            f"{cols * tw}×{rows * th} pixels, more than {MAX_IMAGE_PIXELS}; pass a smaller width or fewer frames"
        )
    sheet = np.zeros((rows * th, cols * tw, 3), dtype=np.uint8)
    for i, (frame, label) in enumerate(zip(frames, labels)):
        tile = cv2.resize(cv2.dilate(np.ascontiguousarray(frame), kernel), (tw, th), interpolation=cv2.INTER_AREA)
        cv2.putText(tile, f"frame {label}", (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2)
        r, c = divmod(i, cols)
        sheet[r * th : (r + 1) * th, c * tw : (c + 1) * tw] = tile
    p = _picture_path(path, lambda p: cv2.haveImageWriter(str(p)))
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        written = cv2.imwrite(str(p), sheet)
    except OSError as exc:
        raise FileWriteError(f"{p}: cannot write the contact sheet ({exc})") from None
    if not written:
        raise FileWriteError(f"{p}: cannot write the contact sheet")
    return p


_REASON_COLORS = ("tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")


def save_record_failure(path: str | os.PathLike[str], record: Any, *, model: Any, bin_bounds: Any, title: str) -> Path:
    """:func:`save_failure` of a failed :class:`binpick.cell.PickRecord`: its last scan, the
    parts it passed over, the pose it went for and what it touched; ``title`` cut to 140 characters."""
    return save_failure(
        path,
        record.scan.points,
        model=model,
        skipped=record.skipped,
        located=record.T_base_object,
        bin_bounds=bin_bounds,
        title=title if len(title) < 140 else title[:137] + "...",
        collisions=record.collisions,
    )


def save_failure(
    path: str | os.PathLike[str],
    points: Any,
    *,
    model: Any,
    skipped: Sequence[Any] = (),
    located: Any = None,
    bin_bounds: Any = None,
    title: str = "",
    collisions: Sequence[Any] = (),
) -> Path:
    """Writes the picture of a failed pick: the cloud (N, 3, mm) from above and from the side,
    each part passed over (:class:`binpick.cell.records.Skipped`: the model at its located pose,
    numbered, with its reason; once, however many looks passed it over) and the gripper poses
    refused for it, one colour per reason (a dot at the TCP and a line 30 mm back along the
    approach); ``located`` (a pose ``T_base_object``) adds the part the failed attempt went for,
    in black; each of ``collisions`` (:attr:`binpick.cell.PickRecord.collisions`) the gripper where
    it first touched something, in red (a cross at the TCP, a line 60 mm back along the approach)."""
    from .cell.records import Skipped

    pts, box = _scene(points, bin_bounds, title)
    model_pts = np.asarray(instance_of(model, Model, "model", "binpick.parts.tee()").points)
    skipped = [instance_of(k, Skipped, f"skipped[{i}]", "a PickRecord's skipped") for i, k in enumerate(skipped)]
    plt = _pyplot()
    fig, (top, side) = plt.subplots(1, 2, figsize=(14, 6), gridspec_kw={"width_ratios": [3, 2]})
    shown = _thin(pts, _MAX_POINTS)
    for ax, (i, j) in ((top, (0, 1)), (side, (0, 2))):
        ax.scatter(shown[:, i], shown[:, j], c=shown[:, 2], s=0.5, cmap="viridis", linewidths=0, alpha=0.6)
    colors: dict[str, str] = {}
    notes = []
    parts: list = []
    seen: list[int] = []
    for k in skipped:  # a part passed over in several looks is drawn once, with its count
        T = as_transform(k.T_base_object, "skipped.T_base_object")
        same = [i for i, p in enumerate(parts) if np.linalg.norm(p[1][:3, 3] - T[:3, 3]) < 10.0]
        if same:
            seen[same[0]] += 1
        else:
            parts.append((len(parts) + 1, T, k.reason, k.refused))
            seen.append(1)
    parts = [(n, T, reason + (f" (in {c} looks)" if c > 1 else ""), r) for (n, T, reason, r), c in zip(parts, seen)]
    if located is not None:
        parts.append((0, as_transform(located, "located"), "the part this pick went for", {}))
    for number, T, reason, refused in parts:
        T = as_transform(T, "T_base_object")
        body = _thin(model_pts @ T[:3, :3].T + T[:3, 3], 1500)
        tone = "black" if number == 0 else "tab:orange"
        for ax, (i, j) in ((top, (0, 1)), (side, (0, 2))):
            ax.scatter(body[:, i], body[:, j], s=0.7, c=tone, linewidths=0)
        if number:
            top.annotate(str(number), T[:2, 3], fontsize=11, weight="bold", color="black", ha="center", va="center")
            notes.append(f"{number}: {reason}")
        for why, poses in refused.items():
            color = colors.setdefault(why, _REASON_COLORS[len(colors) % len(_REASON_COLORS)])
            poses = np.asarray(poses).reshape(-1, 4, 4)
            tcp, back = poses[:, :3, 3], poses[:, :3, 3] - 30.0 * poses[:, :3, 2]
            for ax, (i, j) in ((top, (0, 1)), (side, (0, 2))):
                ax.plot(np.stack([tcp[:, i], back[:, i]]), np.stack([tcp[:, j], back[:, j]]), color=color, lw=0.8)
                ax.scatter(tcp[:, i], tcp[:, j], s=6, color=color)
    top.scatter([], [], s=8, c="tab:green", label="scan points (colour: height)")
    if any(n for n, *_ in parts):
        top.scatter([], [], s=8, c="tab:orange", label="parts passed over (numbered, why below)")
    if located is not None:
        top.scatter([], [], s=8, c="black", label="the part this pick went for")
    for why, color in colors.items():
        top.plot([], [], color=color, label=f"refused grasps: {why}")
    for c in collisions:
        T = _json_pose(c["T_base_gripper"], "collisions.T_base_gripper")
        tcp, back = T[:3, 3], T[:3, 3] - 60.0 * T[:3, 2]
        for ax, (i, j) in ((top, (0, 1)), (side, (0, 2))):
            ax.plot([tcp[i], back[i]], [tcp[j], back[j]], color="red", lw=1.5)
            ax.scatter([tcp[i]], [tcp[j]], s=60, marker="x", color="red")
        top.plot([], [], color="red", marker="x", label=f"gripper at its first touch of {c['with']}")
    if box is not None:
        (x0, y0, z0), (x1, y1, z1) = box
        top.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "k--", linewidth=0.8, label="bin")
        side.plot([x0, x0, x1, x1], [z1, z0, z0, z1], "k--", linewidth=0.8)
    for ax, ylabel, name in ((top, "y (mm)", "from above"), (side, "z (mm)", "from the side (−y)")):
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel(ylabel)
        ax.set_title(name)
    top.legend(loc="upper right", fontsize=7)  # every colour of the picture is named
    if notes:
        fig.text(0.01, 0.01, "\n".join(notes[:8]), fontsize=8, va="bottom", family="monospace")
    fig.suptitle(title or "failed pick")
    fig.tight_layout(rect=(0, 0.04 + 0.022 * min(len(notes), 8), 1, 1))
    return _save(fig, path)
