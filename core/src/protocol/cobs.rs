//! Consistent Overhead Byte Stuffing: removes every 0x00 from a packet so that
//! 0x00 can delimit packets on the wire. Worst-case overhead is one byte per
//! 254 bytes plus one.

/// The output buffer is too small for the encoded or decoded data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferTooSmall;

/// Malformed COBS input: a zero inside the data or a code running past the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CobsError;

/// Largest encoded size of `n` raw bytes (without the 0x00 delimiter).
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Encodes `src` into `dst` (no delimiter); returns the encoded length.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Result<usize, BufferTooSmall> {
    if dst.len() < max_encoded_len(src.len()) {
        return Err(BufferTooSmall);
    }
    let mut code_at = 0;
    let mut out = 1;
    let mut code: u8 = 1;
    for &b in src {
        if b == 0 {
            dst[code_at] = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            dst[out] = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                dst[code_at] = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    Ok(out)
}

/// Decodes `buf[..len]` in place (the output never overtakes the input);
/// returns the decoded length.
pub fn decode_in_place(buf: &mut [u8]) -> Result<usize, CobsError> {
    let len = buf.len();
    let mut read = 0;
    let mut write = 0;
    while read < len {
        let code = buf[read] as usize;
        if code == 0 || read + code > len {
            return Err(CobsError);
        }
        read += 1;
        // Data bytes of this block: copy forward (write <= read always holds).
        for _ in 1..code {
            let b = buf[read];
            if b == 0 {
                return Err(CobsError);
            }
            buf[write] = b;
            write += 1;
            read += 1;
        }
        // A block shorter than 254 data bytes stands for a zero, except at the end.
        if code != 0xFF && read < len {
            buf[write] = 0;
            write += 1;
        }
    }
    Ok(write)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(src: &[u8]) {
        let mut enc = [0u8; 1200];
        let n = encode(src, &mut enc).unwrap();
        assert!(n <= max_encoded_len(src.len()));
        assert!(!enc[..n].contains(&0), "encoded data must not contain 0x00");
        let m = decode_in_place(&mut enc[..n]).unwrap();
        assert_eq!(&enc[..m], src);
    }

    #[test]
    fn known_vectors() {
        // Vectors from the COBS paper / Wikipedia.
        let cases: &[(&[u8], &[u8])] = &[
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, enc) in cases {
            let mut out = [0u8; 16];
            let n = encode(raw, &mut out).unwrap();
            assert_eq!(&out[..n], *enc);
        }
    }

    #[test]
    fn long_runs_roundtrip() {
        let mut v = [0u8; 1000];
        for (i, b) in v.iter_mut().enumerate() {
            *b = (i % 255 + 1) as u8;
        }
        roundtrip(&v);
        roundtrip(&v[..254]);
        roundtrip(&v[..255]);
        roundtrip(&[]);
        v[300] = 0;
        v[999] = 0;
        roundtrip(&v);
        let mut enc = [0u8; 1200];
        let n = encode(&v[..254], &mut enc).unwrap();
        assert_eq!(
            n, 256,
            "254 non-zero bytes: one full block plus the final code"
        );
    }

    #[test]
    fn rejects_malformed() {
        assert_eq!(decode_in_place(&mut [0x05, 0x11]), Err(CobsError));
        assert_eq!(decode_in_place(&mut [0x02, 0x00]), Err(CobsError));
        assert_eq!(decode_in_place(&mut [0x00]), Err(CobsError));
        let mut small = [0u8; 2];
        assert_eq!(encode(&[1, 2, 3], &mut small), Err(BufferTooSmall));
    }
}
