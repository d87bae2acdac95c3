//! Little-endian byte cursor over untrusted section bytes, and the matching writers.
//!
//! Every read checks the remaining length first, so a decoder can only allocate
//! in proportion to bytes that are really there.

use super::error::BundleError;

/// Reads little-endian values from one section's raw bytes; errors name the section.
pub(crate) struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    tag: [u8; 4],
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8], tag: [u8; 4]) -> Cursor<'a> {
        Cursor { bytes, pos: 0, tag }
    }

    pub(crate) fn error(&self, detail: impl Into<String>) -> BundleError {
        BundleError::malformed(self.tag, detail)
    }

    /// The section being read.
    pub(crate) fn tag(&self) -> [u8; 4] {
        self.tag
    }

    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    /// The next `n` bytes; an error naming `what` when fewer remain.
    pub(crate) fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], BundleError> {
        let remaining = self.remaining();
        let n = match usize::try_from(n) {
            Ok(n) if n <= remaining => n,
            _ => return Err(self.error(format!("{what} needs {n} bytes at offset {} but only {remaining} remain", self.pos))),
        };
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], BundleError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N as u64, what)?);
        Ok(out)
    }

    pub(crate) fn u32(&mut self, what: &str) -> Result<u32, BundleError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    pub(crate) fn f32(&mut self, what: &str) -> Result<f32, BundleError> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    pub(crate) fn f64(&mut self, what: &str) -> Result<f64, BundleError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// `count` consecutive little-endian `f32`s (length checked before allocating).
    pub(crate) fn f32s(&mut self, count: u64, what: &str) -> Result<Vec<f32>, BundleError> {
        let bytes = self.take(count.saturating_mul(4), what)?;
        Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }
    /// `count` consecutive little-endian `u32`s (length checked before allocating).
    pub(crate) fn u32s(&mut self, count: u64, what: &str) -> Result<Vec<u32>, BundleError> {
        let bytes = self.take(count.saturating_mul(4), what)?;
        Ok(bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }
    /// `count` consecutive little-endian `u16`s (length checked before allocating).
    pub(crate) fn u16s(&mut self, count: u64, what: &str) -> Result<Vec<u16>, BundleError> {
        let bytes = self.take(count.saturating_mul(2), what)?;
        Ok(bytes.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect())
    }

    /// Skips zero padding up to the next multiple of `align` (relative to the section start).
    pub(crate) fn padding(&mut self, align: usize, what: &str) -> Result<(), BundleError> {
        let pad = (align - self.pos % align) % align;
        let bytes = self.take(pad as u64, what)?;
        if bytes.iter().any(|&b| b != 0) {
            return Err(self.error(format!("{what} padding is not zero")));
        }
        Ok(())
    }

    /// Errors when bytes remain: every section has an exact length.
    pub(crate) fn finish(&self) -> Result<(), BundleError> {
        match self.remaining() {
            0 => Ok(()),
            extra => Err(self.error(format!("{extra} unexpected bytes after the content"))),
        }
    }
}

pub(crate) fn put_u16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_f32(out: &mut Vec<u8>, v: f32) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_f64(out: &mut Vec<u8>, v: f64) {
    out.extend_from_slice(&v.to_le_bytes());
}
/// Appends zero bytes until `out.len()` is a multiple of `align`.
pub(crate) fn pad_to(out: &mut Vec<u8>, align: usize) {
    while out.len() % align != 0 {
        out.push(0);
    }
}
