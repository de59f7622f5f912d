//! The readers never trust a header: counts against bytes, indices against vertices, values
//! finite; and a bounded byte-mutation fuzz in which every outcome is Ok or Err, never a panic.

use super::*;
use crate::rng::Rng;

fn ascii_ply(body: &str, faces: usize) -> Vec<u8> {
    format!(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         element face {faces}\nproperty list uchar int vertex_indices\nend_header\n{body}"
    )
    .into_bytes()
}

const TETRA: &str = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n";

#[test]
fn huge_count_of_an_unused_element_fails_at_once_naming_it() {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement junk 18446744073709551615\nproperty uchar a\n".to_vec();
    b.extend_from_slice(b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
    b.extend_from_slice(&[0u8; 12]);
    let t = std::time::Instant::now();
    let err = parse_ply(&b).unwrap_err();
    assert!(t.elapsed().as_millis() < 100);
    assert!(
        err.contains("element junk") && err.contains("holds only 12 bytes"),
        "{err}"
    );
    // The same in ASCII, and with a count that overflows rows × bytes.
    let a =
        b"ply\nformat ascii 1.0\nelement junk 9223372036854775807\nproperty int a\nproperty int b\nend_header\n1 2\n";
    assert!(parse_ply(a).unwrap_err().contains("element junk"));
}

#[test]
fn an_element_without_properties_is_skipped_however_many_rows_it_declares() {
    let b = b"ply\nformat ascii 1.0\nelement junk 18446744073709551615\nelement vertex 1\nproperty float x\n\
property float y\nproperty float z\nend_header\n1 2 3\n";
    assert_eq!(parse_ply(b).unwrap().points, vec![Point::new(1.0, 2.0, 3.0)]);
}

#[test]
fn face_indices_must_be_non_negative_integers_below_the_vertex_count() {
    assert_eq!(parse_ply(&ascii_ply(TETRA, 4)).unwrap().faces.len(), 4);
    for bad in ["3 -1 2.9 3\n", "3 0 1 2.5\n", "3 0 1 4\n", "2.5 0 1 2\n"] {
        let body = format!("0 0 0\n1 0 0\n0 1 0\n0 0 1\n{bad}");
        let err = parse_ply(&ascii_ply(&body, 1)).unwrap_err();
        assert!(err.contains("corrupt"), "{bad}: {err}");
    }
}

#[test]
fn non_finite_vertices_and_normals_name_the_row() {
    let err = parse_ply(&ascii_ply("0 0 0\n1 0 0\nnan 1 0\n0 0 1\n", 0)).unwrap_err();
    assert!(err.contains("vertex row 2"), "{err}");
    let n = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
property float nx\nproperty float ny\nproperty float nz\nend_header\n0 0 0 0 0 1\n1 0 0 inf 0 1\n";
    let err = parse_ply(n).unwrap_err();
    assert!(err.contains("vertex row 1") && err.contains("normal"), "{err}");
}

#[test]
fn binary_stl_with_a_lying_count_is_not_read_as_binary() {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&u32::MAX.to_le_bytes());
    b.extend_from_slice(&[0u8; 50]);
    assert!(parse_stl(&b).unwrap_err().contains("not a valid STL"));
}

#[test]
fn obj_indices_past_the_vertices_or_huge_are_refused() {
    for f in [
        "f 1 2 4",
        "f 0 1 2",
        "f -9223372036854775808 1 2",
        "f 99999999999999999999 1 2",
    ] {
        let text = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{f}\n");
        assert!(parse_obj(text.as_bytes()).is_err(), "{f}");
    }
}

#[test]
fn an_empty_cloud_is_refused_by_write_ply_as_read_ply_refuses_it() {
    let p = std::env::temp_dir().join(format!("binpick-empty-{}.ply", std::process::id()));
    let err = write_ply(&p, &[], None, false).unwrap_err();
    assert!(err.to_string().contains("points"), "{err}");
    assert!(!p.exists());
}

/// Byte-mutates `seed` `cases` times (flips, overwrites with digits and extremes, truncations,
/// insertions) and feeds each to `parse`; returns (ok, err), panicking the test on any panic.
pub(crate) fn fuzz(seed: &[u8], cases: usize, rng_seed: u64, parse: impl Fn(&[u8]) -> bool) -> (usize, usize) {
    let mut rng = Rng::new(rng_seed);
    let (mut ok, mut err, mut panics) = (0, 0, 0);
    for _ in 0..cases {
        let mut b = seed.to_vec();
        for _ in 0..1 + rng.below(4) {
            let at = rng.below(b.len().max(1));
            match rng.below(5) {
                0 => b[at] ^= 1 << rng.below(8),
                1 => b[at] = b"0123456789-.e9"[rng.below(14)],
                2 => b.truncate(at),
                3 => b.splice(at..at, b"99999999999999999999".iter().copied()).for_each(drop),
                _ => b[at] = [0u8, 0xff, b' ', b'\n'][rng.below(4)],
            }
            if b.is_empty() {
                b.push(b'p');
            }
        }
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse(&b))) {
            Ok(true) => ok += 1,
            Ok(false) => err += 1,
            Err(_) => panics += 1,
        }
    }
    assert_eq!(panics, 0, "{panics} panics in {cases} cases");
    (ok, err)
}

fn binary_tetra_ply() -> Vec<u8> {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for v in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]] {
        v.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    }
    for f in [[0i32, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]] {
        b.push(3);
        f.iter().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    }
    b
}

fn ascii_stl() -> String {
    let v = ["0 0 0", "1 0 0", "0 1 0", "0 0 1"];
    let mut s = String::from("solid t\n");
    for f in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        s.push_str("facet normal 0 0 0\nouter loop\n");
        f.iter().for_each(|&k| s.push_str(&format!("vertex {}\n", v[k])));
        s.push_str("endloop\nendfacet\n");
    }
    s + "endsolid t\n"
}

fn binary_tetra_stl() -> Vec<u8> {
    let m = parse_stl(ascii_stl().as_bytes()).unwrap();
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&(m.faces.len() as u32).to_le_bytes());
    for f in &m.faces {
        b.extend_from_slice(&[0u8; 12]);
        for &v in f {
            let p = m.vertices[v as usize];
            [p.x, p.y, p.z]
                .iter()
                .for_each(|x| b.extend_from_slice(&(*x as f32).to_le_bytes()));
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}

#[test]
fn byte_mutation_fuzz_of_the_mesh_readers_never_panics() {
    let ply = |b: &[u8]| parse_ply(b).is_ok();
    let stl = |b: &[u8]| parse_stl(b).is_ok();
    let obj = |b: &[u8]| parse_obj(b).is_ok();
    let obj_text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf -4 -2 -1\nf 2/1 3/1 4/1\n";
    type Reader<'a> = &'a dyn Fn(&[u8]) -> bool;
    let runs: [(&str, Vec<u8>, Reader); 5] = [
        ("ply ascii", ascii_ply(TETRA, 4), &ply),
        ("ply binary", binary_tetra_ply(), &ply),
        ("stl ascii", ascii_stl().as_bytes().to_vec(), &stl),
        ("stl binary", binary_tetra_stl(), &stl),
        ("obj", obj_text.to_vec(), &obj),
    ];
    for (k, (name, seed, parse)) in runs.iter().enumerate() {
        let (ok, err) = fuzz(seed, 400, 16 + k as u64, parse);
        eprintln!("fuzz {name}: 400 cases, {ok} Ok, {err} Err, 0 panics");
        assert_eq!(ok + err, 400);
    }
}

/// A device is not a mesh file: reading `/dev/zero` would never end (or end with the memory).
#[cfg(unix)]
#[test]
fn a_device_is_refused_before_anything_is_read() {
    let dir = std::env::temp_dir().join(format!("binpick-dev-zero-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("zero.ply");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    for r in [read_ply(&link).map(|_| ()), read_mesh(&link).map(|_| ())] {
        match r {
            Err(Error::BadFile { problem, .. }) => assert!(problem.contains("not a regular file"), "{problem}"),
            other => panic!("/dev/zero was read as a file: {other:?}"),
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
