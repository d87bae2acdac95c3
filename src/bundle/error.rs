//! The one error type of the bundle reader and writer.

use std::fmt;
use std::path::PathBuf;

use super::values::BadValue;

/// A four-byte section tag (`b"MESH"`), shown as ASCII with escapes for other bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Tag(pub [u8; 4]);

impl fmt::Display for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0.escape_ascii())
    }
}

/// Everything that can go wrong encoding, decoding, reading or writing a `.prtb` bundle.
///
/// Messages name the section (or header) and the problem; [`super::read_bundle`] and
/// [`super::write_bundle`] wrap errors in [`BundleError::InFile`] to add the path.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// The bytes end before a structure they announce does.
    #[error("truncated: {what} needs {needed} bytes but only {available} are present")]
    Truncated { what: String, needed: u64, available: u64 },
    /// The first eight bytes are not the `.prtb` magic.
    #[error("not a prtbake bundle ({detail})")]
    NotABundle { detail: String },
    /// A major version this reader does not know; the layout may differ entirely.
    #[error("unsupported bundle version {major}.{minor} (this reader knows major version {known_major})")]
    UnsupportedVersion { major: u16, minor: u16, known_major: u16 },
    /// The header CRC does not match the header and section table.
    #[error("header checksum mismatch: stored {stored:#010x}, computed {computed:#010x} (header or section table corrupted)")]
    HeaderChecksum { stored: u32, computed: u32 },
    /// More bytes than the header's total length.
    #[error("{extra} trailing bytes after the {declared}-byte bundle (the header's total length; the file has {} bytes)", declared.saturating_add(*extra))]
    TrailingBytes { declared: u64, extra: u64 },
    /// The header or section table breaks a layout rule (offsets, padding, reserved fields).
    #[error("bad layout: {0}")]
    Layout(String),
    /// The same tag appears twice in the section table.
    #[error("section {0} appears more than once")]
    DuplicateSection(Tag),
    /// A section every bundle must have is absent.
    #[error("required section {0} is missing")]
    MissingSection(Tag),
    /// A known section uses a codec this reader does not know.
    #[error("section {tag}: unknown codec {codec}")]
    UnknownCodec { tag: Tag, codec: u32 },
    /// zstd failed, or produced a length other than the declared raw length.
    #[error("section {tag}: decompression failed: {detail}")]
    Decompress { tag: Tag, detail: String },
    /// The CRC-32 of the section's stored bytes (as in the file) does not match the table (format ≥ 1.1).
    #[error(
        "section {tag}: stored-bytes checksum mismatch: stored {stored:#010x}, computed {computed:#010x} (payload corrupted in the file)"
    )]
    StoredChecksum { tag: Tag, stored: u32, computed: u32 },
    /// The CRC-32 of the section's raw bytes does not match the table.
    #[error("section {tag}: checksum mismatch: stored {stored:#010x}, computed {computed:#010x}")]
    SectionChecksum { tag: Tag, stored: u32, computed: u32 },
    /// A decoded float lies outside its meaning range (NaN albedo, zero normal, …).
    #[error("section {tag}: {bad}")]
    BadValue { tag: Tag, bad: BadValue },
    /// The section's raw bytes do not describe valid content.
    #[error("section {tag}: {detail}")]
    Malformed { tag: Tag, detail: String },
    /// The bundle handed to the encoder is inconsistent (and would not read back).
    #[error("cannot encode bundle: {0}")]
    Invalid(String),
    /// A file-system operation failed.
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// A decoding or encoding error, with the file it concerns.
    #[error("{path}: {source}")]
    InFile { path: PathBuf, source: Box<BundleError> },
}

impl BundleError {
    pub(crate) fn malformed(tag: [u8; 4], detail: impl Into<String>) -> BundleError {
        BundleError::Malformed { tag: Tag(tag), detail: detail.into() }
    }

    /// A decoded value out of range in section `tag`.
    pub(crate) fn bad_value(tag: [u8; 4]) -> impl FnOnce(BadValue) -> BundleError {
        move |bad| BundleError::BadValue { tag: Tag(tag), bad }
    }

    /// The encoder was handed a value the decoder would refuse.
    pub(crate) fn invalid_value(tag: [u8; 4]) -> impl FnOnce(BadValue) -> BundleError {
        move |bad| BundleError::Invalid(format!("section {}: {bad}", Tag(tag)))
    }

    /// The error without its [`BundleError::InFile`] wrapper, for matching on the kind.
    pub fn kind(&self) -> &BundleError {
        match self {
            BundleError::InFile { source, .. } => source.kind(),
            other => other,
        }
    }
}
