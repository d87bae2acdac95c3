//! The generic sectioned container under `.prtb`: header, section table, codecs, checksums.
//!
//! This file knows nothing of meshes or transfer; it stores tagged byte strings.
//! Layout (all little-endian; see docs/bundle-format.md for the tables):
//!
//! ```text
//! [header 32 B][section table 40 B × n][payload 0][pad to 8][payload 1][pad to 8]…
//! ```
//!
//! The layout is canonical: payloads follow the table in table order, each at the
//! first 8-aligned offset after the previous one, and the file ends at the 8-aligned
//! end of the last payload. Every byte is then covered by a CRC or must be zero
//! (padding). Since format 1.1 each payload has two CRCs: one of its stored
//! bytes, so a flip in a zstd frame header that decodes to the same bytes is
//! still caught, and one of its raw bytes, so a codec bug is caught too.

use std::borrow::Cow;
use std::collections::HashSet;
use std::io::Read;

use super::cursor::{pad_to, put_u16, put_u32, put_u64};
use super::error::{BundleError, Tag};

/// First eight bytes of every bundle. `\r\n` and `\x1a\n` catch text-mode
/// line-ending conversion and DOS end-of-file truncation, as in PNG.
pub const MAGIC: [u8; 8] = *b"PRTB\r\n\x1a\n";
/// Major version written and read; a different major may change any layout.
pub const FORMAT_MAJOR: u16 = 1;
/// Minor version written; minors only add sections and ignorable fields.
/// 1.1 gave the table entry's reserved word a meaning: the stored-bytes CRC.
pub const FORMAT_MINOR: u16 = 1;
/// First minor whose table entries carry `stored_crc32` (offset 36; reserved in 1.0).
pub const STORED_CRC_SINCE_MINOR: u16 = 1;
/// Size of the fixed file header.
pub const HEADER_LEN: usize = 32;
/// Size of one section-table entry.
pub const ENTRY_LEN: usize = 40;
/// Alignment of every payload and of the file length.
pub const ALIGN: u64 = 8;
/// The sections' tags (docs/bundle-format.md, "Sections").
pub(crate) const META: [u8; 4] = *b"META";
pub(crate) const MESH: [u8; 4] = *b"MESH";
pub(crate) const MATL: [u8; 4] = *b"MATL";
pub(crate) const XFER: [u8; 4] = *b"XFER";
pub(crate) const SUNM: [u8; 4] = *b"SUNM";
pub(crate) const SUND: [u8; 4] = *b"SUND";
pub(crate) const ATLS: [u8; 4] = *b"ATLS";
pub(crate) const TXFR: [u8; 4] = *b"TXFR";
pub(crate) const TSUN: [u8; 4] = *b"TSUN";
pub(crate) const TSUF: [u8; 4] = *b"TSUF";
pub(crate) const SIDE: [u8; 4] = *b"SIDE";
pub(crate) const TSID: [u8; 4] = *b"TSID";
pub(crate) const TSAT: [u8; 4] = *b"TSAT";
pub(crate) const TSAB: [u8; 4] = *b"TSAB";
pub(crate) const TSAF: [u8; 4] = *b"TSAF";
/// Offset of the header CRC field; the CRC covers bytes `0..HEADER_CRC_AT` and the table.
const HEADER_CRC_AT: usize = 28;

/// How a section's raw bytes are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// Stored as is: `stored_len == raw_len`.
    Raw = 0,
    /// One or more zstd frames that decompress to exactly `raw_len` bytes.
    Zstd = 1,
}

/// What the encoder does with each section.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Every section raw (codec 0); used for golden byte tests.
    None,
    /// zstd at `level` (single-threaded, so deterministic); a section whose
    /// compressed form is not strictly smaller than its raw bytes is stored raw.
    Zstd { level: i32 },
}

/// Encoder settings. The default is zstd level 9.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncodeOptions {
    pub compression: Compression,
}

impl Default for EncodeOptions {
    fn default() -> EncodeOptions {
        EncodeOptions { compression: Compression::Zstd { level: 9 } }
    }
}

/// One section-table entry, as listed by [`super::list_sections`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    /// Four ASCII bytes, e.g. `*b"MESH"`.
    pub tag: [u8; 4],
    /// 0 raw, 1 zstd; other values may appear only on sections a reader does not know.
    pub codec: u32,
    /// Byte offset of the stored payload from the file start (multiple of 8).
    pub offset: u64,
    /// Payload length in the file.
    pub stored_len: u64,
    /// Payload length after decompression.
    pub raw_len: u64,
    /// CRC-32 (IEEE) of the raw (decompressed) bytes.
    pub crc32: u32,
    /// CRC-32 (IEEE) of the stored bytes as they lie in the file; `None` in
    /// 1.0 files, whose table has a reserved zero word there.
    pub stored_crc32: Option<u32>,
}

impl SectionInfo {
    /// The tag as text, non-ASCII bytes escaped.
    pub fn tag_name(&self) -> String {
        Tag(self.tag).to_string()
    }
    /// `"raw"`, `"zstd"` or `"codec N"`.
    pub fn codec_name(&self) -> String {
        match self.codec {
            0 => "raw".to_string(),
            1 => "zstd".to_string(),
            other => format!("codec {other}"),
        }
    }
}

/// A header and section table that passed every layout check, over the borrowed file bytes.
pub(crate) struct Container<'a> {
    bytes: &'a [u8],
    /// The file's minor version.
    pub minor: u16,
    pub sections: Vec<SectionInfo>,
}

fn read_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn read_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
fn read_u64(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// Reserved fields must be zero in files of a minor this reader knows (`minor ≤ FORMAT_MINOR`).
fn reserved_must_be_zero(minor: u16) -> bool {
    minor.cmp(&FORMAT_MINOR) != std::cmp::Ordering::Greater
}

fn align_up(n: u64) -> Option<u64> {
    n.checked_add(ALIGN - 1).map(|v| v / ALIGN * ALIGN)
}

fn is_tag_byte(b: u8) -> bool {
    b.is_ascii_graphic()
}

/// Why the first bytes are not our magic, in words a user can act on.
fn describe_bad_magic(bytes: &[u8]) -> String {
    let head = &bytes[..bytes.len().min(8)];
    if head.starts_with(b"PRTB\n") || head.starts_with(b"PRTB\r\r\n") {
        "magic mangled by text-mode line-ending conversion".to_string()
    } else {
        format!("first bytes are \"{}\", expected \"{}\"", head.escape_ascii(), MAGIC.escape_ascii())
    }
}

impl<'a> Container<'a> {
    /// Parses and checks the header and table: magic, major version, header CRC,
    /// total length, reserved fields, canonical offsets and zero padding.
    /// Payloads are not decompressed here (see [`Container::payload`]).
    pub(crate) fn parse(bytes: &'a [u8]) -> Result<Container<'a>, BundleError> {
        Container::parse_in(bytes, bytes.len() as u64)
    }

    /// What the fixed header alone says of a file of `file_len` bytes whose
    /// first bytes are `head` (at least [`HEADER_LEN`] of them, or the whole
    /// file): magic, major version, and that the total length it gives is
    /// the file's. Returns the length of the header and section table, which
    /// [`Container::check_head`] checks next; nothing past them need be read
    /// before the file's size is known to be right.
    pub(crate) fn head_len(head: &[u8], file_len: u64) -> Result<u64, BundleError> {
        let prefix = head.len().min(MAGIC.len());
        if head[..prefix] != MAGIC[..prefix] {
            return Err(BundleError::NotABundle { detail: describe_bad_magic(head) });
        }
        if file_len < HEADER_LEN as u64 || head.len() < HEADER_LEN {
            return Err(BundleError::Truncated { what: "the file header".into(), needed: HEADER_LEN as u64, available: file_len });
        }
        let (major, minor) = (read_u16(head, 8), read_u16(head, 10));
        if major != FORMAT_MAJOR {
            return Err(BundleError::UnsupportedVersion { major, minor, known_major: FORMAT_MAJOR });
        }
        let declared_len = read_u64(head, 16);
        if declared_len > file_len {
            return Err(BundleError::Truncated {
                what: "the bundle (header total length)".into(),
                needed: declared_len,
                available: file_len,
            });
        }
        if declared_len < file_len {
            return Err(BundleError::TrailingBytes { declared: declared_len, extra: file_len - declared_len });
        }
        let table_end = u64::from(read_u32(head, 12)) * ENTRY_LEN as u64 + HEADER_LEN as u64;
        if table_end > file_len {
            return Err(BundleError::Truncated {
                what: format!("the section table ({} entries)", read_u32(head, 12)),
                needed: table_end,
                available: file_len,
            });
        }
        Ok(table_end)
    }

    /// Every check of [`Container::parse`] that the header and section table
    /// (`head`, the first [`Container::head_len`] bytes of a file of
    /// `file_len` bytes) allow: header CRC, reserved fields, canonical
    /// offsets, section lengths within the file, the total length the end of
    /// the last section. Padding and payloads are checked once read.
    pub(crate) fn check_head(head: &[u8], file_len: u64) -> Result<(), BundleError> {
        Container::parse_in(head, file_len).map(|_| ())
    }

    /// [`Container::parse`] of the first bytes of a file of `available`
    /// bytes; padding past `bytes` is not checked, nor can payloads be read.
    fn parse_in(bytes: &'a [u8], available: u64) -> Result<Container<'a>, BundleError> {
        // Magic first, on however many bytes there are: a short text file is
        // "not a bundle", a short prefix of a bundle is "truncated".
        let prefix = bytes.len().min(MAGIC.len());
        if bytes[..prefix] != MAGIC[..prefix] {
            return Err(BundleError::NotABundle { detail: describe_bad_magic(bytes) });
        }
        if bytes.len() < HEADER_LEN {
            return Err(BundleError::Truncated { what: "the file header".into(), needed: HEADER_LEN as u64, available });
        }
        let major = read_u16(bytes, 8);
        let minor = read_u16(bytes, 10);
        if major != FORMAT_MAJOR {
            return Err(BundleError::UnsupportedVersion { major, minor, known_major: FORMAT_MAJOR });
        }
        let section_count = read_u32(bytes, 12);
        let declared_len = read_u64(bytes, 16);
        let flags = read_u32(bytes, 24);
        let stored_crc = read_u32(bytes, HEADER_CRC_AT);

        // Section table: bounded by the bytes present before anything is allocated.
        let table_end = (section_count as u64) * ENTRY_LEN as u64 + HEADER_LEN as u64;
        if table_end > bytes.len() as u64 {
            return Err(BundleError::Truncated {
                what: format!("the section table ({section_count} entries)"),
                needed: table_end,
                available,
            });
        }
        let table = &bytes[HEADER_LEN..table_end as usize];
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&bytes[..HEADER_CRC_AT]);
        hasher.update(table);
        let computed = hasher.finalize();
        if computed != stored_crc {
            return Err(BundleError::HeaderChecksum { stored: stored_crc, computed });
        }
        if declared_len > available {
            return Err(BundleError::Truncated { what: "the bundle (header total length)".into(), needed: declared_len, available });
        }
        if declared_len < available {
            return Err(BundleError::TrailingBytes { declared: declared_len, extra: available - declared_len });
        }
        // Reserved fields are corruption in files of a minor we know, and a newer
        // writer's ignorable additions in files of a later minor.
        let reject_reserved = reserved_must_be_zero(minor);
        if reject_reserved && flags != 0 {
            return Err(BundleError::Layout(format!("header flags {flags:#x} set reserved bits")));
        }

        let mut sections = Vec::with_capacity(section_count as usize);
        let mut seen_tags = HashSet::with_capacity(section_count as usize);
        let mut end = table_end;
        for (i, entry) in table.chunks_exact(ENTRY_LEN).enumerate() {
            let info = SectionInfo {
                tag: [entry[0], entry[1], entry[2], entry[3]],
                codec: read_u32(entry, 4),
                offset: read_u64(entry, 8),
                stored_len: read_u64(entry, 16),
                raw_len: read_u64(entry, 24),
                crc32: read_u32(entry, 32),
                stored_crc32: (minor >= STORED_CRC_SINCE_MINOR).then(|| read_u32(entry, 36)),
            };
            let tag = Tag(info.tag);
            if !info.tag.iter().all(|&b| is_tag_byte(b)) {
                return Err(BundleError::Layout(format!("section {i} has a non-ASCII tag \"{tag}\"")));
            }
            // In 1.0 files word 36 is reserved: zero, like every reserved field of a known minor.
            let reserved = read_u32(entry, 36);
            if reject_reserved && info.stored_crc32.is_none() && reserved != 0 {
                return Err(BundleError::Layout(format!("section {tag}: reserved field is {reserved:#x}, must be 0")));
            }
            if !seen_tags.insert(info.tag) {
                return Err(BundleError::DuplicateSection(tag));
            }
            if info.codec == Codec::Raw as u32 && info.stored_len != info.raw_len {
                return Err(BundleError::Layout(format!(
                    "section {tag}: raw codec but stored length {} differs from raw length {}",
                    info.stored_len, info.raw_len
                )));
            }
            let expected = align_up(end).unwrap_or(u64::MAX);
            if info.offset != expected {
                return Err(BundleError::Layout(format!(
                    "section {tag}: offset {} is not the canonical {expected} (8-aligned, right after the previous section)",
                    info.offset
                )));
            }
            let section_end =
                info.offset.checked_add(info.stored_len).filter(|&e| e <= declared_len).ok_or_else(|| BundleError::Truncated {
                    what: format!("section {tag} (offset {}, {} bytes)", info.offset, info.stored_len),
                    needed: info.offset.saturating_add(info.stored_len),
                    available: declared_len,
                })?;
            check_zero_gap(bytes, end, info.offset, &format!("before section {tag}"))?;
            end = section_end;
            sections.push(info);
        }
        let file_end = align_up(end).unwrap_or(u64::MAX);
        if file_end != declared_len {
            return Err(BundleError::Layout(format!(
                "total length {declared_len} is not the 8-aligned end of the last section ({file_end})"
            )));
        }
        check_zero_gap(bytes, end, file_end, "at the end of the file")?;
        Ok(Container { bytes, minor, sections })
    }

    /// Whether reserved fields must be zero: files of a minor this reader knows.
    pub(crate) fn reject_reserved(&self) -> bool {
        reserved_must_be_zero(self.minor)
    }

    /// The table entry for `tag`, if present.
    pub(crate) fn find(&self, tag: [u8; 4]) -> Option<&SectionInfo> {
        self.sections.iter().find(|s| s.tag == tag)
    }

    /// The stored bytes of a section, exactly as they lie in the file.
    fn stored_bytes(&self, info: &SectionInfo) -> Result<&'a [u8], BundleError> {
        usize::try_from(info.offset)
            .ok()
            .zip(usize::try_from(info.stored_len).ok())
            .and_then(|(at, len)| self.bytes.get(at..at.checked_add(len)?))
            .ok_or_else(|| BundleError::Layout(format!("section {} lies outside the file", Tag(info.tag))))
    }

    /// Checks the stored-bytes CRC of a section (files of minor ≥ 1; 1.0 files have none).
    fn check_stored_crc(&self, info: &SectionInfo) -> Result<&'a [u8], BundleError> {
        let stored = self.stored_bytes(info)?;
        if let Some(expected) = info.stored_crc32 {
            let computed = crc32fast::hash(stored);
            if computed != expected {
                return Err(BundleError::StoredChecksum { tag: Tag(info.tag), stored: expected, computed });
            }
        }
        Ok(stored)
    }

    /// Checks the stored-bytes CRC of every section, known to this reader or not,
    /// before anything is decompressed: in a 1.1 file no corrupted byte goes unseen.
    pub(crate) fn check_stored_crcs(&self) -> Result<(), BundleError> {
        self.sections.iter().try_for_each(|info| self.check_stored_crc(info).map(|_| ()))
    }

    /// The raw bytes of a section: stored-CRC-checked (1.1), decompressed (at most
    /// `raw_len` bytes are ever produced), length-checked and raw-CRC-checked.
    pub(crate) fn payload(&self, info: &SectionInfo) -> Result<Cow<'a, [u8]>, BundleError> {
        let tag = Tag(info.tag);
        let stored = self.check_stored_crc(info)?;
        let raw: Cow<'a, [u8]> = match info.codec {
            0 => Cow::Borrowed(stored),
            1 => Cow::Owned(decompress_capped(stored, info.raw_len, tag)?),
            codec => return Err(BundleError::UnknownCodec { tag, codec }),
        };
        let computed = crc32fast::hash(&raw);
        if computed != info.crc32 {
            return Err(BundleError::SectionChecksum { tag, stored: info.crc32, computed });
        }
        Ok(raw)
    }
}

/// Errors unless `bytes[from..to]` are all zero (padding between or after payloads).
fn check_zero_gap(bytes: &[u8], from: u64, to: u64, where_: &str) -> Result<(), BundleError> {
    let gap = bytes.get(from as usize..to as usize).unwrap_or(&[]);
    if gap.iter().any(|&b| b != 0) {
        return Err(BundleError::Layout(format!("padding {where_} is not zero")));
    }
    Ok(())
}

/// Decompresses zstd frames, refusing to produce more than `raw_len` bytes, and
/// growing the buffer only as real output arrives (a hostile `raw_len` costs nothing).
fn decompress_capped(stored: &[u8], raw_len: u64, tag: Tag) -> Result<Vec<u8>, BundleError> {
    let fail = |detail: String| BundleError::Decompress { tag, detail };
    let mut decoder = zstd::stream::read::Decoder::with_buffer(stored).map_err(|e| fail(e.to_string()))?;
    // A frame's window never needs to exceed its content (zstd's encoder sizes it so), and the
    // decoder reserves the window up front: cap it by the declared length, or a hostile frame
    // header alone could make it reserve zstd's default limit, 128 MiB.
    decoder.window_log_max(window_log_for(raw_len)).map_err(|e| fail(e.to_string()))?;
    // Start modestly: zstd rarely exceeds 16:1 on our data; the Vec grows past that.
    let initial = raw_len.min(stored.len() as u64 * 16 + 4096) as usize;
    let mut out = Vec::with_capacity(initial);
    decoder.take(raw_len.saturating_add(1)).read_to_end(&mut out).map_err(|e| fail(e.to_string()))?;
    if out.len() as u64 != raw_len {
        let produced = if (out.len() as u64) > raw_len { "more than that".to_string() } else { out.len().to_string() };
        return Err(fail(format!("declared raw length is {raw_len} bytes, zstd produced {produced}")));
    }
    Ok(out)
}

/// The smallest zstd window log that holds `raw_len` bytes, within zstd's
/// decoding range (2^10 .. 2^31).
fn window_log_for(raw_len: u64) -> u32 {
    let needed = 64 - raw_len.saturating_sub(1).leading_zeros();
    needed.clamp(10, 31)
}

/// Lays out tagged raw payloads as a complete container (header, table, payloads).
///
/// Preconditions: tags are ASCII graphic and distinct (checked; `Invalid` otherwise).
/// Deterministic: the same sections and options give the same bytes.
pub(crate) fn write_container(sections: &[([u8; 4], Vec<u8>)], options: EncodeOptions) -> Result<Vec<u8>, BundleError> {
    for (i, (tag, _)) in sections.iter().enumerate() {
        if !tag.iter().all(|&b| is_tag_byte(b)) || sections[..i].iter().any(|(t, _)| t == tag) {
            return Err(BundleError::Invalid(format!("section tag \"{}\" is not ASCII or repeats", Tag(*tag))));
        }
    }
    let section_count = u32::try_from(sections.len()).map_err(|_| BundleError::Invalid("too many sections".into()))?;
    let table_end = HEADER_LEN + ENTRY_LEN * sections.len();

    // Payloads first, so the table can record offsets and stored lengths.
    let mut body = Vec::new();
    let mut table = Vec::with_capacity(ENTRY_LEN * sections.len());
    for (tag, raw) in sections {
        let (codec, stored) = match options.compression {
            Compression::None => (Codec::Raw, Cow::Borrowed(raw.as_slice())),
            Compression::Zstd { level } => {
                let packed = zstd::bulk::compress(raw, level)
                    .map_err(|e| BundleError::Invalid(format!("zstd failed on section {}: {e}", Tag(*tag))))?;
                if packed.len() < raw.len() {
                    (Codec::Zstd, Cow::Owned(packed))
                } else {
                    (Codec::Raw, Cow::Borrowed(raw.as_slice()))
                }
            }
        };
        table.extend_from_slice(tag);
        put_u32(&mut table, codec as u32);
        put_u64(&mut table, (table_end + body.len()) as u64);
        put_u64(&mut table, stored.len() as u64);
        put_u64(&mut table, raw.len() as u64);
        put_u32(&mut table, crc32fast::hash(raw));
        put_u32(&mut table, crc32fast::hash(&stored));
        body.extend_from_slice(&stored);
        pad_to(&mut body, ALIGN as usize);
    }

    let total_len = (table_end + body.len()) as u64;
    let mut out = Vec::with_capacity(total_len as usize);
    out.extend_from_slice(&MAGIC);
    put_u16(&mut out, FORMAT_MAJOR);
    put_u16(&mut out, FORMAT_MINOR);
    put_u32(&mut out, section_count);
    put_u64(&mut out, total_len);
    put_u32(&mut out, 0); // flags: none defined in 1.x
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(&out);
    hasher.update(&table);
    put_u32(&mut out, hasher.finalize());
    out.extend_from_slice(&table);
    out.extend_from_slice(&body);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(compression: Compression) -> Vec<u8> {
        let sections = vec![(*b"AAAA", vec![7u8; 100]), (*b"BBBB", b"hello".to_vec()), (*b"CCCC", Vec::new())];
        write_container(&sections, EncodeOptions { compression }).unwrap()
    }

    #[test]
    fn container_round_trips_payloads_with_both_codecs() {
        for compression in [Compression::None, Compression::Zstd { level: 9 }] {
            let bytes = sample(compression);
            assert_eq!(bytes.len() % 8, 0);
            let c = Container::parse(&bytes).unwrap();
            assert_eq!(c.sections.len(), 3);
            assert_eq!(&*c.payload(c.find(*b"AAAA").unwrap()).unwrap(), &[7u8; 100][..]);
            assert_eq!(&*c.payload(c.find(*b"BBBB").unwrap()).unwrap(), b"hello");
            assert!(c.payload(c.find(*b"CCCC").unwrap()).unwrap().is_empty());
            let expected_codec = if compression == Compression::None { 0 } else { 1 };
            assert_eq!(c.find(*b"AAAA").unwrap().codec, expected_codec);
            // "hello" does not shrink under zstd, so it is always stored raw.
            assert_eq!(c.find(*b"BBBB").unwrap().codec, 0);
        }
    }

    #[test]
    fn zstd_output_longer_than_declared_is_refused() {
        let bytes = sample(Compression::Zstd { level: 9 });
        let c = Container::parse(&bytes).unwrap();
        let mut info = *c.find(*b"AAAA").unwrap();
        info.raw_len = 99;
        assert!(matches!(c.payload(&info), Err(BundleError::Decompress { .. })));
        info.raw_len = 101;
        assert!(matches!(c.payload(&info), Err(BundleError::Decompress { .. })));
        info.raw_len = u64::MAX; // must not try to allocate it
        assert!(matches!(c.payload(&info), Err(BundleError::Decompress { .. })));
    }

    /// A frame header may claim any window up to zstd's limit, which the decoder
    /// would reserve before producing a byte: the window is capped by the
    /// section's declared length, so such a frame is refused instead.
    #[test]
    fn zstd_window_larger_than_the_section_is_refused() {
        use std::io::Write;
        let raw = vec![7u8; 1000];
        let frame = |window_log: u32| {
            let mut encoder = zstd::stream::write::Encoder::new(Vec::new(), 3).unwrap();
            encoder.window_log(window_log).unwrap();
            encoder.include_contentsize(false).unwrap();
            encoder.write_all(&raw).unwrap();
            encoder.finish().unwrap()
        };
        let tag = Tag(*b"AAAA");
        assert_eq!(window_log_for(1000), 10);
        assert_eq!(decompress_capped(&frame(10), 1000, tag).unwrap(), raw);
        let err = decompress_capped(&frame(27), 1000, tag).unwrap_err().to_string();
        assert!(err.contains("memory") || err.contains("window"), "{err}");
        // What our writer produces always fits: zstd sizes the window to the content.
        let packed = zstd::bulk::compress(&vec![3u8; 300_000], 19).unwrap();
        assert_eq!(decompress_capped(&packed, 300_000, tag).unwrap().len(), 300_000);
    }

    #[test]
    fn text_mode_mangled_magic_is_named() {
        let mut bytes = sample(Compression::None);
        bytes.remove(4); // "\r\n" -> "\n"
        let err = Container::parse(&bytes).err().unwrap().to_string();
        assert!(err.contains("not a prtbake bundle") && err.contains("line-ending"), "{err}");
    }

    #[test]
    fn duplicate_tags_are_refused_on_write() {
        let sections = vec![(*b"AAAA", vec![]), (*b"AAAA", vec![])];
        assert!(write_container(&sections, EncodeOptions::default()).is_err());
    }
}
