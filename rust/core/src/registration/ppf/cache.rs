//! The table as bytes, for a cache on disk: a versioned little-endian layout.

use super::*;

const MAGIC: &[u8; 8] = b"BPPPF\x00\x00\x03";

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
            let s = bytes.get(at..at + n).ok_or_else(|| bad("truncated"))?;
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
        if used > m.min(keys) {
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
