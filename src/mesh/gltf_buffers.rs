//! glTF byte sources: the GLB container, and buffers resolved without the gltf
//! crate's `import` feature (GLB binary chunk, `data:` URIs, files beside the .gltf).
//!
//! GLB layout (glTF 2.0 spec, "Binary glTF Layout"): a 12-byte header
//! (`magic "glTF"`, `version = 2`, `length` of the whole file), then chunks of
//! (`u32 length`, `u32 type`, data): the first is `JSON`, an optional `BIN\0` follows,
//! unknown chunk types are skipped. All little-endian.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use base64::Engine;

use super::MeshError;

/// The two payloads of a GLB file.
#[derive(Debug)]
pub(crate) struct GlbChunks<'a> {
    pub json: &'a [u8],
    pub bin: Option<&'a [u8]>,
}

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"
const GLB_HEADER_LEN: usize = 12;
const CHUNK_HEADER_LEN: usize = 8;

/// True when `bytes` starts like a GLB container.
pub(crate) fn is_glb(bytes: &[u8]) -> bool {
    bytes.starts_with(GLB_MAGIC)
}

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let word = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(word.try_into().ok()?))
}

/// Bytes of a GLB file's header and first chunk's header, which
/// [`check_glb_head`] reads before the rest.
pub(crate) const GLB_HEAD_LEN: usize = GLB_HEADER_LEN + CHUNK_HEADER_LEN;

/// What a GLB file's first bytes (`head`: [`GLB_HEAD_LEN`] of them, or the
/// whole file) say of a file of `file_len` bytes: magic, version 2, the
/// total length the header gives is the file's (a file longer or shorter is
/// refused, as the glTF validator does: `GLB_LENGTH_MISMATCH`), and the JSON
/// chunk fits in it. A loader checks this before reading the rest.
pub(crate) fn check_glb_head(head: &[u8], file_len: u64) -> Result<(), String> {
    if !is_glb(head) {
        return Err("not a GLB file (bad magic)".into());
    }
    let (Some(version), Some(declared)) = (read_u32(head, 4), read_u32(head, 8)) else {
        return Err(format!("GLB header truncated ({file_len} bytes)"));
    };
    if version != 2 {
        return Err(format!("GLB version {version} is not supported (expected 2)"));
    }
    let declared = u64::from(declared);
    if declared < GLB_HEAD_LEN as u64 {
        return Err(format!("GLB header declares a length of {declared} bytes, too small for a JSON chunk"));
    }
    if declared > file_len {
        return Err(format!("GLB truncated: header declares {declared} bytes, file has {file_len}"));
    }
    if declared < file_len {
        return Err(format!(
            "the GLB header declares {declared} bytes but the file has {file_len}: {} bytes past its end (appended to, or not this GLB)",
            file_len - declared
        ));
    }
    if let Some(json) = read_u32(head, GLB_HEADER_LEN) {
        if GLB_HEAD_LEN as u64 + u64::from(json) > declared {
            return Err(format!(
                "GLB chunk at byte {GLB_HEADER_LEN} declares {json} bytes, only {} remain",
                declared - GLB_HEAD_LEN as u64
            ));
        }
    }
    Ok(())
}

/// Splits a GLB container into its JSON and (optional) BIN chunk, checking every
/// length against the bytes actually present ([`check_glb_head`] first: the
/// file is exactly as long as its header says). Errors say what is wrong,
/// telling a truncated file from a bad header.
pub(crate) fn split_glb(bytes: &[u8]) -> Result<GlbChunks<'_>, String> {
    check_glb_head(bytes, bytes.len() as u64)?;
    let body = bytes;
    let mut chunks = Vec::new();
    let mut at = GLB_HEADER_LEN;
    while at < body.len() {
        let (Some(length), Some(kind)) = (read_u32(body, at), read_u32(body, at + 4)) else {
            return Err(format!("GLB chunk header at byte {at} is truncated"));
        };
        let start = at + CHUNK_HEADER_LEN;
        let Some(data) = start.checked_add(length as usize).and_then(|end| body.get(start..end)) else {
            return Err(format!("GLB chunk at byte {at} declares {length} bytes, only {} remain", body.len().saturating_sub(start)));
        };
        chunks.push((kind, data));
        at = start + data.len();
    }
    let json = match chunks.first() {
        Some(&(CHUNK_JSON, data)) => data,
        Some(&(kind, _)) => return Err(format!("first GLB chunk has type {kind:#010x}, expected JSON")),
        None => return Err("GLB has no chunks".into()),
    };
    let bin = chunks.iter().skip(1).find(|(kind, _)| *kind == CHUNK_BIN).map(|&(_, data)| data);
    Ok(GlbChunks { json, bin })
}

/// Loads the bytes of every buffer of `document`, in buffer order.
///
/// A buffer without `uri` is the GLB binary chunk; `data:...;base64,` URIs are
/// decoded; other URIs are percent-decoded and read relative to `base_dir` (only
/// regular files, at most `byteLength` bytes; their paths are added to `sources`). Each
/// result is checked to hold at least `byteLength` bytes and cut to exactly that.
pub(crate) fn load_buffers<'a>(
    document: &gltf::Document,
    glb_bin: Option<&'a [u8]>,
    base_dir: &Path,
    path: &Path,
    sources: &mut Vec<PathBuf>,
) -> Result<Vec<Cow<'a, [u8]>>, MeshError> {
    let mut buffers = Vec::with_capacity(document.buffers().len());
    for buffer in document.buffers() {
        let index = buffer.index();
        let mut data: Cow<'a, [u8]> = match buffer.source() {
            gltf::buffer::Source::Bin => match glb_bin {
                Some(bin) => Cow::Borrowed(bin),
                None => return Err(MeshError::gltf(path, format!("buffer {index} has no uri and the file has no GLB binary chunk"))),
            },
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                Cow::Owned(decode_data_uri(uri).map_err(|e| MeshError::gltf(path, format!("buffer {index}: {e}")))?)
            }
            gltf::buffer::Source::Uri(uri) => {
                let file = resolve_relative_uri(uri, base_dir).map_err(|e| MeshError::gltf(path, format!("buffer {index}: {e}")))?;
                // Never read past the declared length: a uri naming /dev/zero or a
                // FIFO is refused, a file shorter than its byteLength is refused
                // before a byte is read, and a longer one is read only as far as needed.
                let declared = buffer.length() as u64;
                sources.push(file.clone());
                let missing = |source| MeshError::MissingBuffer { path: path.to_path_buf(), buffer: index, file: file.clone(), source };
                let size = crate::files::read::check_regular(&file, crate::files::Limit::Mesh).map_err(missing)?;
                if size < declared {
                    return Err(MeshError::gltf(
                        path,
                        format!("buffer {index} declares byteLength {declared} but {} holds only {size} bytes", file.display()),
                    ));
                }
                Cow::Owned(crate::files::read::read_head(&file, crate::files::Limit::Mesh, declared).map_err(missing)?)
            }
        };
        let declared = buffer.length();
        if data.len() < declared {
            return Err(MeshError::gltf(
                path,
                format!("buffer {index} declares byteLength {declared} but holds only {} bytes", data.len()),
            ));
        }
        // GLB chunks are padded to 4 bytes: use exactly the declared length.
        match &mut data {
            Cow::Borrowed(slice) => *slice = &slice[..declared],
            Cow::Owned(vec) => vec.truncate(declared),
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// Decodes a `data:[<media type>];base64,<payload>` URI.
fn decode_data_uri(uri: &str) -> Result<Vec<u8>, String> {
    let Some((header, payload)) = uri.split_once(',') else {
        return Err("data URI has no ',' before its payload".into());
    };
    if !header.ends_with(";base64") {
        return Err(format!("data URI {header:?} is not base64-encoded (only base64 data URIs are supported)"));
    }
    // Accept payloads with or without '=' padding: both occur in the wild.
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new().with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
    );
    engine.decode(payload.trim()).map_err(|e| format!("bad base64 in data URI: {e}"))
}

/// Turns a relative URI reference into a path under `base_dir` (percent-decoded).
fn resolve_relative_uri(uri: &str, base_dir: &Path) -> Result<PathBuf, String> {
    // A scheme ("http:", "file:") ends before the first '/', '?' or '#'.
    let scheme_end = uri.find([':', '/', '?', '#']);
    if let Some(i) = scheme_end {
        if uri.as_bytes().get(i) == Some(&b':') {
            return Err(format!("uri {uri:?} is not a relative file reference"));
        }
    }
    let without_query = uri.split(['?', '#']).next().unwrap_or(uri);
    let decoded = percent_decode(without_query).ok_or_else(|| format!("uri {uri:?} has bad percent-encoding"))?;
    Ok(base_dir.join(decoded))
}

/// Decodes `%XX` escapes; `None` on a malformed escape or non-UTF-8 result.
fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while let Some(&byte) = bytes.get(i) {
        if byte == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(byte);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glb(json: &[u8], bin: Option<&[u8]>) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(json);
        if let Some(bin) = bin {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend_from_slice(bin);
        }
        let len = out.len() as u32;
        out[8..12].copy_from_slice(&len.to_le_bytes());
        out
    }

    #[test]
    fn splits_well_formed_glb() {
        let bytes = glb(b"{}  ", Some(&[1, 2, 3, 4]));
        let chunks = split_glb(&bytes).unwrap();
        assert_eq!(chunks.json, b"{}  ");
        assert_eq!(chunks.bin, Some(&[1u8, 2, 3, 4][..]));
    }

    /// Every truncation of a valid GLB is refused or yields shorter chunks; none panics.
    #[test]
    fn every_truncation_is_an_error_not_a_panic() {
        let bytes = glb(b"{\"asset\":{}}", Some(&[9; 16]));
        for len in 0..bytes.len() {
            assert!(split_glb(&bytes[..len]).is_err(), "length {len} accepted");
        }
        let mut small = bytes.clone();
        small[8..12].copy_from_slice(&3u32.to_le_bytes()); // declared length < header
        assert!(split_glb(&small).unwrap_err().contains("too small"));
        let mut version = bytes;
        version[4] = 1;
        assert!(split_glb(&version).unwrap_err().contains("version 1"));
    }

    #[test]
    fn decodes_data_uris_and_relative_paths() {
        assert_eq!(decode_data_uri("data:application/octet-stream;base64,AAEC").unwrap(), vec![0, 1, 2]);
        assert_eq!(decode_data_uri("data:application/gltf-buffer;base64,AAECAw").unwrap(), vec![0, 1, 2, 3]);
        assert!(decode_data_uri("data:text/plain,hello").is_err());
        assert!(decode_data_uri("data:;base64,@@@").is_err());
        let base = Path::new("/models");
        assert_eq!(resolve_relative_uri("my%20file.bin", base).unwrap(), Path::new("/models/my file.bin"));
        assert!(resolve_relative_uri("http://example.com/a.bin", base).is_err());
        assert!(resolve_relative_uri("bad%2", base).is_err());
    }
}
