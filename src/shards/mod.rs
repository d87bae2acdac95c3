//! Bakes split into shards that run as separate processes (batch jobs on
//! other machines) and merge into the bundle a single process would write,
//! byte for byte (docs/scale.md).
//!
//! Shard K of N takes a contiguous range of the bake's items (the order
//! every sum runs in), balanced by estimated cost: sample points × rays, or
//! × day steps for sun masks, computed the same way by every shard from the
//! mesh and the parameters. A shard runs the same functions as a whole bake
//! over its range: per-item corner sums added to their vertices in item
//! order. A vertex whose first item is in the range gets its sums there; a
//! vertex first touched by an earlier shard gets this shard's contributions
//! listed one by one, added by the merge after the earlier shards' sums. So
//! every vertex's f32 sum runs in the order of a whole bake.
//!
//! Transfer runs round by round: round b needs every vertex's bounce b − 1.
//! Round 0 traces and keeps its hit records in its own file; each merge but
//! the last writes one layer file (the normalised previous bounce, weights
//! and running total); later rounds gather from their hit records and that
//! layer; the last merge gives the bundle. Sun masks take one round.
//!
//! - [`codec`]: the byte layout shared by every shard file (magic, version,
//!   CRC-32 trailer) and bounded little-endian reads.
//! - [`key`]: the parameters every part of one bake must share.
//! - [`files`]: transfer parts, hit records, layers and sun parts as structs ⇄ bytes.
//! - [`round`]: one shard of a transfer or sun round (no I/O).
//! - [`merge`]: the checks that parts belong together, and their merge.

pub mod codec;
pub mod files;
pub mod key;
pub mod merge;
pub mod round;
pub mod run;

use std::ops::Range;
use std::path::PathBuf;

use crate::mesh::Mesh;

pub use codec::FileKind;
pub use files::{
    ChartLevels, HitFile, Identity, LayerFile, PilotFile, SunPart, TexelHits, TexelLayer, TexelRoundPart, TexelSunPart, TransferPart,
};
pub use key::{atlas_crc, SunKey, TexelKey, TransferKey};
pub use merge::{merge_sun_parts, merge_transfer, merged_texel_transfer, MergedSun, TransferMerge};
pub use round::{bake_sun_shard, bake_transfer_shard, PilotInput, RoundInput, RoundOutput, Stage};
pub use run::ShardRun;

/// Most shards of one bake.
pub const MAX_SHARDS: u32 = 100_000;

/// Shard `index` of `count` (`K/N` on the command line, K in 0..N).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    /// Parses `K/N`.
    pub fn parse(text: &str) -> Result<Shard, ShardError> {
        let bad = |problem: &str| ShardError::Spec { text: text.to_string(), problem: problem.to_string() };
        let (k, n) = text.split_once('/').ok_or_else(|| bad("expected K/N, e.g. 0/8"))?;
        let index: u32 = k.trim().parse().map_err(|_| bad("K is not a whole number"))?;
        let count: u32 = n.trim().parse().map_err(|_| bad("N is not a whole number"))?;
        if count == 0 || count > MAX_SHARDS {
            return Err(bad(&format!("N must be in 1..={MAX_SHARDS}")));
        }
        if index >= count {
            return Err(bad("K must be in 0..N (shards count from 0)"));
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Contiguous item ranges, one per shard, of about equal cost: shard k
/// starts at the first item whose cost prefix reaches k/N of the total.
/// Integer arithmetic only, so every shard computes the same ranges.
pub fn split_by_cost(costs: &[u64], count: u32) -> Vec<Range<usize>> {
    let mut prefix = Vec::with_capacity(costs.len() + 1);
    let mut sum = 0u128;
    prefix.push(0u128);
    for &c in costs {
        sum += c as u128;
        prefix.push(sum);
    }
    let n = count.max(1) as u128;
    let mut starts: Vec<usize> = (0..count.max(1) as u128).map(|k| prefix.partition_point(|&p| p * n < k * sum).min(costs.len())).collect();
    starts[0] = 0;
    starts.push(costs.len());
    starts.windows(2).map(|w| w[0]..w[1].max(w[0])).collect()
}

/// What identifies the mesh a shard baked: a CRC-32 over every array the
/// bake reads or the bundle stores, and its counts. Computed after loading
/// (and `--clean`), so parts of the same file under the same options agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshId {
    pub crc: u32,
    pub vertices: u64,
    pub triangles: u64,
}

impl MeshId {
    pub fn of(mesh: &Mesh) -> MeshId {
        let mut h = crc32fast::Hasher::new();
        let floats = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        hash_values(&mut h, mesh.positions.iter().flat_map(|p| p.to_array()).map(f32::to_le_bytes));
        hash_values(&mut h, mesh.normals.iter().flat_map(|n| n.to_array()).map(f32::to_le_bytes));
        hash_values(&mut h, mesh.uvs.iter().flat_map(|t| t.to_array()).map(f32::to_le_bytes));
        hash_values(&mut h, mesh.colors.iter().flatten().map(|c| c.to_le_bytes()));
        for m in &mesh.materials {
            h.update(&floats(&[m.albedo[0], m.albedo[1], m.albedo[2], m.transmittance]));
            h.update(&[m.role as u8]);
            h.update(&(m.name.len() as u64).to_le_bytes());
            h.update(m.name.as_bytes());
        }
        for g in &mesh.groups {
            h.update(&(g.len() as u64).to_le_bytes());
            h.update(g.as_bytes());
        }
        hash_values(&mut h, mesh.indices.iter().map(|i| i.to_le_bytes()));
        hash_values(&mut h, mesh.tri_material.iter().map(|m| m.to_le_bytes()));
        hash_values(&mut h, mesh.tri_group.iter().map(|g| g.to_le_bytes()));
        MeshId { crc: h.finalize(), vertices: mesh.vertex_count() as u64, triangles: mesh.triangle_count() as u64 }
    }
}

/// Feeds little-endian values to `h` a few kilobytes at a time.
fn hash_values<const N: usize>(h: &mut crc32fast::Hasher, values: impl Iterator<Item = [u8; N]>) {
    let mut chunk = Vec::with_capacity(8192);
    for v in values {
        chunk.extend_from_slice(&v);
        if chunk.len() >= 8192 {
            h.update(&chunk);
            chunk.clear();
        }
    }
    h.update(&chunk);
}

impl std::fmt::Display for MeshId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} vertices, {} triangles, CRC-32 {:08x}", self.vertices, self.triangles, self.crc)
    }
}

/// Errors of shards and merges; each names the file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    #[error("--shard {text:?}: {problem}")]
    Spec { text: String, problem: String },
    /// A file that is not a readable shard file of this version.
    #[error("{}: {problem}", path.display())]
    Malformed { path: PathBuf, problem: String },
    /// A file from another bake, round or shard than the others.
    #[error("{}: {problem}", path.display())]
    Mismatch { path: PathBuf, problem: String },
    #[error("{}: shard {index}/{count} is given twice (also as {}): give each part once", path.display(), other.display())]
    Duplicate { path: PathBuf, other: PathBuf, index: u32, count: u32 },
    #[error("missing part(s) of {count} shards: {missing} (given: {given}); run the missing shard(s) and merge again")]
    Missing { count: u32, missing: String, given: String },
    #[error("no parts given: merge needs every part of one round")]
    NoParts,
    #[error(transparent)]
    Bake(#[from] crate::bake::BakeError),
}

impl ShardError {
    pub(crate) fn malformed(path: impl Into<PathBuf>, problem: impl Into<String>) -> ShardError {
        ShardError::Malformed { path: path.into(), problem: problem.into() }
    }
    pub(crate) fn mismatch(path: impl Into<PathBuf>, problem: impl Into<String>) -> ShardError {
        ShardError::Mismatch { path: path.into(), problem: problem.into() }
    }
}

/// The canonical name of shard `shard`'s hit records in its shard folder
/// (round 0 writes it, later rounds read it back).
pub fn hit_file_name(shard: Shard) -> String {
    format!("hits-{}-of-{}.prth", shard.index, shard.count)
}

#[cfg(test)]
mod fuzz_tests;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_specs_parse_and_bad_ones_say_why() {
        assert_eq!(Shard::parse("3/8").unwrap(), Shard { index: 3, count: 8 });
        assert_eq!(Shard::parse("0/1").unwrap().to_string(), "0/1");
        for (text, why) in [("8/8", "0..N"), ("1", "K/N"), ("a/2", "K is"), ("0/0", "N must"), ("-1/2", "K is"), ("0/100001", "N must")] {
            let e = Shard::parse(text).unwrap_err().to_string();
            assert!(e.contains(why) && e.contains(text), "{text}: {e}");
        }
    }

    #[test]
    fn splits_tile_the_items_and_balance_their_cost() {
        let costs: Vec<u64> = (0..1000u64).map(|i| 1 + (i * 7919) % 13).collect();
        let total: u64 = costs.iter().sum();
        for n in [1u32, 2, 3, 7, 64, 999, 1000, 1500] {
            let ranges = split_by_cost(&costs, n);
            assert_eq!(ranges.len(), n as usize);
            assert_eq!(ranges[0].start, 0);
            assert_eq!(ranges.last().unwrap().end, costs.len());
            for w in ranges.windows(2) {
                assert_eq!(w[0].end, w[1].start, "{n} shards: {ranges:?}");
            }
            // Each share is within one item's cost (≤ 13) of total / n.
            for r in &ranges {
                let share: u64 = costs[r.clone()].iter().sum();
                assert!((share as f64 - total as f64 / n as f64).abs() <= 13.0, "{n} shards: share {share} of {total}");
            }
        }
        assert_eq!(split_by_cost(&[], 3), vec![0..0, 0..0, 0..0]);
    }

    /// Runs every round of a sharded bake in process, shards in reverse
    /// order and every file through its bytes, and returns the merged
    /// result (and in texel mode, with the atlas `texels`, its texels).
    fn sharded_with(
        mesh: &Mesh,
        key: &TransferKey,
        count: u32,
        texels: Option<&crate::atlas::Atlas>,
    ) -> (crate::bake::TransferResult, Option<TexelLayer>) {
        use std::path::{Path, PathBuf};
        let surfaces = crate::bake::Surfaces::resolve(mesh, &key.window_patterns).unwrap();
        let scene = crate::trace::Scene::build(mesh, crate::trace::BuildQuality::Sah).unwrap();
        let bounces = key.params.bounces;
        let points_per_texel = key.texels.as_ref().map_or(0, |t| t.points_per_texel);
        let texel_adaptive = key.texels.as_ref().map_or(0.0, |t| t.adaptive);
        let texel_plan = || {
            texels.map(|atlas| {
                crate::bake::texels::TexelTransferPlan::new(mesh, atlas, points_per_texel, texel_adaptive, &key.params).unwrap()
            })
        };
        let mut layer: Option<(LayerFile, u32)> = None;
        let mut hits: Vec<Option<HitFile>> = vec![None; count as usize];
        // Adaptive allocation: the pilot stage first, merged into the pilot every round reads.
        let pilot: Option<(PilotFile, u32)> = (key.params.adaptive > 0.0 || texel_adaptive > 0.0).then(|| {
            let parts: Vec<(PathBuf, TransferPart)> = (0..count)
                .map(|index| {
                    let shard = Shard { index, count };
                    let out =
                        bake_transfer_shard(mesh, &scene, &surfaces, key, texel_plan().as_mut(), true, shard, Stage::Pilot, None, None)
                            .unwrap();
                    assert!(out.hits.is_none(), "the pilot keeps no hit records");
                    (PathBuf::from(format!("pilot-{index}")), TransferPart::decode(&out.part.to_bytes()).unwrap())
                })
                .collect();
            let TransferMerge::Pilot(p) = merge_transfer(&parts, None).unwrap() else { panic!("pilot parts merge into a pilot") };
            let mut bytes = Vec::new();
            p.write_to(&mut bytes).unwrap();
            PilotFile::decode(&bytes).unwrap()
        });
        for round in 0..=bounces {
            let mut parts = Vec::new();
            for index in (0..count).rev() {
                let input = layer.as_ref().map(|(layer, crc)| RoundInput {
                    hits_path: Path::new("hits"),
                    hits: hits[index as usize].clone().unwrap(),
                    layer_path: Path::new("layer"),
                    layer: layer.clone(),
                    layer_crc: *crc,
                });
                let pilot = pilot.as_ref().map(|(p, crc)| PilotInput { path: Path::new("pilot"), pilot: p.clone(), crc: *crc });
                let shard = Shard { index, count };
                let out = bake_transfer_shard(
                    mesh,
                    &scene,
                    &surfaces,
                    key,
                    texel_plan().as_mut(),
                    true,
                    shard,
                    Stage::Round(round),
                    input,
                    pilot,
                )
                .unwrap();
                if round == 0 {
                    hits[index as usize] = out.hits.map(|h| {
                        let mut bytes = Vec::new();
                        h.write_to(&mut bytes).unwrap();
                        HitFile::decode(&bytes).unwrap()
                    });
                }
                let mut part = out.part;
                part.frame = b"frame".to_vec();
                parts.push((PathBuf::from(format!("part-{index}")), TransferPart::decode(&part.to_bytes()).unwrap()));
            }
            match merge_transfer(&parts, layer.take().map(|(l, crc)| (Path::new("layer"), l, crc))).unwrap() {
                TransferMerge::Layer(l) => {
                    let mut bytes = Vec::new();
                    l.write_to(&mut bytes).unwrap();
                    layer = Some(LayerFile::decode(&bytes).unwrap());
                }
                TransferMerge::Final { result, texels, .. } => return (result, texels),
                TransferMerge::Pilot(_) => panic!("rounds do not merge into a pilot"),
            }
        }
        unreachable!("the last round's merge is final")
    }

    /// The key of a bake of `params` with no patterns and the bake's own storage.
    fn key_of(params: crate::bake::BakeParams, texels: Option<TexelKey>) -> TransferKey {
        TransferKey { params, window_patterns: Vec::new(), one_sided_patterns: Vec::new(), quantize: None, max_error: None, texels }
    }

    fn sharded(mesh: &Mesh, key: &TransferKey, count: u32) -> crate::bake::TransferResult {
        sharded_with(mesh, key, count, None).0
    }

    /// Texel mode through shards: each shard traces its range of texels
    /// beside its items, and the merged vertices and texels (every bounce,
    /// the noise, the counts) are a whole texel bake's bits, with uniform
    /// and adaptive points, at several shard counts.
    #[test]
    fn merged_texel_shards_equal_a_whole_texel_bake_bit_for_bit() {
        use crate::bake::{BakeParams, Mode};
        use crate::verify::shapes;
        use glam::Vec3;
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut open_mesh = shapes::plane_grid(4, 2.0);
        let mut sphere = shapes::icosphere(2);
        shapes::transform(&mut sphere, 0.3, Vec3::new(0.2, 0.45, 0.0));
        shapes::append(&mut open_mesh, &sphere);
        open_mesh.materials[0].albedo = [0.7, 0.5, 0.3];
        let (mut window_mesh, _) = shapes::integrating_sphere(1, 0.6, 0.7, shapes::Opening::Window);
        window_mesh.materials[0].albedo = [0.7, 0.5, 0.3];
        // (mesh, mode, vertex adaptive, texel adaptive, shard counts)
        let cases = [
            (&open_mesh, Mode::Open, 0.0f32, 0.0f32, [1u32, 2, 5].as_slice()),
            (&open_mesh, Mode::Open, 1.0, 0.0, &[3]),
            (&window_mesh, Mode::Window, 0.0, 0.0, &[2]),
            // Texel points placed by the pilot stage, with and without the vertices'.
            (&open_mesh, Mode::Open, 0.0, 1.0, &[1, 3]),
            (&window_mesh, Mode::Window, 1.0, 0.5, &[2]),
        ];
        for (mesh, mode, adaptive, texel_adaptive, counts) in cases {
            let mesh = mesh.clone();
            let atlas = crate::atlas::Atlas::unwrap(&mesh, 0.1).unwrap();
            let surfaces = crate::bake::Surfaces::resolve(&mesh, &[]).unwrap();
            let scene = crate::trace::Scene::build(&mesh, crate::trace::BuildQuality::Sah).unwrap();
            let params = BakeParams { rays: 16, seed: 4, bounces: 2, mode, store_bounces: true, adaptive, ..BakeParams::default() };
            // The vertices with fewer rays than the texels (`--vertex-rays`).
            let (whole, whole_texels) = crate::bake::texels::bake_texels_for(
                &mesh,
                &scene,
                &surfaces,
                &params,
                atlas.clone(),
                crate::bake::texels::TexelSampling { adaptive: texel_adaptive, ..crate::bake::texels::TexelSampling::uniform(3, 8) },
                None,
            )
            .unwrap();
            assert_eq!(whole_texels.points_added > 0, texel_adaptive > 0.0);
            let texel_key = TexelKey {
                texel_size: atlas.texel_size,
                points_per_texel: 3,
                fractions: false,
                covered_texels: whole_texels.texels.len() as u32,
                atlas_crc: atlas_crc(&atlas),
                vertex_rays: 8,
                adaptive: texel_adaptive,
            };
            let key = key_of(params, Some(texel_key));
            for &count in counts {
                let what = format!("{mode:?}, adaptive {adaptive}, texel adaptive {texel_adaptive}, {count} shards");
                let (merged, texels) = sharded_with(&mesh, &key, count, Some(&atlas));
                assert_eq!(bits(&merged.total), bits(&whole.total), "{what}: vertex total");
                assert_eq!(bits(&merged.front_share), bits(&whole.front_share), "{what}: vertex side shares");
                let t = texels.expect("texel mode merges texels");
                assert!(t.total.iter().any(|&x| x != 0.0), "{what}: the texels hold light");
                assert_eq!(bits(&t.total), bits(&whole_texels.total), "{what}: texel total");
                assert_eq!(t.layers.len(), 3);
                for (a, b) in t.layers.iter().zip(&whole_texels.bounces) {
                    assert_eq!(bits(a), bits(b), "{what}: a texel bounce");
                }
                assert_eq!(bits(&t.noise), bits(&whole_texels.noise), "{what}: texel noise");
                let coeffs = crate::sh::coeff_count(params.order);
                let shares = crate::bake::side_share::front_shares(mode, &t.back_dc, &t.total, whole.channels, coeffs);
                assert_eq!(bits(&shares), bits(&whole_texels.front_share), "{what}: texel side shares");
                assert_eq!(shares.is_empty(), mode == Mode::Open, "{what}: texel sides kept");
                assert_eq!(bits(&t.weights), bits(&whole_texels.covered_area), "{what}: texel weights");
                assert_eq!(
                    (t.points, t.points_rejected, t.rays, t.rays_traced),
                    (whole_texels.points, whole_texels.points_rejected, whole_texels.rays, whole_texels.rays_traced),
                    "{what}: texel counts"
                );
            }
        }
    }

    /// Merged shards give a whole bake's bits (noise estimate included): interior and vertex sampling,
    /// window mode in colour (with and without window sampling) and open
    /// mode in grey, at several shard counts.
    #[test]
    fn merged_shards_equal_a_whole_bake_bit_for_bit() {
        use crate::bake::{bake_transfer, BakeParams, Mode, Sampling};
        use crate::verify::shapes;
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let cases = [
            (shapes::Opening::Window, Mode::Window, Sampling::interior(), false, 2, [1u32, 2, 5].as_slice()),
            (shapes::Opening::Window, Mode::Window, Sampling::interior(), true, 1, &[3]),
            (shapes::Opening::Hole, Mode::Open, Sampling::Vertex, false, 2, &[4]),
        ];
        let adaptive_cases = [
            (shapes::Opening::Window, Mode::Window, Sampling::interior(), false, 2, [1u32, 3, 5].as_slice()),
            (shapes::Opening::Hole, Mode::Open, Sampling::interior(), false, 1, &[2]),
        ];
        let all = cases.iter().map(|c| (*c, 0.0f32)).chain(adaptive_cases.iter().map(|c| (*c, 1.0f32)));
        for ((opening, mode, sampling, window_sampling, bounces, counts), adaptive) in all {
            let (mut mesh, _) = shapes::integrating_sphere(2, 0.6, 0.7, opening);
            if mode == Mode::Window {
                mesh.materials[0].albedo = [0.7, 0.5, 0.3];
            }
            let params =
                BakeParams { rays: 24, bounces, mode, sampling, window_sampling, store_bounces: true, adaptive, ..BakeParams::default() };
            let key = key_of(params, None);
            let surfaces = crate::bake::Surfaces::resolve(&mesh, &[]).unwrap();
            let scene = crate::trace::Scene::build(&mesh, crate::trace::BuildQuality::Sah).unwrap();
            let whole = bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
            assert_eq!(whole.stats.points_added > 0, adaptive > 0.0, "adaptive cases add points");
            for &count in counts {
                let merged = sharded(&mesh, &key, count);
                let what = format!("{mode:?} {sampling:?} adaptive {adaptive}, {count} shards");
                assert_eq!(bits(&merged.total), bits(&whole.total), "{what}: total");
                assert_eq!(merged.bounces.len(), whole.bounces.len());
                for (a, b) in merged.bounces.iter().zip(&whole.bounces) {
                    assert_eq!(bits(a), bits(b), "{what}: a bounce");
                }
                // The noise estimate too (what `--max-error` budgets with), measured with interior sampling.
                assert_eq!(bits(&merged.noise), bits(&whole.noise), "{what}: noise");
                assert_eq!(merged.noise.is_empty(), sampling == Sampling::Vertex, "{what}: noise measured");
                assert_eq!(bits(&merged.front_share), bits(&whole.front_share), "{what}: side shares");
                assert_eq!(merged.front_share.is_empty(), mode == Mode::Open || sampling == Sampling::Vertex, "{what}: sides kept");
                let (m, w) = (&merged.stats, &whole.stats);
                assert_eq!(
                    (
                        m.points,
                        m.points_rejected,
                        m.vertices_without_samples,
                        &m.rays_per_bounce,
                        m.rays,
                        m.rays_gathered,
                        m.window_triangles
                    ),
                    (
                        w.points,
                        w.points_rejected,
                        w.vertices_without_samples,
                        &w.rays_per_bounce,
                        w.rays,
                        w.rays_gathered,
                        w.window_triangles
                    ),
                    "{what}: stats"
                );
            }
        }
    }

    #[test]
    fn mesh_ids_see_every_array() {
        let (mesh, _) = crate::fixtures::cabin::generate_cabin(4.0);
        let id = MeshId::of(&mesh);
        assert_eq!(id, MeshId::of(&mesh.clone()));
        let mut moved = mesh.clone();
        moved.positions[7].x += 1e-6;
        let mut renamed = mesh.clone();
        renamed.groups[0].push('x');
        let mut recoloured = mesh.clone();
        recoloured.materials[0].albedo[1] = 0.5;
        for other in [moved, renamed, recoloured] {
            assert_ne!(MeshId::of(&other), id);
        }
    }
}
