//! The parameters every part of one bake must share, as a canonical byte
//! block (its layout is in docs/scale.md): a merge compares the blocks, and
//! names the first field that differs.

use super::codec::Reader;
use crate::bake::{BakeParams, Channels, DirectionPattern, Mode, Sampling, SunParams};
use crate::bundle::Quantization;
use crate::sky::SunStep;

/// What a transfer bake's result and bundle depend on besides the mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferKey {
    /// `quiet` and `hit_cache_bytes` are not part of the bake (not stored).
    pub params: BakeParams,
    pub window_patterns: Vec<String>,
    /// `--one-sided` patterns: materials or groups whose back reflects nothing.
    pub one_sided_patterns: Vec<String>,
    /// How the bundle stores the transfer: a fixed quantization, or `None` to choose one within the budget.
    pub quantize: Option<Quantization>,
    pub max_error: Option<f64>,
    /// Texel mode (`--texel-size`): transfer per texel of this atlas too.
    pub texels: Option<TexelKey>,
}

/// What a sun bake's masks and bundle depend on besides the mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct SunKey {
    /// `loop_order`, `shadow_cache`, `packets` and `quiet` never change the masks (not stored).
    pub params: SunParams,
    pub window_patterns: Vec<String>,
    pub steps: u32,
    /// CRC-32 of the day (every step's time, direction, sun colour and sky)
    /// and of the sun metadata (site, date, north, turbidity, …).
    pub day_crc: u32,
    /// Texel mode: the atlas and points the texels' bits come from.
    pub texels: Option<TexelKey>,
}

/// Texel mode: what every part's texel rows depend on besides the
/// parameters (the atlas, unwrapped by each shard, and the texels' points).
#[derive(Clone, Debug, PartialEq)]
pub struct TexelKey {
    pub texel_size: f32,
    pub points_per_texel: u32,
    /// Sun bakes: whether the bundle stores each texel's lit share
    /// (`--texel-fractions`); always false in a transfer key.
    pub fractions: bool,
    pub covered_texels: u32,
    /// [`atlas_crc`] of the atlas.
    pub atlas_crc: u32,
    /// Transfer bakes: rays per vertex sample point (`--vertex-rays`; the
    /// texels take the block's rays); 0 in a sun key.
    pub vertex_rays: u32,
    /// Transfer bakes: extra texel points per base point (`--texel-adaptive`); 0 in a sun key.
    pub adaptive: f32,
}

/// CRC-32 of an atlas: its size, texel size, UVs, vertex sources, indices
/// and charts, so shards that unwrapped apart agree only on the same atlas.
pub fn atlas_crc(atlas: &crate::atlas::Atlas) -> u32 {
    let mut h = crc32fast::Hasher::new();
    for v in [atlas.width, atlas.height, atlas.texel_size.to_bits(), atlas.chart_count] {
        h.update(&v.to_le_bytes());
    }
    for uv in &atlas.uv {
        h.update(&uv.x.to_le_bytes());
        h.update(&uv.y.to_le_bytes());
    }
    for list in [&atlas.source_vertex, &atlas.indices, &atlas.triangle_chart] {
        h.update(&(list.len() as u64).to_le_bytes());
        for v in list.iter() {
            h.update(&v.to_le_bytes());
        }
    }
    h.finalize()
}

/// CRC-32 of the day (each step's time, sun, colour, sky) and of the sun
/// metadata without its stats: what every shard of one sun bake must share.
fn day_crc(steps: &[SunStep], meta_without_stats: &serde_json::Value) -> u32 {
    let mut h = crc32fast::Hasher::new();
    for s in steps {
        h.update(&s.unix_time_utc.to_le_bytes());
        let floats = s.direction.iter().chain([&s.elevation_deg, &s.azimuth_deg]).chain(&s.sun_rgb).chain(s.sky_sh.iter().flatten());
        for f in floats {
            h.update(&f.to_le_bytes());
        }
        h.update(&[s.night as u8]);
        h.update(&(s.sky_sh.len() as u64).to_le_bytes());
    }
    h.update(&serde_json::to_vec(meta_without_stats).unwrap_or_default());
    h.finalize()
}

fn mode_code(mode: Mode) -> u8 {
    match mode {
        Mode::Open => 0,
        Mode::Window => 1,
    }
}

fn mode_of(code: u8) -> Result<Mode, String> {
    match code {
        0 => Ok(Mode::Open),
        1 => Ok(Mode::Window),
        c => Err(format!("mode code {c} is not 0 (open) or 1 (window)")),
    }
}

fn quantize_code(q: Option<Quantization>) -> u8 {
    match q {
        None => 0,
        Some(q) => 1 + q.code() as u8,
    }
}

fn quantize_of(code: u8) -> Result<Option<Quantization>, String> {
    Ok(match code {
        0 => None,
        1 => Some(Quantization::F32),
        2 => Some(Quantization::F16),
        3 => Some(Quantization::I16PerVertexScale),
        4 => Some(Quantization::F16Tinted),
        c => return Err(format!("quantization code {c} is not 0..=4")),
    })
}

fn flag(code: u8, what: &str) -> Result<bool, String> {
    match code {
        0 => Ok(false),
        1 => Ok(true),
        c => Err(format!("{what} flag is {c}, not 0 or 1")),
    }
}

fn put_patterns(out: &mut Vec<u8>, patterns: &[String]) {
    out.extend_from_slice(&(patterns.len() as u32).to_le_bytes());
    for p in patterns {
        out.extend_from_slice(&(p.len() as u32).to_le_bytes());
        out.extend_from_slice(p.as_bytes());
        out.resize(out.len().next_multiple_of(4), 0);
    }
}

fn read_patterns(r: &mut Reader) -> Result<Vec<String>, String> {
    let count = r.u32("pattern count")?;
    // Each pattern takes at least its 4-byte length: no allocation beyond the bytes present.
    let mut patterns = Vec::new();
    for _ in 0..count {
        patterns.push(r.string("pattern")?);
    }
    Ok(patterns)
}

/// Reads a key block: its fields in order, then nothing else.
fn read_block<T>(block: &[u8], read: impl FnOnce(&mut Reader) -> Result<T, String>) -> Result<T, String> {
    let mut r = Reader::new(block);
    let value = read(&mut r)?;
    r.finish().map_err(|e| format!("parameter block: {e}"))?;
    Ok(value)
}

impl TransferKey {
    /// The canonical block (docs/scale.md "Transfer parameter block").
    pub fn encode(&self) -> Vec<u8> {
        let p = &self.params;
        let mut out = Vec::with_capacity(64);
        let u32 = |out: &mut Vec<u8>, v: u32| out.extend_from_slice(&v.to_le_bytes());
        u32(&mut out, p.order as u32);
        u32(&mut out, p.rays);
        u32(&mut out, p.seed);
        u32(&mut out, p.point_seed.is_some() as u32);
        u32(&mut out, p.point_seed.unwrap_or(0));
        let (sampling, samples_per_vertex, max_per_triangle) = match p.sampling {
            Sampling::Interior { samples_per_vertex, max_per_triangle } => (0u8, samples_per_vertex, max_per_triangle),
            Sampling::Vertex => (1, 0.0, 0),
        };
        let channels = match p.channels {
            Channels::Auto => 0u8,
            Channels::One => 1,
            Channels::Three => 3,
        };
        let pattern = match p.pattern {
            DirectionPattern::Sobol => 0u8,
            DirectionPattern::Random => 1,
        };
        out.extend_from_slice(&[mode_code(p.mode), sampling, channels, pattern]);
        out.extend_from_slice(&samples_per_vertex.to_le_bytes());
        u32(&mut out, max_per_triangle);
        u32(&mut out, p.bounces);
        out.extend_from_slice(&[
            p.store_bounces as u8,
            p.window_sampling as u8 | (p.keep_outside_sides as u8) << 1 | (p.two_sided as u8) << 2,
            quantize_code(self.quantize),
            self.max_error.is_some() as u8,
        ]);
        out.extend_from_slice(&p.inside_distance.to_le_bytes());
        out.extend_from_slice(&self.max_error.unwrap_or(0.0).to_le_bytes());
        out.extend_from_slice(&p.adaptive.to_le_bytes());
        put_patterns(&mut out, &self.window_patterns);
        put_patterns(&mut out, &self.one_sided_patterns);
        out.extend_from_slice(&p.denoise.to_le_bytes());
        put_texel_key(&mut out, self.texels.as_ref());
        out
    }

    /// Reads a block written by [`TransferKey::encode`]; the parameters are range-checked.
    pub fn decode(block: &[u8]) -> Result<TransferKey, String> {
        read_block(block, |r| {
            let order = r.u32("order")? as usize;
            let rays = r.u32("rays")?;
            let seed = r.u32("seed")?;
            let has_point_seed = flag(r.u32("point seed flag")?.min(2) as u8, "point seed")?;
            let point_seed = r.u32("point seed")?;
            let mode = mode_of(r.u8("mode")?)?;
            let sampling_code = r.u8("sampling")?;
            let channels = match r.u8("channels")? {
                0 => Channels::Auto,
                1 => Channels::One,
                3 => Channels::Three,
                c => return Err(format!("channels code {c} is not 0, 1 or 3")),
            };
            let pattern = match r.u8("pattern")? {
                0 => DirectionPattern::Sobol,
                1 => DirectionPattern::Random,
                c => return Err(format!("pattern code {c} is not 0 or 1")),
            };
            let samples_per_vertex = r.f32("samples per vertex")?;
            let max_per_triangle = r.u32("max per triangle")?;
            let sampling = match sampling_code {
                0 => Sampling::Interior { samples_per_vertex, max_per_triangle },
                1 => Sampling::Vertex,
                c => return Err(format!("sampling code {c} is not 0 or 1")),
            };
            let bounces = r.u32("bounces")?;
            let store_bounces = flag(r.u8("store bounces")?, "store bounces")?;
            let window_options = r.u8("window options")?;
            if window_options > 7 {
                return Err(format!("options {window_options} has bits other than 0, 1 and 2"));
            }
            let (window_sampling, keep_outside_sides, two_sided) =
                (window_options & 1 == 1, window_options & 2 == 2, window_options & 4 == 4);
            let quantize = quantize_of(r.u8("quantize")?)?;
            let has_max_error = flag(r.u8("max error flag")?, "max error")?;
            let inside_distance = r.f32("inside distance")?;
            let max_error = r.f64("max error")?;
            let adaptive = r.f32("adaptive")?;
            let window_patterns = read_patterns(r)?;
            let one_sided_patterns = read_patterns(r)?;
            let denoise = r.f32("denoise")?;
            let texels = read_texel_key(r)?;
            if texels.as_ref().is_some_and(|t| t.fractions) {
                return Err("texel fractions are a sun bake's, not a transfer's".into());
            }
            if let Some(t) = texels.as_ref().filter(|t| t.vertex_rays == 0 || t.vertex_rays > crate::sampling::MAX_RAYS_PER_POINT) {
                return Err(format!("{} rays per vertex point is outside 1..={}", t.vertex_rays, crate::sampling::MAX_RAYS_PER_POINT));
            }
            let params = BakeParams {
                order,
                rays,
                seed,
                point_seed: has_point_seed.then_some(point_seed),
                mode,
                sampling,
                bounces,
                channels,
                store_bounces,
                pattern,
                window_sampling,
                keep_outside_sides,
                inside_distance,
                adaptive,
                two_sided,
                denoise,
                ..BakeParams::default()
            };
            params.check().map_err(|e| e.to_string())?;
            let max_error = has_max_error.then_some(max_error);
            Ok(TransferKey { params, window_patterns, one_sided_patterns, quantize, max_error, texels })
        })
    }

    /// Each field and its value, for naming what differs between two parts.
    pub fn fields(&self) -> Vec<(&'static str, String)> {
        let p = &self.params;
        vec![
            ("order", p.order.to_string()),
            ("rays", p.rays.to_string()),
            ("seed", p.seed.to_string()),
            ("point seed", format!("{:?}", p.point_seed)),
            ("mode", format!("{:?}", p.mode)),
            ("sampling", format!("{:?}", p.sampling)),
            ("channels", format!("{:?}", p.channels)),
            ("pattern", format!("{:?}", p.pattern)),
            ("bounces", p.bounces.to_string()),
            ("store bounces", p.store_bounces.to_string()),
            ("window sampling", p.window_sampling.to_string()),
            ("keep outside sides", p.keep_outside_sides.to_string()),
            ("inside distance", p.inside_distance.to_string()),
            ("adaptive", p.adaptive.to_string()),
            ("window patterns", format!("{:?}", self.window_patterns)),
            ("two-sided", p.two_sided.to_string()),
            ("one-sided patterns", format!("{:?}", self.one_sided_patterns)),
            ("quantize", format!("{:?}", self.quantize)),
            ("max error", format!("{:?}", self.max_error)),
            ("denoise", p.denoise.to_string()),
        ]
        .into_iter()
        .chain(texel_fields(self.texels.as_ref()).into_iter().filter(|(name, _)| *name != "texel fractions"))
        .collect()
    }
}

impl SunKey {
    /// The key of a sun bake of `steps` (the whole day, nights included)
    /// whose bundle metadata without its stats is `meta_without_stats`.
    pub fn of_day(params: SunParams, window_patterns: Vec<String>, steps: &[SunStep], meta_without_stats: &serde_json::Value) -> SunKey {
        SunKey { params, window_patterns, steps: steps.len() as u32, day_crc: day_crc(steps, meta_without_stats), texels: None }
    }

    /// The canonical block (docs/scale.md "Sun parameter block").
    pub fn encode(&self) -> Vec<u8> {
        let p = &self.params;
        let mut out = vec![mode_code(p.mode), p.keep_outside_sides as u8, 0, 0];
        out.extend_from_slice(&p.samples_per_vertex.to_le_bytes());
        out.extend_from_slice(&p.max_per_triangle.to_le_bytes());
        out.extend_from_slice(&p.seed.to_le_bytes());
        out.extend_from_slice(&self.steps.to_le_bytes());
        out.extend_from_slice(&self.day_crc.to_le_bytes());
        put_patterns(&mut out, &self.window_patterns);
        put_texel_key(&mut out, self.texels.as_ref());
        out
    }

    pub fn decode(block: &[u8]) -> Result<SunKey, String> {
        read_block(block, |r| {
            let mode = mode_of(r.u8("mode")?)?;
            let keep_outside_sides = flag(r.u8("keep outside sides")?, "keep outside sides")?;
            if r.take(2, "reserved")? != [0, 0] {
                return Err("reserved bytes are not zero".into());
            }
            let params = SunParams {
                mode,
                keep_outside_sides,
                samples_per_vertex: r.f32("samples per vertex")?,
                max_per_triangle: r.u32("max per triangle")?,
                seed: r.u32("seed")?,
                ..SunParams::default()
            };
            params.check().map_err(|e| e.to_string())?;
            let steps = r.u32("steps")?;
            if steps == 0 || steps as usize > crate::bake::sun::MAX_SUN_STEPS {
                return Err(format!("{steps} steps, outside 1..={}", crate::bake::sun::MAX_SUN_STEPS));
            }
            let day_crc = r.u32("day CRC")?;
            let window_patterns = read_patterns(r)?;
            let texels = read_texel_key(r)?;
            if texels.as_ref().is_some_and(|t| t.vertex_rays != 0 || t.adaptive != 0.0) {
                return Err("rays per vertex point and texel adaptive allocation are a transfer bake's, not a sun bake's".into());
            }
            Ok(SunKey { params, window_patterns, steps, day_crc, texels })
        })
    }

    pub fn fields(&self) -> Vec<(&'static str, String)> {
        let p = &self.params;
        vec![
            ("mode", format!("{:?}", p.mode)),
            ("keep outside sides", p.keep_outside_sides.to_string()),
            ("samples per vertex", p.samples_per_vertex.to_string()),
            ("max per triangle", p.max_per_triangle.to_string()),
            ("seed", p.seed.to_string()),
            ("window patterns", format!("{:?}", self.window_patterns)),
            ("steps", self.steps.to_string()),
            ("day and sky (site, date, time line, north, turbidity, sky order)", format!("CRC-32 {:08x}", self.day_crc)),
        ]
        .into_iter()
        .chain(texel_fields(self.texels.as_ref()))
        .collect()
    }
}

/// A texel key after its parameter block's other fields (a zero `u32` when off).
fn put_texel_key(out: &mut Vec<u8>, texels: Option<&TexelKey>) {
    match texels {
        None => out.extend_from_slice(&0u32.to_le_bytes()),
        Some(t) => {
            out.extend_from_slice(&t.points_per_texel.to_le_bytes());
            out.extend_from_slice(&t.texel_size.to_le_bytes());
            out.extend_from_slice(&t.covered_texels.to_le_bytes());
            out.extend_from_slice(&t.atlas_crc.to_le_bytes());
            out.extend_from_slice(&[t.fractions as u8, 0, 0, 0]);
            out.extend_from_slice(&t.vertex_rays.to_le_bytes());
            out.extend_from_slice(&t.adaptive.to_le_bytes());
        }
    }
}

fn read_texel_key(r: &mut Reader) -> Result<Option<TexelKey>, String> {
    let points_per_texel = r.u32("points per texel")?;
    if points_per_texel == 0 {
        return Ok(None);
    }
    let texel_size = r.f32("texel size")?;
    if !(texel_size.is_finite() && texel_size > 0.0) {
        return Err(format!("texel size {texel_size} is not a positive length"));
    }
    let covered_texels = r.u32("covered texels")?;
    let atlas_crc = r.u32("atlas CRC")?;
    let fractions = flag(r.u8("fractions")?, "fractions")?;
    if r.take(3, "reserved")? != [0, 0, 0] {
        return Err("reserved bytes are not zero".into());
    }
    let vertex_rays = r.u32("vertex rays")?;
    let adaptive = r.f32("texel adaptive")?;
    if !(0.0..=16.0).contains(&adaptive) {
        return Err(format!("texel adaptive allocation {adaptive} is outside 0..=16"));
    }
    Ok(Some(TexelKey { texel_size, points_per_texel, fractions, covered_texels, atlas_crc, vertex_rays, adaptive }))
}

fn texel_fields(texels: Option<&TexelKey>) -> Vec<(&'static str, String)> {
    vec![
        ("texel mode", texels.map_or("off".into(), |t| format!("{} m texels, {} points each", t.texel_size, t.points_per_texel))),
        ("texel fractions", texels.is_some_and(|t| t.fractions).to_string()),
        ("covered texels", texels.map_or(0, |t| t.covered_texels).to_string()),
        ("atlas", texels.map_or("none".into(), |t| format!("CRC-32 {:08x}", t.atlas_crc))),
        ("vertex rays", texels.map_or(0, |t| t.vertex_rays).to_string()),
        ("texel adaptive", texels.map_or(0.0, |t| t.adaptive).to_string()),
    ]
}

/// The first field whose values differ, as "rays 32 here, 64 in the other".
pub fn first_difference(here: &[(&'static str, String)], there: &[(&'static str, String)]) -> Option<String> {
    here.iter().zip(there).find(|(a, b)| a != b).map(|((name, a), (_, b))| format!("{name} {a} here, {b} in"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_and_name_their_differences() {
        let key = TransferKey {
            params: BakeParams { rays: 64, bounces: 3, mode: Mode::Window, seed: 7, store_bounces: true, ..BakeParams::default() },
            window_patterns: vec!["glass*".into(), "Glass_Gray=0.6".into()],
            one_sided_patterns: vec!["curtain".into()],
            quantize: Some(Quantization::F16),
            max_error: Some(0.01),
            texels: None,
        };
        let block = key.encode();
        assert_eq!(block.len() % 4, 0);
        assert_eq!(TransferKey::decode(&block).unwrap(), key);
        let other = TransferKey { params: BakeParams { rays: 32, ..key.params }, ..key.clone() };
        assert_eq!(first_difference(&other.fields(), &key.fields()).unwrap(), "rays 32 here, 64 in");
        let texel_key = TexelKey {
            texel_size: 0.02,
            points_per_texel: 16,
            fractions: false,
            covered_texels: 99,
            atlas_crc: 0xabc,
            vertex_rays: 8,
            adaptive: 0.5,
        };
        let texel_mode = TransferKey { params: BakeParams { denoise: 1.5, ..key.params }, texels: Some(texel_key), ..key.clone() };
        assert_eq!(TransferKey::decode(&texel_mode.encode()).unwrap(), texel_mode);
        assert_eq!(first_difference(&key.fields(), &texel_mode.fields()).unwrap(), "denoise 0 here, 1.5 in");
        let vertex_only = TransferKey { params: texel_mode.params, ..key.clone() };
        assert_eq!(
            first_difference(&vertex_only.fields(), &texel_mode.fields()).unwrap(),
            "texel mode off here, 0.02 m texels, 16 points each in"
        );

        let sun = SunKey {
            params: SunParams { seed: 9, ..SunParams::default() },
            window_patterns: vec![],
            steps: 92,
            day_crc: 0xdead_beef,
            texels: None,
        };
        assert_eq!(SunKey::decode(&sun.encode()).unwrap(), sun);
        let texels = TexelKey {
            texel_size: 0.05,
            points_per_texel: 4,
            fractions: true,
            covered_texels: 1234,
            atlas_crc: 0xfeed,
            vertex_rays: 0,
            adaptive: 0.0,
        };
        let with_texels = SunKey { texels: Some(texels.clone()), ..sun.clone() };
        let block = with_texels.encode();
        assert_eq!(block.len() % 4, 0);
        assert_eq!(SunKey::decode(&block).unwrap(), with_texels);
        for len in 0..block.len() {
            assert!(SunKey::decode(&block[..len]).is_err(), "a block cut to {len} bytes decoded");
        }
        let other_atlas = SunKey { texels: Some(TexelKey { atlas_crc: 0xbeef, ..texels }), ..sun.clone() };
        assert_eq!(
            first_difference(&other_atlas.fields(), &with_texels.fields()).unwrap(),
            "atlas CRC-32 0000beef here, CRC-32 0000feed in"
        );
        assert_eq!(first_difference(&sun.fields(), &with_texels.fields()).unwrap(), "texel mode off here, 0.05 m texels, 4 points each in");
    }

    #[test]
    fn bad_blocks_are_errors_not_panics() {
        let block = TransferKey {
            params: BakeParams::default(),
            window_patterns: vec!["a".into()],
            one_sided_patterns: Vec::new(),
            quantize: None,
            max_error: None,
            texels: None,
        }
        .encode();
        for len in 0..block.len() {
            assert!(TransferKey::decode(&block[..len]).is_err());
        }
        let mut bad = block.clone();
        bad[0] = 0; // order 0
        assert!(TransferKey::decode(&bad).unwrap_err().contains("order"));
        for byte in 0..block.len() {
            for value in [0u8, 2, 0xff] {
                let mut bad = block.clone();
                bad[byte] = value;
                let _ = TransferKey::decode(&bad);
                let _ = SunKey::decode(&bad);
            }
        }
    }
}
