//! A little-endian CDR (XCDR1) reader for ROS 2 messages.
//!
//! Primitives are aligned to their size relative to the start of the data
//! after the 4-byte encapsulation header. Every read is bounds-checked:
//! malformed input gives an error saying what was expected, never a panic.

/// Reads one CDR-encoded message.
#[derive(Debug)]
pub(crate) struct Cdr<'a> {
    data: &'a [u8],
    pos: usize,
}

/// Why a CDR message does not decode. `what` names the field being read.
/// A [`BagError`](super::BagError) adds the bag, message and topic.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CdrError {
    /// Fewer bytes than the 4-byte encapsulation header.
    #[error("{len} bytes is too short for a CDR header")]
    TooShort {
        /// Bytes in the message.
        len: usize,
    },
    /// Big-endian CDR, which this reader does not decode.
    #[error("big-endian CDR is not supported")]
    BigEndian,
    /// An encapsulation header of another kind than CDR.
    #[error("unknown CDR encapsulation 0x{:02x}{:02x}", .header[0], .header[1])]
    Encapsulation {
        /// Its first two bytes.
        header: [u8; 2],
    },
    /// A field whose end lies past the largest address.
    #[error("{what}: size overflow")]
    SizeOverflow {
        /// The field.
        what: &'static str,
    },
    /// A field that runs past the end of the message.
    #[error("{what}: needs {needed} bytes at offset {offset}, the message has {len} (truncated?)")]
    Truncated {
        /// The field.
        what: &'static str,
        /// Bytes it needs.
        needed: usize,
        /// Where it starts (after alignment), from the end of the header.
        offset: usize,
        /// Bytes in the message after the header.
        len: usize,
    },
    /// A string that is not UTF-8.
    #[error("{what}: not UTF-8")]
    NotUtf8 {
        /// The field.
        what: &'static str,
    },
    /// A sequence longer than the bytes left could hold.
    #[error("{what}: {count} elements do not fit in the {left} bytes left (corrupt length?)")]
    CorruptLength {
        /// The field.
        what: &'static str,
        /// Elements announced.
        count: usize,
        /// Bytes left in the message.
        left: usize,
    },
    /// A scan whose geometry no laser has (see
    /// `LaserReading::check_geometry`).
    #[error("LaserScan: {0}")]
    ScanGeometry(String),
}

/// What went wrong decoding.
pub(crate) type CdrResult<T> = Result<T, CdrError>;

impl<'a> Cdr<'a> {
    /// Checks the encapsulation header (CDR little endian, with or without
    /// the XCDR1 "plain" options).
    pub(crate) fn new(bytes: &'a [u8]) -> CdrResult<Self> {
        match bytes {
            [_, 0x01, _, _, ..] => Ok(Cdr { data: &bytes[4..], pos: 0 }),
            [_, 0x00, _, _, ..] => Err(CdrError::BigEndian),
            [first, second, _, _, ..] => Err(CdrError::Encapsulation { header: [*first, *second] }),
            _ => Err(CdrError::TooShort { len: bytes.len() }),
        }
    }

    fn take(&mut self, n: usize, align: usize, what: &'static str) -> CdrResult<&'a [u8]> {
        let start = self.pos.div_ceil(align) * align;
        let end = start.checked_add(n).ok_or(CdrError::SizeOverflow { what })?;
        if end > self.data.len() {
            return Err(CdrError::Truncated { what, needed: n, offset: start, len: self.data.len() });
        }
        self.pos = end;
        Ok(&self.data[start..end])
    }

    /// The next `N` bytes, aligned to `N`: a primitive's.
    fn array<const N: usize>(&mut self, what: &'static str) -> CdrResult<[u8; N]> {
        let mut out = [0; N];
        // `take` returns exactly the N bytes asked for, or an error.
        out.copy_from_slice(self.take(N, N, what)?);
        Ok(out)
    }

    pub(crate) fn u32(&mut self, what: &'static str) -> CdrResult<u32> {
        self.array(what).map(u32::from_le_bytes)
    }

    pub(crate) fn i32(&mut self, what: &'static str) -> CdrResult<i32> {
        self.array(what).map(i32::from_le_bytes)
    }

    pub(crate) fn f32(&mut self, what: &'static str) -> CdrResult<f32> {
        self.array(what).map(f32::from_le_bytes)
    }

    pub(crate) fn f64(&mut self, what: &'static str) -> CdrResult<f64> {
        self.array(what).map(f64::from_le_bytes)
    }

    /// A string: u32 length including the terminating NUL, then the bytes.
    pub(crate) fn string(&mut self, what: &'static str) -> CdrResult<String> {
        let len = self.u32(what)? as usize;
        let bytes = self.take(len, 1, what)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| CdrError::NotUtf8 { what })
    }

    /// A sequence length, checked against the bytes left for `elem` bytes
    /// per element (so a corrupt length cannot allocate gigabytes).
    pub(crate) fn seq_len(&mut self, elem: usize, what: &'static str) -> CdrResult<usize> {
        let n = self.u32(what)? as usize;
        let left = self.data.len().saturating_sub(self.pos);
        if n.saturating_mul(elem) > left {
            return Err(CdrError::CorruptLength { what, count: n, left });
        }
        Ok(n)
    }

    pub(crate) fn f32_seq(&mut self, what: &'static str) -> CdrResult<Vec<f32>> {
        let n = self.seq_len(4, what)?;
        // seq_len checked that n × 4 bytes are left: no overflow.
        let bytes = self.take(n * 4, 4, what)?;
        Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    /// Skips `n` f64 values (fixed-size arrays such as covariances).
    pub(crate) fn skip_f64s(&mut self, n: usize, what: &'static str) -> CdrResult<()> {
        self.take(n.saturating_mul(8), 8, what).map(|_| ())
    }
}

/// Writes one little-endian CDR (XCDR1) message: the encapsulation header,
/// then primitives aligned to their size relative to the data after it, as
/// ROS 2 middlewares expect.
#[derive(Debug)]
pub(crate) struct CdrWriter {
    bytes: Vec<u8>,
}

/// The encapsulation header: CDR, little endian, no options.
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

impl CdrWriter {
    pub(crate) fn new() -> Self {
        CdrWriter { bytes: CDR_LE.to_vec() }
    }

    fn align(&mut self, to: usize) {
        let data = self.bytes.len() - CDR_LE.len();
        self.bytes.resize(self.bytes.len() + (data.div_ceil(to) * to - data), 0);
    }

    /// A primitive's little-endian bytes, aligned to its size.
    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        self.align(N);
        self.bytes.extend_from_slice(&bytes);
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }

    pub(crate) fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes());
    }

    pub(crate) fn f32(&mut self, v: f32) {
        self.put(v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes());
    }

    /// A string: u32 length including the terminating NUL, the bytes, NUL.
    pub(crate) fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.bytes.extend_from_slice(s.as_bytes());
        self.bytes.push(0);
    }

    /// A sequence of bytes (`int8[]`, `uint8[]`): u32 length, the bytes.
    pub(crate) fn byte_seq(&mut self, v: impl ExactSizeIterator<Item = u8>) {
        self.u32(v.len() as u32);
        self.bytes.extend(v);
    }

    pub(crate) fn finish(self) -> Vec<u8> {
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_writer_aligns_as_the_reader_expects() {
        let mut w = CdrWriter::new();
        w.u32(7);
        w.string("ab");
        w.f64(1.5);
        w.byte_seq([1u8, 2, 3].into_iter());
        w.f32(-2.0);
        let bytes = w.finish();
        // Same layout as the reader's test: pad to 8 after "ab\0".
        assert_eq!(&bytes[..4], &CDR_LE);
        assert_eq!(bytes.len(), 4 + 4 + 4 + 3 + 5 + 8 + 4 + 3 + 1 + 4);
        let mut c = Cdr::new(&bytes).unwrap();
        assert_eq!(c.u32("a").unwrap(), 7);
        assert_eq!(c.string("s").unwrap(), "ab");
        assert_eq!(c.f64("x").unwrap(), 1.5);
        let n = c.seq_len(1, "seq").unwrap();
        assert_eq!(n, 3);
        assert_eq!(c.take(3, 1, "seq").unwrap(), &[1, 2, 3]);
        assert_eq!(c.f32("y").unwrap(), -2.0);
    }

    #[test]
    fn aligns_relative_to_the_payload_and_checks_bounds() {
        // header, u32 7, string "ab" (len 3), pad to 8, f64 1.5
        let mut b = vec![0, 1, 0, 0];
        b.extend(7u32.to_le_bytes());
        b.extend(3u32.to_le_bytes());
        b.extend(b"ab\0");
        b.extend([0; 5]);
        b.extend(1.5f64.to_le_bytes());
        let mut c = Cdr::new(&b).unwrap();
        assert_eq!(c.u32("a").unwrap(), 7);
        assert_eq!(c.string("s").unwrap(), "ab");
        assert_eq!(c.f64("x").unwrap(), 1.5);
        assert!(c.u32("past the end").unwrap_err().to_string().contains("truncated"));
    }

    #[test]
    fn corrupt_lengths_are_errors() {
        let mut b = vec![0, 1, 0, 0];
        b.extend(u32::MAX.to_le_bytes());
        assert!(Cdr::new(&b).unwrap().f32_seq("ranges").unwrap_err().to_string().contains("corrupt length"));
        assert_eq!(Cdr::new(&[0, 0, 0, 0]).unwrap_err().to_string(), "big-endian CDR is not supported");
        assert_eq!(Cdr::new(&[0, 1]).unwrap_err().to_string(), "2 bytes is too short for a CDR header");
        assert_eq!(Cdr::new(&[0, 7, 0, 0]).unwrap_err().to_string(), "unknown CDR encapsulation 0x0007");
    }
}
