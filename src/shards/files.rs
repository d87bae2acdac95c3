//! The shard files as structs ⇄ bytes (layouts in docs/scale.md): transfer
//! parts, hit records, merged layers and sun parts. Writers stream through
//! [`codec::Writer`]; decoders check every count against the bytes present
//! and every index against the mesh, and return an error, never panic.

use std::io::Write;
use std::ops::Range;

use super::codec::{self, FileKind, Reader, Writer};
use super::{MeshId, MAX_SHARDS};

/// What every file of one bake shares: the mesh, the shard count and the
/// parameter block ([`super::key`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Identity {
    pub mesh: MeshId,
    /// Vertices and triangles the bake sums into and gathers from: the
    /// mesh's, and its back sides' twins after them (`bake::twins`).
    pub plan_vertices: u64,
    pub plan_triangles: u64,
    /// N, the number of shards.
    pub shards: u32,
    /// A [`super::TransferKey`] or [`super::SunKey`] block.
    pub key: Vec<u8>,
}

impl Identity {
    fn write<W: Write>(&self, w: &mut Writer<W>) -> std::io::Result<()> {
        w.u32(self.mesh.crc)?;
        w.u32(self.shards)?;
        w.u64(self.mesh.vertices)?;
        w.u64(self.mesh.triangles)?;
        w.u64(self.plan_vertices)?;
        w.u64(self.plan_triangles)?;
        w.u32(self.key.len() as u32)?;
        w.bytes(&self.key)?;
        w.pad4()
    }

    fn read(r: &mut Reader) -> Result<Identity, String> {
        let crc = r.u32("mesh CRC")?;
        let shards = r.u32("shard count")?;
        if shards == 0 || shards > MAX_SHARDS {
            return Err(format!("shard count {shards} is outside 1..={MAX_SHARDS}"));
        }
        let vertices = r.u64("vertex count")?;
        let triangles = r.u64("triangle count")?;
        let plan_vertices = r.u64("plan vertex count")?;
        let plan_triangles = r.u64("plan triangle count")?;
        if plan_vertices > u32::MAX as u64 + 1 {
            return Err(format!("{plan_vertices} vertices: more than 32-bit indices reach"));
        }
        if !(vertices <= plan_vertices && triangles <= plan_triangles && plan_triangles <= 2 * triangles && plan_vertices <= 2 * vertices) {
            return Err(format!(
                "the bake's {plan_vertices} vertices and {plan_triangles} triangles are not the mesh's {vertices} and {triangles} with their back sides"
            ));
        }
        let len = r.u32("parameter block length")?;
        let key = r.take(len as u64, "parameter block")?.to_vec();
        r.pad4("parameter block")?;
        Ok(Identity { mesh: MeshId { crc, vertices, triangles }, plan_vertices, plan_triangles, shards, key })
    }

    fn read_shard(&self, r: &mut Reader) -> Result<u32, String> {
        let index = r.u32("shard index")?;
        if index >= self.shards {
            return Err(format!("shard index {index} is not below the shard count {}", self.shards));
        }
        Ok(index)
    }
}

/// Per-vertex rows: `stride` floats for each vertex of `vertices`, and in
/// round 0 its barycentric weight and (interior sampling) the moments of its
/// points' DC that the noise estimate needs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VertexRows {
    pub vertices: Vec<u32>,
    pub rows: Vec<f32>,
    /// One per vertex in round 0, else empty.
    pub weights: Vec<f32>,
    /// One `[Σ w², Σ w²x, Σ w²x², Σ w·b]` per vertex in a bake that
    /// tracks noise (`bake::noise::Moments`), else empty.
    pub moments: Vec<[f64; 4]>,
}

fn write_moments<W: Write>(w: &mut Writer<W>, moments: &[[f64; 4]]) -> std::io::Result<()> {
    let bits: Vec<u64> = moments.iter().flat_map(|m| m.map(f64::to_bits)).collect();
    w.u64s(&bits)
}

fn read_moments(r: &mut Reader, count: u64, what: &str) -> Result<Vec<[f64; 4]>, String> {
    let bits = r.u64s(count.saturating_mul(4), what)?;
    let moments: Vec<[f64; 4]> = bits.chunks_exact(4).map(|m| [0, 1, 2, 3].map(|k| f64::from_bits(m[k]))).collect();
    if moments.iter().any(|m| !m.iter().all(|x| x.is_finite()) || m[0] < 0.0 || m[2] < 0.0) {
        return Err(format!("{what}: a moment is negative or not finite"));
    }
    Ok(moments)
}

impl VertexRows {
    pub fn len(&self) -> usize {
        self.vertices.len()
    }
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    fn write<W: Write>(&self, w: &mut Writer<W>) -> std::io::Result<()> {
        w.u64(self.vertices.len() as u64)?;
        w.u32s(&self.vertices)?;
        w.f32s(&self.rows)?;
        w.f32s(&self.weights)?;
        write_moments(w, &self.moments)
    }

    fn read(
        r: &mut Reader,
        what: &str,
        stride: u64,
        with_weights: bool,
        with_moments: bool,
        vertex_count: u64,
    ) -> Result<VertexRows, String> {
        let count = r.u64(what)?;
        let vertices = r.u32s(count, what)?;
        if let Some(&v) = vertices.iter().find(|&&v| v as u64 >= vertex_count) {
            return Err(format!("{what}: vertex {v} of a mesh of {vertex_count}"));
        }
        let rows = r.f32s(count.saturating_mul(stride), what)?;
        let weights = if with_weights { r.f32s(count, what)? } else { Vec::new() };
        let moments = if with_moments { read_moments(r, count, what)? } else { Vec::new() };
        Ok(VertexRows { vertices, rows, weights, moments })
    }
}

fn read_range32(r: &mut Reader, what: &str, limit: u32) -> Result<Range<u32>, String> {
    let (start, end) = (r.u32(what)?, r.u32(what)?);
    if start > end || end > limit {
        return Err(format!("{what} {start}..{end} is not within 0..{limit}"));
    }
    Ok(start..end)
}

fn read_range64(r: &mut Reader, what: &str, limit: u64) -> Result<Range<u64>, String> {
    let (start, end) = (r.u64(what)?, r.u64(what)?);
    if start > end || end > limit {
        return Err(format!("{what} {start}..{end} is not within 0..{limit}"));
    }
    Ok(start..end)
}

/// Order `coeffs` and channels a file may hold.
fn check_sizes(channels: u32, coeffs: u32, pass_channels: u32) -> Result<(), String> {
    let order = (coeffs as f64).sqrt() as u32;
    if order == 0 || order as usize > crate::sh::MAX_ORDER || order * order != coeffs {
        return Err(format!("{coeffs} coefficients is not the square of an order in 1..={}", crate::sh::MAX_ORDER));
    }
    if !(channels == 1 || channels == 3) || !(pass_channels == 1 || pass_channels == channels) {
        return Err(format!("{pass_channels} of {channels} channel(s) is not a transfer layout"));
    }
    Ok(())
}

/// One shard's sums of one transfer round (`PRTP`, `.prtp`).
#[derive(Clone, Debug, PartialEq)]
pub struct TransferPart {
    pub identity: Identity,
    /// K.
    pub shard: u32,
    /// The bounce this part traced or gathered.
    pub round: u32,
    pub items: Range<u32>,
    pub item_count: u32,
    pub points: Range<u64>,
    pub point_count: u64,
    pub window_triangles: u64,
    /// The CRC of the layer file gathered from (rounds ≥ 1), else 0.
    pub layer_crc: u32,
    /// Channels of this round's rows (1 in round 0), of the result, and SH coefficients.
    pub pass_channels: u32,
    pub channels: u32,
    pub coeffs: u32,
    /// Rays evaluated and traced, and points found inside geometry (round 0).
    pub rays: u64,
    pub traced: u64,
    pub rejected: u64,
    /// Round 0 in window mode: the DC through glass that the shard's points
    /// met, summed in task order, on sides kept and on sides the enclosure
    /// rule dropped (`BakeStats::outside_light_share`); else zeros.
    pub glass_light: [f64; 2],
    /// Round 0 of interior sampling: the rows carry their points' DC moments.
    pub tracks_noise: bool,
    /// The pilot of adaptive allocation (base points only, bounce 0): the
    /// merge makes a [`PilotFile`] of it, not a layer.
    pub pilot: bool,
    /// Sums of the vertices whose first item is this shard's.
    pub opened: VertexRows,
    /// Contributions to vertices an earlier shard opened, in item and corner order.
    pub late: VertexRows,
    /// Texel mode: this shard's range of covered texels and their sums.
    pub texels: Option<TexelRoundPart>,
    /// Last round, shard 0: a bundle holding the mesh and the metadata the
    /// final bundle is made with (empty otherwise).
    pub frame: Vec<u8>,
}

/// A shard's covered texels in one transfer round. A texel's points all lie
/// in one shard's range, so its sums are whole and the merge joins the
/// ranges in texel order.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelRoundPart {
    pub texels: Range<u32>,
    pub texel_count: u32,
    /// The texels' sample points, of `point_count` in all texels.
    pub points: Range<u64>,
    pub point_count: u64,
    /// Rays evaluated and traced, and points found inside geometry (round 0).
    pub rays: u64,
    pub traced: u64,
    pub rejected: u64,
    /// Per texel, `stride` sums of its points' results weighted by area.
    pub sums: Vec<f32>,
    /// Per texel in round 0, the footprint its kept points stand for; else empty.
    pub weights: Vec<f32>,
    /// Per texel, the moments of its points' DC (`bake::noise::Moments`).
    pub moments: Vec<[f64; 4]>,
}

impl TexelRoundPart {
    fn write<W: Write>(part: Option<&TexelRoundPart>, w: &mut Writer<W>) -> std::io::Result<()> {
        let Some(t) = part else { return w.u32(0) };
        w.u32(1)?;
        for v in [t.texels.start, t.texels.end, t.texel_count] {
            w.u32(v)?;
        }
        for v in [t.points.start, t.points.end, t.point_count, t.rays, t.traced, t.rejected] {
            w.u64(v)?;
        }
        w.f32s(&t.sums)?;
        w.u32(!t.weights.is_empty() as u32)?;
        w.f32s(&t.weights)?;
        write_moments(w, &t.moments)
    }

    fn read(r: &mut Reader, stride: u64, round: u32) -> Result<Option<TexelRoundPart>, String> {
        match r.u32("texel flag")? {
            0 => return Ok(None),
            1 => {}
            f => return Err(format!("texel flag is {f}, not 0 or 1")),
        }
        let texels = read_range32(r, "texel range", u32::MAX)?;
        let texel_count = r.u32("texel count")?;
        if texels.end > texel_count {
            return Err(format!("texel range {texels:?} is past the {texel_count} covered texels"));
        }
        let points = read_range64(r, "texel point range", u64::MAX)?;
        let point_count = r.u64("texel point count")?;
        if points.end > point_count {
            return Err(format!("texel point range {points:?} is past the {point_count} texel points"));
        }
        let (rays, traced, rejected) = (r.u64("texel rays")?, r.u64("texel rays traced")?, r.u64("texel points rejected")?);
        let n = (texels.end - texels.start) as u64;
        let sums = r.f32s(n.saturating_mul(stride), "texel sums")?;
        let with_weights = flag_u32(r.u32("texel weight flag")?, "texel weight")?;
        if with_weights != (round == 0) {
            return Err(format!("round {round} {} texel weights", if with_weights { "carries" } else { "lacks" }));
        }
        let weights = if with_weights { r.f32s(n, "texel weights")? } else { Vec::new() };
        let moments = read_moments(r, n, "texel moments")?;
        Ok(Some(TexelRoundPart { texels, texel_count, points, point_count, rays, traced, rejected, sums, weights, moments }))
    }
}

/// The light through glass kept and dropped (two f64s, finite and not
/// negative); a part's rounds after 0 trace nothing and carry zeros.
fn read_glass_light(r: &mut Reader, round: u32, part: bool) -> Result<[f64; 2], String> {
    let light = [r.f64("light through glass kept")?, r.f64("light through glass dropped")?];
    if light.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
        return Err(format!("its light through glass ({}, {}) is negative or not finite", light[0], light[1]));
    }
    if part && round > 0 && light != [0.0; 2] {
        return Err(format!("round {round} carries light through glass, which only round 0 traces"));
    }
    Ok(light)
}

fn flag_u32(value: u32, what: &str) -> Result<bool, String> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        v => Err(format!("{what} flag is {v}, not 0 or 1")),
    }
}

impl TransferPart {
    pub fn stride(&self) -> usize {
        (self.pass_channels * self.coeffs) as usize
    }

    pub fn write_to<W: Write>(&self, out: W) -> std::io::Result<u32> {
        let mut w = Writer::new(out, FileKind::TransferPart)?;
        self.identity.write(&mut w)?;
        for v in [self.shard, self.round, self.items.start, self.items.end, self.item_count] {
            w.u32(v)?;
        }
        for v in [self.points.start, self.points.end, self.point_count, self.window_triangles] {
            w.u64(v)?;
        }
        for v in [self.layer_crc, self.pass_channels, self.channels, self.coeffs] {
            w.u32(v)?;
        }
        for v in [self.rays, self.traced, self.rejected] {
            w.u64(v)?;
        }
        for v in self.glass_light {
            w.f64(v)?;
        }
        w.u32(self.tracks_noise as u32 | (self.pilot as u32) << 1)?;
        self.opened.write(&mut w)?;
        self.late.write(&mut w)?;
        TexelRoundPart::write(self.texels.as_ref(), &mut w)?;
        w.blob(&self.frame)?;
        w.finish()
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        // Writing into a Vec cannot fail.
        let _ = self.write_to(&mut out);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<TransferPart, String> {
        let (mut r, _) = codec::open(bytes, FileKind::TransferPart)?;
        let identity = Identity::read(&mut r)?;
        let shard = identity.read_shard(&mut r)?;
        let round = r.u32("round")?;
        if round > 16 {
            return Err(format!("round {round}: bakes have at most 16 bounces"));
        }
        let items = read_range32(&mut r, "item range", u32::MAX)?;
        let item_count = r.u32("item count")?;
        if items.end > item_count {
            return Err(format!("item range {items:?} is past the {item_count} items"));
        }
        let points = read_range64(&mut r, "point range", u64::MAX)?;
        let point_count = r.u64("point count")?;
        if points.end > point_count {
            return Err(format!("point range {points:?} is past the {point_count} points"));
        }
        let window_triangles = r.u64("window triangles")?;
        let layer_crc = r.u32("layer CRC")?;
        let (pass_channels, channels, coeffs) = (r.u32("pass channels")?, r.u32("channels")?, r.u32("coefficients")?);
        check_sizes(channels, coeffs, pass_channels)?;
        // Round 0 is traced colourless, later rounds in every channel.
        if pass_channels != if round == 0 { 1 } else { channels } {
            return Err(format!("round {round} with {pass_channels} of {channels} channels"));
        }
        let (rays, traced, rejected) = (r.u64("rays")?, r.u64("rays traced")?, r.u64("points rejected")?);
        let glass_light = read_glass_light(&mut r, round, true)?;
        let (tracks_noise, pilot) = match r.u32("row flags")? {
            0 => (false, false),
            1 => (true, false),
            3 if round == 0 => (true, true),
            f => return Err(format!("row flags {f} in round {round}: rows carry moments (1), and only round 0's pilot is a pilot (3)")),
        };
        let stride = (pass_channels * coeffs) as u64;
        let vertex_count = identity.plan_vertices;
        let opened = VertexRows::read(&mut r, "opened vertices", stride, round == 0, tracks_noise, vertex_count)?;
        let late = VertexRows::read(&mut r, "late contributions", stride, round == 0, tracks_noise, vertex_count)?;
        let texels = TexelRoundPart::read(&mut r, stride, round)?;
        if pilot && texels.is_some() {
            // Only `--texel-adaptive` places texel points by the pilot stage.
            let texel_adaptive = super::TransferKey::decode(&identity.key).ok().and_then(|k| k.texels).is_some_and(|t| t.adaptive > 0.0);
            if !texel_adaptive {
                return Err("a pilot part holds texel rows, and its bake places no texel points by them (no --texel-adaptive)".into());
            }
        }
        let frame = r.blob("bundle frame")?.to_vec();
        r.finish()?;
        Ok(TransferPart {
            identity,
            shard,
            round,
            items,
            item_count,
            points,
            point_count,
            window_triangles,
            layer_crc,
            pass_channels,
            channels,
            coeffs,
            rays,
            traced,
            rejected,
            glass_light,
            tracks_noise,
            pilot,
            opened,
            late,
            texels,
            frame,
        })
    }
}

/// One shard's bounce-0 hit records (`PRTH`, `.prth`): 8 bytes a ray, and
/// which of its points lie inside geometry. Written by round 0, read back
/// by the same shard in every later round.
#[derive(Clone, Debug, PartialEq)]
pub struct HitFile {
    pub identity: Identity,
    pub shard: u32,
    pub items: Range<u32>,
    pub points: Range<u64>,
    pub rays: u32,
    /// Bit p % 32 of word p / 32: point `points.start + p` was rejected.
    pub rejected: Vec<u32>,
    /// `rays` records per point, in point order ([`crate::bake`]'s hit encoding).
    pub records: Vec<u64>,
    /// Texel mode: the same for this shard's texels' points.
    pub texels: Option<TexelHits>,
}

/// A shard's texel points' bounce-0 hit records and rejections.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelHits {
    pub texels: Range<u32>,
    pub points: Range<u64>,
    /// Rays per texel point (the vertices' may be fewer, `--vertex-rays`).
    pub rays: u32,
    /// Bit p % 32 of word p / 32: texel point `points.start + p` was rejected.
    pub rejected: Vec<u32>,
    pub records: Vec<u64>,
    /// `--texel-levels`: the charts' levels round 0's pilot chose, which
    /// later rounds (no BVH, no pilot) repack the atlas by, and META
    /// `texels.density` as JSON, which the last round's frame carries.
    pub density: Option<ChartLevels>,
}

/// A density choice as a shard's hit records keep it (`TexelHits::density`).
#[derive(Clone, Debug, PartialEq)]
pub struct ChartLevels {
    /// Per chart of the pilot's atlas, its level (0 = the pilot's texel size).
    pub levels: Vec<u8>,
    pub meta: String,
}

impl TexelHits {
    pub fn is_rejected(&self, local_point: u64) -> bool {
        (self.rejected[(local_point / 32) as usize] >> (local_point % 32)) & 1 == 1
    }
}

impl HitFile {
    pub fn is_rejected(&self, local_point: u64) -> bool {
        (self.rejected[(local_point / 32) as usize] >> (local_point % 32)) & 1 == 1
    }

    pub fn write_to<W: Write>(&self, out: W) -> std::io::Result<u32> {
        let mut w = Writer::new(out, FileKind::Hits)?;
        self.identity.write(&mut w)?;
        for v in [self.shard, self.items.start, self.items.end] {
            w.u32(v)?;
        }
        w.u64(self.points.start)?;
        w.u64(self.points.end)?;
        w.u32(self.rays)?;
        w.u32s(&self.rejected)?;
        w.u64s(&self.records)?;
        match &self.texels {
            None => w.u32(0)?,
            Some(t) => {
                w.u32(1)?;
                for v in [t.texels.start, t.texels.end] {
                    w.u32(v)?;
                }
                w.u64(t.points.start)?;
                w.u64(t.points.end)?;
                w.u32(t.rays)?;
                w.u32s(&t.rejected)?;
                w.u64s(&t.records)?;
                match &t.density {
                    None => w.u32(0)?,
                    Some(d) => {
                        w.u32(1)?;
                        w.blob(&d.levels)?;
                        w.string(&d.meta)?;
                    }
                }
            }
        }
        w.finish()
    }

    pub fn decode(bytes: &[u8]) -> Result<HitFile, String> {
        let (mut r, _) = codec::open(bytes, FileKind::Hits)?;
        let identity = Identity::read(&mut r)?;
        let shard = identity.read_shard(&mut r)?;
        let items = read_range32(&mut r, "item range", u32::MAX)?;
        let points = read_range64(&mut r, "point range", u64::MAX)?;
        let rays = r.u32("rays")?;
        let count = points.end - points.start;
        let rejected = r.u32s(count.div_ceil(32), "rejected points")?;
        let records = r.u64s(count.saturating_mul(rays as u64), "hit records")?;
        let texels = match flag_u32(r.u32("texel flag")?, "texel")? {
            false => None,
            true => {
                let texels = read_range32(&mut r, "texel range", u32::MAX)?;
                let points = read_range64(&mut r, "texel point range", u64::MAX)?;
                let rays = r.u32("texel rays")?;
                let count = points.end - points.start;
                let rejected = r.u32s(count.div_ceil(32), "rejected texel points")?;
                let records = r.u64s(count.saturating_mul(rays as u64), "texel hit records")?;
                let density = match flag_u32(r.u32("density flag")?, "density")? {
                    false => None,
                    true => {
                        let levels = r.blob("chart levels")?.to_vec();
                        let meta = r.string("density META")?;
                        if serde_json::from_str::<serde_json::Value>(&meta).map_or(true, |m| !m.is_object()) {
                            return Err("the density META is not a JSON object".into());
                        }
                        Some(ChartLevels { levels, meta })
                    }
                };
                Some(TexelHits { texels, points, rays, rejected, records, density })
            }
        };
        r.finish()?;
        // The gather indexes the hit triangle's corners: a record past the mesh would read out of bounds.
        let triangles = identity.plan_triangles;
        let all = records.iter().chain(texels.iter().flat_map(|t| &t.records));
        if let Some((i, h)) =
            all.enumerate().find(|&(_, &h)| h != crate::bake::gather::NO_HIT && crate::bake::gather::decode_hit(h).0 as u64 >= triangles)
        {
            return Err(format!("hit record {i} names triangle {} of a mesh of {triangles}", crate::bake::gather::decode_hit(*h).0 as u64));
        }
        Ok(HitFile { identity, shard, items, points, rays, rejected, records, texels })
    }
}

/// A merged round (`PRTL`, `.prtl`): what later rounds and merges need of
/// the rounds so far, and no hit record.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerFile {
    pub identity: Identity,
    /// The bounce this layer completes.
    pub round: u32,
    pub channels: u32,
    pub coeffs: u32,
    /// Channels of `source`: 1 after round 0, else `channels`.
    pub source_channels: u32,
    pub window_triangles: u64,
    pub points: u64,
    pub points_rejected: u64,
    pub rays_traced: u64,
    /// Round 0's [`TransferPart::glass_light`], summed over the shards in order.
    pub glass_light: [f64; 2],
    /// Rays evaluated in each round so far.
    pub rays_per_bounce: Vec<u64>,
    /// Per vertex: barycentric weight (from round 0).
    pub weights: Vec<f32>,
    /// Per vertex: the DC standard error of the rounds so far in quadrature
    /// (`TransferResult::noise`), from their moments; empty when not tracked.
    pub noise: Vec<f32>,
    /// Per vertex: the DC of the rounds so far that came through the back
    /// of its face (`bake::side_share`), from their moments; empty as `noise`.
    pub back_dc: Vec<f32>,
    /// Window mode: `source` (and the texels') holds every receiver's front
    /// side's rows, then every receiver's back side's (`bake::transfer::split_sides`).
    pub source_sides: bool,
    /// Per vertex `[source channel][coeff]`: this bounce normalised, what the next round gathers.
    pub source: Vec<f32>,
    /// Per vertex `[channel][coeff]`: bounces 0..=round summed in order.
    pub total: Vec<f32>,
    /// With `--store-bounces`, each bounce so far; else empty.
    pub layers: Vec<Vec<f32>>,
    /// Texel mode: the same per covered texel.
    pub texels: Option<TexelLayer>,
}

/// The texels' rounds so far, merged: as [`LayerFile`]'s vertex fields, per covered texel.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelLayer {
    pub texel_count: u32,
    pub points: u64,
    pub points_rejected: u64,
    pub rays: u64,
    pub rays_traced: u64,
    /// Per texel: the footprint its kept points stand for (from round 0).
    pub weights: Vec<f32>,
    pub noise: Vec<f32>,
    pub back_dc: Vec<f32>,
    /// `source` split by side (window mode), as [`LayerFile::source_sides`].
    pub source_sides: bool,
    pub source: Vec<f32>,
    pub total: Vec<f32>,
    pub layers: Vec<Vec<f32>>,
}

impl LayerFile {
    pub fn write_to<W: Write>(&self, out: W) -> std::io::Result<u32> {
        let mut w = Writer::new(out, FileKind::Layer)?;
        self.identity.write(&mut w)?;
        for v in [self.round, self.channels, self.coeffs, self.source_channels] {
            w.u32(v)?;
        }
        for v in [self.window_triangles, self.points, self.points_rejected, self.rays_traced] {
            w.u64(v)?;
        }
        for v in self.glass_light {
            w.f64(v)?;
        }
        w.u32(self.rays_per_bounce.len() as u32)?;
        w.u64s(&self.rays_per_bounce)?;
        w.f32s(&self.weights)?;
        w.u32(!self.noise.is_empty() as u32)?;
        w.f32s(&self.noise)?;
        w.f32s(&self.back_dc)?;
        w.u32(self.source_sides as u32)?;
        w.f32s(&self.source)?;
        w.f32s(&self.total)?;
        w.u32(self.layers.len() as u32)?;
        for layer in &self.layers {
            w.f32s(layer)?;
        }
        match &self.texels {
            None => w.u32(0)?,
            Some(t) => {
                w.u32(1)?;
                w.u32(t.texel_count)?;
                for v in [t.points, t.points_rejected, t.rays, t.rays_traced] {
                    w.u64(v)?;
                }
                for rows in [&t.weights, &t.noise, &t.back_dc] {
                    w.f32s(rows)?;
                }
                w.u32(t.source_sides as u32)?;
                for rows in [&t.source, &t.total] {
                    w.f32s(rows)?;
                }
                for layer in &t.layers {
                    w.f32s(layer)?;
                }
            }
        }
        w.finish()
    }

    /// Decodes a layer file; also returns its CRC (the parts gathered from it name it).
    pub fn decode(bytes: &[u8]) -> Result<(LayerFile, u32), String> {
        let (mut r, crc) = codec::open(bytes, FileKind::Layer)?;
        let identity = Identity::read(&mut r)?;
        let round = r.u32("round")?;
        let (channels, coeffs, source_channels) = (r.u32("channels")?, r.u32("coefficients")?, r.u32("source channels")?);
        check_sizes(channels, coeffs, source_channels)?;
        if round > 16 || source_channels != if round == 0 { 1 } else { channels } {
            return Err(format!("round {round} with {source_channels} of {channels} source channels"));
        }
        let (window_triangles, points, points_rejected, rays_traced) =
            (r.u64("window triangles")?, r.u64("points")?, r.u64("points rejected")?, r.u64("rays traced")?);
        let glass_light = read_glass_light(&mut r, round, false)?;
        let bounces = r.u32("bounce count")?;
        if bounces != round + 1 {
            return Err(format!("{bounces} ray counts for round {round}"));
        }
        let rays_per_bounce = r.u64s(bounces as u64, "rays per bounce")?;
        let v = identity.plan_vertices;
        let weights = r.f32s(v, "weights")?;
        let (noise, back_dc) = match r.u32("noise flag")? {
            0 => (Vec::new(), Vec::new()),
            1 => (r.f32s(v, "noise")?, r.f32s(v, "back-side DC")?),
            f => return Err(format!("noise flag {f} is not 0 or 1")),
        };
        if noise.iter().any(|n| !(n.is_finite() && *n >= 0.0)) {
            return Err("a vertex's noise is negative or not finite".into());
        }
        if back_dc.iter().any(|n| !n.is_finite()) {
            return Err("a vertex's back-side DC is not finite".into());
        }
        let source_sides = flag_u32(r.u32("source sides flag")?, "source sides")?;
        let sides = if source_sides { 2 } else { 1 };
        let source = r.f32s(v.saturating_mul((source_channels * coeffs) as u64).saturating_mul(sides), "source rows")?;
        let layer_len = v.saturating_mul((channels * coeffs) as u64);
        let total = r.f32s(layer_len, "total")?;
        let stored = r.u32("stored layers")?;
        if stored != 0 && stored != round + 1 {
            return Err(format!("{stored} stored layers after round {round}"));
        }
        let layers = (0..stored).map(|_| r.f32s(layer_len, "stored layer")).collect::<Result<_, _>>()?;
        let texels = match flag_u32(r.u32("texel flag")?, "texel")? {
            false => None,
            true => {
                let texel_count = r.u32("texel count")?;
                let (points, points_rejected, rays, rays_traced) =
                    (r.u64("texel points")?, r.u64("texel points rejected")?, r.u64("texel rays")?, r.u64("texel rays traced")?);
                let n = texel_count as u64;
                let weights = r.f32s(n, "texel weights")?;
                let noise = r.f32s(n, "texel noise")?;
                if noise.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                    return Err("a texel's noise is negative or not finite".into());
                }
                let back_dc = r.f32s(n, "texel back-side DC")?;
                if back_dc.iter().any(|x| !x.is_finite()) {
                    return Err("a texel's back-side DC is not finite".into());
                }
                let texel_sides = flag_u32(r.u32("texel source sides flag")?, "texel source sides")?;
                let source = r.f32s(
                    n.saturating_mul((source_channels * coeffs) as u64).saturating_mul(if texel_sides { 2 } else { 1 }),
                    "texel source rows",
                )?;
                let layer_len = n.saturating_mul((channels * coeffs) as u64);
                let total = r.f32s(layer_len, "texel total")?;
                let layers = (0..stored).map(|_| r.f32s(layer_len, "stored texel layer")).collect::<Result<_, _>>()?;
                Some(TexelLayer {
                    texel_count,
                    points,
                    points_rejected,
                    rays,
                    rays_traced,
                    weights,
                    noise,
                    back_dc,
                    source_sides: texel_sides,
                    source,
                    total,
                    layers,
                })
            }
        };
        r.finish()?;
        let layer = LayerFile {
            identity,
            round,
            channels,
            coeffs,
            source_channels,
            window_triangles,
            points,
            points_rejected,
            rays_traced,
            glass_light,
            rays_per_bounce,
            weights,
            noise,
            back_dc,
            source_sides,
            source,
            total,
            layers,
            texels,
        };
        Ok((layer, crc))
    }
}

/// The merged pilot of adaptive allocation (`PRTA`, `.prta`): bounce 0's
/// base points summed per vertex, what every shard needs to decide where
/// the extra points go (`bake::transfer::adaptive::extra_counts`, the same in every
/// shard and in a whole bake).
#[derive(Clone, Debug, PartialEq)]
pub struct PilotFile {
    pub identity: Identity,
    /// Base points of the bake (its base layout).
    pub points: u64,
    /// Per vertex: summed sample weight, Σ w·DC and the DC moments.
    pub weights: Vec<f32>,
    pub dc_sums: Vec<f32>,
    pub moments: Vec<[f64; 4]>,
    /// `--texel-adaptive`: the same per covered texel, of its base points.
    pub texels: Option<TexelPilotRows>,
}

/// A merged pilot's texels: per covered texel Σ w, Σ w·DC and the DC moments.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelPilotRows {
    pub weights: Vec<f32>,
    pub dc_sums: Vec<f32>,
    pub moments: Vec<[f64; 4]>,
}

impl PilotFile {
    pub fn write_to<W: Write>(&self, out: W) -> std::io::Result<u32> {
        let mut w = Writer::new(out, FileKind::Pilot)?;
        self.identity.write(&mut w)?;
        w.u64(self.points)?;
        w.f32s(&self.weights)?;
        w.f32s(&self.dc_sums)?;
        write_moments(&mut w, &self.moments)?;
        match &self.texels {
            None => w.u32(0)?,
            Some(t) => {
                w.u32(1)?;
                w.u64(t.weights.len() as u64)?;
                w.f32s(&t.weights)?;
                w.f32s(&t.dc_sums)?;
                write_moments(&mut w, &t.moments)?;
            }
        }
        w.finish()
    }

    /// Decodes a pilot file; also returns its CRC (round-0 parts name it).
    pub fn decode(bytes: &[u8]) -> Result<(PilotFile, u32), String> {
        let (mut r, crc) = codec::open(bytes, FileKind::Pilot)?;
        let identity = Identity::read(&mut r)?;
        let points = r.u64("base points")?;
        let v = identity.plan_vertices;
        let weights = r.f32s(v, "weights")?;
        let dc_sums = r.f32s(v, "DC sums")?;
        let moments = read_moments(&mut r, v, "moments")?;
        let texels = match flag_u32(r.u32("texel flag")?, "texel")? {
            false => None,
            true => {
                let n = r.u64("covered texels")?;
                let weights = r.f32s(n, "texel weights")?;
                let dc_sums = r.f32s(n, "texel DC sums")?;
                let moments = read_moments(&mut r, n, "texel moments")?;
                Some(TexelPilotRows { weights, dc_sums, moments })
            }
        };
        r.finish()?;
        let texel_values = texels.iter().flat_map(|t| t.weights.iter().chain(&t.dc_sums));
        let all_weights = weights.iter().chain(texels.iter().flat_map(|t| &t.weights));
        if weights.iter().chain(&dc_sums).chain(texel_values).any(|x| !x.is_finite()) || all_weights.into_iter().any(|&w| w < 0.0) {
            return Err("a weight or DC sum is not finite, or a weight is negative".into());
        }
        Ok((PilotFile { identity, points, weights, dc_sums, moments, texels }, crc))
    }
}

/// One shard's sun bits (`PRTS`, `.prtp`).
#[derive(Clone, Debug, PartialEq)]
pub struct SunPart {
    pub identity: Identity,
    pub shard: u32,
    pub items: Range<u32>,
    pub item_count: u32,
    pub points: Range<u64>,
    pub point_count: u64,
    /// Mask words per sample.
    pub words: u32,
    pub rays: u64,
    /// `words` per point of `points`, in point order.
    pub bits: Vec<u32>,
    /// Shard 0: the output bundle as the single process writes it, with its
    /// masks zero and its statistics to be filled in (empty otherwise).
    pub frame: Vec<u8>,
    /// Texel mode: this shard's range of covered texels, their bits final.
    pub texels: Option<TexelSunPart>,
}

/// A shard's covered texels of a texel sun bake: a texel's bits depend on
/// its own points alone, so a part holds its texels' rows as the whole
/// bake writes them, and the merge joins them in texel order.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelSunPart {
    pub texels: Range<u32>,
    pub texel_count: u32,
    /// Mask words and fraction words per texel (fraction words 0 when the
    /// bundle stores no fractions).
    pub words: u32,
    pub fraction_words: u32,
    /// Points traced (window triangles' left out) and rays.
    pub points: u64,
    pub rays: u64,
    pub masks: Vec<u32>,
    pub fractions: Vec<u32>,
}

impl SunPart {
    pub fn write_to<W: Write>(&self, out: W) -> std::io::Result<u32> {
        let mut w = Writer::new(out, FileKind::SunPart)?;
        self.identity.write(&mut w)?;
        for v in [self.shard, self.items.start, self.items.end, self.item_count] {
            w.u32(v)?;
        }
        for v in [self.points.start, self.points.end, self.point_count] {
            w.u64(v)?;
        }
        w.u32(self.words)?;
        w.u64(self.rays)?;
        w.u32s(&self.bits)?;
        w.blob(&self.frame)?;
        match &self.texels {
            None => w.u32(0)?,
            Some(t) => {
                w.u32(1)?;
                for v in [t.texels.start, t.texels.end, t.texel_count, t.words, t.fraction_words] {
                    w.u32(v)?;
                }
                w.u64(t.points)?;
                w.u64(t.rays)?;
                w.u32s(&t.masks)?;
                w.u32s(&t.fractions)?;
            }
        }
        w.finish()
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let _ = self.write_to(&mut out);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<SunPart, String> {
        let (mut r, _) = codec::open(bytes, FileKind::SunPart)?;
        let identity = Identity::read(&mut r)?;
        let shard = identity.read_shard(&mut r)?;
        let items = read_range32(&mut r, "item range", u32::MAX)?;
        let item_count = r.u32("item count")?;
        if items.end > item_count {
            return Err(format!("item range {items:?} is past the {item_count} items"));
        }
        let points = read_range64(&mut r, "point range", u64::MAX)?;
        let point_count = r.u64("point count")?;
        if points.end > point_count {
            return Err(format!("point range {points:?} is past the {point_count} points"));
        }
        let words = r.u32("words per sample")?;
        if words == 0 || words as usize > crate::bake::sun::MAX_SUN_STEPS.div_ceil(32) {
            return Err(format!("{words} mask words per sample"));
        }
        let rays = r.u64("rays")?;
        let bits = r.u32s((points.end - points.start).saturating_mul(words as u64), "sample bits")?;
        let frame = r.blob("bundle frame")?.to_vec();
        let texels = match r.u32("texel flag")? {
            0 => None,
            1 => {
                let texels = read_range32(&mut r, "texel range", u32::MAX)?;
                let texel_count = r.u32("texel count")?;
                if texels.end > texel_count {
                    return Err(format!("texel range {texels:?} is past the {texel_count} covered texels"));
                }
                let texel_words = r.u32("mask words per texel")?;
                if texel_words != words {
                    return Err(format!("{texel_words} mask words per texel, but {words} per sample"));
                }
                let fraction_words = r.u32("fraction words per texel")?;
                if fraction_words > words * 4 {
                    return Err(format!("{fraction_words} fraction words per texel for {words} mask words"));
                }
                let (points, rays) = (r.u64("texel points")?, r.u64("texel rays")?);
                let n = (texels.end - texels.start) as u64;
                let masks = r.u32s(n * words as u64, "texel bits")?;
                let fractions = r.u32s(n * fraction_words as u64, "texel fractions")?;
                Some(TexelSunPart { texels, texel_count, words, fraction_words, points, rays, masks, fractions })
            }
            f => return Err(format!("texel flag is {f}, not 0 or 1")),
        };
        r.finish()?;
        Ok(SunPart { identity, shard, items, item_count, points, point_count, words, rays, bits, frame, texels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity() -> Identity {
        Identity {
            mesh: MeshId { crc: 0x1234_5678, vertices: 5, triangles: 3 },
            plan_vertices: 5,
            plan_triangles: 3,
            shards: 3,
            key: vec![1, 2, 3, 4],
        }
    }

    fn part() -> TransferPart {
        TransferPart {
            identity: identity(),
            shard: 1,
            round: 0,
            items: 1..2,
            item_count: 3,
            points: 3..6,
            point_count: 9,
            window_triangles: 0,
            layer_crc: 0,
            pass_channels: 1,
            channels: 3,
            coeffs: 4,
            rays: 96,
            traced: 96,
            rejected: 1,
            glass_light: [2.5, 0.75],
            tracks_noise: true,
            pilot: false,
            opened: VertexRows {
                vertices: vec![3],
                rows: vec![0.5, -0.25, 0.0, 1.0],
                weights: vec![0.75],
                moments: vec![[0.5, 0.25, 0.125, 0.0625]],
            },
            late: VertexRows {
                vertices: vec![0, 2],
                rows: vec![1.0; 8],
                weights: vec![0.5, 0.25],
                moments: vec![[0.25, 0.0, 0.0, 0.125], [0.0625, -0.5, 4.0, 0.0]],
            },
            texels: Some(TexelRoundPart {
                texels: 3..5,
                texel_count: 6,
                points: 10..17,
                point_count: 20,
                rays: 224,
                traced: 230,
                rejected: 1,
                sums: vec![0.125; 8],
                weights: vec![0.5, 0.75],
                moments: vec![[0.25, 0.5, 1.0, -0.25], [0.0, 0.0, 0.0, 0.0]],
            }),
            frame: b"frame".to_vec(),
        }
    }

    /// Every file kind round-trips, and every truncation and every flipped
    /// byte of it is an error, not a panic.
    #[test]
    fn files_round_trip_and_refuse_damage() {
        let hits = HitFile {
            identity: identity(),
            shard: 2,
            items: 2..3,
            points: 6..9,
            rays: 2,
            rejected: vec![0b010],
            records: vec![1, 2, 3 | crate::bake::gather::BACK_SIDE, 4, u64::MAX, u64::MAX],
            texels: Some(TexelHits {
                texels: 1..2,
                points: 4..6,
                rays: 2,
                rejected: vec![0b01],
                records: vec![7, 8, 2 << 32, u64::MAX],
                density: Some(ChartLevels { levels: vec![0, 2, 1], meta: r#"{"levels":3}"#.into() }),
            }),
        };
        let layer = LayerFile {
            identity: identity(),
            round: 1,
            channels: 3,
            coeffs: 1,
            source_channels: 3,
            window_triangles: 2,
            points: 9,
            points_rejected: 1,
            rays_traced: 300,
            glass_light: [2.5, 0.75],
            rays_per_bounce: vec![288, 256],
            weights: vec![1.0; 5],
            noise: vec![0.0, 0.5, 0.25, 0.0, 1.0],
            back_dc: vec![0.0, 0.125, 0.0, 0.0, 0.5],
            source_sides: true,
            source: vec![0.25; 30],
            total: vec![0.5; 15],
            layers: vec![vec![0.25; 15], vec![0.25; 15]],
            texels: Some(TexelLayer {
                texel_count: 2,
                points: 8,
                points_rejected: 1,
                rays: 512,
                rays_traced: 260,
                weights: vec![1.0, 0.0],
                noise: vec![0.125, 0.0],
                back_dc: vec![0.25, 0.0],
                source_sides: true,
                source: vec![0.5; 12],
                total: vec![0.75; 6],
                layers: vec![vec![0.25; 6], vec![0.5; 6]],
            }),
        };
        let sun = SunPart {
            identity: identity(),
            shard: 0,
            items: 0..1,
            item_count: 3,
            points: 0..3,
            point_count: 9,
            words: 2,
            rays: 40,
            bits: vec![1, 2, 3, 4, 5, 6],
            frame: vec![9; 7],
            texels: Some(TexelSunPart {
                texels: 2..4,
                texel_count: 5,
                words: 2,
                fraction_words: 8,
                points: 7,
                rays: 30,
                masks: vec![3, 0, 1, 2],
                fractions: (0..16).collect(),
            }),
        };
        // A merged pilot of vertex and texel sums (`--texel-adaptive`).
        let pilot = PilotFile {
            identity: identity(),
            points: 12,
            weights: vec![1.0, 0.5, 0.0, 2.0, 1.0],
            dc_sums: vec![0.25, 0.125, 0.0, 1.0, 0.5],
            moments: vec![[1.0, 0.5, 0.25, 0.0]; 5],
            texels: Some(TexelPilotRows { weights: vec![0.75, 1.0], dc_sums: vec![0.5, 0.25], moments: vec![[0.5, 0.25, 0.125, 0.0]; 2] }),
        };
        let mut hit_bytes = Vec::new();
        hits.write_to(&mut hit_bytes).unwrap();
        let mut layer_bytes = Vec::new();
        let crc = layer.write_to(&mut layer_bytes).unwrap();
        let mut pilot_bytes = Vec::new();
        let pilot_crc = pilot.write_to(&mut pilot_bytes).unwrap();
        let files: [(Vec<u8>, fn(&[u8]) -> bool); 5] = [
            (part().to_bytes(), |b| TransferPart::decode(b).is_ok_and(|p| p == part())),
            (hit_bytes, |b| HitFile::decode(b).is_ok()),
            (layer_bytes.clone(), |b| LayerFile::decode(b).is_ok()),
            (sun.to_bytes(), |b| SunPart::decode(b).is_ok()),
            (pilot_bytes.clone(), |b| PilotFile::decode(b).is_ok()),
        ];
        assert_eq!(LayerFile::decode(&layer_bytes).unwrap(), (layer, crc));
        assert_eq!(PilotFile::decode(&pilot_bytes).unwrap(), (pilot, pilot_crc));
        assert_eq!(HitFile::decode(&files[1].0).unwrap(), hits);
        assert!(hits.is_rejected(1) && !hits.is_rejected(0));
        assert_eq!(SunPart::decode(&files[3].0).unwrap(), sun);
        for (bytes, decodes) in &files {
            assert!(decodes(bytes));
            for len in 0..bytes.len() {
                assert!(!decodes(&bytes[..len]));
            }
            for i in 0..bytes.len() {
                let mut bad = bytes.clone();
                bad[i] ^= 0x41;
                assert!(!decodes(&bad), "byte {i} changed was accepted");
            }
        }
    }

    /// A well-formed file (CRC right) whose fields lie: vertex ids past the
    /// mesh, ranges past their counts, hostile counts.
    #[test]
    fn consistent_checksums_do_not_excuse_bad_fields() {
        let mut p = part();
        p.late.vertices[1] = 5;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("vertex 5 of a mesh of 5"));
        let mut p = part();
        p.items = 2..4;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("past the 3 items"));
        let mut p = part();
        p.shard = 3;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("shard index 3"));
        let mut p = part();
        p.glass_light[1] = f64::NAN;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("light through glass"));
        let mut p = part();
        p.glass_light[0] = -1.0;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("negative or not finite"));
        let mut p = part();
        p.coeffs = 5;
        p.opened.rows.push(0.0);
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("5 coefficients"));
        let mut hits = Vec::new();
        let bad_hits = HitFile {
            identity: identity(),
            shard: 0,
            items: 0..1,
            points: 0..1,
            rays: 2,
            rejected: vec![0],
            records: vec![u64::MAX, 3 << 32],
            texels: None,
        };
        bad_hits.write_to(&mut hits).unwrap();
        assert!(HitFile::decode(&hits).unwrap_err().contains("names triangle 3 of a mesh of 3"));
        let bad_texel_hits = HitFile {
            records: vec![u64::MAX, 0],
            texels: Some(TexelHits { texels: 0..1, points: 0..1, rays: 2, rejected: vec![0], records: vec![0, 4 << 32], density: None }),
            ..bad_hits
        };
        let mut hits = Vec::new();
        bad_texel_hits.write_to(&mut hits).unwrap();
        assert!(HitFile::decode(&hits).unwrap_err().contains("names triangle 4 of a mesh of 3"));
        let mut p = part();
        p.texels.as_mut().unwrap().texels = 5..7;
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("past the 6 covered texels"));
        let mut p = part();
        p.texels.as_mut().unwrap().weights.clear();
        assert!(TransferPart::decode(&p.to_bytes()).unwrap_err().contains("round 0 lacks texel weights"));
        let big = codec::to_vec(FileKind::Hits, |w| {
            identity().write(w)?;
            for v in [0u32, 0, 1] {
                w.u32(v)?;
            }
            w.u64(0)?;
            w.u64(u64::MAX)?;
            w.u32(u32::MAX)
        });
        assert!(HitFile::decode(&big).is_err());
    }
}
