"""Whether a camera calibration from checkerboard views can be trusted (issue 38 item 6).

:func:`~binpick.calibration.calibrate_camera` measures its own result and refuses it with
:class:`~binpick.errors.UntrustedCalibrationError` when a figure misses its limit in
:class:`CalibrationLimits`; the figures and the causes found are the :class:`CalibrationQuality`
every result carries. A limit can be moved knowingly (``limits=CalibrationLimits(...)``, on the
command line ``--min-views`` and the like) or the result kept anyway (``accept_untrusted=True``,
``--accept-untrusted``), which still warns.

Why each test: a focal length is told apart from the board's distance only by perspective, so
views must tilt the board (Zhang 2000); lens distortion is only measured where the board's
corners were seen, and extrapolated elsewhere; and OpenCV's estimated standard deviations
(``calibrateCameraExtended``) say how well the views pin the focal length down — except in the
degenerate case of parallel boards, where the focal length and the distance trade freely and
the reported deviation stays small (in binpick's own test, 14 rendered fronto-parallel views at
one distance gave a focal length 15 % off with a reported 1-sigma of 0.04 %). Hence the tilt
test besides the deviation test.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import cv2
import numpy as np

from .._validate import count, number, positive

__all__ = ["CLI_FLAGS", "CalibrationLimits", "CalibrationQuality", "assess"]


@dataclass(frozen=True)
class CalibrationLimits:
    """When a camera calibration is refused: the one place of these limits.

    ``min_views`` (8): views in which the board was found. Each view's homography gives two
    constraints on fx, fy, cx, cy (Zhang 2000), so two views are the bare minimum; eight give
    fourfold redundancy, so that one bad view (a blurred one, a misread corner order) bends the
    result by a fraction of its own error instead of carrying it whole, and so that the
    5 distortion coefficients ``[k1, k2, p1, p2, k3]`` are fitted over several board positions.
    OpenCV's tutorial asks for at least 10 views, Bouguet's toolbox for about 20.

    ``min_found_share`` (0.5): the share of the images given in which the board was found.
    When it was missed in most of them, the views found are the easy ones (near the image's
    centre, little tilt) — those that pin the focal length least — and something in the set-up
    is wrong: the pattern size (inner corners), focus, glare.

    ``min_coverage`` (0.25): the share of the image inside the union of the board's corner
    hulls over all views. Lens distortion grows with the distance from the centre (r², r⁴, r⁶)
    and is measured only where corners were seen; below a quarter of the image, most of it,
    its corners included, is an extrapolation of a sixth-order polynomial.

    ``min_tilt_spread_deg`` (20°): the largest angle between the board planes of two views.
    Parallel boards cannot tell the focal length from the distance (and OpenCV's deviation
    does not see it, see the module doc); in a trial with 14 rendered views (0.08 px RMS) the
    focal length's 1-sigma was 8 % at a 4° spread, 2 % at 8°, 0.9 % at 12°, 0.4 % at 20° and
    0.2 % at 30°. A set whose views tilt the board 20–40° toward each side spreads 40–80°.

    ``max_rms_px`` (0.5 px): the reprojection RMS over all corners. ``cornerSubPix`` locates the
    corners of a sharp, flat board to about 0.1–0.2 px (0.18 px on OpenCV's own sample photos,
    under 0.1 px on binpick's rendered boards); several times that means something other than
    corner noise dominates: blur, a board that is not flat, a wrong square size, a lens the
    five-coefficient model cannot hold, or a fit caught in a wrong minimum (one met in a trial at
    0.66 px put the focal length at 4.5 times the truth).

    ``max_focal_sigma_pct`` (0.5 %): the focal length's estimated 1-sigma (OpenCV's
    ``stdDeviationsIntrinsics``; the larger of fx's and fy's), relative. A focal length off by a
    fraction ε puts a point 150 mm from the optical axis (the edge of a 300 mm bin) ε·150 mm off
    sideways: at 0.5 %, 3 sigma is 2.25 mm, inside the 3 mm of a pick-grade pose.
    """

    min_views: int = 8
    min_found_share: float = 0.5
    min_coverage: float = 0.25
    min_tilt_spread_deg: float = 20.0
    max_rms_px: float = 0.5
    max_focal_sigma_pct: float = 0.5

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "min_views", count(self.min_views, "min_views", 1))
        set_(self, "min_found_share", number(self.min_found_share, "min_found_share", 0.0, 1.0))
        set_(self, "min_coverage", number(self.min_coverage, "min_coverage", 0.0, 1.0))
        set_(self, "min_tilt_spread_deg", number(self.min_tilt_spread_deg, "min_tilt_spread_deg", 0.0, 90.0, "°"))
        set_(self, "max_rms_px", positive(self.max_rms_px, "max_rms_px", "px"))
        set_(self, "max_focal_sigma_pct", positive(self.max_focal_sigma_pct, "max_focal_sigma_pct", "%"))


#: The ``binpick calibrate`` flag that sets each limit (and keeps an untrusted result).
CLI_FLAGS = {
    "min_views": "--min-views",
    "min_found_share": "--min-found-share",
    "min_coverage": "--min-coverage",
    "min_tilt_spread_deg": "--min-tilt-spread",
    "max_rms_px": "--max-rms",
    "max_focal_sigma_pct": "--max-focal-sigma",
    "accept_untrusted": "--accept-untrusted",
}


@dataclass(frozen=True, eq=False)
class CalibrationQuality:
    """How far a camera calibration can be trusted: its figures, the limits it was judged by and
    ``problems``, one sentence per limit missed naming the cause, the fix and the flag (empty:
    ``trusted``).

    ``images``: images given; ``views``: images where the board was found; ``coverage``: share
    of the image inside the union of the board's corner hulls; ``tilt_spread_deg``: largest
    angle between two views' board planes; ``max_tilt_deg``: largest angle between a board's
    normal and the optical axis; ``rms_px``: reprojection RMS; ``focal_sigma_pct``: the focal
    length's estimated 1-sigma, % (the larger of fx's and fy's; ``nan`` when not estimated);
    ``std_intrinsics``: OpenCV's 1-sigma of fx, fy, cx, cy (px) and k1, k2, p1, p2, k3."""

    images: int
    views: int
    coverage: float
    tilt_spread_deg: float
    max_tilt_deg: float
    rms_px: float
    focal_sigma_pct: float
    std_intrinsics: np.ndarray
    limits: CalibrationLimits = field(default_factory=CalibrationLimits)
    problems: tuple[str, ...] = ()

    @property
    def trusted(self) -> bool:
        """Whether every figure is within its limit."""
        return not self.problems

    @property
    def found_share(self) -> float:
        """The share of the images given in which the board was found."""
        return self.views / self.images if self.images else 0.0

    def as_dict(self) -> dict:
        """The figures, the limits and the problems, for a JSON or TOML file."""
        return {
            "trusted": self.trusted,
            "images": self.images,
            "views": self.views,
            "found_share": round(self.found_share, 4),
            "coverage": round(self.coverage, 4),
            "tilt_spread_deg": round(self.tilt_spread_deg, 3),
            "max_tilt_deg": round(self.max_tilt_deg, 3),
            "rms_px": round(self.rms_px, 4),
            "focal_sigma_pct": round(self.focal_sigma_pct, 5) if math.isfinite(self.focal_sigma_pct) else None,
            "std_intrinsics": [float(v) for v in self.std_intrinsics],
            "limits": asdict(self.limits),
            "warnings": list(self.problems),
        }

    def toml(self, table: str = "quality.camera") -> str:
        """The figures, the problems (``warnings``) and the limits as TOML tables ``[table]`` and
        ``[table.limits]``."""
        doc = self.as_dict()
        limits = doc.pop("limits")
        lines = [f"[{table}]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in doc.items()]
        lines += ["", f"[{table}.limits]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in limits.items()]
        return "\n".join(lines) + "\n"

    def summary(self) -> str:
        """One line of the figures against their limits."""
        lim = self.limits
        return (
            f"board found in {self.views} of {self.images} images (at least {lim.min_views}, "
            f"{lim.min_found_share:.0%}), coverage {self.coverage:.0%} (≥ {lim.min_coverage:.0%}), "
            f"tilt spread {self.tilt_spread_deg:.1f}° (≥ {lim.min_tilt_spread_deg:g}°), "
            f"RMS {self.rms_px:.3f} px (≤ {lim.max_rms_px:g}), focal 1-sigma {self.focal_sigma_pct:.3f} % "
            f"(≤ {lim.max_focal_sigma_pct:g} %): {'trusted' if self.trusted else 'NOT TRUSTED'}"
        )

    def message(self) -> str:
        """Why the calibration is refused: each cause with its fix, and how to keep it knowingly."""
        causes = "\n".join(f"  - {p}" for p in self.problems)
        return (
            f"images: this camera calibration cannot be trusted:\n{causes}\n"
            f"  To keep it knowingly pass {CLI_FLAGS['accept_untrusted']} (it still warns), or move a limit "
            "with the flag named (Python: accept_untrusted=True, limits=CalibrationLimits(...))."
        )


def _toml_value(v: object) -> str:
    if v is None:  # a figure not estimated
        return "nan"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string (\uXXXX escapes) is a TOML basic string
    return repr(v) if isinstance(v, int) or math.isfinite(v) else "nan"


#: Longest side of the mask the coverage is drawn on, px (a share of the image to about 0.5 %).
_COVERAGE_MASK_PX = 400


def _coverage(corners: list[np.ndarray], width: int, height: int) -> float:
    """The share of the image inside the union of each view's corner hull."""
    scale = min(1.0, _COVERAGE_MASK_PX / max(width, height))
    mask = np.zeros((max(1, round(height * scale)), max(1, round(width * scale))), np.uint8)
    for c in corners:
        hull = cv2.convexHull((np.asarray(c, np.float64).reshape(-1, 2) * scale).astype(np.float32))
        cv2.fillConvexPoly(mask, np.round(hull.reshape(-1, 2)).astype(np.int32), 1)
    return float(mask.mean())


def _tilts(rotations: list[np.ndarray]) -> tuple[float, float]:
    """(largest angle between two board planes, largest angle between a board normal and the
    optical axis), degrees."""
    normals = np.array([R[:, 2] for R in rotations])
    cos = np.clip(np.abs(normals @ normals.T), 0.0, 1.0)
    spread = math.degrees(math.acos(float(cos.min())))
    tilt = math.degrees(math.acos(float(np.clip(np.abs(normals[:, 2]), 0.0, 1.0).min())))
    return spread, tilt


def _flag(name: str) -> str:
    return f"[{CLI_FLAGS[name]}]"


def assess(
    *,
    images: int,
    corners: list[np.ndarray],
    size: tuple[int, int],
    rotations: list[np.ndarray],
    rms: float,
    K: np.ndarray,
    std_intrinsics: np.ndarray,
    per_view_rms: np.ndarray,
    view_ids: np.ndarray,
    limits: CalibrationLimits,
) -> CalibrationQuality:
    """The :class:`CalibrationQuality` of a calibration from ``corners`` found in ``images``
    images of ``size`` (width, height) — in the images ``view_ids`` (counted from 0), with the
    board rotations ``rotations`` (camera frame) and reprojection RMS ``per_view_rms`` there."""
    width, height = size
    views = len(corners)
    coverage = _coverage(corners, width, height)
    spread, max_tilt = _tilts(rotations)
    std = np.ravel(std_intrinsics)[:9].astype(np.float64)
    sigma = 100.0 * max(std[0] / K[0, 0], std[1] / K[1, 1]) if len(std) >= 2 else math.nan
    lim, problems = limits, []
    add_views = "add views of the whole board tilted 20–40° toward each image corner"
    if views < lim.min_views:
        problems.append(
            f"the board was found in only {views} views; at least {lim.min_views} are needed to pin down fx, fy, "
            f"cx, cy and the 5 distortion coefficients — {add_views} {_flag('min_views')}"
        )
    share = views / images
    if share < lim.min_found_share:
        problems.append(
            f"the board was found in {views} of {images} images ({share:.0%}, less than {lim.min_found_share:.0%}): "
            "the views found are the easy ones — check the pattern size (inner corners), focus and glare in the "
            f"images it was missed in {_flag('min_found_share')}"
        )
    if coverage < lim.min_coverage:
        problems.append(
            f"the board's corners cover {coverage:.0%} of the image (at least {lim.min_coverage:.0%} needed): the lens "
            "distortion is extrapolated over the rest — add views with the board near each image corner and edge "
            f"{_flag('min_coverage')}"
        )
    if spread < lim.min_tilt_spread_deg:
        problems.append(
            f"the board's planes differ by at most {spread:.1f}° across the views (at least "
            f"{lim.min_tilt_spread_deg:g}° needed): the views are too alike to tell the focal length from the "
            f"board's distance — {add_views} {_flag('min_tilt_spread_deg')}"
        )
    if not rms <= lim.max_rms_px:
        worst = np.argsort(per_view_rms)[::-1][:3]
        problems.append(
            f"the reprojection RMS is {rms:.3f} px (at most {lim.max_rms_px:g} px): the corners do not fit the camera "
            "model — check for blur, a board that is not flat and the square size; the worst are images "
            + ", ".join(f"{int(view_ids[i])} ({per_view_rms[i]:.2f} px)" for i in worst)
            + f" (counted from 0) {_flag('max_rms_px')}"
        )
    if not sigma <= lim.max_focal_sigma_pct:
        problems.append(
            f"the focal length's estimated 1-sigma is {sigma:.2f} % (at most {lim.max_focal_sigma_pct:g} %): the views "
            f"do not pin it down — {add_views} {_flag('max_focal_sigma_pct')}"
        )
    return CalibrationQuality(
        images=images,
        views=views,
        coverage=coverage,
        tilt_spread_deg=spread,
        max_tilt_deg=max_tilt,
        rms_px=float(rms),
        focal_sigma_pct=float(sigma),
        std_intrinsics=std,
        limits=limits,
        problems=tuple(problems),
    )
