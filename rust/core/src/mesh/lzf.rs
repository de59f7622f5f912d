//! LZF decompression (liblzf's format), the codec of PCL's `binary_compressed` point clouds.
//!
//! The stream is a sequence of tokens, each opening with a control byte `c`: `c < 32` is a
//! literal run (the next `c + 1` bytes as they are); otherwise a back-reference of `(c >> 5) + 2`
//! bytes (when `c >> 5` is 7 the next byte adds to it), copied from `((c & 31) << 8) + next + 1`
//! bytes back in the output, the copy overlapping what it writes when the distance is shorter.

/// Most bytes one input byte can stand for: a 3-byte back-reference copies at most 264 bytes.
pub const LZF_MAX_RATIO: usize = 88;

/// Decompresses `data` to exactly `size` bytes; a stream that runs past its input, refers before
/// the output's start or does not unpack to `size` bytes is an `Err` naming the byte where it
/// went wrong. Allocates no more than the input can unpack to, whatever `size` claims.
pub fn lzf_decompress(data: &[u8], size: usize) -> std::result::Result<Vec<u8>, String> {
    let mut out: Vec<u8> = Vec::with_capacity(size.min(data.len().saturating_mul(LZF_MAX_RATIO)));
    let n = data.len();
    let mut i = 0usize;
    while i < n {
        let c = usize::from(data[i]);
        let at = i;
        i += 1;
        if c < 32 {
            let run = c + 1;
            if i + run > n || out.len() + run > size {
                return Err(format!(
                    "a literal run of {run} bytes at input byte {at} runs past the data"
                ));
            }
            out.extend_from_slice(&data[i..i + run]);
            i += run;
            continue;
        }
        let mut length = c >> 5;
        if length == 7 {
            if i >= n {
                return Err(format!(
                    "the back-reference at input byte {at} stops before its length byte"
                ));
            }
            length += usize::from(data[i]);
            i += 1;
        }
        if i >= n {
            return Err(format!(
                "the back-reference at input byte {at} stops before its offset byte"
            ));
        }
        let back = ((c & 31) << 8) + usize::from(data[i]) + 1;
        i += 1;
        length += 2;
        if back > out.len() {
            return Err(format!(
                "a back-reference {back} bytes back at output byte {} is out of range",
                out.len()
            ));
        }
        if out.len() + length > size {
            return Err(format!("the data unpacks to more than the {size} bytes declared"));
        }
        let start = out.len() - back;
        if back >= length {
            out.extend_from_within(start..start + length);
        } else {
            // Overlapping: the last `back` bytes repeat.
            for k in 0..length {
                let b = out[start + k];
                out.push(b);
            }
        }
    }
    if out.len() != size {
        return Err(format!(
            "the data unpacks to {} bytes, not the {size} declared",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_and_overlapping_references_unpack() {
        // "abc" as a literal run, then 6 bytes copied from 3 back (overlapping): "abcabcabc".
        let data = [2u8, b'a', b'b', b'c', (4 << 5), 2];
        assert_eq!(lzf_decompress(&data, 9).unwrap(), b"abcabcabc");
        // A long reference: length 7 + 10 + 2 = 19 bytes of 'x' from 1 back.
        let data = [0u8, b'x', (7 << 5), 10, 0];
        assert_eq!(lzf_decompress(&data, 20).unwrap(), vec![b'x'; 20]);
    }

    #[test]
    fn corrupt_streams_are_errors_not_panics() {
        assert!(lzf_decompress(&[5, b'a'], 6).unwrap_err().contains("literal run"));
        assert!(lzf_decompress(&[(1 << 5), 0], 3).unwrap_err().contains("out of range"));
        assert!(lzf_decompress(&[0, b'a', (7 << 5)], 12)
            .unwrap_err()
            .contains("length byte"));
        assert!(lzf_decompress(&[0, b'a'], 2)
            .unwrap_err()
            .contains("not the 2 declared"));
        assert!(lzf_decompress(&[0, b'a', (1 << 5), 0], 2)
            .unwrap_err()
            .contains("more than"));
        // A size far beyond what the input can hold allocates only what the input could unpack to.
        assert!(lzf_decompress(&[0, b'a'], usize::MAX).is_err());
    }
}
