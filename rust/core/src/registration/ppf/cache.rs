//! The table as bytes, for a cache on disk: a versioned little-endian layout.

use super::*;

const MAGIC: &[u8; 8] = b"BPPPF\x00\x00\x03";

/// Bytes before the points: magic, two f64 and four u32.
const HEADER_LEN: usize = 8 + 16 + 16;

impl PpfModel {
    /// Serialises the model (for a cache on disk): a versioned little-endian byte layout.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + self.points.len() * 48 + self.entries.len() * 4);
        out.extend_from_slice(MAGIC);
        for v in [self.config.sampling_ratio, self.diameter] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in [
            self.config.angle_bins,
            self.config.rotation_bins,
            self.points.len() as u32,
            self.entries.len() as u32,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for (p, n) in self.points.iter().zip(&self.normals) {
            for v in [p.x, p.y, p.z, n.x, n.y, n.z] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        for &(i, a) in &self.entries {
            out.extend_from_slice(&i.to_le_bytes());
            out.extend_from_slice(&a.to_le_bytes());
        }
        // The key table is mostly empty: store (key, count) of the keys that hold pairs.
        let used: Vec<(u32, u32)> = self
            .offsets
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1] > w[0])
            .map(|(k, w)| (k as u32, w[1] - w[0]))
            .collect();
        out.extend_from_slice(&(used.len() as u32).to_le_bytes());
        for (k, c) in used {
            out.extend_from_slice(&k.to_le_bytes());
            out.extend_from_slice(&c.to_le_bytes());
        }
        out
    }

    /// Reads what [`PpfModel::to_bytes`] wrote; any mismatch is an error (the caller rebuilds).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let bad = |what: &str| {
            Error::invalid(
                "ppf_cache",
                format!("{what}; the cache file is stale or corrupt and will be rebuilt"),
            )
        };
        let mut at = 0usize;
        let mut take = |n: usize| -> Result<&[u8]> {
            let s = at
                .checked_add(n)
                .and_then(|end| bytes.get(at..end))
                .ok_or_else(|| bad("truncated"))?;
            at += n;
            Ok(s)
        };
        if take(8)? != MAGIC {
            return Err(bad("wrong magic or version"));
        }
        let f64_at = |s: &[u8]| f64::from_le_bytes(s.try_into().expect("8 bytes"));
        let u32_at = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes"));
        let sampling_ratio = f64_at(take(8)?);
        let diameter = f64_at(take(8)?);
        let angle_bins = u32_at(take(4)?);
        let rotation_bins = u32_at(take(4)?);
        let n = u32_at(take(4)?) as usize;
        let m = u32_at(take(4)?) as usize;
        let config = PpfConfig {
            sampling_ratio,
            angle_bins,
            rotation_bins,
        };
        config.validate().map_err(|_| bad("invalid parameters"))?;
        if !(diameter.is_finite() && diameter > 0.0 && (4..=60_000).contains(&n)) || m > n * n {
            return Err(bad("invalid sizes"));
        }
        // Nothing is allocated for rows the bytes do not hold: n points of 48 bytes, m pairs of 4
        // and the 4-byte key count must all be present.
        let needed = n
            .checked_mul(48)
            .and_then(|p| m.checked_mul(4).and_then(|e| p.checked_add(e)))
            .and_then(|b| b.checked_add(4));
        let after_header = bytes.len() - HEADER_LEN;
        let Some(tail) = needed.and_then(|b| after_header.checked_sub(b)) else {
            return Err(bad(&format!(
                "it declares {n} points and {m} pairs but holds only {after_header} bytes after its header"
            )));
        };
        let mut points = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        for _ in 0..n {
            let s = take(48)?;
            let v: Vec<f64> = s.chunks_exact(8).map(f64_at).collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(bad("non-finite point"));
            }
            points.push(Point::new(v[0], v[1], v[2]));
            normals.push(Vector3::new(v[3], v[4], v[5]));
        }
        let mut entries = Vec::with_capacity(m);
        for _ in 0..m {
            let s = take(4)?;
            let i = u16::from_le_bytes([s[0], s[1]]);
            if i as usize >= n {
                return Err(bad("pair index out of range"));
            }
            entries.push((i, u16::from_le_bytes([s[2], s[3]])));
        }
        let step = sampling_ratio * diameter;
        let distance_bins = (diameter / step).ceil() as u32 + 2;
        let frames = points.iter().zip(&normals).map(|(p, n)| Frame::new(p, n)).collect();
        let mut model = PpfModel {
            config,
            step,
            diameter,
            points,
            normals,
            frames,
            distance_bins,
            offsets: Vec::new(),
            entries,
        };
        let keys = model.key_count();
        let used = u32_at(take(4)?) as usize;
        if used > m.min(keys) || used.checked_mul(8) != Some(tail) {
            return Err(bad("inconsistent table"));
        }
        let mut counts = vec![0u32; keys + 1];
        let mut previous: Option<u32> = None;
        for _ in 0..used {
            let (k, c) = (u32_at(take(4)?), u32_at(take(4)?));
            if k as usize >= keys || c == 0 || previous.is_some_and(|p| k <= p) {
                return Err(bad("inconsistent table"));
            }
            counts[k as usize + 1] = c;
            previous = Some(k);
        }
        for k in 0..keys {
            counts[k + 1] = counts[k]
                .checked_add(counts[k + 1])
                .ok_or_else(|| bad("inconsistent table"))?;
        }
        if at != bytes.len() || counts[keys] as usize != m {
            return Err(bad("inconsistent table"));
        }
        model.offsets = counts;
        Ok(model)
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{box_mesh, prepared};
    use super::*;
    use crate::mesh::{sample_surface, Density};

    fn small_cache() -> (PpfModel, Vec<u8>) {
        let mesh = box_mesh(20.0, 15.0, 10.0);
        let s = sample_surface(&mesh, Density::Spacing(2.0), 3).unwrap();
        let model = prepared(&s.points, &s.normals, mesh.diameter());
        let bytes = model.to_bytes();
        (model, bytes)
    }

    #[test]
    fn lying_counts_fail_before_allocating_what_the_bytes_do_not_hold() {
        let (model, bytes) = small_cache();
        let n = model.points.len() as u32;
        // m up to n² passes the old size check yet would reserve up to 14 GB of pairs.
        for (field, value) in [(36, n * n), (36, n * n / 2), (32, 60_000), (32, n + 1)] {
            let mut bad = bytes.clone();
            bad[field..field + 4].copy_from_slice(&value.to_le_bytes());
            let err = PpfModel::from_bytes(&bad).unwrap_err().to_string();
            assert!(err.contains("ppf_cache"), "{err}");
        }
        let mut bad = bytes.clone();
        bad.truncate(HEADER_LEN + 48 * n as usize);
        assert!(PpfModel::from_bytes(&bad)
            .unwrap_err()
            .to_string()
            .contains("holds only"));
    }

    #[test]
    fn byte_mutation_fuzz_of_the_cache_never_panics() {
        let (_, bytes) = small_cache();
        let parse = |b: &[u8]| PpfModel::from_bytes(b).is_ok();
        let (ok, err) = crate::mesh::io::guards::fuzz(&bytes, 300, 7, parse);
        eprintln!("fuzz ppf cache: 300 cases, {ok} Ok, {err} Err, 0 panics");
        assert_eq!(ok + err, 300);
    }
}
