//! The `.prtb` bundle: a compact, versioned, checksummed container for a baked scene.
//!
//! A bundle holds the mesh, its materials, per-vertex SH transfer and sun masks
//! with per-step sun/sky data, each in its own tagged section, zstd-compressed
//! per section, CRC-32 over the header and table and, per section, of the stored
//! and of the decoded bytes (format 1.1; 1.0 files, with the decoded CRC only, still read).
//! Little-endian everywhere. The byte layout is specified in docs/bundle-format.md.
//!
//! - `container`: header, section table, codecs, checksums (knows no content).
//! - `sections`: typed encode/decode of META, MESH, MATL, XFER, SUNM, SUND, ATLS, TXFR, TSUN.
//! - `quantize`: f32 / f16 / i16-with-per-vertex-scale transfer storage.
//! - `export_gltf`: the mesh as GLB with transfer and sun masks as `_PRT_…` vertex attributes;
//!   `export_texels`: a texel bundle's atlas split, `TEXCOORD_1` and texel textures for it.
//!
//! Decoding never panics on hostile bytes: counts are checked against section
//! lengths before allocation and every failure is a [`BundleError`] naming the
//! section and the problem.

mod assemble;
pub mod budget;
mod container;
mod cursor;
mod error;
mod export_gltf;
mod export_texels;
mod quantize;
pub mod recipe;
mod sections;
mod types;
mod values;

#[cfg(test)]
pub(crate) mod fuzz_tests;
#[cfg(test)]
mod tests;

use std::path::Path;

pub use assemble::{
    add_texel_transfer, bundle_meta, conventions, encode_transfer_bundle, make_bundle, make_bundle_stored, note_vertex_rays, storage_meta,
    StorageRequest, AUTO_QUANTIZE_BUDGET,
};
pub use container::{
    Codec, Compression, EncodeOptions, SectionInfo, ALIGN, ENTRY_LEN, FORMAT_MAJOR, FORMAT_MINOR, HEADER_LEN, MAGIC, STORED_CRC_SINCE_MINOR,
};
pub use error::{BundleError, Tag};
pub use export_gltf::{
    export_glb, transfer_attributes, GltfExportReport, GLTF_EXPORT_FORMAT, SUN_ATTRIBUTE_PREFIX, TRANSFER_ATTRIBUTE_PREFIX,
};
pub use quantize::{choose_quantization, dequantize_i16, i16_scale, quantization_error, quantize_i16, round_trip, tint_split};
pub use sections::quantize_share;
pub use types::{
    window_patterns_in, Bundle, LayerKind, Quantization, SunSeries, SunStep, TexelAtlas, TexelLayers, Transfer, TransferLayer,
};
pub use values::{BadValue, ValueProblem, UNIT_LENGTH_TOLERANCE};

use container::{write_container, Container};
use sections::{ReadRules, ATLS, MATL, MESH, META, SIDE, SUND, SUNM, TSAB, TSAF, TSAT, TSID, TSUF, TSUN, TXFR, XFER};

/// Encodes a bundle with the default options (zstd level 9 per section).
///
/// Deterministic: the same bundle gives the same bytes (fixed level, single-threaded
/// zstd, no timestamps). Errors with [`BundleError::Invalid`] when the bundle would
/// not read back: mesh invariants ([`crate::mesh::Mesh::validate`]), transfer or mask
/// lengths that do not match the vertex count, non-finite values anywhere, sun
/// values out of range (direction not unit, elevation, azimuth, negative irradiance),
/// f16 overflow, duplicate layer kinds, mask bits past the last step.
///
/// Three kinds of loader output are stored in range instead (as the bake uses
/// them): albedo and transmittance clamped into [0, 1], negative colour channels
/// as 0, zero normals replaced by the vertex's face normal.
pub fn encode_bundle(b: &Bundle) -> Result<Vec<u8>, BundleError> {
    encode_bundle_with(b, EncodeOptions::default())
}

/// [`encode_bundle`] with explicit options (e.g. [`Compression::None`] for golden tests).
pub fn encode_bundle_with(b: &Bundle, options: EncodeOptions) -> Result<Vec<u8>, BundleError> {
    b.mesh.validate().map_err(|e| BundleError::Invalid(format!("mesh: {e}")))?;
    let vertex_count = b.mesh.vertex_count();
    let mut parts = vec![
        (META, sections::encode_meta(&b.meta)?),
        (MESH, sections::encode_mesh(&b.mesh)?),
        (MATL, sections::encode_materials(&b.mesh.materials, &b.mesh.groups)?),
    ];
    if let Some(t) = &b.transfer {
        parts.push((XFER, sections::encode_transfer(t, vertex_count)?));
        if !t.front_share.is_empty() {
            parts.push((SIDE, sections::encode_side_shares(&t.front_share, vertex_count, SIDE)?));
        }
    }
    if let Some(sun) = &b.sun {
        parts.push((SUNM, sections::encode_sun_masks(sun, vertex_count)?));
        parts.push((SUND, sections::encode_sun_data(sun)?));
    }
    if let Some(t) = &b.texels {
        parts.push((ATLS, sections::encode_atlas(&t.atlas, &t.texels, &b.mesh)?));
        if let Some(transfer) = &t.transfer {
            parts.push((TXFR, sections::encode_transfer_of(t.texels.len(), transfer, TXFR)?));
            if !transfer.front_share.is_empty() {
                parts.push((TSID, sections::encode_side_shares(&transfer.front_share, t.texels.len(), TSID)?));
            }
        }
    }
    if let Some(sun) = &b.sun {
        parts.extend(texel_sun_sections(sun, b.texels.as_ref(), &b.mesh)?);
    }
    if b.texels.as_ref().is_some_and(|t| t.transfer.is_none()) && b.sun.as_ref().is_none_or(|s| s.texel_masks.is_empty()) {
        return Err(BundleError::Invalid("an atlas with neither texel transfer nor texel sun masks".into()));
    }
    write_container(&parts, options)
}

/// TSUN and TSUF of `sun` over `texels`' atlas, or TSAT, TSAB and TSAF
/// over the sun's own (none when it has no texel masks). The bits on the
/// sun's own atlas have tags of their own, so a reader that knows none of
/// the three skips them all and reads the rest of the bundle.
fn texel_sun_sections(
    sun: &SunSeries,
    texels: Option<&TexelLayers>,
    mesh: &crate::mesh::Mesh,
) -> Result<Vec<([u8; 4], Vec<u8>)>, BundleError> {
    if sun.texel_masks.is_empty() {
        if !sun.texel_fractions.is_empty() {
            return Err(BundleError::Invalid("texel sun fractions without texel sun masks".into()));
        }
        if sun.texel_atlas.is_some() {
            return Err(BundleError::Invalid("a sun atlas without texel sun masks".into()));
        }
        return Ok(Vec::new());
    }
    let mut parts = Vec::new();
    if let Some(own) = &sun.texel_atlas {
        // Its own atlas sits beside the texel transfer's; beside vertex transfer the atlas is ATLS.
        if texels.is_none_or(|t| t.transfer.is_none()) {
            return Err(BundleError::Invalid("a sun atlas of its own (TSAT) needs texel transfer; store the atlas as ATLS".into()));
        }
        parts.push((TSAT, sections::encode_atlas(&own.atlas, &own.texels, mesh)?));
    }
    let count = sun.texel_count(texels).ok_or_else(|| BundleError::Invalid("texel sun masks without an atlas".into()))?;
    let own = sun.texel_atlas.is_some();
    let (bits, shares) = if own { (TSAB, TSAF) } else { (TSUN, TSUF) };
    parts.push((bits, sections::encode_texel_sun_masks(sun, count, own)?));
    if !sun.texel_fractions.is_empty() {
        parts.push((shares, sections::encode_texel_sun_fractions(sun, count, own)?));
    }
    Ok(parts)
}

/// Decodes and fully checks a bundle (see "Reader rules" in docs/bundle-format.md).
///
/// The stored-bytes CRC of every section (1.1 files) is checked before anything
/// is decompressed, so a corrupted section is refused even when this reader
/// does not know its tag.
/// Sections with unknown tags are skipped; a file of a later minor version is read
/// for what this reader knows. Transfer data comes back dequantized to f32.
pub fn decode_bundle(bytes: &[u8]) -> Result<Bundle, BundleError> {
    let container = Container::parse(bytes)?;
    container.check_stored_crcs()?;
    let rules = ReadRules {
        reject_reserved: container.reject_reserved(),
        bring_legacy_values_into_range: container.minor < values::RANGES_CHECKED_SINCE_MINOR,
    };
    let section = |tag: [u8; 4]| container.find(tag).map(|info| container.payload(info)).transpose();
    let required = |tag: [u8; 4]| section(tag)?.ok_or(BundleError::MissingSection(Tag(tag)));

    let meta = sections::decode_meta(&required(META)?)?;
    let (materials, groups) = sections::decode_materials(&required(MATL)?, rules)?;
    let mut mesh = sections::decode_mesh(&required(MESH)?, rules)?;
    mesh.materials = materials;
    mesh.groups = groups;
    mesh.validate().map_err(|e| BundleError::malformed(MESH, e))?;
    let vertex_count = mesh.vertex_count();

    let transfer = match (section(XFER)?, section(SIDE)?) {
        (Some(raw), side) => {
            let mut transfer = sections::decode_transfer(&raw, vertex_count, rules)?;
            if let Some(side) = side {
                transfer.front_share = sections::decode_side_shares(&side, vertex_count, SIDE)?;
            }
            Some(transfer)
        }
        (None, Some(_)) => return Err(BundleError::MissingSection(Tag(XFER))),
        (None, None) => None,
    };
    let sun = match (section(SUNM)?, section(SUND)?) {
        (None, None) => None,
        (Some(_), None) => return Err(BundleError::MissingSection(Tag(SUND))),
        (None, Some(_)) => return Err(BundleError::MissingSection(Tag(SUNM))),
        (Some(masks_raw), Some(data_raw)) => {
            let (step_count, words_per_vertex, masks) = sections::decode_sun_masks(&masks_raw, vertex_count, rules)?;
            let (sky_order, steps) = sections::decode_sun_data(&data_raw, rules)?;
            if steps.len() != step_count as usize {
                return Err(BundleError::malformed(SUND, format!("{} steps, but SUNM has {step_count}", steps.len())));
            }
            Some(SunSeries::per_vertex(sky_order, steps, words_per_vertex, masks))
        }
    };
    let (atlas_raw, texel_transfer_raw, texel_sun_raw) = (section(ATLS)?, section(TXFR)?, section(TSUN)?);
    let texel_side_raw = section(TSID)?;
    if texel_side_raw.is_some() && texel_transfer_raw.is_none() {
        return Err(BundleError::MissingSection(Tag(TXFR)));
    }
    let texel_fractions_raw = section(TSUF)?;
    if texel_fractions_raw.is_some() && texel_sun_raw.is_none() {
        return Err(BundleError::MissingSection(Tag(TSUN)));
    }
    let texels = match atlas_raw {
        None if texel_transfer_raw.is_some() || texel_sun_raw.is_some() => return Err(BundleError::MissingSection(Tag(ATLS))),
        None => None,
        Some(atlas_raw) => {
            let (atlas, texels) = sections::decode_atlas(&atlas_raw, &mesh, rules, ATLS)?;
            let transfer = match texel_transfer_raw {
                Some(raw) => {
                    let mut transfer = sections::decode_transfer_of(&raw, texels.len(), rules, TXFR)?;
                    if let Some(side) = texel_side_raw {
                        transfer.front_share = sections::decode_side_shares(&side, texels.len(), TSID)?;
                    }
                    Some(transfer)
                }
                None if texel_sun_raw.is_none() => return Err(BundleError::MissingSection(Tag(TXFR))),
                None => None,
            };
            Some(TexelLayers { atlas, texels, transfer })
        }
    };
    let mut sun = sun;
    if let (Some(raw), Some(t)) = (texel_sun_raw, &texels) {
        let series = sun.as_mut().ok_or(BundleError::MissingSection(Tag(SUNM)))?;
        series.texel_masks = sections::decode_texel_sun_masks(&raw, t.texels.len(), series.steps.len() as u32, rules, false)?;
        if let Some(raw) = texel_fractions_raw {
            series.texel_fractions = sections::decode_texel_sun_fractions(&raw, t.texels.len(), series.steps.len() as u32, rules, false)?;
        }
    }
    // The sun's own atlas (TSAT) with its bits (TSAB) and shares (TSAF), beside texel transfer.
    let (own_atlas_raw, own_bits_raw, own_shares_raw) = (section(TSAT)?, section(TSAB)?, section(TSAF)?);
    match (own_atlas_raw, own_bits_raw) {
        (None, None) if own_shares_raw.is_some() => return Err(BundleError::MissingSection(Tag(TSAB))),
        (None, None) => {}
        (Some(_), None) => return Err(BundleError::MissingSection(Tag(TSAB))),
        (None, Some(_)) => return Err(BundleError::MissingSection(Tag(TSAT))),
        (Some(atlas_raw), Some(bits_raw)) => {
            if texels.as_ref().is_none_or(|t| t.transfer.is_none()) {
                return Err(BundleError::MissingSection(Tag(TXFR)));
            }
            let series = sun.as_mut().ok_or(BundleError::MissingSection(Tag(SUNM)))?;
            if !series.texel_masks.is_empty() {
                return Err(BundleError::malformed(TSAB, "sun bits on the sun's own atlas and on the transfer's (TSUN) both"));
            }
            let (atlas, covered) = sections::decode_atlas(&atlas_raw, &mesh, rules, TSAT)?;
            let steps = series.steps.len() as u32;
            series.texel_masks = sections::decode_texel_sun_masks(&bits_raw, covered.len(), steps, rules, true)?;
            if let Some(raw) = own_shares_raw {
                series.texel_fractions = sections::decode_texel_sun_fractions(&raw, covered.len(), steps, rules, true)?;
            }
            series.texel_atlas = Some(TexelAtlas { atlas, texels: covered });
        }
    }
    Ok(Bundle { meta, mesh, transfer, sun, texels })
}

/// Re-encodes the bundle `original` with new metadata and a new sun series,
/// copying every other section's raw payload verbatim (MESH, MATL, XFER and
/// sections this reader does not know), so the transfer stays bit-identical
/// whatever its quantization. (From a 1.0 original, MESH and MATL are written
/// as decoded, in range; the result is a file of the current minor.) The
/// sections come in [`encode_bundle`]'s order: META replaced in place, the
/// other sections before the sun in their order, then SUNM and SUND, then
/// ATLS and TXFR, then TSUN and TSUF (the texels' masks and fractions) or
/// TSAT, TSAB and TSAF (the sun's own atlas, masks and fractions), when the
/// series has them; earlier ones are dropped otherwise.
///
/// `original` is fully decoded first (every check of [`decode_bundle`]); the
/// sun series must match its mesh's vertex count.
pub fn encode_with_sun(original: &[u8], meta: &serde_json::Value, sun: &SunSeries) -> Result<Vec<u8>, BundleError> {
    encode_with_sun_on(original, meta, sun, None)
}

/// [`encode_with_sun`] with the atlas its texel sun masks are laid over:
/// added as ATLS to an `original` without one (texel sun bits beside
/// per-vertex transfer), or the same as `original`'s (else refused). A
/// series with an atlas of its own ([`SunSeries::texel_atlas`]) goes to TSAT
/// beside `original`'s texel transfer; `atlas` is then `None`.
pub fn encode_with_sun_on(
    original: &[u8],
    meta: &serde_json::Value,
    sun: &SunSeries,
    atlas: Option<(&crate::atlas::Atlas, &[u32])>,
) -> Result<Vec<u8>, BundleError> {
    let decoded = decode_bundle(original)?;
    let added_atlas = match (atlas, &decoded.texels) {
        (Some((a, texels)), None) => {
            let layers = TexelLayers { atlas: a.clone(), texels: texels.to_vec(), transfer: None };
            Some((sections::encode_atlas(&layers.atlas, &layers.texels, &decoded.mesh)?, layers))
        }
        (Some((a, texels)), Some(t)) if (a, texels) != (&t.atlas, &t.texels[..]) => {
            return Err(BundleError::Invalid("the texel sun masks' atlas is not the bundle's".into()));
        }
        _ => None,
    };
    let texels = added_atlas.as_ref().map(|(_, layers)| layers).or(decoded.texels.as_ref());
    let container = Container::parse(original)?;
    let vertex_count = decoded.mesh.vertex_count();
    let sun_masks = sections::encode_sun_masks(sun, vertex_count)?;
    let sun_data = sections::encode_sun_data(sun)?;
    if texels.is_none() && !sun.texel_masks.is_empty() && sun.texel_atlas.is_none() {
        return Err(BundleError::Invalid("texel sun masks, but the bundle has no atlas".into()));
    }
    let texel_sun = texel_sun_sections(sun, texels, &decoded.mesh)?;
    // A 1.0 file's mesh and materials may hold values its writer did not bring
    // into range (the decoder did): those two are stored as decoded.
    let legacy_values = container.minor < values::RANGES_CHECKED_SINCE_MINOR;
    // Sections in encode_bundle's order whichever way the bundle was made,
    // so a sharded sun bake's merge (which adds the sun to shard 0's frame)
    // writes the bytes of a single process: the sun after the vertices'
    // sections, then the atlas, its transfer and its sun.
    let mut parts = Vec::with_capacity(container.sections.len() + 2);
    let mut texel_sections = Vec::new();
    for info in &container.sections {
        match info.tag {
            META => parts.push((META, sections::encode_meta(meta)?)),
            SUNM | SUND | TSUN | TSUF | TSAT | TSAB | TSAF => {}
            ATLS | TXFR | TSID => texel_sections.push((info.tag, container.payload(info)?.into_owned())),
            MESH if legacy_values => parts.push((MESH, sections::encode_mesh(&decoded.mesh)?)),
            MATL if legacy_values => parts.push((MATL, sections::encode_materials(&decoded.mesh.materials, &decoded.mesh.groups)?)),
            tag => parts.push((tag, container.payload(info)?.into_owned())),
        }
    }
    parts.push((SUNM, sun_masks));
    parts.push((SUND, sun_data));
    if let Some((raw, _)) = added_atlas {
        parts.push((ATLS, raw));
    }
    parts.extend(texel_sections);
    parts.extend(texel_sun);
    write_container(&parts, EncodeOptions::default())
}

/// The section table of a bundle, after the header checks (magic, version, header
/// CRC, length, layout); payloads are neither decompressed nor CRC-checked.
/// For `prtbake inspect`.
pub fn list_sections(bytes: &[u8]) -> Result<Vec<SectionInfo>, BundleError> {
    Container::parse(bytes).map(|c| c.sections)
}

/// Encodes `b` and writes it atomically ([`crate::files::write_atomic`]): on
/// failure `path` is untouched.
pub fn write_bundle(path: &Path, b: &Bundle) -> Result<(), BundleError> {
    let bytes = encode_bundle(b).map_err(|source| BundleError::InFile { path: path.to_path_buf(), source: Box::new(source) })?;
    crate::files::write_atomic(path, &bytes).map_err(|source| BundleError::Io { path: path.to_path_buf(), source })
}

/// Reads and decodes a bundle file; errors carry the path.
pub fn read_bundle(path: &Path) -> Result<Bundle, BundleError> {
    let bytes = read_bundle_bytes(path)?;
    decode_bundle(&bytes).map_err(|source| BundleError::InFile { path: path.to_path_buf(), source: Box::new(source) })
}

/// A bundle file's bytes, read only from a regular file within
/// [`Limit::Bundle`](crate::files::Limit), and only once its header and
/// section table agree with the file: its magic (a 3 GB file of something
/// else is refused after 32 bytes), the total length the header gives
/// against the file's size (a bundle with 3 GB appended likewise), then the
/// header CRC and the table's layout, read before any payload.
pub fn read_bundle_bytes(path: &Path) -> Result<Vec<u8>, BundleError> {
    use crate::files::{read::check_regular, read::read_head, Limit};
    let io = |source| BundleError::Io { path: path.to_path_buf(), source };
    let in_file = |source| BundleError::InFile { path: path.to_path_buf(), source: Box::new(source) };
    let size = check_regular(path, Limit::Bundle).map_err(io)?;
    let head = read_head(path, Limit::Bundle, HEADER_LEN as u64).map_err(io)?;
    let head_len = Container::head_len(&head, size).map_err(in_file)?;
    let head = read_head(path, Limit::Bundle, head_len).map_err(io)?;
    Container::check_head(&head, size).map_err(in_file)?;
    read_head(path, Limit::Bundle, size).map_err(io)
}
