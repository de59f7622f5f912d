"""Scene clouds from the files integrators have: PLY, PCD (as PCL writes it), NPY and XYZ.

:func:`read_scene` reads any of them into an (N, 3) float64 array in millimetres;
:func:`write_scene` writes one, the format chosen by the file's extension.

Formats read:

- PLY (ASCII or binary; :func:`binpick.read_ply`, which refuses a non-finite vertex as a
  corrupt file rather than dropping it).
- PCD, versions 0.5–0.7 (0.6 and older have no VIEWPOINT, 0.5 may lack COUNT): any FIELDS with
  SIZE/TYPE/COUNT (float of 4 or 8 bytes, signed and unsigned integers of 1, 2, 4 or 8 bytes,
  COUNT > 1), organized (HEIGHT > 1) or not, DATA ``ascii``, ``binary`` (packed records, row by
  row) and ``binary_compressed`` (uint32 compressed size, uint32 uncompressed size, then the
  LZF-compressed fields laid out one after the other, each for every point: structure of arrays).
- NPY: (N, 3) or an organized (H, W, 3) array of numbers.
- XYZ (also .txt, .asc, .pts): text, one point per line as ``x y z`` (spaces, tabs or commas),
  further columns ignored, blank lines and lines starting with ``#`` or ``//`` skipped.

A file may say its length unit in a comment (``# unit: m`` in XYZ or PCD, ``comment unit: m`` in
PLY); its points are then converted to millimetres. Where the file says where the sensor was
(:attr:`SceneCloud.viewpoint`, the ``viewpoint`` of :func:`binpick.estimate_pose`): PCD's VIEWPOINT
when it is not PCL's default (the origin, unturned), and for an organized cloud (a camera's image,
in the camera's frame) the default too; the origin for an organized NPY array; a ``viewpoint: x y z``
comment in XYZ, PLY or PCD (as :func:`write_scene` writes it). A file that says nothing is taken as mm
unless the caller says otherwise. Points with a NaN or infinite coordinate (the holes of an
organized cloud) are dropped (PLY excepted, above) and counted in :attr:`SceneCloud.dropped`.

Nothing in a header is trusted: every count and size is checked against the bytes present before
anything is allocated for it, so a truncated, damaged or lying file raises
:class:`binpick.MeshFileError` naming the file, the problem and the fix.
"""

from __future__ import annotations

import os
import re
import tokenize
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from . import _core
from ._paths import check_file
from ._validate import MAX_UNSIGNED, as_float_array, as_points, as_vector, choice, count, unit_scale
from .errors import (
    FileWriteError,
    InvalidInputError,
    InvalidTypeError,
    MeshFileError,
    MeshFileNotFoundError,
    UnknownUnitError,
)
from .ros import is_rosbag, read_rosbag

__all__ = ["SceneCloud", "SCENE_FORMATS", "read_scene", "write_scene", "write_pcd", "lzf_decompress"]

#: The scene formats by file extension (lower case).
SCENE_FORMATS = {
    ".ply": "ply",
    ".pcd": "pcd",
    ".npy": "npy",
    ".xyz": "xyz",
    ".txt": "xyz",
    ".asc": "xyz",
    ".pts": "xyz",
}

#: Most bytes of a PCD header (its lines up to and including DATA); real headers take ~200.
MAX_PCD_HEADER = 64 << 10

#: Largest COUNT of one PCD field (PCL's widest, the 308-bin VFH histogram, fits with room to spare).
MAX_FIELD_COUNT = 1 << 16

#: Largest text file (XYZ, ASCII PCD) read, bytes: far beyond a real scene (≈ 100 M points).
MAX_TEXT_BYTES = 4 << 30

#: LZF turns at most 2 input bytes into 264 output bytes (a 7 + 255 + 2 byte back-reference).
_LZF_MAX_RATIO = 132

_UNIT_COMMENT = re.compile(rb"^\s*(?:#|//|comment)\s*units?\s*[:=]?\s*([A-Za-z]+)\s*$", re.IGNORECASE)
_VIEWPOINT_COMMENT = re.compile(
    rb"^\s*(?:#|//|comment)\s*viewpoint\s*[:=]?\s*(\S+)[\s,]+(\S+)[\s,]+(\S+)\s*$", re.IGNORECASE
)


@dataclass(frozen=True, eq=False)
class SceneCloud:
    """A scene read from a file.

    Attributes:
        points: (N, 3) float64, millimetres, every coordinate finite.
        format: ``"ply"``, ``"pcd"``, ``"npy"`` or ``"xyz"``.
        file_unit: the length unit the file declares (as written), or None when it declares none.
        dropped: points left out for a NaN or infinite coordinate (an organized cloud's holes).
        viewpoint: (3,) the sensor's position in the scene's frame, mm, where the file says it (see
            the module notes), else None.
    """

    points: np.ndarray
    format: str
    file_unit: Optional[str] = None
    dropped: int = 0
    viewpoint: Optional[np.ndarray] = None

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        unit = f", file unit {self.file_unit}" if self.file_unit else ""
        seen = "" if self.viewpoint is None else f", viewpoint {np.round(self.viewpoint, 1).tolist()}"
        return f"SceneCloud({len(self)} points from {self.format}{unit}{seen}, {self.dropped} non-finite dropped)"


def read_scene(path: str | os.PathLike[str], *, unit: Optional[str] = None) -> SceneCloud:
    """Reads a scene cloud (PLY, PCD, NPY or XYZ; the format from the file's first bytes, else its
    extension; or a ROS 2 bag's first PointCloud2 message, :mod:`binpick.ros`) into millimetres.

    ``unit`` (mm, cm, m, in) is the unit of the file's coordinates; None takes the unit the file
    declares, and mm when it declares none. Raises MeshFileNotFoundError for a missing file,
    MeshFileError for a damaged or unsupported one, UnknownUnitError for a unit binpick does not know.
    """
    name = os.fspath(path)
    scale = None if unit is None else unit_scale(unit)
    if is_rosbag(name):  # its first PointCloud2 message, in metres unless ``unit`` says otherwise
        first = read_rosbag(name, unit="m" if unit is None else unit, max_messages=1)[0]
        return SceneCloud(points=first.points, format="rosbag2", file_unit=unit or "m", dropped=first.dropped)
    kind = _format_of(name)
    pts, declared, viewpoint = _READERS[kind](name)
    if scale is None:
        scale = 1.0 if declared is None else _declared_scale(name, declared)
    if viewpoint is not None:
        viewpoint = np.asarray(viewpoint, dtype=np.float64) * scale
    pts = as_float_array(pts, name)
    finite = np.isfinite(pts).all(axis=1)
    dropped = int(len(pts) - np.count_nonzero(finite))
    if dropped:
        pts = pts[finite]
    if scale != 1.0:
        pts = pts * scale
    return SceneCloud(
        points=np.ascontiguousarray(pts), format=kind, file_unit=declared, dropped=dropped, viewpoint=viewpoint
    )


def write_scene(path: str | os.PathLike[str], points: Any, *, viewpoint: Any = None) -> Path:
    """Writes (N, 3) points in mm as PLY (binary), PCD (binary), NPY or XYZ by ``path``'s extension;
    PCD and XYZ say ``unit: mm`` in a comment, and the sensor's position ``viewpoint`` (mm, the
    scene's frame) when given: PCD in its VIEWPOINT, XYZ in a ``# viewpoint:`` comment (PLY and NPY
    cannot hold it). Returns the path."""
    from .models import write_ply

    target = Path(path)
    kind = SCENE_FORMATS.get(target.suffix.lower())
    if kind is None:
        raise InvalidInputError(f"path: {target} has no scene extension; end it in {', '.join(sorted(SCENE_FORMATS))}")
    pts = as_points(points, "points", min_points=0)
    vp = None if viewpoint is None else as_vector(viewpoint, "viewpoint")
    if kind == "ply":
        write_ply(target, pts)
        return target
    if kind == "pcd":
        return write_pcd(target, pts, viewpoint=vp)
    try:
        if kind == "npy":
            np.save(target, pts, allow_pickle=False)
        else:
            with open(target, "w", encoding="ascii") as f:
                f.write("# unit: mm\n")
                if vp is not None:
                    f.write(f"# viewpoint: {float(vp[0])!r} {float(vp[1])!r} {float(vp[2])!r}\n")
                np.savetxt(f, pts, fmt="%.6f")
    except OSError as exc:
        raise FileWriteError(f"{target}: cannot write the scene ({exc.strerror or exc})") from None
    return target


def write_pcd(path: str | os.PathLike[str], points: Any, *, encoding: str = "binary", viewpoint: Any = None) -> Path:
    """Writes (N, 3) points in mm as a PCD v0.7 file PCL reads (fields x y z, float32, unorganized),
    DATA ``binary`` or ``ascii``, with a ``# unit: mm`` comment and the sensor's position
    ``viewpoint`` (mm) in VIEWPOINT when given (PCL's default, the origin, otherwise). Returns the path."""
    pts = as_points(points, "points", min_points=0).astype(np.float32)
    encoding = choice(encoding, "encoding", ("binary", "ascii"))
    vp = np.zeros(3) if viewpoint is None else as_vector(viewpoint, "viewpoint")
    n = len(pts)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n# unit: mm\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n"
        f"TYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        f"VIEWPOINT {float(vp[0])!r} {float(vp[1])!r} {float(vp[2])!r} 1 0 0 0\n"
        f"POINTS {n}\nDATA {encoding}\n"
    )
    target = Path(path)
    try:
        with open(target, "wb") as f:
            f.write(header.encode("ascii"))
            if encoding == "binary":
                f.write(pts.astype("<f4").tobytes())
            else:
                f.write("".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in pts.tolist()).encode("ascii"))
    except OSError as exc:
        raise FileWriteError(f"{target}: cannot write the PCD file ({exc.strerror or exc})") from None
    return target


# --------------------------------------------------------------------------- format and unit


def _format_of(path: str) -> str:
    """The scene format: the file's magic bytes (PLY, NPY, PCD), else its extension."""
    check_file(path, "scene file", give="a PLY, PCD, NPY or XYZ file")
    try:
        with open(path, "rb") as f:
            head = f.read(256)
    except (OSError, ValueError) as exc:
        raise MeshFileNotFoundError(
            f"{path}: cannot open the scene file ({getattr(exc, 'strerror', None) or exc})"
        ) from None
    if head.startswith(b"ply"):
        return "ply"
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if re.match(rb"\s*(#[^\n]*\n\s*)*(VERSION|FIELDS)\s", head):
        return "pcd"
    ext = os.path.splitext(path)[1].lower()
    if ext in SCENE_FORMATS and SCENE_FORMATS[ext] in ("xyz", "pcd"):
        return SCENE_FORMATS[ext]
    raise MeshFileError(
        f"{path}: not a scene format binpick reads (PLY, PCD, NPY, or XYZ text with extension "
        ".xyz/.txt/.asc/.pts); convert it to one of them"
    )


def _declared_scale(path: str, declared: str) -> float:
    try:
        return unit_scale(declared)
    except UnknownUnitError:
        raise UnknownUnitError(
            f"{path}: declares the unit {declared!r:.40}, which binpick does not know; fix the comment "
            "(mm, cm, m or in) or pass the unit explicitly"
        ) from None


def _unit_in(lines: list[bytes]) -> Optional[str]:
    """The unit a comment among ``lines`` declares, or None."""
    for line in lines:
        m = _UNIT_COMMENT.match(line)
        if m:
            return m.group(1).decode("ascii")
    return None


def _viewpoint_in(path: str, lines: list[bytes]) -> Optional[np.ndarray]:
    """The sensor position a ``viewpoint: x y z`` comment among ``lines`` states, or None."""
    for line in lines:
        m = _VIEWPOINT_COMMENT.match(line)
        if m:
            try:
                vp = np.array([float(v) for v in m.groups()])
            except ValueError:
                vp = np.array([np.nan])
            if not np.isfinite(vp).all():
                raise MeshFileError(
                    f"{path}: the viewpoint comment {line.decode('ascii', 'replace')[:60]!r} is not three finite "
                    "numbers; fix it or remove it"
                )
            return vp
    return None


def _read_bytes(path: str, limit: Optional[int] = None) -> bytes:
    try:
        size = os.path.getsize(path)
        if limit is not None and size > limit:
            raise MeshFileError(
                f"{path}: {size} bytes is larger than the {limit} binpick reads as text; is it a scene?"
            )
        with open(path, "rb") as f:
            return f.read()
    except OSError as exc:
        raise MeshFileNotFoundError(f"{path}: cannot read the scene file ({exc.strerror or exc})") from None


# --------------------------------------------------------------------------- PLY, NPY, XYZ


def _read_ply_scene(path: str) -> tuple[np.ndarray, Optional[str], Optional[np.ndarray]]:
    from .models import read_ply

    with open(path, "rb") as f:
        head = f.read(MAX_PCD_HEADER)
    end = head.find(b"end_header")
    lines = head[: end if end >= 0 else len(head)].splitlines()
    comments = [ln for ln in lines if ln.strip().lower().startswith(b"comment")]
    return read_ply(path)[0], _unit_in(comments), _viewpoint_in(path, comments)


def _read_npy(path: str) -> tuple[np.ndarray, Optional[str], Optional[np.ndarray]]:
    try:
        # Memory-mapped: numpy checks the header's shape against the file's size before any copy.
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    # numpy parses the header (SyntaxError, TokenError), and mmap refuses a negative shape (OverflowError).
    except (OSError, ValueError, OverflowError, EOFError, SyntaxError, tokenize.TokenError) as exc:
        raise MeshFileError(
            f"{path}: cannot be read as a NumPy .npy array ({str(exc)[:200]}); save it with np.save"
        ) from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "iuf":
        raise MeshFileError(
            f"{path}: holds {getattr(arr, 'dtype', type(arr).__name__)}, not numbers; save float coordinates"
        )
    if arr.ndim not in (2, 3) or arr.shape[-1] != 3:
        raise MeshFileError(
            f"{path}: array of shape {arr.shape}; a scene is (N, 3) points or an organized (H, W, 3) cloud, in mm"
        )
    # An organized array is a camera's image: its points are in the camera's frame.
    return np.asarray(arr, dtype=np.float64).reshape(-1, 3), None, np.zeros(3) if arr.ndim == 3 else None


def _read_xyz(path: str) -> tuple[np.ndarray, Optional[str], Optional[np.ndarray]]:
    data = _read_bytes(path, MAX_TEXT_BYTES)
    rows, comments = [], []
    for k, raw in enumerate(data.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith((b"#", b"//")):
            comments.append(line)
            continue
        cols = line.replace(b",", b" ").split()
        if len(cols) < 3:
            raise MeshFileError(
                f"{path}: line {k} has {len(cols)} columns; an XYZ line is 'x y z' (more columns are ignored)"
            )
        rows.append(cols[:3])
    try:
        pts = np.array(rows, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next(k for k, r in enumerate(rows) if not _all_numbers(r))
        raise MeshFileError(
            f"{path}: point {bad} ({b' '.join(rows[bad]).decode('ascii', 'replace')[:60]!r}) is not three numbers; "
            "fix or remove that line"
        ) from None
    return pts, _unit_in(comments), _viewpoint_in(path, comments)


def _all_numbers(tokens: list[bytes]) -> bool:
    try:
        [float(t) for t in tokens]
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------- PCD

_PCD_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    **{("I", s): f"i{s}" for s in (1, 2, 4, 8)},
    **{("U", s): f"u{s}" for s in (1, 2, 4, 8)},
}
_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_PCD_VERSIONS = {"0.5", ".5", "0.6", ".6", "0.7", ".7"}


@dataclass(frozen=True)
class _PcdHeader:
    fields: tuple[str, ...]
    dtypes: tuple[np.dtype, ...]
    counts: tuple[int, ...]
    points: int
    data: str
    start: int  # offset of the first data byte
    unit: Optional[str]
    viewpoint: Optional[np.ndarray]  # where the header says the sensor was (module notes), else None

    @property
    def record(self) -> int:
        return sum(d.itemsize * c for d, c in zip(self.dtypes, self.counts))

    def column(self, name: str) -> int:
        """Index of field ``name``'s first value among a point's values."""
        i = self.fields.index(name)
        return sum(self.counts[:i])


def _pcd_header(path: str, data: bytes) -> _PcdHeader:
    bad = f"{path}: PCD header"
    values: dict[str, list[str]] = {}
    comments: list[bytes] = []
    pos = 0
    while "DATA" not in values:
        end = data.find(b"\n", pos)
        if end < 0 or end > MAX_PCD_HEADER:
            raise MeshFileError(
                f"{bad} has no DATA line in its first {MAX_PCD_HEADER} bytes; the file is truncated or not PCD"
            )
        raw, pos = data[pos:end].strip(), end + 1
        if not raw:
            continue
        if raw.startswith(b"#"):
            comments.append(raw)
            continue
        try:
            key, *rest = raw.decode("ascii").split()
        except UnicodeDecodeError:
            raise MeshFileError(f"{bad}: a header line is not ASCII text; the file is damaged") from None
        if key not in _PCD_KEYS:
            raise MeshFileError(f"{bad}: unknown entry {key!r:.30}; a PCD header has {', '.join(_PCD_KEYS)}")
        if key in values:
            raise MeshFileError(f"{bad}: {key} appears twice; the file is damaged")
        values[key] = rest
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "DATA"):
        if key not in values:
            raise MeshFileError(f"{bad} has no {key} line; write the file with PCL or fix the header")
    version = values.get("VERSION", ["0.7"])
    if len(version) != 1 or version[0] not in _PCD_VERSIONS:
        raise MeshFileError(f"{bad}: VERSION {' '.join(version)[:20]!r}; binpick reads PCD 0.5 to 0.7")
    fields = tuple(values["FIELDS"])
    n = len(fields)
    if n == 0:
        raise MeshFileError(f"{bad}: FIELDS is empty; a scene needs x y z")
    counts_raw = values.get("COUNT", ["1"] * n)
    for key, row in (("SIZE", values["SIZE"]), ("TYPE", values["TYPE"]), ("COUNT", counts_raw)):
        if len(row) != n:
            raise MeshFileError(f"{bad}: {key} has {len(row)} entries for {n} FIELDS; give one per field")
    sizes = [_header_int(bad, "SIZE", s, 1, 8) for s in values["SIZE"]]
    counts = tuple(_header_int(bad, "COUNT", c, 1, MAX_FIELD_COUNT) for c in counts_raw)
    dtypes = []
    for name, t, s in zip(fields, values["TYPE"], sizes):
        if (t, s) not in _PCD_TYPES:
            raise MeshFileError(
                f"{bad}: field {name!r:.30} has TYPE {t!r:.10} SIZE {s}; "
                "PCD types are F (4, 8 bytes), I and U (1, 2, 4, 8)"
            )
        dtypes.append(np.dtype("<" + _PCD_TYPES[(t, s)]))
    named = [f for f in fields if f != "_"]  # PCL names padding fields "_"
    if len(set(named)) != len(named):
        raise MeshFileError(f"{bad}: a field name appears twice in FIELDS {' '.join(fields)[:80]}")
    for axis in "xyz":
        if axis not in fields:
            raise MeshFileError(f"{bad}: FIELDS {' '.join(fields)[:80]} has no {axis}; a scene needs x y z coordinates")
        if counts[fields.index(axis)] != 1:
            raise MeshFileError(f"{bad}: field {axis} has COUNT {counts[fields.index(axis)]}; coordinates have COUNT 1")
    width = _single_int(bad, "WIDTH", values["WIDTH"])
    height = _single_int(bad, "HEIGHT", values["HEIGHT"])
    points = _single_int(bad, "POINTS", values["POINTS"]) if "POINTS" in values else width * height
    if points != width * height:
        raise MeshFileError(f"{bad}: POINTS {points} is not WIDTH × HEIGHT = {width} × {height}; the header is damaged")
    viewpoint = _pcd_viewpoint(bad, values.get("VIEWPOINT"), height > 1)
    if viewpoint is None:
        viewpoint = _viewpoint_in(path, comments)
    encoding = values["DATA"]
    if len(encoding) != 1 or encoding[0] not in ("ascii", "binary", "binary_compressed"):
        raise MeshFileError(f"{bad}: DATA {' '.join(encoding)[:30]!r}; PCD data is ascii, binary or binary_compressed")
    return _PcdHeader(fields, tuple(dtypes), counts, points, encoding[0], pos, _unit_in(comments), viewpoint)


def _pcd_viewpoint(where: str, row: Optional[list[str]], organized: bool) -> Optional[np.ndarray]:
    """The sensor position of a VIEWPOINT row (tx ty tz qw qx qy qz): its translation where it is
    not PCL's default (the origin, unturned), or for an organized cloud (a camera's image in the
    camera's frame) the default too; None otherwise."""
    if row is None:
        return np.zeros(3) if organized else None
    if len(row) != 7:
        raise MeshFileError(f"{where}: VIEWPOINT has {len(row)} numbers; it takes tx ty tz qw qx qy qz")
    try:
        v = np.array([float(x) for x in row])
    except ValueError:
        v = np.array([np.nan])
    if not np.isfinite(v).all():
        raise MeshFileError(
            f"{where}: VIEWPOINT {' '.join(row)[:60]!r} is not seven finite numbers; the header is damaged"
        )
    default = not v[:3].any() and abs(abs(v[3]) - 1.0) < 1e-9 and not v[4:].any()
    return None if default and not organized else v[:3]


def _header_int(where: str, key: str, text: str, low: int, high: int) -> int:
    if not text.isdigit() or not low <= int(text) <= high:
        raise MeshFileError(f"{where}: {key} entry {text!r:.20} is not a whole number in [{low}, {high}]")
    return int(text)


def _single_int(where: str, key: str, row: list[str]) -> int:
    if len(row) != 1 or not row[0].isdigit() or len(row[0]) > 18:
        raise MeshFileError(f"{where}: {key} must be one whole number, got {' '.join(row)[:30]!r}")
    return int(row[0])


def _read_pcd(path: str) -> tuple[np.ndarray, Optional[str], Optional[np.ndarray]]:
    data = _read_bytes(path)
    h = _pcd_header(path, data)
    body = memoryview(data)[h.start :]
    read = {"ascii": _pcd_ascii, "binary": _pcd_binary, "binary_compressed": _pcd_compressed}[h.data]
    return read(path, h, body), h.unit, h.viewpoint


def _pcd_ascii(path: str, h: _PcdHeader, body: memoryview) -> np.ndarray:
    per_point = sum(h.counts)
    if h.points * per_point * 2 - 1 > len(body):  # each value takes a digit and a separator at least
        raise MeshFileError(
            f"{path}: the header declares {h.points} points of {per_point} values but only {len(body)} bytes of "
            "ascii data follow; the file is truncated or its POINTS is wrong"
        )
    tokens = bytes(body).split()
    if len(tokens) != h.points * per_point:
        raise MeshFileError(
            f"{path}: the ascii data holds {len(tokens)} values, not POINTS × values per point = {h.points} × "
            f"{per_point}; the file is truncated or damaged"
        )
    try:
        cols = [np.array(tokens[h.column(a) :: per_point], dtype=np.float64) for a in "xyz"]
    except ValueError:
        raise MeshFileError(
            f"{path}: an x, y or z value of the ascii data is not a number; the file is damaged"
        ) from None
    # A float32 field is rounded to float32, as PCL reads it, so an ascii file gives what binary would.
    with np.errstate(over="ignore"):
        cols = [c.astype(np.float32) if h.dtypes[h.fields.index(a)] == np.float32 else c for c, a in zip(cols, "xyz")]
    return np.stack(cols, axis=1).astype(np.float64)


def _pcd_binary(path: str, h: _PcdHeader, body: memoryview) -> np.ndarray:
    need = h.points * h.record
    if need > len(body):
        raise MeshFileError(
            f"{path}: the header declares {h.points} points of {h.record} bytes ({need} bytes) but {len(body)} "
            "bytes of binary data follow; the file is truncated or its POINTS/SIZE/COUNT are wrong"
        )
    offsets = np.cumsum([0] + [d.itemsize * c for d, c in zip(h.dtypes, h.counts)])
    out = np.empty((h.points, 3), dtype=np.float64)
    records = np.frombuffer(body, dtype=np.uint8, count=need).reshape(h.points, h.record)
    for k, axis in enumerate("xyz"):
        i = h.fields.index(axis)
        raw = np.ascontiguousarray(records[:, offsets[i] : offsets[i] + h.dtypes[i].itemsize])
        with np.errstate(invalid="ignore"):
            out[:, k] = raw.view(h.dtypes[i]).ravel()
    return out


def _pcd_compressed(path: str, h: _PcdHeader, body: memoryview) -> np.ndarray:
    if len(body) < 8:
        raise MeshFileError(f"{path}: binary_compressed data stops before its two size words; the file is truncated")
    packed, unpacked = (int.from_bytes(body[i : i + 4], "little") for i in (0, 4))
    need = h.points * h.record
    if unpacked != need:
        raise MeshFileError(
            f"{path}: binary_compressed data unpacks to {unpacked} bytes but the header's {h.points} points of "
            f"{h.record} bytes take {need}; the header or the data is damaged"
        )
    if packed > len(body) - 8:
        raise MeshFileError(
            f"{path}: binary_compressed data declares {packed} compressed bytes but {len(body) - 8} follow; "
            "the file is truncated"
        )
    if unpacked > packed * _LZF_MAX_RATIO:
        raise MeshFileError(
            f"{path}: {packed} compressed bytes cannot unpack to {unpacked} (LZF expands at most "
            f"{_LZF_MAX_RATIO}×); the file is damaged"
        )
    plain = lzf_decompress(bytes(body[8 : 8 + packed]), unpacked, source=path)
    out = np.empty((h.points, 3), dtype=np.float64)
    start = 0
    for name, dtype, c in zip(h.fields, h.dtypes, h.counts):  # fields one after the other (SoA)
        size = h.points * dtype.itemsize * c
        if name in ("x", "y", "z"):
            out[:, "xyz".index(name)] = np.frombuffer(plain, dtype=dtype, count=h.points, offset=start)
        start += size
    return out


def lzf_decompress(data: bytes, size: int, *, source: str = "data") -> bytes:
    """Decompresses LZF (liblzf's format, which PCL's binary_compressed uses) to exactly ``size`` bytes.

    The stream is a sequence of tokens, each opening with a control byte ``c``:

    - ``c < 32`` (``000LLLLL``): a literal run, the next ``c + 1`` bytes copied as they are;
    - else (``LLLooooo``): a back-reference of ``L + 2`` bytes (``L`` = ``c >> 5``; when ``L`` is
      7 the next byte is added to it), copied from ``((c & 31) << 8) + next byte + 1`` bytes back
      in the output (the copy may overlap what it writes).

    A token that runs past the input, a reference before the output's start and an output that
    is not ``size`` bytes long raise MeshFileError naming ``source``; ``data`` that is not bytes
    or a ``size`` that is not a whole number ≥ 0 raise InvalidInputError naming it.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InvalidTypeError(f"data: expected bytes, got {type(data).__name__}")
    size = count(size, "size", 0, MAX_UNSIGNED)
    plain, why = _core.lzf_decompress(bytes(data), size)  # the GIL released while it unpacks
    if why is not None:
        raise _lzf_error(source, why)
    return plain


def _lzf_error(source: str, problem: str) -> MeshFileError:
    return MeshFileError(f"{source}: binary_compressed data is corrupt: {problem}; write the file again")


_READERS = {"ply": _read_ply_scene, "pcd": _read_pcd, "npy": _read_npy, "xyz": _read_xyz}
