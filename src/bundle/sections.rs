//! Typed encode/decode of each section's raw (decompressed) bytes.
//!
//! Decoders take untrusted bytes: every count is multiplied out with checked
//! arithmetic and compared with the section length before anything is allocated,
//! and each section must be consumed exactly. Layouts are documented in
//! docs/bundle-format.md; the comments here name the fields in order.

use glam::{Vec2, Vec3};

use super::cursor::{pad_to, put_f32, put_f64, put_u16, put_u32, Cursor};
use super::error::BundleError;
use super::quantize::{decode_layer, encode_layer, layer_bytes};
use super::types::{LayerKind, Quantization, SunSeries, SunStep, Transfer, TransferLayer};
use super::values;
use crate::mesh::{Material, MaterialRole, Mesh};

pub(crate) use super::container::{ATLS, MATL, MESH, META, SIDE, SUND, SUNM, TSAB, TSAF, TSAT, TSID, TSUF, TSUN, TXFR, XFER};

const MESH_HAS_UVS: u32 = 1;
const MESH_HAS_COLORS: u32 = 2;
const MESH_HAS_LIGHTMAP_UVS: u32 = 4;
const STEP_NIGHT: u32 = 1;
/// Fixed part of one SUND step record: f64 time, f32 × 3 dir, elev, azim, f32 × 3 rgb, u32 flags.
const SUN_STEP_FIXED: u64 = 8 + 12 + 4 + 4 + 12 + 4;

/// How a file's minor version changes the checks.
#[derive(Clone, Copy)]
pub(crate) struct ReadRules {
    /// Reserved fields must be zero (see `Container::reject_reserved`).
    pub reject_reserved: bool,
    /// A 1.0 file: albedo, transmittance, colours and normals are brought into
    /// range as the 1.1 writer stores them, instead of refused (the 1.0 writer
    /// did not clamp them). Non-finite values are refused all the same.
    pub bring_legacy_values_into_range: bool,
}

fn invalid(what: impl Into<String>) -> BundleError {
    BundleError::Invalid(what.into())
}

fn count_u32(n: usize, what: &str) -> Result<u32, BundleError> {
    u32::try_from(n).map_err(|_| invalid(format!("{what} {n} does not fit in u32")))
}

/// Checked product/sum helper: `None` means the declared counts overflow u64.
fn checked_len(parts: &[(u64, u64)]) -> Option<u64> {
    parts.iter().try_fold(0u64, |acc, &(count, size)| acc.checked_add(count.checked_mul(size)?))
}

fn round_up4(n: u64) -> u64 {
    n.div_ceil(4) * 4
}
fn round_up8(n: u64) -> u64 {
    n.div_ceil(8) * 8
}

fn check_exact_len(cur: &Cursor, expected: Option<u64>, what: impl FnOnce() -> String) -> Result<(), BundleError> {
    match expected {
        Some(n) if n == cur.remaining() as u64 => Ok(()),
        Some(n) => Err(cur.error(format!("{} needs {n} bytes, the section has {}", what(), cur.remaining()))),
        None => Err(cur.error(format!("{}: size overflows", what()))),
    }
}

// ---------------------------------------------------------------- META

/// META: compact UTF-8 JSON of any value.
pub(crate) fn encode_meta(meta: &serde_json::Value) -> Result<Vec<u8>, BundleError> {
    serde_json::to_vec(meta).map_err(|e| invalid(format!("META does not serialize: {e}")))
}

pub(crate) fn decode_meta(raw: &[u8]) -> Result<serde_json::Value, BundleError> {
    serde_json::from_slice(raw).map_err(|e| BundleError::malformed(META, format!("not valid UTF-8 JSON: {e}")))
}

// ---------------------------------------------------------------- MESH

/// MESH: u32 V, u32 T, u32 flags, positions f32×3×V, normals f32×3×V, [uvs f32×2×V],
/// [colors f32×3×V], [lightmap uvs f32×2×V], indices u32×3×T, tri_material u16×T
/// (pad 4), tri_group u32×T.
///
/// Zero normals are replaced and negative colour channels stored as 0 (see
/// `values`), so the section always passes the decoder's range checks.
pub(crate) fn encode_mesh(mesh: &Mesh) -> Result<Vec<u8>, BundleError> {
    let v = count_u32(mesh.vertex_count(), "vertex count")?;
    let t = count_u32(mesh.triangle_count(), "triangle count")?;
    values::check_positions(&mesh.positions).map_err(BundleError::invalid_value(MESH))?;
    let normals = values::normals_for_writing(mesh).map_err(BundleError::invalid_value(MESH))?;
    values::check_uvs(&mesh.uvs).map_err(BundleError::invalid_value(MESH))?;
    values::check_lightmap_uvs(&mesh.lightmap_uvs).map_err(BundleError::invalid_value(MESH))?;
    let colors: Vec<[f32; 3]> = mesh
        .colors
        .iter()
        .enumerate()
        .map(|(v, &c)| values::colour_for_writing(v, c))
        .collect::<Result<_, _>>()
        .map_err(BundleError::invalid_value(MESH))?;
    let flag = |empty: bool, bit: u32| if empty { 0 } else { bit };
    let flags = flag(mesh.uvs.is_empty(), MESH_HAS_UVS)
        | flag(colors.is_empty(), MESH_HAS_COLORS)
        | flag(mesh.lightmap_uvs.is_empty(), MESH_HAS_LIGHTMAP_UVS);
    let mut out = Vec::new();
    put_u32(&mut out, v);
    put_u32(&mut out, t);
    put_u32(&mut out, flags);
    mesh.positions.iter().chain(normals.iter()).for_each(|p| p.to_array().iter().for_each(|&x| put_f32(&mut out, x)));
    mesh.uvs.iter().for_each(|uv| uv.to_array().iter().for_each(|&x| put_f32(&mut out, x)));
    colors.iter().for_each(|c| c.iter().for_each(|&x| put_f32(&mut out, x)));
    mesh.lightmap_uvs.iter().for_each(|uv| uv.to_array().iter().for_each(|&x| put_f32(&mut out, x)));
    mesh.indices.iter().for_each(|&i| put_u32(&mut out, i));
    mesh.tri_material.iter().for_each(|&m| put_u16(&mut out, m));
    pad_to(&mut out, 4);
    mesh.tri_group.iter().for_each(|&g| put_u32(&mut out, g));
    Ok(out)
}

fn vec3s(values: Vec<f32>) -> Vec<Vec3> {
    values.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Geometry only: `materials` and `groups` come from MATL.
pub(crate) fn decode_mesh(raw: &[u8], rules: ReadRules) -> Result<Mesh, BundleError> {
    let mut cur = Cursor::new(raw, MESH);
    let v = cur.u32("vertex count")? as u64;
    let t = cur.u32("triangle count")? as u64;
    let flags = cur.u32("flags")?;
    if rules.reject_reserved && flags & !(MESH_HAS_UVS | MESH_HAS_COLORS | MESH_HAS_LIGHTMAP_UVS) != 0 {
        return Err(cur.error(format!("flags {flags:#x} set reserved bits")));
    }
    let has_uvs = flags & MESH_HAS_UVS != 0;
    let has_colors = flags & MESH_HAS_COLORS != 0;
    let has_lightmap = flags & MESH_HAS_LIGHTMAP_UVS != 0;
    let expected = checked_len(&[
        (v, 24 + if has_uvs { 8 } else { 0 } + if has_colors { 12 } else { 0 } + if has_lightmap { 8 } else { 0 }),
        (t, 12 + 4),
        (round_up4(t.saturating_mul(2)), 1),
    ]);
    check_exact_len(&cur, expected, || format!("a mesh of {v} vertices and {t} triangles (flags {flags:#x})"))?;

    let positions = vec3s(cur.f32s(3 * v, "positions")?);
    let normals = vec3s(cur.f32s(3 * v, "normals")?);
    let uvs = if has_uvs { cur.f32s(2 * v, "uvs")?.chunks_exact(2).map(Vec2::from_slice).collect() } else { Vec::new() };
    let colors = if has_colors { cur.f32s(3 * v, "colors")?.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect() } else { Vec::new() };
    let lightmap_uvs =
        if has_lightmap { cur.f32s(2 * v, "lightmap uvs")?.chunks_exact(2).map(Vec2::from_slice).collect() } else { Vec::new() };
    let indices = cur.u32s(3 * t, "indices")?;
    let tri_material = cur.u16s(t, "triangle materials")?;
    cur.padding(4, "triangle materials")?;
    let tri_group = cur.u32s(t, "triangle groups")?;
    cur.finish()?;
    let mut mesh = Mesh { positions, normals, uvs, lightmap_uvs, colors, indices, tri_material, tri_group, ..Mesh::default() };
    if rules.bring_legacy_values_into_range {
        mesh = values::legacy_mesh_in_range(mesh).map_err(BundleError::bad_value(MESH))?;
    }
    values::check_mesh(&mesh).map_err(BundleError::bad_value(MESH))?;
    Ok(mesh)
}

// ---------------------------------------------------------------- MATL

fn role_code(role: MaterialRole) -> u32 {
    match role {
        MaterialRole::Opaque => 0,
        MaterialRole::Window => 1,
        MaterialRole::Panel => 2,
    }
}

fn put_name(out: &mut Vec<u8>, name: &str) -> Result<(), BundleError> {
    put_u32(out, count_u32(name.len(), "name length")?);
    out.extend_from_slice(name.as_bytes());
    pad_to(out, 4);
    Ok(())
}

fn read_name(cur: &mut Cursor, what: &str) -> Result<String, BundleError> {
    let len = cur.u32(what)?;
    let bytes = cur.take(len as u64, what)?;
    let name = std::str::from_utf8(bytes).map_err(|_| cur.error(format!("{what} is not UTF-8")))?.to_string();
    cur.padding(4, what)?;
    Ok(name)
}

/// MATL: u32 material_count, u32 group_count; per material u32 role, f32×3 albedo,
/// f32 transmittance, name; per group a name. A name is u32 byte length, UTF-8, pad 4.
///
/// Albedo and transmittance are stored clamped into [0, 1] (see `values`).
pub(crate) fn encode_materials(materials: &[Material], groups: &[String]) -> Result<Vec<u8>, BundleError> {
    let mut out = Vec::new();
    put_u32(&mut out, count_u32(materials.len(), "material count")?);
    put_u32(&mut out, count_u32(groups.len(), "group count")?);
    for (i, m) in materials.iter().enumerate() {
        let m = values::material_for_writing(i, m).map_err(BundleError::invalid_value(MATL))?;
        put_u32(&mut out, role_code(m.role));
        m.albedo.iter().for_each(|&a| put_f32(&mut out, a));
        put_f32(&mut out, m.transmittance);
        put_name(&mut out, &m.name)?;
    }
    for g in groups {
        put_name(&mut out, g)?;
    }
    Ok(out)
}

pub(crate) fn decode_materials(raw: &[u8], rules: ReadRules) -> Result<(Vec<Material>, Vec<String>), BundleError> {
    let mut cur = Cursor::new(raw, MATL);
    let material_count = cur.u32("material count")? as u64;
    let group_count = cur.u32("group count")? as u64;
    // Smallest possible records (empty names) must fit before we reserve anything.
    let minimum = checked_len(&[(material_count, 24), (group_count, 4)]).unwrap_or(u64::MAX);
    if minimum > cur.remaining() as u64 {
        return Err(cur.error(format!(
            "{material_count} materials and {group_count} groups need at least {minimum} bytes, the section has {}",
            cur.remaining()
        )));
    }
    let mut materials = Vec::with_capacity(material_count as usize);
    for i in 0..material_count {
        let role = match cur.u32("material role")? {
            0 => MaterialRole::Opaque,
            1 => MaterialRole::Window,
            2 => MaterialRole::Panel,
            other => return Err(cur.error(format!("material {i} has unknown role {other}"))),
        };
        let albedo = [cur.f32("albedo")?, cur.f32("albedo")?, cur.f32("albedo")?];
        let transmittance = cur.f32("transmittance")?;
        let name = read_name(&mut cur, "material name")?;
        let mut material = Material { name, albedo, role, transmittance };
        if rules.bring_legacy_values_into_range {
            material = values::material_for_writing(i as usize, &material).map_err(BundleError::bad_value(MATL))?;
        }
        values::check_material(i as usize, &material).map_err(BundleError::bad_value(MATL))?;
        materials.push(material);
    }
    let mut groups = Vec::with_capacity(group_count as usize);
    for _ in 0..group_count {
        groups.push(read_name(&mut cur, "group name")?);
    }
    cur.finish()?;
    Ok((materials, groups))
}

// ---------------------------------------------------------------- XFER

/// XFER: u32 order, u32 channels, u32 layer_count, u32 quantization; per layer
/// u32 kind (0 total, 1 + b bounce b), u32 reserved, data (see `quantize`).
pub(crate) fn encode_transfer(t: &Transfer, vertex_count: usize) -> Result<Vec<u8>, BundleError> {
    encode_transfer_of(vertex_count, t, XFER)
}

/// XFER's layout over any receivers: the vertices (XFER) or the covered texels (TXFR).
pub(crate) fn encode_transfer_of(vertex_count: usize, t: &Transfer, tag: [u8; 4]) -> Result<Vec<u8>, BundleError> {
    if t.order == 0 || t.channels == 0 || t.layers.is_empty() {
        return Err(invalid(format!(
            "transfer needs order ≥ 1, channels ≥ 1 and a layer (order {}, channels {}, {} layers)",
            t.order,
            t.channels,
            t.layers.len()
        )));
    }
    let stride = t.values_per_vertex();
    let expected = (vertex_count as u64).checked_mul(stride);
    let mut out = Vec::new();
    put_u32(&mut out, t.order);
    put_u32(&mut out, t.channels);
    put_u32(&mut out, count_u32(t.layers.len(), "layer count")?);
    put_u32(&mut out, t.quantization.code());
    for (i, layer) in t.layers.iter().enumerate() {
        let code = layer.kind.code().ok_or_else(|| invalid(format!("layer {i}: bounce index too large")))?;
        if t.layers[..i].iter().any(|l| l.kind == layer.kind) {
            return Err(invalid(format!("transfer layer kind {:?} appears twice", layer.kind)));
        }
        if Some(layer.data.len() as u64) != expected {
            return Err(invalid(format!(
                "transfer layer {i} has {} values, expected {vertex_count} vertices × {stride}",
                layer.data.len()
            )));
        }
        values::check_layer(i, &layer.data, stride).map_err(BundleError::invalid_value(tag))?;
        if matches!(t.quantization, Quantization::F16 | Quantization::F16Tinted) {
            if let Some(j) = layer.data.iter().position(|v| !half::f16::from_f32(*v).is_finite()) {
                return Err(invalid(format!("transfer layer {i} value {j} ({}) overflows f16", layer.data[j])));
            }
        }
        put_u32(&mut out, code);
        put_u32(&mut out, 0);
        encode_layer(&layer.data, stride as usize, t.channels as usize, t.quantization, &mut out);
    }
    Ok(out)
}

pub(crate) fn decode_transfer(raw: &[u8], vertex_count: usize, rules: ReadRules) -> Result<Transfer, BundleError> {
    decode_transfer_of(raw, vertex_count, rules, XFER)
}

/// [`decode_transfer`] over any receivers (see [`encode_transfer_of`]).
pub(crate) fn decode_transfer_of(raw: &[u8], vertex_count: usize, rules: ReadRules, tag: [u8; 4]) -> Result<Transfer, BundleError> {
    let mut cur = Cursor::new(raw, tag);
    let order = cur.u32("order")?;
    let channels = cur.u32("channels")?;
    let layer_count = cur.u32("layer count")? as u64;
    let code = cur.u32("quantization")?;
    let quantization = Quantization::from_code(code).ok_or_else(|| cur.error(format!("unknown quantization {code}")))?;
    if order == 0 || channels == 0 || layer_count == 0 {
        return Err(cur.error(format!("order {order}, channels {channels}, {layer_count} layers: each must be ≥ 1")));
    }
    let v = vertex_count as u64;
    let stride = (channels as u64).checked_mul((order as u64) * (order as u64));
    let per_layer = stride.and_then(|s| layer_bytes(v, s, channels as u64, quantization)).and_then(|n| n.checked_add(8));
    let expected = per_layer.and_then(|n| n.checked_mul(layer_count));
    check_exact_len(&cur, expected, || {
        format!("{layer_count} {} layers of order {order} × {channels} channels for {v} vertices", quantization.name())
    })?;
    let stride = stride.unwrap_or(0); // checked just above

    let mut layers: Vec<TransferLayer> = Vec::with_capacity(layer_count as usize);
    for i in 0..layer_count {
        let kind = LayerKind::from_code(cur.u32("layer kind")?);
        let reserved = cur.u32("layer reserved")?;
        if rules.reject_reserved && reserved != 0 {
            return Err(cur.error(format!("layer {i}: reserved field is {reserved:#x}, must be 0")));
        }
        if layers.iter().any(|l| l.kind == kind) {
            return Err(cur.error(format!("layer {kind} appears twice")));
        }
        let data = decode_layer(&mut cur, v, stride, channels as u64, quantization, i as usize)?;
        values::check_layer(i as usize, &data, stride).map_err(BundleError::bad_value(tag))?;
        layers.push(TransferLayer { kind, data });
    }
    cur.finish()?;
    Ok(Transfer { order, channels, quantization, layers, front_share: Vec::new() })
}

// ---------------------------------------------------------------- SUNM

/// SUNM: u32 step_count, u32 words_per_vertex, u32 vertex_count, u32 reserved, u32 words.
pub(crate) fn encode_sun_masks(sun: &SunSeries, vertex_count: usize) -> Result<Vec<u8>, BundleError> {
    let steps = count_u32(sun.steps.len(), "step count")?;
    if sun.words_per_vertex != steps.div_ceil(32) {
        return Err(invalid(format!("{} words per vertex for {steps} steps", sun.words_per_vertex)));
    }
    if Some(sun.masks.len()) != vertex_count.checked_mul(sun.words_per_vertex as usize) {
        return Err(invalid(format!("{} mask words for {vertex_count} vertices × {} words", sun.masks.len(), sun.words_per_vertex)));
    }
    if let Some(v) = first_with_values_past(&sun.masks, steps, 1) {
        return Err(invalid(format!("sun mask of vertex {v} has bits set past step {steps}")));
    }
    let mut out = Vec::with_capacity(16 + 4 * sun.masks.len());
    put_u32(&mut out, steps);
    put_u32(&mut out, sun.words_per_vertex);
    put_u32(&mut out, count_u32(vertex_count, "vertex count")?);
    put_u32(&mut out, 0);
    sun.masks.iter().for_each(|&w| put_u32(&mut out, w));
    Ok(out)
}

/// Returns `(step_count, words_per_vertex, masks)`.
pub(crate) fn decode_sun_masks(raw: &[u8], vertex_count: usize, rules: ReadRules) -> Result<(u32, u32, Vec<u32>), BundleError> {
    let mut cur = Cursor::new(raw, SUNM);
    let steps = cur.u32("step count")?;
    let words_per_vertex = cur.u32("words per vertex")?;
    let declared_vertices = cur.u32("vertex count")?;
    let reserved = cur.u32("reserved")?;
    if rules.reject_reserved && reserved != 0 {
        return Err(cur.error(format!("reserved field is {reserved:#x}, must be 0")));
    }
    if words_per_vertex != steps.div_ceil(32) {
        return Err(cur.error(format!("{words_per_vertex} words per vertex for {steps} steps, expected {}", steps.div_ceil(32))));
    }
    if declared_vertices as usize != vertex_count {
        return Err(cur.error(format!("masks for {declared_vertices} vertices, the mesh has {vertex_count}")));
    }
    let expected = checked_len(&[(declared_vertices as u64, 4 * words_per_vertex as u64)]);
    check_exact_len(&cur, expected, || format!("{declared_vertices} vertices × {words_per_vertex} words"))?;
    let masks = cur.u32s(declared_vertices as u64 * words_per_vertex as u64, "mask words")?;
    if let Some(v) = first_with_values_past(&masks, steps, 1) {
        return Err(cur.error(format!("mask of vertex {v} has bits set past step {steps} (must be zero)")));
    }
    cur.finish()?;
    Ok((steps, words_per_vertex, masks))
}

// ---------------------------------------------------------------- SIDE, TSID

/// Levels of a stored front-side share (`v / SHARE_LEVELS`).
pub(crate) const SHARE_LEVELS: f32 = 255.0;

/// A share as stored: the nearest of the 256 levels.
pub fn quantize_share(share: f32) -> f32 {
    share_code(share) as f32 / SHARE_LEVELS
}

fn share_code(share: f32) -> u8 {
    (share.clamp(0.0, 1.0) * SHARE_LEVELS).round() as u8
}

/// SIDE (per vertex) and TSID (per covered texel): u32 receiver count, u32
/// bits per value (8), then one byte per receiver, `v / 255` the share of
/// its light that reached it through the front of its face; zero pad to 4.
pub(crate) fn encode_side_shares(shares: &[f32], count: usize, tag: [u8; 4]) -> Result<Vec<u8>, BundleError> {
    if shares.len() != count {
        return Err(invalid(format!("{} side shares for {count} receivers ({})", shares.len(), String::from_utf8_lossy(&tag))));
    }
    if let Some(i) = shares.iter().position(|s| !(0.0..=1.0).contains(s)) {
        return Err(invalid(format!("side share {} of receiver {i} is not in [0, 1] ({})", shares[i], String::from_utf8_lossy(&tag))));
    }
    let mut out = Vec::with_capacity(8 + round_up4(count as u64) as usize);
    put_u32(&mut out, count_u32(count, "side share count")?);
    put_u32(&mut out, 8);
    out.extend(shares.iter().map(|&s| share_code(s)));
    out.resize(round_up4(out.len() as u64) as usize, 0);
    Ok(out)
}

pub(crate) fn decode_side_shares(raw: &[u8], count: usize, tag: [u8; 4]) -> Result<Vec<f32>, BundleError> {
    let mut cur = Cursor::new(raw, tag);
    let declared = cur.u32("receiver count")?;
    let bits = cur.u32("bits per value")?;
    if bits != 8 {
        return Err(cur.error(format!("{bits} bits per value, expected 8")));
    }
    if declared as usize != count {
        return Err(cur.error(format!("shares of {declared} receivers, the bundle has {count}")));
    }
    check_exact_len(&cur, Some(round_up4(declared as u64)), || format!("{declared} one-byte shares"))?;
    let shares = cur.take(declared as u64, "shares")?.iter().map(|&v| v as f32 / SHARE_LEVELS).collect();
    cur.padding(4, "padding")?;
    cur.finish()?;
    Ok(shares)
}

// ---------------------------------------------------------------- TSUN, TSUF

/// A texel sun section's values per step, packed texel-major in u32 words,
/// step k at bit `bits · k` of its texel's words; a texel's last word is
/// zero past the last step. TSUN holds a bit per step and stores its words
/// per texel in the second header field; TSUF holds a 4-bit share per step
/// and stores its bits per value there.
#[derive(Clone, Copy)]
struct TexelSteps {
    tag: [u8; 4],
    bits: u32,
    what: &'static str,
}

/// TSUN: u32 step_count, u32 words_per_texel, u32 covered_count, u32
/// reserved, then the words: SUNM's layout over the atlas's covered texels.
const TEXEL_SUN_BITS: TexelSteps = TexelSteps { tag: TSUN, bits: 1, what: "sun mask" };
/// TSUF: u32 step_count, u32 bits per value (4), u32 covered_count, u32
/// reserved, then per covered texel `ceil(step_count / 8)` words of 4-bit
/// values (step k in bits `4 (k % 8)` of word `k / 8`).
const TEXEL_SUN_SHARES: TexelSteps = TexelSteps { tag: TSUF, bits: 4, what: "sun fraction" };
/// TSAB and TSAF: TSUN's and TSUF's layouts over the sun's own atlas (TSAT).
const OWN_ATLAS_SUN_BITS: TexelSteps = TexelSteps { tag: TSAB, bits: 1, what: "sun mask" };
const OWN_ATLAS_SUN_SHARES: TexelSteps = TexelSteps { tag: TSAF, bits: 4, what: "sun fraction" };

/// The layouts of the sun bits and shares: on the bundle's atlas, or (`own`) on the sun's own.
fn texel_sun_layouts(own: bool) -> (TexelSteps, TexelSteps) {
    if own {
        (OWN_ATLAS_SUN_BITS, OWN_ATLAS_SUN_SHARES)
    } else {
        (TEXEL_SUN_BITS, TEXEL_SUN_SHARES)
    }
}

impl TexelSteps {
    fn words_per_texel(self, steps: u32) -> u64 {
        (steps as u64 * self.bits as u64).div_ceil(32)
    }

    /// The second header field for `steps`.
    fn second_field(self, steps: u32) -> u64 {
        if self.bits == 1 {
            self.words_per_texel(steps)
        } else {
            self.bits as u64
        }
    }

    fn encode(self, values: &[u32], steps: usize, covered: usize) -> Result<Vec<u8>, BundleError> {
        let steps = count_u32(steps, "step count")?;
        let words = self.words_per_texel(steps) as usize;
        if Some(values.len()) != covered.checked_mul(words) {
            return Err(invalid(format!("{} {} words for {covered} covered texels × {words} words", values.len(), self.what)));
        }
        if let Some(i) = first_with_values_past(values, steps, self.bits) {
            return Err(invalid(format!("{} of covered texel {i} has values past step {steps}", self.what)));
        }
        let mut out = Vec::with_capacity(16 + 4 * values.len());
        put_u32(&mut out, steps);
        put_u32(&mut out, self.second_field(steps) as u32);
        put_u32(&mut out, count_u32(covered, "covered texel count")?);
        put_u32(&mut out, 0);
        values.iter().for_each(|&w| put_u32(&mut out, w));
        Ok(out)
    }

    /// Decodes the section for an atlas of `covered` texels and a series of
    /// `step_count` steps (SUNM's).
    fn decode(self, raw: &[u8], covered: usize, step_count: u32, rules: ReadRules) -> Result<Vec<u32>, BundleError> {
        let mut cur = Cursor::new(raw, self.tag);
        let steps = cur.u32("step count")?;
        let second = cur.u32(if self.bits == 1 { "words per texel" } else { "bits per value" })?;
        let declared = cur.u32("covered texel count")?;
        let reserved = cur.u32("reserved")?;
        if rules.reject_reserved && reserved != 0 {
            return Err(cur.error(format!("reserved field is {reserved:#x}, must be 0")));
        }
        if steps != step_count {
            return Err(cur.error(format!("{steps} steps, but SUNM has {step_count}")));
        }
        if second as u64 != self.second_field(steps) {
            return Err(cur.error(format!("header field {second} for {steps} steps, expected {}", self.second_field(steps))));
        }
        if declared as usize != covered {
            return Err(cur.error(format!("values for {declared} texels, the atlas covers {covered}")));
        }
        let words = self.words_per_texel(steps);
        let expected = checked_len(&[(declared as u64, 4 * words)]);
        check_exact_len(&cur, expected, || format!("{declared} texels × {words} words"))?;
        let values = cur.u32s(declared as u64 * words, "value words")?;
        if let Some(i) = first_with_values_past(&values, steps, self.bits) {
            return Err(cur.error(format!("{} of covered texel {i} has values past step {steps} (must be zero)", self.what)));
        }
        cur.finish()?;
        Ok(values)
    }
}

/// The first receiver (rows of `ceil(step_count · bits / 32)` words) whose
/// last word has non-zero bits past step `step_count`.
fn first_with_values_past(words: &[u32], step_count: u32, bits: u32) -> Option<usize> {
    let per_receiver = (step_count as u64 * bits as u64).div_ceil(32) as usize;
    let used = (step_count as u64 * bits as u64 % 32) as u32;
    if used == 0 || per_receiver == 0 {
        return None;
    }
    let unused = !((1u32 << used) - 1);
    words.chunks_exact(per_receiver).position(|w| w.last().is_some_and(|w| w & unused != 0))
}

/// TSUN, or TSAB on the sun's own atlas (`own`).
pub(crate) fn encode_texel_sun_masks(sun: &SunSeries, covered: usize, own: bool) -> Result<Vec<u8>, BundleError> {
    texel_sun_layouts(own).0.encode(&sun.texel_masks, sun.steps.len(), covered)
}

pub(crate) fn decode_texel_sun_masks(
    raw: &[u8],
    covered: usize,
    step_count: u32,
    rules: ReadRules,
    own: bool,
) -> Result<Vec<u32>, BundleError> {
    texel_sun_layouts(own).0.decode(raw, covered, step_count, rules)
}

/// TSUF, or TSAF on the sun's own atlas (`own`).
pub(crate) fn encode_texel_sun_fractions(sun: &SunSeries, covered: usize, own: bool) -> Result<Vec<u8>, BundleError> {
    texel_sun_layouts(own).1.encode(&sun.texel_fractions, sun.steps.len(), covered)
}

pub(crate) fn decode_texel_sun_fractions(
    raw: &[u8],
    covered: usize,
    step_count: u32,
    rules: ReadRules,
    own: bool,
) -> Result<Vec<u32>, BundleError> {
    texel_sun_layouts(own).1.decode(raw, covered, step_count, rules)
}

// ---------------------------------------------------------------- SUND

fn sun_step_record_len(sky_order: u32) -> Option<u64> {
    let coeffs = (sky_order as u64).checked_mul(sky_order as u64)?;
    Some(round_up8(coeffs.checked_mul(12)?.checked_add(SUN_STEP_FIXED)?))
}

/// SUND: u32 step_count, u32 sky_order; per step (padded to 8 bytes): f64 unix time,
/// f32×3 direction, f32 elevation, f32 azimuth, f32×3 sun RGB, u32 flags (bit 0 night),
/// f32×3 × sky_order² sky SH.
pub(crate) fn encode_sun_data(sun: &SunSeries) -> Result<Vec<u8>, BundleError> {
    let coeffs = (sun.sky_order as usize).checked_mul(sun.sky_order as usize);
    let mut out = Vec::new();
    put_u32(&mut out, count_u32(sun.steps.len(), "step count")?);
    put_u32(&mut out, sun.sky_order);
    for (k, s) in sun.steps.iter().enumerate() {
        if Some(s.sky_sh.len()) != coeffs {
            return Err(invalid(format!("sun step {k} has {} sky coefficients for sky order {}", s.sky_sh.len(), sun.sky_order)));
        }
        values::check_sun_step(k, s).map_err(BundleError::invalid_value(SUND))?;
        put_f64(&mut out, s.unix_time_utc);
        s.direction.iter().chain([&s.elevation_deg, &s.azimuth_deg]).chain(&s.sun_rgb).for_each(|&x| put_f32(&mut out, x));
        put_u32(&mut out, if s.night { STEP_NIGHT } else { 0 });
        s.sky_sh.iter().flatten().for_each(|&x| put_f32(&mut out, x));
        pad_to(&mut out, 8);
    }
    Ok(out)
}

/// Returns `(sky_order, steps)`.
pub(crate) fn decode_sun_data(raw: &[u8], rules: ReadRules) -> Result<(u32, Vec<SunStep>), BundleError> {
    let mut cur = Cursor::new(raw, SUND);
    let step_count = cur.u32("step count")? as u64;
    let sky_order = cur.u32("sky order")?;
    let expected = sun_step_record_len(sky_order).and_then(|n| n.checked_mul(step_count));
    check_exact_len(&cur, expected, || format!("{step_count} steps with sky order {sky_order}"))?;
    let coeffs = sky_order as u64 * sky_order as u64;

    let mut steps = Vec::with_capacity(step_count as usize);
    for k in 0..step_count {
        let unix_time_utc = cur.f64("time")?;
        let fixed = cur.f32s(8, "sun direction, angles and irradiance")?;
        let flags = cur.u32("step flags")?;
        if rules.reject_reserved && flags & !STEP_NIGHT != 0 {
            return Err(cur.error(format!("step {k}: flags {flags:#x} set reserved bits")));
        }
        let sky = cur.f32s(3 * coeffs, "sky SH")?;
        cur.padding(8, "step record")?;
        let step = SunStep {
            unix_time_utc,
            direction: [fixed[0], fixed[1], fixed[2]],
            elevation_deg: fixed[3],
            azimuth_deg: fixed[4],
            sun_rgb: [fixed[5], fixed[6], fixed[7]],
            night: flags & STEP_NIGHT != 0,
            sky_sh: sky.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        values::check_sun_step(k as usize, &step).map_err(BundleError::bad_value(SUND))?;
        steps.push(step);
    }
    cur.finish()?;
    Ok((sky_order, steps))
}

// ---------------------------------------------------------------- ATLS, TXFR

/// ATLS: u32 width, u32 height, f32 texel_size, u32 chart_count, u32
/// atlas_vertex_count V, u32 triangle_count T, u32 covered_count C, u32
/// reserved; V × (f32 u, f32 v); V × u32 source vertex; T × 3 u32 atlas
/// vertex; T × u32 chart (0xFFFFFFFF: none); C × u32 texel id, ascending.
/// TSAT (the sun's own atlas) has the same layout.
pub(crate) fn encode_atlas(a: &crate::atlas::Atlas, texels: &[u32], mesh: &Mesh) -> Result<Vec<u8>, BundleError> {
    check_atlas(a, texels, mesh).map_err(invalid)?;
    let mut out = Vec::new();
    put_u32(&mut out, a.width);
    put_u32(&mut out, a.height);
    put_f32(&mut out, a.texel_size);
    put_u32(&mut out, a.chart_count);
    put_u32(&mut out, count_u32(a.uv.len(), "atlas vertex count")?);
    put_u32(&mut out, count_u32(a.triangle_count(), "atlas triangle count")?);
    put_u32(&mut out, count_u32(texels.len(), "covered texel count")?);
    put_u32(&mut out, 0);
    a.uv.iter().for_each(|p| {
        put_f32(&mut out, p.x);
        put_f32(&mut out, p.y);
    });
    a.source_vertex.iter().for_each(|&v| put_u32(&mut out, v));
    a.indices.iter().for_each(|&i| put_u32(&mut out, i));
    a.triangle_chart.iter().for_each(|&c| put_u32(&mut out, c));
    texels.iter().for_each(|&x| put_u32(&mut out, x));
    Ok(out)
}

/// Decodes ATLS (or TSAT, `tag`) against the bundle's mesh; returns the atlas and the covered texels.
pub(crate) fn decode_atlas(
    raw: &[u8],
    mesh: &Mesh,
    rules: ReadRules,
    tag: [u8; 4],
) -> Result<(crate::atlas::Atlas, Vec<u32>), BundleError> {
    let mut cur = Cursor::new(raw, tag);
    let width = cur.u32("width")?;
    let height = cur.u32("height")?;
    let texel_size = cur.f32("texel size")?;
    let chart_count = cur.u32("chart count")?;
    let vertices = cur.u32("atlas vertex count")? as u64;
    let triangles = cur.u32("triangle count")? as u64;
    let covered = cur.u32("covered texel count")? as u64;
    let reserved = cur.u32("reserved")?;
    if rules.reject_reserved && reserved != 0 {
        return Err(cur.error(format!("reserved field is {reserved:#x}, must be 0")));
    }
    let expected = checked_len(&[(vertices, 12), (triangles, 16), (covered, 4)]);
    check_exact_len(&cur, expected, || format!("{vertices} atlas vertices, {triangles} triangles and {covered} texels"))?;
    let uv: Vec<Vec2> = cur.f32s(vertices * 2, "uv")?.chunks_exact(2).map(|p| Vec2::new(p[0], p[1])).collect();
    let source_vertex = cur.u32s(vertices, "source vertex")?;
    let indices = cur.u32s(triangles * 3, "atlas indices")?;
    let triangle_chart = cur.u32s(triangles, "charts")?;
    let texels = cur.u32s(covered, "texels")?;
    cur.finish()?;
    let atlas = crate::atlas::Atlas { width, height, texel_size, uv, source_vertex, indices, triangle_chart, chart_count };
    check_atlas(&atlas, &texels, mesh).map_err(|e| BundleError::malformed(tag, e))?;
    Ok((atlas, texels))
}

/// The atlas fits the mesh and itself: one entry per triangle, indices and
/// charts in range, UVs finite and inside the texture, texels ascending and
/// inside it, the texture no larger than [`crate::atlas::MAX_TEXELS`].
fn check_atlas(a: &crate::atlas::Atlas, texels: &[u32], mesh: &Mesh) -> Result<(), String> {
    if !(a.texel_size.is_finite() && a.texel_size > 0.0) {
        return Err(format!("texel size {} is not a positive length", a.texel_size));
    }
    let area = a.width as f64 * a.height as f64;
    if a.width == 0 || a.height == 0 || area > crate::atlas::MAX_TEXELS {
        return Err(format!("{} × {} texels: each side ≥ 1, at most {:.3e} in all", a.width, a.height, crate::atlas::MAX_TEXELS));
    }
    if a.triangle_count() != mesh.triangle_count() || a.indices.len() % 3 != 0 || a.triangle_chart.len() != mesh.triangle_count() {
        return Err(format!("{} triangles in the atlas, {} in the mesh", a.triangle_count(), mesh.triangle_count()));
    }
    if a.uv.len() != a.source_vertex.len() {
        return Err(format!("{} atlas UVs for {} atlas vertices", a.uv.len(), a.source_vertex.len()));
    }
    if let Some(i) = a.indices.iter().position(|&i| i as usize >= a.uv.len()) {
        return Err(format!("atlas index {i} is {}, past the {} atlas vertices", a.indices[i], a.uv.len()));
    }
    if let Some(v) = a.source_vertex.iter().position(|&s| s as usize >= mesh.vertex_count()) {
        return Err(format!("atlas vertex {v} copies vertex {}, past the mesh's {}", a.source_vertex[v], mesh.vertex_count()));
    }
    if let Some(t) = a.triangle_chart.iter().position(|&c| c != crate::atlas::NO_CHART && c >= a.chart_count) {
        return Err(format!("triangle {t} is in chart {}, past the {} charts", a.triangle_chart[t], a.chart_count));
    }
    let inside = |p: &Vec2| p.is_finite() && p.x >= 0.0 && p.y >= 0.0 && p.x <= a.width as f32 && p.y <= a.height as f32;
    if let Some(v) = a.uv.iter().position(|p| !inside(p)) {
        return Err(format!("atlas vertex {v}'s UV {} lies outside the {} × {} texture", a.uv[v], a.width, a.height));
    }
    if let Some(k) = texels.windows(2).position(|w| w[0] >= w[1]) {
        return Err(format!("texel ids {} then {} are not ascending", texels[k], texels[k + 1]));
    }
    if let Some(&last) = texels.last().filter(|&&x| x as f64 >= area) {
        return Err(format!("texel {last} lies past the {} × {} texture", a.width, a.height));
    }
    Ok(())
}
