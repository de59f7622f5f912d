"""Scene files (binpick.clouds): PCD as PCL writes it, checked against a second writer written here
from the format's definition (with its own LZF compressor, sharing no code with the reader's
decompressor), LZF golden vectors, lying headers, a fuzz over byte mutations, XYZ, NPY and PLY;
and the ``reconstruct`` and ``estimate`` commands end to end on a simulated scan folder."""

from __future__ import annotations

import json
import struct
import time

import numpy as np
import pytest

import binpick
from binpick.clouds import lzf_decompress, read_scene, write_pcd, write_scene
from binpick.errors import BinpickError, MeshFileError, MeshFileNotFoundError, UnknownUnitError

# ----------------------------------------------------------------------------- the second writer

_STRUCT = {("F", 4): "f", ("F", 8): "d", ("I", 1): "b", ("I", 2): "h", ("I", 4): "i", ("I", 8): "q"}
_STRUCT.update({("U", 1): "B", ("U", 2): "H", ("U", 4): "I", ("U", 8): "Q"})


def lzf_compress(data: bytes) -> bytes:
    """Greedy LZF with a hash chain of 3-byte prefixes, from liblzf's format definition."""
    out, literal = bytearray(), bytearray()
    chains: dict[bytes, list[int]] = {}
    i, n = 0, len(data)

    def flush() -> None:
        for k in range(0, len(literal), 32):
            chunk = literal[k : k + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        literal.clear()

    while i < n:
        best_len, best_pos = 0, 0
        key = data[i : i + 3]
        if len(key) == 3:
            for p in reversed(chains.get(key, [])[-16:]):
                if i - p > 8192:
                    break
                m = 0
                while m < 264 and i + m < n and data[p + m] == data[i + m]:
                    m += 1
                if m > best_len:
                    best_len, best_pos = m, p
            chains.setdefault(key, []).append(i)
        if best_len >= 3:
            flush()
            length, off = best_len - 2, i - best_pos - 1
            if length < 7:
                out.append((length << 5) | (off >> 8))
            else:
                out.extend((0xE0 | (off >> 8), length - 7))
            out.append(off & 0xFF)
            for k in range(i + 1, i + best_len):
                if k + 3 <= n:
                    chains.setdefault(data[k : k + 3], []).append(k)
            i += best_len
        else:
            literal.append(data[i])
            i += 1
    flush()
    return bytes(out)


def _ascii_value(value, kind: str, name: str) -> str:
    if kind == "F" and name == "rgb":  # as PCL: the packed colour's bits as an unsigned integer
        return str(struct.unpack("<I", struct.pack("<f", value))[0])
    if kind == "F":
        return "nan" if value != value else f"{value:.9g}"
    return str(int(value))


def pcl_write(path, fields, width, height=1, encoding="binary", version="0.7", comments=(), viewpoint="0 0 0 1 0 0 0"):
    """Writes a PCD file as PCL does. ``fields``: (name, TYPE, SIZE, values of shape (N, COUNT))."""
    n = width * height
    head = ["# .PCD v0.7 - Point Cloud Data file format", *comments, f"VERSION {version}"]
    head.append("FIELDS " + " ".join(f[0] for f in fields))
    head.append("SIZE " + " ".join(str(f[2]) for f in fields))
    head.append("TYPE " + " ".join(f[1] for f in fields))
    head.append("COUNT " + " ".join(str(len(f[3][0])) for f in fields))
    head += [f"WIDTH {width}", f"HEIGHT {height}"]
    if version not in ("0.6", ".6"):
        head.append(f"VIEWPOINT {viewpoint}")
    head += [f"POINTS {n}", f"DATA {encoding}"]
    body = b""
    if encoding == "ascii":
        lines = []
        for k in range(n):
            lines.append(" ".join(_ascii_value(v, t, name) for name, t, _, vals in fields for v in vals[k]))
        body = ("\n".join(lines) + "\n").encode()
    elif encoding == "binary":
        parts = []
        for k in range(n):
            for _, t, s, vals in fields:
                parts.append(struct.pack("<" + _STRUCT[(t, s)] * len(vals[k]), *vals[k]))
        body = b"".join(parts)
    else:
        raw = b"".join(
            struct.pack("<" + _STRUCT[(t, s)] * len(vals[k]), *vals[k]) for _, t, s, vals in fields for k in range(n)
        )
        packed = lzf_compress(raw)
        body = struct.pack("<II", len(packed), len(raw)) + packed
    path.write_bytes(("\n".join(head) + "\n").encode() + body)
    return path


def _xyz_fields(pts, kind="F", size=4):
    return [(a, kind, size, pts[:, [k]].tolist()) for k, a in enumerate("xyz")]


ENCODINGS = ("ascii", "binary", "binary_compressed")

# ----------------------------------------------------------------------------- LZF


@pytest.mark.parametrize(
    "packed,plain",
    [
        (b"\x02abc", b"abc"),  # 000LLLLL: a literal run of L + 1 bytes
        (b"\x02abc\x20\x02", b"abcabc"),  # LLLooooo oooooooo: 1 + 2 bytes from 2 + 1 back
        (b"\x00a\xe0\x0a\x00", b"a" * 20),  # L = 7: + extra byte 10 → 19 bytes, overlapping, 1 back
        (b"\x03abcd\x40\x03", b"abcdabcd"),  # 2 + 2 bytes from 4 back
        (b"\x1f" + bytes(range(32)), bytes(range(32))),  # the longest literal run
        (b"\x00z\xe0\xff\x00", b"z" * 265),  # the longest back-reference: 7 + 255 + 2
    ],
)
def test_lzf_golden_vectors_from_the_format_definition(packed, plain):
    assert lzf_decompress(packed, len(plain)) == plain


@pytest.mark.parametrize(
    "packed,size,match",
    [
        (b"\x20\x00", 3, "out of range"),  # a back-reference into nothing
        (b"\x01ab\x20\x05", 5, "out of range"),  # 6 back after 2 bytes
        (b"\x05ab", 6, "literal run"),  # the run stops early
        (b"\x00a\xe0", 10, "length byte"),
        (b"\x00a\x20", 10, "offset byte"),
        (b"\x02abc", 4, "unpacks to 3 bytes"),
        (b"\x02abc\x20\x02", 5, "more than the 5"),
    ],
)
def test_corrupt_lzf_is_a_mesh_file_error(packed, size, match):
    with pytest.raises(MeshFileError, match=match):
        lzf_decompress(packed, size, source="scene.pcd")


def test_the_second_compressor_round_trips_through_the_decompressor():
    rng = np.random.default_rng(4)
    samples = [
        b"",
        b"x",
        bytes(1000),
        rng.integers(0, 256, 3000, dtype=np.uint8).tobytes(),
        np.repeat(rng.integers(0, 4, 400, dtype=np.uint8), 7).tobytes(),
        rng.normal(size=500).astype("<f4").tobytes() * 3,
    ]
    for data in samples:
        packed = lzf_compress(data)
        assert lzf_decompress(packed, len(data)) == data
    assert len(lzf_compress(bytes(1000))) < 40  # it compresses, so back-references are exercised


# ----------------------------------------------------------------------------- PCD


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_an_unorganized_cloud_reads_back_in_every_encoding(tmp_path, encoding):
    pts = np.random.default_rng(1).uniform(-500, 500, (300, 3)).astype(np.float32)
    path = pcl_write(tmp_path / "c.pcd", _xyz_fields(pts), 300, encoding=encoding)
    scene = read_scene(path)
    assert scene.format == "pcd" and scene.dropped == 0 and scene.file_unit is None
    assert scene.points.dtype == np.float64 and scene.points.shape == (300, 3)
    assert np.array_equal(scene.points, pts.astype(np.float64))


def _organized(rng, width=24, height=16):
    n = width * height
    pts = rng.uniform(-200, 200, (n, 3)).astype(np.float32)
    holes = rng.random(n) < 0.2
    pts[holes] = np.nan
    rgb = (rng.integers(0, 256, (n, 3)) * [1 << 16, 1 << 8, 1]).sum(axis=1).astype("<u4")
    normals = rng.normal(size=(n, 3)).astype(np.float32)
    fields = [
        *_xyz_fields(pts),
        ("rgb", "F", 4, rgb.view("<f4").reshape(-1, 1).tolist()),
        *[(f"normal_{a}", "F", 4, normals[:, [k]].tolist()) for k, a in enumerate("xyz")],
        ("curvature", "F", 4, rng.random((n, 1)).tolist()),
        ("intensity", "U", 2, rng.integers(0, 65536, (n, 1)).tolist()),
    ]
    return pts, holes, fields


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_an_organized_cloud_with_holes_and_extra_fields_reads_back(tmp_path, encoding):
    rng = np.random.default_rng(2)
    pts, holes, fields = _organized(rng)
    path = pcl_write(tmp_path / "org.pcd", fields, 24, 16, encoding=encoding)
    scene = read_scene(path)
    assert scene.dropped == int(holes.sum()) > 0
    assert np.array_equal(scene.points, pts[~holes].astype(np.float64))  # row-major order kept


def test_the_viewpoint_is_read_where_the_file_states_it(tmp_path):
    rng = np.random.default_rng(3)
    pts = rng.uniform(-200, 200, (50, 3)).astype(np.float32)
    # PCL's default viewpoint says nothing of an unorganized cloud (any tool writes it) ...
    assert read_scene(pcl_write(tmp_path / "a.pcd", _xyz_fields(pts), 50)).viewpoint is None
    # ... but an organized one is a camera's image in the camera's frame: the sensor is at the origin.
    _, _, fields = _organized(rng)
    organized = read_scene(pcl_write(tmp_path / "o.pcd", fields, 24, 16))
    assert organized.viewpoint is not None and not organized.viewpoint.any()
    # A stated viewpoint is read (and scaled with the file's unit); damaged ones are refused.
    moved = pcl_write(
        tmp_path / "v.pcd", _xyz_fields(pts), 50, viewpoint="0.1 -0.2 0.7 1 0 0 0", comments=["# unit: m"]
    )
    assert np.allclose(read_scene(moved).viewpoint, [100.0, -200.0, 700.0])
    for bad in ("0 0 1 1 0 0", "0 0 nan 1 0 0 0", "a b c 1 0 0 0"):
        path = pcl_write(tmp_path / "bad.pcd", _xyz_fields(pts), 50, viewpoint=bad)
        with pytest.raises(MeshFileError, match="VIEWPOINT"):
            read_scene(path)
    # An organized NPY array is a camera's image too; a flat one says nothing.
    np.save(tmp_path / "o.npy", rng.uniform(1, 2, (4, 5, 3)))
    np.save(tmp_path / "f.npy", rng.uniform(1, 2, (20, 3)))
    assert not read_scene(tmp_path / "o.npy").viewpoint.any()
    assert read_scene(tmp_path / "f.npy").viewpoint is None


@pytest.mark.parametrize("ext", ("pcd", "xyz"))
def test_write_scene_keeps_the_viewpoint(tmp_path, ext):
    pts = np.random.default_rng(4).uniform(-300, 300, (40, 3))
    back = read_scene(write_scene(tmp_path / f"s.{ext}", pts, viewpoint=(400.0, -20.5, 650.25)))
    assert np.allclose(back.viewpoint, [400.0, -20.5, 650.25])
    assert read_scene(write_scene(tmp_path / f"n.{ext}", pts)).viewpoint is None
    (tmp_path / "bad.xyz").write_text("# viewpoint: 1 2 inf\n1 2 3\n")
    with pytest.raises(MeshFileError, match="viewpoint"):
        read_scene(tmp_path / "bad.xyz")


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_every_field_type_and_count_and_padding_is_laid_out_right(tmp_path, encoding):
    rng = np.random.default_rng(3)
    n = 50
    pts = rng.uniform(-1e3, 1e3, (n, 3))
    fields = [
        ("_", "U", 1, rng.integers(0, 255, (n, 3)).tolist()),
        ("label", "I", 8, rng.integers(-(2**40), 2**40, (n, 1)).tolist()),
        ("x", "F", 8, pts[:, [0]].tolist()),
        ("histogram", "F", 4, rng.random((n, 5)).tolist()),
        ("y", "F", 8, pts[:, [1]].tolist()),
        ("ring", "I", 2, rng.integers(-300, 300, (n, 1)).tolist()),
        ("_", "U", 1, rng.integers(0, 255, (n, 1)).tolist()),
        ("z", "F", 8, pts[:, [2]].tolist()),
        ("t", "U", 8, rng.integers(0, 2**62, (n, 1)).tolist()),
        ("flag", "I", 1, rng.integers(-100, 100, (n, 2)).tolist()),
        ("id", "U", 4, rng.integers(0, 2**32, (n, 1)).tolist()),
    ]
    scene = read_scene(pcl_write(tmp_path / "types.pcd", fields, n, encoding=encoding))
    tol = 1e-6 if encoding == "ascii" else 0.0  # ascii holds 9 significant digits
    assert np.allclose(scene.points, pts, rtol=tol, atol=0) if tol else np.array_equal(scene.points, pts)


def test_integer_coordinates_and_old_versions(tmp_path):
    pts = np.arange(30).reshape(10, 3)
    for version in ("0.6", ".7", "0.5"):
        path = pcl_write(tmp_path / "v.pcd", _xyz_fields(pts, "I", 4), 10, version=version)
        assert np.array_equal(read_scene(path).points, pts)


def test_a_unit_comment_is_honoured_and_an_explicit_unit_wins(tmp_path):
    pts = np.array([[0.25, -0.5, 1.0]], dtype=np.float32)
    path = pcl_write(tmp_path / "m.pcd", _xyz_fields(pts), 1, comments=["# unit: m"])
    scene = read_scene(path)
    assert scene.file_unit == "m" and np.array_equal(scene.points, [[250.0, -500.0, 1000.0]])
    assert np.array_equal(read_scene(path, unit="cm").points, [[2.5, -5.0, 10.0]])
    bad = pcl_write(tmp_path / "f.pcd", _xyz_fields(pts), 1, comments=["# units: furlong"])
    with pytest.raises(UnknownUnitError, match="furlong"):
        read_scene(bad)


@pytest.mark.parametrize("encoding", ("ascii", "binary"))
def test_the_package_pcd_writer_round_trips(tmp_path, encoding):
    pts = np.random.default_rng(5).uniform(-100, 100, (200, 3)).astype(np.float32).astype(np.float64)
    scene = read_scene(write_pcd(tmp_path / "w.pcd", pts, encoding=encoding))
    assert scene.file_unit == "mm" and np.array_equal(scene.points, pts)


def _valid_header(n=4, data="binary"):
    return (
        f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )


@pytest.mark.parametrize(
    "text,match",
    [
        (
            lambda h: h.replace("POINTS 4", "POINTS 1000000000000").replace("WIDTH 4", "WIDTH 1000000000000"),
            "truncated",
        ),
        (lambda h: h.replace("POINTS 4", "POINTS 5"), "WIDTH × HEIGHT"),
        (lambda h: h.replace("SIZE 4 4 4", "SIZE 4 3 4"), "TYPE 'F' SIZE 3"),
        (lambda h: h.replace("SIZE 4 4 4", "SIZE 4 4 99"), r"SIZE entry '99'"),
        (lambda h: h.replace("TYPE F F F", "TYPE F F Q"), "TYPE 'Q'"),
        (lambda h: h.replace("COUNT 1 1 1", "COUNT 1 1"), "COUNT has 2 entries"),
        (lambda h: h.replace("COUNT 1 1 1", "COUNT 1 2 1"), "field y has COUNT 2"),
        (lambda h: h.replace("FIELDS x y z", "FIELDS x y w"), "has no z"),
        (lambda h: h.replace("FIELDS x y z", "FIELDS x y y"), "appears twice"),
        (lambda h: h.replace("DATA binary", "DATA zip"), "ascii, binary or binary_compressed"),
        (lambda h: h.replace("VERSION 0.7", "VERSION 2"), "0.5 to 0.7"),
        (lambda h: h.replace("HEIGHT 1\n", ""), "no HEIGHT"),
        (lambda h: h.replace("WIDTH 4", "WIDTH -4"), "WIDTH must be one whole number"),
        (lambda h: h.replace("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0"), "VIEWPOINT has 2"),
        (lambda h: "COLOR red\n" + h, "unknown entry 'COLOR'"),
        (lambda h: h.replace("DATA binary\n", ""), "no DATA line"),
    ],
)
def test_a_lying_pcd_header_is_refused_before_any_allocation(tmp_path, text, match):
    path = tmp_path / "lie.pcd"
    path.write_bytes(text(_valid_header()).encode() + bytes(48))
    t0 = time.perf_counter()
    with pytest.raises(MeshFileError, match=match) as info:
        read_scene(path)
    assert time.perf_counter() - t0 < 0.5
    assert str(info.value).startswith(str(path))


def test_truncated_and_damaged_pcd_data(tmp_path):
    pts = np.random.default_rng(6).normal(size=(40, 3)).astype(np.float32)
    cases = {}
    for enc in ENCODINGS:
        cases[enc] = pcl_write(tmp_path / f"{enc}.pcd", _xyz_fields(pts), 40, encoding=enc).read_bytes()
    path = tmp_path / "bad.pcd"

    def refused(data: bytes, match: str) -> None:
        path.write_bytes(data)
        with pytest.raises(MeshFileError, match=match):
            read_scene(path)

    refused(cases["binary"][:-1], "truncated")
    refused(cases["ascii"].rstrip()[:-12], "truncated")
    ascii_start = cases["ascii"].index(b"DATA ascii\n") + len(b"DATA ascii\n")
    first_line = cases["ascii"].index(b"\n", ascii_start)
    refused(cases["ascii"][:first_line] + b" 7" + cases["ascii"][first_line:], "holds 121 values")
    refused(cases["ascii"][:first_line] + b"q" + cases["ascii"][first_line:], "not a number")
    comp = cases["binary_compressed"]
    start = comp.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    packed, raw = struct.unpack("<II", comp[start : start + 8])
    refused(comp[:-3], "truncated")
    refused(comp[: start + 4] + struct.pack("<I", raw + 4) + comp[start + 8 :], "take 480")
    refused(comp[:start] + struct.pack("<I", packed + 100) + comp[start + 4 :], "truncated")
    refused(comp[:start], "before its two size words")
    lying = comp.replace(b"POINTS 40", b"POINTS 400000").replace(b"WIDTH 40", b"WIDTH 400000")
    lying = lying[: lying.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")]
    refused(lying + struct.pack("<II", 8, 4_800_000) + bytes(8), "at most 132")


def test_fuzzed_pcd_files_raise_only_binpick_errors(tmp_path):
    rng = np.random.default_rng(7)
    pts, _, fields = _organized(rng, 6, 4)
    seeds = [pcl_write(tmp_path / f"{e}.pcd", fields, 6, 4, encoding=e).read_bytes() for e in ENCODINGS]
    path = tmp_path / "fuzz.pcd"
    t0, tried, read = time.perf_counter(), 0, 0
    while time.perf_counter() - t0 < 1.5:
        data = bytearray(seeds[tried % 3])
        for _ in range(int(rng.integers(1, 5))):
            k = int(rng.integers(0, len(data)))
            op = rng.integers(0, 3)
            if op == 0:
                data[k] = int(rng.integers(0, 256))
            elif op == 1:
                del data[k : k + int(rng.integers(1, 9))]
            else:
                data[k:k] = bytes(rng.integers(0, 256, int(rng.integers(1, 9)), dtype=np.uint8))
        path.write_bytes(bytes(data))
        tried += 1
        try:
            scene = read_scene(path)
        except BinpickError:
            continue
        read += 1
        assert scene.points.ndim == 2 and scene.points.shape[1] == 3 and np.isfinite(scene.points).all()
    assert tried > 200 and read > 0


# ----------------------------------------------------------------------------- XYZ, NPY, PLY


def test_xyz_text_with_comments_blank_lines_commas_and_extra_columns(tmp_path):
    path = tmp_path / "s.xyz"
    path.write_text("# scanner export\n// unit: cm\n\n1 2 3\n4.5,5,6e1, 7 8\n  -1\t-2\t-3 255 0 0\nnan 1 2\n")
    scene = read_scene(path)
    assert scene.format == "xyz" and scene.file_unit == "cm" and scene.dropped == 1
    assert np.array_equal(scene.points, [[10, 20, 30], [45, 50, 600], [-10, -20, -30]])
    path.write_text("1 2 3\n4 5\n")
    with pytest.raises(MeshFileError, match="line 2 has 2 columns"):
        read_scene(path)
    path.write_text("1 2 3\n4 five 6\n")
    with pytest.raises(MeshFileError, match="point 1 .*is not three numbers"):
        read_scene(path)


def test_npy_flat_and_organized(tmp_path):
    grid = np.random.default_rng(8).normal(size=(5, 7, 3))
    grid[1, 2] = np.nan
    np.save(tmp_path / "o.npy", grid)
    scene = read_scene(tmp_path / "o.npy")
    assert scene.dropped == 1 and len(scene) == 34
    assert np.array_equal(scene.points, grid.reshape(-1, 3)[np.isfinite(grid.reshape(-1, 3)).all(axis=1)])
    np.save(tmp_path / "i.npy", np.arange(12, dtype=np.int16).reshape(4, 3))
    assert np.array_equal(read_scene(tmp_path / "i.npy").points, np.arange(12).reshape(4, 3))
    np.save(tmp_path / "b.npy", np.zeros((4, 2)))
    with pytest.raises(MeshFileError, match=r"shape \(4, 2\)"):
        read_scene(tmp_path / "b.npy")


def test_an_npy_header_claiming_a_trillion_points_fails_fast(tmp_path):
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 3), }"
    header += " " * (117 - len(header)) + "\n"
    (tmp_path / "big.npy").write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
    t0 = time.perf_counter()
    with pytest.raises(MeshFileError, match="big.npy"):
        read_scene(tmp_path / "big.npy")
    assert time.perf_counter() - t0 < 0.5


def test_ply_with_a_unit_comment_and_unknown_files(tmp_path):
    path = tmp_path / "s.ply"
    path.write_text(
        "ply\nformat ascii 1.0\ncomment unit: m\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0.5 0 1\n0 0.25 0\n"
    )
    scene = read_scene(path)
    assert scene.file_unit == "m" and np.array_equal(scene.points, [[500, 0, 1000], [0, 250, 0]])
    path.write_text(path.read_text().replace("0 0.25 0", "nan 0.25 0"))
    with pytest.raises(MeshFileError, match="non-finite"):  # the core's PLY reader refuses it
        read_scene(path)
    (tmp_path / "s.bin").write_bytes(b"\x00\x01")
    with pytest.raises(MeshFileError, match="not a scene format"):
        read_scene(tmp_path / "s.bin")
    with pytest.raises(MeshFileNotFoundError, match="does not exist"):
        read_scene(tmp_path / "none.pcd")
    with pytest.raises(MeshFileError, match="is a folder"):
        read_scene(tmp_path)


@pytest.mark.parametrize("ext", ("ply", "pcd", "xyz", "npy"))
def test_write_scene_round_trips_by_extension(tmp_path, ext):
    pts = np.random.default_rng(9).uniform(-300, 300, (100, 3)).astype(np.float32).astype(np.float64)
    back = binpick.read_scene(binpick.write_scene(tmp_path / f"s.{ext}", pts))
    assert np.allclose(back.points, pts, atol=1e-6, rtol=0)
    with pytest.raises(binpick.InvalidInputError, match="extension"):
        write_scene(tmp_path / "s.stl", pts)


# ----------------------------------------------------------------------------- the commands


@pytest.fixture(scope="module")
def scan_folder(tmp_path_factory):
    from binpick import sim

    t0 = time.perf_counter()
    scan = sim.simulate_scan(binpick.parts.tee(), 3, seed=1, frames=30)
    root = sim.write_scan(scan, tmp_path_factory.mktemp("scan"))
    assert time.perf_counter() - t0 < 20
    return root


def _pick_grade(doc, root) -> bool:
    gt = json.loads((root / "ground_truth.json").read_text())
    model = binpick.parts.tee()
    errors = [model.pose_error(np.array(doc["T_scene_model"]), np.array(T)) for T in gt["T_base_object"]]
    return any(r < 5 and t < 3 for r, t in errors)  # pick-grade against the nearest instance


def test_reconstruct_writes_the_scan_cloud_in_each_format(scan_folder, tmp_path, capsys):
    from binpick.cli import main
    from binpick.scan import load_scan
    from binpick.vision import reconstruct

    live = reconstruct(load_scan(scan_folder)).points
    for ext in ("ply", "pcd", "xyz", "npy"):
        out = tmp_path / f"scene.{ext}"
        assert main(["reconstruct", str(scan_folder), "--out", str(out)]) == 0
        assert f"{len(live)} points" in capsys.readouterr().out
        assert np.allclose(read_scene(out).points, live, atol=1e-3, rtol=0), ext
    assert main(["reconstruct", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x.ply")]) == 2
    assert main(["reconstruct", str(tmp_path), "--out", str(tmp_path / "x.ply")]) == 2
    assert "without scan.json" in capsys.readouterr().err


def test_the_readme_scene_commands_work_word_for_word(tmp_path, monkeypatch, capsys):
    """simulate, reconstruct, then estimate from the scan folder and from its reconstructed PCD."""
    import shlex
    from pathlib import Path

    from binpick.cli import main

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme.split("### Scene files and scan folders", 1)[1]
    block = section.split("```\n", 2)[1]
    commands = [shlex.split(line) for line in block.splitlines() if line.strip()]
    assert [c[:2] for c in commands] == [["binpick", "simulate"], ["binpick", "reconstruct"]] + [
        ["binpick", "estimate"]
    ] * 2
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        assert main(argv[1:]) == 0, " ".join(argv)
        out = capsys.readouterr().out
        if argv[1] == "estimate":  # the pose found is pick-grade against the simulated pile
            assert _pick_grade(json.loads(out), tmp_path / "scan"), " ".join(argv)
    assert read_scene(tmp_path / "scene.pcd").format == "pcd"
    assert main(["estimate", "scene.pcd", "tee", "--scene-unit", "furlong"]) == 2
    assert main(["estimate", "scan", "tee", "--scene-unit", "m"]) == 2
