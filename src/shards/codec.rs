//! The byte layout every shard file shares (docs/scale.md "File formats"):
//! a 16-byte header (magic naming the kind, version, flags), a body of
//! little-endian fields, and a 12-byte trailer (the file's length and the
//! CRC-32 of every byte before the CRC), so a truncated, extended or
//! corrupted file is refused before a field is read.
//!
//! Writing streams through [`Writer`] (hit records run to gigabytes: they are
//! never copied into one buffer); reading goes through [`open`] and a
//! bounds-checked [`Reader`] that never allocates more than the bytes present.

use std::io::Write;

/// Format version written; readers accept any minor of this major.
pub const MAJOR: u16 = 9;
pub const MINOR: u16 = 0;
pub const HEADER_LEN: usize = 16;
pub const TRAILER_LEN: usize = 12;

/// What a shard file holds, named by its magic's fourth byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// `PRTP`: one shard's sums of one transfer round (`.prtp`).
    TransferPart,
    /// `PRTS`: one shard's sun bits (`.prtp`).
    SunPart,
    /// `PRTH`: one shard's bounce-0 hit records (`.prth`).
    Hits,
    /// `PRTL`: a merged round's layer (`.prtl`).
    Layer,
    /// `PRTA`: the merged pilot of adaptive allocation (`.prta`).
    Pilot,
}

impl FileKind {
    pub fn magic(self) -> [u8; 8] {
        let letter = match self {
            FileKind::TransferPart => b'P',
            FileKind::SunPart => b'S',
            FileKind::Hits => b'H',
            FileKind::Layer => b'L',
            FileKind::Pilot => b'A',
        };
        [b'P', b'R', b'T', letter, b'\r', b'\n', 0x1a, b'\n']
    }

    pub fn name(self) -> &'static str {
        match self {
            FileKind::TransferPart => "a transfer part",
            FileKind::SunPart => "a sun part",
            FileKind::Hits => "a hit-record file",
            FileKind::Layer => "a merged layer",
            FileKind::Pilot => "a merged pilot",
        }
    }

    /// The kind a file's first bytes name, or what they look like instead.
    pub fn of(bytes: &[u8]) -> Result<FileKind, String> {
        let kinds = [FileKind::TransferPart, FileKind::SunPart, FileKind::Hits, FileKind::Layer, FileKind::Pilot];
        if let Some(kind) = kinds.into_iter().find(|k| bytes.starts_with(&k.magic())) {
            return Ok(kind);
        }
        if bytes.starts_with(&crate::bundle::MAGIC) {
            return Err("is a bundle (.prtb), not a shard file".into());
        }
        Err("is not a prtbake shard file (no PRTP/PRTS/PRTH/PRTL/PRTA magic)".into())
    }
}

/// Streams a shard file: header, fields, then [`Writer::finish`] for the trailer.
pub struct Writer<W: Write> {
    inner: W,
    crc: crc32fast::Hasher,
    len: u64,
    /// Encodes arrays in slices of this buffer, not one copy of the whole.
    scratch: Vec<u8>,
}

impl<W: Write> Writer<W> {
    /// Starts a file of `kind` (writes its header).
    pub fn new(inner: W, kind: FileKind) -> std::io::Result<Writer<W>> {
        let mut w = Writer { inner, crc: crc32fast::Hasher::new(), len: 0, scratch: Vec::with_capacity(1 << 16) };
        w.bytes(&kind.magic())?;
        w.u16(MAJOR)?;
        w.u16(MINOR)?;
        w.u32(0)?;
        Ok(w)
    }

    pub fn bytes(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.crc.update(bytes);
        self.len += bytes.len() as u64;
        self.inner.write_all(bytes)
    }
    pub fn u8(&mut self, v: u8) -> std::io::Result<()> {
        self.bytes(&[v])
    }
    pub fn u16(&mut self, v: u16) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u32(&mut self, v: u32) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u64(&mut self, v: u64) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f32(&mut self, v: f32) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f64(&mut self, v: f64) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    /// Zero bytes up to the next multiple of 4 from the file start.
    pub fn pad4(&mut self) -> std::io::Result<()> {
        let pad = (4 - self.len % 4) % 4;
        self.bytes(&[0u8; 3][..pad as usize])
    }
    /// A length-prefixed blob (u64 length, bytes, pad to 4).
    pub fn blob(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.u64(bytes.len() as u64)?;
        self.bytes(bytes)?;
        self.pad4()
    }
    /// A u32 length-prefixed UTF-8 string, padded to 4.
    pub fn string(&mut self, s: &str) -> std::io::Result<()> {
        self.u32(s.len() as u32)?;
        self.bytes(s.as_bytes())?;
        self.pad4()
    }

    fn array<T: Copy, const N: usize>(&mut self, values: &[T], encode: impl Fn(T) -> [u8; N]) -> std::io::Result<()> {
        let mut scratch = std::mem::take(&mut self.scratch);
        for chunk in values.chunks(8192) {
            scratch.clear();
            chunk.iter().for_each(|&v| scratch.extend_from_slice(&encode(v)));
            self.bytes(&scratch)?;
        }
        self.scratch = scratch;
        Ok(())
    }
    pub fn f32s(&mut self, values: &[f32]) -> std::io::Result<()> {
        self.array(values, f32::to_le_bytes)
    }
    pub fn u32s(&mut self, values: &[u32]) -> std::io::Result<()> {
        self.array(values, u32::to_le_bytes)
    }
    pub fn u64s(&mut self, values: &[u64]) -> std::io::Result<()> {
        self.array(values, u64::to_le_bytes)
    }

    /// Writes the trailer (length, then the CRC of everything before it) and
    /// returns the CRC: the file's identity for the files that name it.
    pub fn finish(mut self) -> std::io::Result<u32> {
        let total = self.len + TRAILER_LEN as u64;
        self.bytes(&total.to_le_bytes())?;
        let crc = self.crc.clone().finalize();
        self.inner.write_all(&crc.to_le_bytes())?;
        self.inner.flush()?;
        Ok(crc)
    }
}

/// Writes a whole file into memory (small files, tests).
pub fn to_vec(kind: FileKind, body: impl FnOnce(&mut Writer<&mut Vec<u8>>) -> std::io::Result<()>) -> Vec<u8> {
    let mut out = Vec::new();
    let written = (|| {
        let mut w = Writer::new(&mut out, kind)?;
        body(&mut w)?;
        w.finish()
    })();
    // Writing into a Vec cannot fail.
    debug_assert!(written.is_ok());
    out
}

/// What a shard file's first [`HEADER_LEN`] and last [`TRAILER_LEN`] bytes
/// (`head`, `tail`) say of a file of `file_len` bytes: its kind (any shard
/// file), its major version and flags, and that the length its trailer
/// gives is the file's. A reader checks this before reading the body, so a
/// part with gigabytes appended (or a file of zeros behind a shard magic)
/// costs 28 bytes; [`open`] checks the rest, the CRC included, once read.
pub fn check_frame(head: &[u8], tail: &[u8], file_len: u64) -> Result<FileKind, String> {
    let kind = FileKind::of(head)?;
    if file_len < (HEADER_LEN + TRAILER_LEN) as u64 || head.len() < HEADER_LEN || tail.len() < TRAILER_LEN {
        return Err(format!("is {file_len} bytes, shorter than a header and trailer: truncated"));
    }
    let major = u16::from_le_bytes([head[8], head[9]]);
    if major != MAJOR {
        return Err(format!("is format version {major}, this prtbake reads version {MAJOR}: bake and merge with the same release"));
    }
    if head[12..16] != [0; 4] {
        return Err("has flags set that this version does not know".into());
    }
    let tail = &tail[tail.len() - TRAILER_LEN..];
    let length = u64::from_le_bytes(tail[..8].try_into().unwrap_or([0; 8]));
    if length != file_len {
        // The length sits in the trailer: when it disagrees, those bytes are
        // whatever the cut left at the end, so they are not quoted.
        return Err(format!(
            "is {file_len} bytes and does not end in its own length and CRC-32: truncated or extended (a copy cut short, or bytes appended)"
        ));
    }
    Ok(kind)
}

/// Checks a file's header and trailer: its kind is `expected`, its major
/// version is this reader's, its length is the one it says and its CRC
/// matches. Returns a reader over the body and the file's CRC.
pub fn open(bytes: &[u8], expected: FileKind) -> Result<(Reader<'_>, u32), String> {
    let kind = FileKind::of(bytes)?;
    if kind != expected {
        return Err(format!("is {}, not {}", kind.name(), expected.name()));
    }
    if bytes.len() < HEADER_LEN + TRAILER_LEN {
        return Err(format!("is {} bytes, shorter than a header and trailer: truncated", bytes.len()));
    }
    let major = u16::from_le_bytes([bytes[8], bytes[9]]);
    if major != MAJOR {
        return Err(format!("is format version {major}, this prtbake reads version {MAJOR}: bake and merge with the same release"));
    }
    if bytes[12..16] != [0; 4] {
        return Err("has flags set that this version does not know".into());
    }
    let (content, crc_bytes) = bytes.split_at(bytes.len() - 4);
    let length = u64::from_le_bytes(content[content.len() - 8..].try_into().unwrap_or([0; 8]));
    if length != bytes.len() as u64 {
        // The length sits in the trailer: when it disagrees, those bytes are
        // whatever the cut left at the end, so they are not quoted.
        return Err(format!(
            "is {} bytes and does not end in its own length and CRC-32: truncated or extended (a copy cut short, or bytes appended)",
            bytes.len()
        ));
    }
    let stored = u32::from_le_bytes(crc_bytes.try_into().unwrap_or([0; 4]));
    let crc = crc32fast::hash(content);
    if crc != stored {
        return Err(format!("CRC-32 mismatch (stored {stored:08x}, computed {crc:08x}): the file is corrupted"));
    }
    Ok((Reader { bytes: &content[..content.len() - 8], pos: HEADER_LEN }, crc))
}

/// Reads little-endian fields of a checked body; every read checks the
/// bytes remaining first, and errors name the field.
pub struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader over a block of its own (offsets and padding count from its start).
    pub fn new(bytes: &'a [u8]) -> Reader<'a> {
        Reader { bytes, pos: 0 }
    }

    pub fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], String> {
        let remaining = self.bytes.len() - self.pos;
        match usize::try_from(n) {
            Ok(n) if n <= remaining => {
                let out = &self.bytes[self.pos..self.pos + n];
                self.pos += n;
                Ok(out)
            }
            _ => Err(format!("{what} needs {n} bytes at offset {} but only {remaining} remain", self.pos)),
        }
    }
    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], String> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N as u64, what)?);
        Ok(out)
    }
    pub fn u8(&mut self, what: &str) -> Result<u8, String> {
        Ok(self.array::<1>(what)?[0])
    }
    pub fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    pub fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    pub fn f32(&mut self, what: &str) -> Result<f32, String> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    pub fn f64(&mut self, what: &str) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
    pub fn pad4(&mut self, what: &str) -> Result<(), String> {
        let pad = (4 - self.pos % 4) % 4;
        if self.take(pad as u64, what)?.iter().any(|&b| b != 0) {
            return Err(format!("{what}: padding is not zero"));
        }
        Ok(())
    }
    pub fn blob(&mut self, what: &str) -> Result<&'a [u8], String> {
        let len = self.u64(what)?;
        let bytes = self.take(len, what)?;
        self.pad4(what)?;
        Ok(bytes)
    }
    pub fn string(&mut self, what: &str) -> Result<String, String> {
        let len = self.u32(what)?;
        let bytes = self.take(len as u64, what)?;
        self.pad4(what)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
    /// `count` values of `N` bytes each, checked against the bytes present before allocating.
    fn values<T, const N: usize>(&mut self, count: u64, what: &str, decode: impl Fn([u8; N]) -> T) -> Result<Vec<T>, String> {
        let bytes = self.take(count.checked_mul(N as u64).unwrap_or(u64::MAX), what)?;
        Ok(bytes.chunks_exact(N).map(|c| decode(c.try_into().unwrap_or([0; N]))).collect())
    }
    pub fn f32s(&mut self, count: u64, what: &str) -> Result<Vec<f32>, String> {
        self.values(count, what, f32::from_le_bytes)
    }
    pub fn u32s(&mut self, count: u64, what: &str) -> Result<Vec<u32>, String> {
        self.values(count, what, u32::from_le_bytes)
    }
    pub fn u64s(&mut self, count: u64, what: &str) -> Result<Vec<u64>, String> {
        self.values(count, what, u64::from_le_bytes)
    }
    /// Every byte of the body was read.
    pub fn finish(&self) -> Result<(), String> {
        match self.bytes.len() - self.pos {
            0 => Ok(()),
            extra => Err(format!("{extra} bytes after the last field")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        to_vec(FileKind::Layer, |w| {
            w.u32(7)?;
            w.string("glass*")?;
            w.f32s(&[1.5, -0.0, f32::MIN_POSITIVE])?;
            w.blob(b"abc")?;
            w.u64s(&[u64::MAX, 3])
        })
    }

    #[test]
    fn fields_round_trip_and_the_whole_file_is_consumed() {
        let bytes = sample();
        assert_eq!(bytes.len() % 4, 0);
        let (mut r, crc) = open(&bytes, FileKind::Layer).unwrap();
        assert_eq!(crc, u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap()));
        assert_eq!(r.u32("a").unwrap(), 7);
        assert_eq!(r.string("b").unwrap(), "glass*");
        let floats = r.f32s(3, "c").unwrap();
        assert_eq!(floats.iter().map(|f| f.to_bits()).collect::<Vec<_>>(), [1.5f32, -0.0, f32::MIN_POSITIVE].map(f32::to_bits));
        assert_eq!(r.blob("d").unwrap(), b"abc");
        assert_eq!(r.u64s(2, "e").unwrap(), vec![u64::MAX, 3]);
        r.finish().unwrap();
    }

    #[test]
    fn every_flipped_bit_and_every_truncation_is_refused() {
        let bytes = sample();
        for bit in 0..bytes.len() * 8 {
            let mut bad = bytes.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            assert!(open(&bad, FileKind::Layer).is_err(), "bit {bit} flipped was accepted");
        }
        for len in 0..bytes.len() {
            assert!(open(&bytes[..len], FileKind::Layer).is_err(), "truncated to {len} was accepted");
        }
        let e = open(&bytes, FileKind::Hits).err().unwrap();
        assert!(e.contains("is a merged layer, not a hit-record file"), "{e}");
        let e = open(b"PRTB\r\n\x1a\n and more bytes after", FileKind::Hits).err().unwrap();
        assert!(e.contains("bundle"), "{e}");
    }

    #[test]
    fn hostile_counts_are_refused_before_allocating() {
        let bytes = to_vec(FileKind::Hits, |w| w.u64(u64::MAX));
        let (mut r, _) = open(&bytes, FileKind::Hits).unwrap();
        let count = r.u64("count").unwrap();
        let e = r.f32s(count, "values").unwrap_err();
        assert!(e.contains("values needs"), "{e}");
        assert!(r.u64s(u64::MAX / 3, "records").is_err());
    }
}
