//! Reading meshes (STL binary and ASCII, PLY ASCII and binary, OBJ) and reading and writing
//! PLY point clouds that MeshLab and CloudCompare open.

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// What a reader stopped by a cancel says; nobody reads it, the caller has gone.
const CANCELLED: &str = "reading was cancelled";

/// Whether a reader at row `i` should stop: the call was cancelled (looked at every 2^16 rows).
fn cancelled_at(i: usize) -> bool {
    i.is_multiple_of(1 << 16) && crate::cancel::requested()
}

/// The largest mesh or cloud file read, bytes (4 GiB): far beyond any part's CAD model, and a
/// bound on what a file that is not one (a device, a pipe) can make the reader allocate.
const MAX_FILE_BYTES: u64 = 1 << 32;

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let shown = path.display().to_string();
    let not_found = |reason: String| Error::FileNotFound {
        path: shown.clone(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| not_found(e.to_string()))?;
    if meta.is_dir() {
        return Err(not_found("it is a directory".into()));
    }
    if !meta.is_file() {
        return Err(Error::bad_file(
            shown,
            "it is not a regular file (a device, a pipe or a socket); save the mesh or cloud to a file and read that",
        ));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(Error::bad_file(
            shown,
            format!("{} bytes is over the ceiling of {MAX_FILE_BYTES} bytes", meta.len()),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| not_found(e.to_string()))?;
    // Read no more than the ceiling even if the file grows while it is read.
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| not_found(e.to_string()))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(Error::bad_file(
            shown,
            format!("it grew over the ceiling of {MAX_FILE_BYTES} bytes while it was read"),
        ));
    }
    if bytes.is_empty() {
        return Err(Error::bad_file(shown, "the file is empty"));
    }
    Ok(bytes)
}

/// Reads a triangle mesh, choosing the format by the file extension (`.stl`, `.ply`, `.obj`).
/// Coordinates are returned as stored; convert units with [`crate::mesh::unit_scale`].
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    let shown = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if !matches!(ext.as_str(), "stl" | "ply" | "obj") {
        return Err(Error::bad_file(
            shown,
            format!("unsupported extension {ext:?}; binpick reads .stl, .ply and .obj meshes (and .step/.stp with the extra: pip install \"binpick[step]\")"),
        ));
    }
    let bytes = read_bytes(path)?;
    let mut mesh = match ext.as_str() {
        "stl" => parse_stl(&bytes),
        "ply" => parse_ply(&bytes).and_then(|p| {
            if p.faces.is_empty() {
                Err("the PLY file has no faces; it is a point cloud, not a mesh (use read_ply)".to_string())
            } else {
                Ok(TriMesh {
                    vertices: p.points,
                    faces: p.faces,
                })
            }
        }),
        _ => parse_obj(&bytes),
    }
    .map_err(|problem| Error::bad_file(shown.clone(), problem))?;
    if let Err(Error::NonFinite { index, .. }) = crate::geometry::check_finite("vertices", &mesh.vertices) {
        return Err(Error::bad_file(
            shown,
            format!("vertex {index} is not finite; the file is corrupt"),
        ));
    }
    mesh.drop_degenerate_faces();
    if mesh.faces.is_empty() {
        return Err(Error::bad_file(shown, "the mesh has no triangle with a non-zero area"));
    }
    Ok(mesh)
}

/// Merges exactly equal vertices, as STL repeats every corner per triangle.
struct Welder {
    map: HashMap<[u64; 3], u32>,
    vertices: Vec<Point>,
}

impl Welder {
    fn new() -> Self {
        Welder {
            map: HashMap::new(),
            vertices: Vec::new(),
        }
    }
    fn add(&mut self, p: [f64; 3]) -> u32 {
        // +0.0 and -0.0 are the same place.
        let key = p.map(|v| if v == 0.0 { 0u64 } else { v.to_bits() });
        let next = self.vertices.len() as u32;
        *self.map.entry(key).or_insert_with(|| {
            self.vertices.push(Point::new(p[0], p[1], p[2]));
            next
        })
    }
}

fn parse_stl(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
        if n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
            return parse_stl_binary(bytes, n);
        }
    }
    let text = std::str::from_utf8(bytes).map_err(|_| {
        "not a valid STL: the size does not match a binary STL's triangle count and the content is not ASCII text"
            .to_string()
    })?;
    if !text.trim_start().to_ascii_lowercase().starts_with("solid") {
        return Err(
            "not a valid STL: neither a binary STL (size mismatch) nor an ASCII one (no 'solid' header)".into(),
        );
    }
    parse_stl_ascii(text)
}

fn parse_stl_binary(bytes: &[u8], n: usize) -> std::result::Result<TriMesh, String> {
    if n == 0 {
        return Err("the binary STL holds zero triangles".into());
    }
    let mut w = Welder::new();
    let mut faces = Vec::with_capacity(n);
    for t in 0..n {
        if cancelled_at(t) {
            return Err(CANCELLED.into());
        }
        let base = 84 + 50 * t + 12;
        let mut corner = |k: usize| {
            let o = base + 12 * k;
            let f = |i: usize| f32::from_le_bytes(bytes[o + 4 * i..o + 4 * i + 4].try_into().unwrap()) as f64;
            w.add([f(0), f(1), f(2)])
        };
        faces.push([corner(0), corner(1), corner(2)]);
    }
    Ok(TriMesh {
        vertices: w.vertices,
        faces,
    })
}

fn parse_stl_ascii(text: &str) -> std::result::Result<TriMesh, String> {
    let mut w = Welder::new();
    let mut faces = Vec::new();
    let mut corners: Vec<u32> = Vec::with_capacity(3);
    for (lineno, line) in text.lines().enumerate() {
        if cancelled_at(lineno) {
            return Err(CANCELLED.into());
        }
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                let v: Vec<f64> = it
                    .map(|s| s.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| format!("line {}: a vertex with a bad number: {line:?}", lineno + 1))?;
                if v.len() != 3 {
                    return Err(format!("line {}: a vertex needs 3 coordinates: {line:?}", lineno + 1));
                }
                corners.push(w.add([v[0], v[1], v[2]]));
            }
            Some("endloop") => {
                if corners.len() != 3 {
                    return Err(format!(
                        "line {}: a facet with {} vertices; STL facets have 3",
                        lineno + 1,
                        corners.len()
                    ));
                }
                faces.push([corners[0], corners[1], corners[2]]);
                corners.clear();
            }
            _ => {}
        }
    }
    if faces.is_empty() {
        return Err("the ASCII STL holds no complete facet".into());
    }
    Ok(TriMesh {
        vertices: w.vertices,
        faces,
    })
}

fn parse_obj(bytes: &[u8]) -> std::result::Result<TriMesh, String> {
    let text = String::from_utf8_lossy(bytes);
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for (lineno, line) in text.lines().enumerate() {
        if cancelled_at(lineno) {
            return Err(CANCELLED.into());
        }
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let v: Vec<f64> = it
                    .take(3)
                    .map(|s| s.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| format!("line {}: a vertex with a bad number: {line:?}", lineno + 1))?;
                if v.len() != 3 {
                    return Err(format!("line {}: a vertex needs 3 coordinates: {line:?}", lineno + 1));
                }
                vertices.push(Point::new(v[0], v[1], v[2]));
            }
            Some("f") => {
                let mut idx = Vec::new();
                for tok in it {
                    let first = tok.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| format!("line {}: a face index that is not a number: {tok:?}", lineno + 1))?;
                    let n = vertices.len() as i64;
                    let resolved = if i > 0 {
                        i - 1
                    } else if i < 0 {
                        n + i
                    } else {
                        -1
                    };
                    if resolved < 0 || resolved >= n {
                        return Err(format!(
                            "line {}: face index {i} refers to no vertex (only {n} defined so far)",
                            lineno + 1
                        ));
                    }
                    idx.push(resolved as u32);
                }
                if idx.len() < 3 {
                    return Err(format!("line {}: a face needs at least 3 vertices", lineno + 1));
                }
                for k in 1..idx.len() - 1 {
                    faces.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if faces.is_empty() {
        return Err("the OBJ file defines no face".into());
    }
    Ok(TriMesh { vertices, faces })
}

/// What a PLY file holds: points, optional normals, and faces if it is a mesh.
#[derive(Debug, Clone, Default)]
pub struct PlyData {
    /// Vertex positions.
    pub points: Vec<Point>,
    /// Vertex normals, if the file has nx, ny, nz.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Triangles (polygons fan-triangulated); empty for a point cloud.
    pub faces: Vec<[u32; 3]>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn read(self, b: &[u8], big: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => rd!(i16, 2),
            Scalar::U16 => rd!(u16, 2),
            Scalar::I32 => rd!(i32, 4),
            Scalar::U32 => rd!(u32, 4),
            Scalar::F32 => rd!(f32, 4),
            Scalar::F64 => rd!(f64, 8),
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(PartialEq)]
enum PlyFormat {
    Ascii,
    BinaryLe,
    BinaryBe,
}

/// Parses PLY bytes (ASCII, binary little- or big-endian).
fn parse_ply(bytes: &[u8]) -> std::result::Result<PlyData, String> {
    if !bytes.starts_with(b"ply") {
        return Err("not a PLY file: it does not start with 'ply'".into());
    }
    let end = find_header_end(bytes).ok_or("the PLY header has no 'end_header' line")?;
    let header = std::str::from_utf8(&bytes[..end.0]).map_err(|_| "the PLY header is not text")?;
    let (format, elements) = parse_header(header)?;
    let body = &bytes[end.1..];
    for el in &elements {
        check_element_fits(el, &format, body.len())?;
    }
    let ascii = match format {
        PlyFormat::Ascii => Some(
            std::str::from_utf8(body)
                .map_err(|_| "the ASCII PLY body is not text")?
                .split_ascii_whitespace(),
        ),
        _ => None,
    };
    let mut reader = Body {
        ascii,
        bytes: body,
        pos: 0,
        big: format == PlyFormat::BinaryBe,
    };
    let mut out = PlyData::default();
    for el in &elements {
        read_element(el, &mut reader, &mut out)?;
    }
    let n = out.points.len() as u32;
    if let Some(f) = out.faces.iter().find(|f| f.iter().any(|&v| v >= n)) {
        return Err(format!(
            "a face {f:?} indexes past the {n} vertices; the file is corrupt"
        ));
    }
    Ok(out)
}

/// Refuses an element whose declared rows cannot fit in the body's `available` bytes, before any
/// row is read: a binary row takes at least the sum of its scalar sizes (a list at least its count
/// field), an ASCII row at least one character and one separator per property.
fn check_element_fits(el: &Element, format: &PlyFormat, available: usize) -> std::result::Result<(), String> {
    let min_row: usize = el
        .props
        .iter()
        .map(|p| match (format, p) {
            (PlyFormat::Ascii, _) => 2,
            (_, Property::Scalar(_, t)) => t.size(),
            (_, Property::List(_, c, _)) => c.size(),
        })
        .sum();
    let needed = el.count.checked_mul(min_row).map(|b| b.saturating_sub(1));
    match needed {
        Some(b) if b <= available => Ok(()),
        _ => Err(format!(
            "element {} declares {} rows of at least {min_row} bytes each, but the body holds only {available} \
             bytes; the header lies or the file is truncated",
            el.name, el.count
        )),
    }
}

/// The body's format and its elements with their properties, from the header's lines.
fn parse_header(header: &str) -> std::result::Result<(PlyFormat, Vec<Element>), String> {
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in header.lines().skip(1) {
        let tok: Vec<&str> = line.split_whitespace().collect();
        match tok.first().copied() {
            Some("format") => {
                format = Some(match tok.get(1).copied() {
                    Some("ascii") => PlyFormat::Ascii,
                    Some("binary_little_endian") => PlyFormat::BinaryLe,
                    Some("binary_big_endian") => PlyFormat::BinaryBe,
                    other => return Err(format!("unknown PLY format {other:?}")),
                })
            }
            Some("element") => {
                let name = tok.get(1).ok_or("an element line without a name")?.to_string();
                let count = tok
                    .get(2)
                    .and_then(|c| c.parse().ok())
                    .ok_or(format!("element {name} has no valid count"))?;
                elements.push(Element {
                    name,
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let el = elements.last_mut().ok_or("a property before any element")?;
                el.props.push(parse_property(&tok, line)?);
            }
            _ => {}
        }
    }
    Ok((format.ok_or("the PLY header has no format line")?, elements))
}

/// One `property` line, split into tokens.
fn parse_property(tok: &[&str], line: &str) -> std::result::Result<Property, String> {
    if tok.get(1) == Some(&"list") {
        let (c, i, n) = (tok.get(2), tok.get(3), tok.get(4));
        let c = c
            .and_then(|s| Scalar::parse(s))
            .ok_or(format!("bad list count type in {line:?}"))?;
        let i = i
            .and_then(|s| Scalar::parse(s))
            .ok_or(format!("bad list item type in {line:?}"))?;
        Ok(Property::List(n.unwrap_or(&"").to_string(), c, i))
    } else {
        let t = tok
            .get(1)
            .and_then(|s| Scalar::parse(s))
            .ok_or(format!("bad property type in {line:?}"))?;
        Ok(Property::Scalar(tok.get(2).unwrap_or(&"").to_string(), t))
    }
}

/// The PLY body, read value by value: whitespace-separated numbers, or binary scalars.
struct Body<'a> {
    ascii: Option<std::str::SplitAsciiWhitespace<'a>>,
    bytes: &'a [u8],
    pos: usize,
    big: bool,
}

impl Body<'_> {
    /// The next value, of type `t` in a binary body.
    fn next(&mut self, t: Scalar) -> std::result::Result<f64, String> {
        match self.ascii.as_mut() {
            Some(it) => {
                let s = it
                    .next()
                    .ok_or("the ASCII PLY body ends early; the file is truncated")?;
                s.parse::<f64>()
                    .map_err(|_| format!("a value that is not a number: {s:?}"))
            }
            None => {
                let n = t.size();
                if self.pos + n > self.bytes.len() {
                    return Err("the binary PLY body ends early; the file is truncated".into());
                }
                let v = t.read(&self.bytes[self.pos..], self.big);
                self.pos += n;
                Ok(v)
            }
        }
    }
}

/// Reads one element's rows: vertices (with normals when it has nx, ny, nz) and faces (fanned
/// into triangles) go into `out`; other elements are read past.
fn read_element(el: &Element, body: &mut Body<'_>, out: &mut PlyData) -> std::result::Result<(), String> {
    let is_vertex = el.name == "vertex";
    let is_face = el.name == "face";
    let names: Vec<&str> = el
        .props
        .iter()
        .map(|p| match p {
            Property::Scalar(n, _) | Property::List(n, _, _) => n.as_str(),
        })
        .collect();
    let col = |n: &str| names.iter().position(|x| *x == n);
    let (xi, yi, zi) = (col("x"), col("y"), col("z"));
    let (nxi, nyi, nzi) = (col("nx"), col("ny"), col("nz"));
    if is_vertex && (xi.is_none() || yi.is_none() || zi.is_none()) {
        return Err("the PLY vertex element lacks x, y or z".into());
    }
    let has_normals = is_vertex && nxi.is_some() && nyi.is_some() && nzi.is_some();
    let mut normals = Vec::new();
    if el.props.is_empty() {
        // Rows without properties hold no bytes: nothing to read, however many are declared.
        return Ok(());
    }
    let mut row = vec![0.0; el.props.len()];
    for r in 0..el.count {
        if cancelled_at(r) {
            return Err(CANCELLED.into());
        }
        let mut list: Vec<u32> = Vec::new();
        for (k, p) in el.props.iter().enumerate() {
            match p {
                Property::Scalar(_, t) => row[k] = body.next(*t)?,
                Property::List(name, ct, it) => {
                    let n = body.next(*ct)?;
                    if !(0.0..1e6).contains(&n) || n.fract() != 0.0 {
                        return Err(format!("{} row {r}: a list of {n} items; the file is corrupt", el.name));
                    }
                    let keep = is_face && (name == "vertex_indices" || name == "vertex_index");
                    for _ in 0..n as usize {
                        let v = body.next(*it)?;
                        if keep {
                            list.push(face_index(v, r)?);
                        }
                    }
                }
            }
        }
        if is_vertex {
            let p = Point::new(row[xi.unwrap()], row[yi.unwrap()], row[zi.unwrap()]);
            if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
                return Err(format!(
                    "vertex row {r} has a non-finite coordinate {p:?}; the file is corrupt"
                ));
            }
            out.points.push(p);
            if has_normals {
                let n = Vector3::new(row[nxi.unwrap()], row[nyi.unwrap()], row[nzi.unwrap()]);
                if !n.iter().all(|v| v.is_finite()) {
                    return Err(format!(
                        "vertex row {r} has a non-finite normal {n:?}; the file is corrupt"
                    ));
                }
                normals.push(n);
            }
        }
        if is_face && list.len() >= 3 {
            for k in 1..list.len() - 1 {
                out.faces.push([list[0], list[k], list[k + 1]]);
            }
        }
    }
    if has_normals {
        out.normals = Some(normals);
    }
    Ok(())
}

/// A face's vertex index as stored: a non-negative integer that fits a `u32` (checked against the
/// vertex count once all elements are read).
fn face_index(v: f64, row: usize) -> std::result::Result<u32, String> {
    if v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64 {
        Ok(v as u32)
    } else {
        Err(format!(
            "face row {row}: vertex index {v} is not a non-negative integer; the file is corrupt"
        ))
    }
}

/// (end of the header text, start of the body) after the `end_header` line.
fn find_header_end(bytes: &[u8]) -> Option<(usize, usize)> {
    let pat = b"end_header";
    let at = bytes.windows(pat.len()).position(|w| w == pat)?;
    let mut body = at + pat.len();
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) == Some(&b'\n') {
        body += 1;
    }
    Some((at, body))
}

/// Reads a PLY point cloud (or the vertices of a PLY mesh) with normals when present.
pub fn read_ply(path: &Path) -> Result<PlyData> {
    let shown = path.display().to_string();
    let bytes = read_bytes(path)?;
    let data = parse_ply(&bytes).map_err(|p| Error::bad_file(shown.clone(), p))?;
    if data.points.is_empty() {
        return Err(Error::bad_file(shown, "the PLY file holds no vertex"));
    }
    Ok(data)
}

/// Writes points (and normals) as a PLY file, binary little-endian (float64) or ASCII.
pub fn write_ply(path: &Path, points: &[Point], normals: Option<&[Vector3<f64>]>, ascii: bool) -> Result<()> {
    let shown = path.display().to_string();
    if points.is_empty() {
        // read_ply refuses a file without a vertex, so an empty cloud is refused here too: what
        // write_ply writes, read_ply reads back.
        return Err(Error::invalid(
            "points",
            "is empty; a PLY point cloud needs at least one point (skip writing an empty cloud)",
        ));
    }
    if let Some(n) = normals {
        if n.len() != points.len() {
            return Err(Error::invalid(
                "normals",
                format!("has {} rows but points has {}", n.len(), points.len()),
            ));
        }
    }
    let mut buf: Vec<u8> = Vec::with_capacity(64 + points.len() * 48);
    let fmt = if ascii { "ascii" } else { "binary_little_endian" };
    write!(buf, "ply\nformat {fmt} 1.0\ncomment written by binpick, units mm\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\n", points.len()).unwrap();
    if normals.is_some() {
        buf.extend_from_slice(b"property double nx\nproperty double ny\nproperty double nz\n");
    }
    buf.extend_from_slice(b"end_header\n");
    for (i, p) in points.iter().enumerate() {
        let mut vals = vec![p.x, p.y, p.z];
        if let Some(n) = normals {
            vals.extend_from_slice(&[n[i].x, n[i].y, n[i].z]);
        }
        if ascii {
            let line: Vec<String> = vals.iter().map(|v| format!("{v:?}")).collect();
            buf.extend_from_slice(line.join(" ").as_bytes());
            buf.push(b'\n');
        } else {
            for v in vals {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, buf).map_err(|e| Error::WriteFailed {
        path: shown,
        reason: e.to_string(),
    })
}

#[cfg(test)]
#[path = "io_guards.rs"]
pub(crate) mod guards;

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra_ascii_stl() -> String {
        let tris = [
            [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        ];
        let mut s = String::from("solid t\n");
        for t in tris {
            s.push_str("facet normal 0 0 0\nouter loop\n");
            for v in t {
                s.push_str(&format!("vertex {} {} {}\n", v[0], v[1], v[2]));
            }
            s.push_str("endloop\nendfacet\n");
        }
        s.push_str("endsolid t\n");
        s
    }

    #[test]
    fn ascii_stl_welds_corners() {
        let m = parse_stl(tetra_ascii_stl().as_bytes()).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.faces.len(), 4);
        assert!((m.volume() - 1.0 / 6.0).abs() < 1e-12);
    }

    #[test]
    fn ply_binary_roundtrip() {
        let dir = std::env::temp_dir().join(format!("binpick-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pts = vec![Point::new(1.0, 2.0, 3.0), Point::new(-4.5, 0.25, 1e-3)];
        let ns = vec![Vector3::z(), Vector3::x()];
        for ascii in [false, true] {
            let p = dir.join(format!("c{ascii}.ply"));
            write_ply(&p, &pts, Some(&ns), ascii).unwrap();
            let back = read_ply(&p).unwrap();
            assert_eq!(back.points, pts);
            assert_eq!(back.normals.unwrap(), ns);
        }
    }

    #[test]
    fn obj_polygons_and_negative_indices() {
        let m = parse_obj(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n").unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(parse_obj(b"v 0 0 0\nf 1 2 3\n").is_err());
    }
}
