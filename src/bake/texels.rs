//! Texel mode: transfer per texel of a lightmap atlas ([`crate::atlas`])
//! where vertices cannot hold the light. A texel's value is the mean of the
//! transfer over its footprint (`bake::transfer::texels`); the vertex bake
//! runs alongside. From bounce 1 on, vertices and texels alike read the
//! previous bounce at a hit from the texels around it
//! ([`super::texel_lookup`]), so the bounce gather's bias falls with the
//! texel size; the vertices' own rows serve only back sides.

use super::transfer::texels::{denoise_texels, texel_charts, TexelRowsMut, TexelState};
use super::{BakeError, BakeParams, Surfaces, TransferResult};
use crate::atlas::coverage::Coverage;
use crate::atlas::density::ChartDetail;
use crate::atlas::Atlas;
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

/// Sample points per texel by default (spread over its footprint's triangles by area).
pub const POINTS_PER_TEXEL: u32 = 4;

/// Transfer per covered texel of an atlas.
#[derive(Clone, Debug)]
pub struct TexelTransfer {
    pub atlas: Atlas,
    /// The covered texels (`y * width + x`, ascending): one row each below.
    pub texels: Vec<u32>,
    /// Sum of the bounces, `[texel][channel][coeff]`.
    pub total: Vec<f32>,
    /// Each bounce, when `store_bounces`.
    pub bounces: Vec<Vec<f32>>,
    /// The footprint each texel's kept points stood for (texels²; 0: every
    /// point inside geometry, or a texel of nothing).
    pub covered_area: Vec<f32>,
    /// Per texel, the standard error of its DC (channel 0), after `--denoise`.
    pub noise: Vec<f32>,
    /// Window mode: per texel, the share of its light that reached it
    /// through the front of its face (`bake::side_share`); else empty.
    pub front_share: Vec<f32>,
    pub points: u64,
    /// Of `points`, those `--texel-adaptive` added.
    pub points_added: u64,
    pub points_rejected: u64,
    /// Rays evaluated and traced for the texels (the vertices' are in the vertex result).
    pub rays: u64,
    pub rays_traced: u64,
    /// Wall seconds of each bounce's texel pass (not in the vertex result's).
    pub seconds_per_bounce: Vec<f64>,
}

impl TexelTransfer {
    /// Coefficients of covered texel `i` (an index into `texels`), channel `c`.
    pub fn coefficients(&self, i: usize, c: usize, channels: usize, coeffs: usize) -> &[f32] {
        &self.total[(i * channels + c) * coeffs..][..coeffs]
    }
}

/// Bakes `mesh`'s vertices as [`super::bake_transfer`] does, and the texels
/// of `atlas` (unwrapped from `mesh`) with `points_per_texel` points each.
pub fn bake_texels(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    atlas: Atlas,
    points_per_texel: u32,
) -> Result<(TransferResult, TexelTransfer), BakeError> {
    bake_texels_for(mesh, scene, surfaces, params, atlas, TexelSampling::uniform(points_per_texel, params.rays), None)
}

/// How a texel bake samples: points per texel, and where the extras go.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelSampling {
    /// Base points per texel (`--texel-points`).
    pub points: u32,
    /// Rays per vertex sample point (`--vertex-rays`; the texels take `BakeParams::rays`).
    pub vertex_rays: u32,
    /// Extra texel points after bounce 0, as a share of the base points
    /// (`--texel-adaptive`; 0: none).
    pub adaptive: f32,
}

impl TexelSampling {
    /// `points` a texel, none added, `vertex_rays` a vertex point.
    pub fn uniform(points: u32, vertex_rays: u32) -> TexelSampling {
        TexelSampling { points, vertex_rays, adaptive: 0.0 }
    }
}

/// [`bake_texels`] sampled as `sampling` says: `vertex_rays` rays per vertex sample point, the
/// texels keeping `params.rays` (the picture reads the texels; the vertices
/// serve tools that read vertices and, from bounce 1 on, the back sides of
/// faces, so a texel bake may spend fewer rays on them), and with the
/// vertices of the triangles of `receivers` only (`Some(all false)`: the
/// texels alone, as a pilot that reads no vertex needs them).
#[allow(clippy::too_many_arguments)]
pub(crate) fn bake_texels_for(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    atlas: Atlas,
    sampling: TexelSampling,
    receivers: Option<&[bool]>,
) -> Result<(TransferResult, TexelTransfer), BakeError> {
    check_texel_inputs(mesh, &atlas, sampling.points)?;
    if !(0.0..=16.0).contains(&sampling.adaptive) {
        return Err(BakeError::Params(format!(
            "texel adaptive allocation {} is outside 0..=16 (extra points per base point)",
            sampling.adaptive
        )));
    }
    let coverage = Coverage::of(&atlas);
    let mut state = TexelState::new(&atlas, &coverage, sampling.points, sampling.adaptive, params);
    let vertex_params = BakeParams { rays: sampling.vertex_rays, ..*params };
    let result = super::transfer::bake_layers_with_texels(mesh, scene, surfaces, &vertex_params, receivers, None, Some(&mut state))?;
    let coeffs = crate::sh::coeff_count(params.order);
    let front_share = super::side_share::front_shares(params.mode, &state.back_dc, &state.total, result.channels, coeffs);
    if params.denoise > 0.0 {
        state.denoise(result.channels * crate::sh::coeff_count(params.order), params.denoise);
    }
    let texel = TexelTransfer {
        texels: state.texels,
        total: state.total,
        bounces: state.bounces,
        covered_area: state.weights,
        noise: state.noise,
        front_share,
        points: state.points.len() as u64,
        points_added: state.points_added,
        points_rejected: state.rejected.iter().filter(|&&r| r).count() as u64,
        rays: state.rays,
        rays_traced: state.traced,
        seconds_per_bounce: state.seconds,
        atlas,
    };
    Ok((result, texel))
}

/// A pilot texel bake's measure of each chart for [`crate::atlas::density`]:
/// per covered texel, how far its DC (the channels' mean) stands from the
/// mean of its covered 4-neighbours in the same chart, squared, less what the
/// noise of both explains; a texel with fewer than two such neighbours adds
/// nothing. The value is the DC.
pub fn transfer_chart_detail(texels: &TexelTransfer, channels: usize, coeffs: usize) -> ChartDetail {
    let atlas = &texels.atlas;
    let coverage = Coverage::of(atlas);
    let chart = texel_charts(atlas, &coverage);
    let dc = |i: usize| (0..channels).map(|c| f64::from(texels.coefficients(i, c, channels, coeffs)[0])).sum::<f64>() / channels as f64;
    let noise = |i: usize| texels.noise.get(i).map_or(0.0, |&n| f64::from(n));
    let width = atlas.width as i64;
    ChartDetail::from_texels(atlas, &coverage, |i| {
        let id = coverage.texels[i];
        let (x, y) = (i64::from(id) % width, i64::from(id) / width);
        let neighbours: Vec<usize> = [(-1, 0), (1, 0), (0, -1), (0, 1)]
            .iter()
            .map(|&(dx, dy)| (x + dx, y + dy))
            .filter(|&(u, v)| (0..width).contains(&u) && (0..i64::from(atlas.height)).contains(&v))
            .filter_map(|(u, v)| coverage.texels.binary_search(&((v * width + u) as u32)).ok())
            .filter(|&j| chart[j] == chart[i])
            .collect();
        let value = dc(i);
        if neighbours.len() < 2 {
            return (0.0, value * value);
        }
        let m = neighbours.len() as f64;
        let detail = value - neighbours.iter().map(|&j| dc(j)).sum::<f64>() / m;
        let variance = noise(i).powi(2) + neighbours.iter().map(|&j| noise(j).powi(2)).sum::<f64>() / (m * m);
        ((detail * detail - variance).max(0.0), value * value)
    })
}

/// An atlas of `mesh`'s triangles and at least one point per texel.
pub(crate) fn check_texel_inputs(mesh: &Mesh, atlas: &Atlas, points_per_texel: u32) -> Result<(), BakeError> {
    if atlas.triangle_count() != mesh.triangle_count() {
        return Err(BakeError::Params(format!("the atlas has {} triangles, the mesh {}", atlas.triangle_count(), mesh.triangle_count())));
    }
    if points_per_texel == 0 {
        return Err(BakeError::Params("points per texel must be at least 1".into()));
    }
    Ok(())
}

/// Texel mode run in pieces (a sharded bake, `crate::shards`): the atlas's
/// covered texels and their points, made once per process; each shard
/// traces a range of texels in each round.
pub struct TexelTransferPlan {
    pub(crate) state: TexelState,
    /// After [`TexelTransferPlan::grow`]: what round 0 traces of the grown texels.
    pub(crate) growth: Option<super::transfer::texels::Growth>,
}

impl TexelTransferPlan {
    /// The plan of `atlas` (unwrapped from `mesh`) with `points_per_texel`
    /// points a texel and `adaptive` × as many placed by the merged pilot
    /// ([`TexelTransferPlan::grow`]).
    pub fn new(
        mesh: &Mesh,
        atlas: &Atlas,
        points_per_texel: u32,
        adaptive: f32,
        params: &BakeParams,
    ) -> Result<TexelTransferPlan, BakeError> {
        check_texel_inputs(mesh, atlas, points_per_texel)?;
        let coverage = Coverage::of(atlas);
        Ok(TexelTransferPlan { state: TexelState::new(atlas, &coverage, points_per_texel, adaptive, params), growth: None })
    }

    /// `--texel-adaptive`: grows the texels as a whole bake does after its
    /// base pass, from the merged pilot's per-texel sums (Σ w, Σ w·DC, DC
    /// moments); round 0 then traces the base points and the extras of its
    /// range ([`TexelState::trace_grown`]), later rounds the joined set.
    pub fn grow(
        &mut self,
        mesh: &Mesh,
        weights: &[f32],
        dc_sums: &[f32],
        moments: &[[f64; 4]],
        params: &BakeParams,
    ) -> Result<(), BakeError> {
        let n = self.state.texels.len();
        if weights.len() != n || dc_sums.len() != n || moments.len() != n {
            return Err(BakeError::Params(format!("the pilot holds {} texels, the atlas covers {n}", weights.len())));
        }
        let moments: Vec<crate::bake::noise::Moments> = moments.iter().map(|&m| crate::bake::noise::Moments::from_array(m)).collect();
        let dc_sums = dc_sums.iter().map(|&s| f64::from(s)).collect();
        self.growth = self.state.grow(mesh, weights, dc_sums, &moments, params);
        self.state.rejected = vec![false; self.state.points.len()];
        Ok(())
    }

    /// Of the points, those the pilot added.
    pub fn points_added(&self) -> u64 {
        self.state.points_added
    }

    /// The covered texels (`y * width + x`, ascending).
    pub fn texels(&self) -> &[u32] {
        &self.state.texels
    }

    /// Sample points of all covered texels.
    pub fn point_count(&self) -> u64 {
        self.state.points.len() as u64
    }
}

/// `--denoise K` over a texel transfer summed elsewhere (a sharded bake's
/// merge): the filter [`bake_texels`] runs, each texel's chart read from
/// the atlas. `stride` is channels × coefficients.
pub fn denoise_texel_transfer(texels: &mut TexelTransfer, stride: usize, k: f32) -> Result<(), BakeError> {
    let coverage = Coverage::of(&texels.atlas);
    if coverage.texels != texels.texels {
        return Err(BakeError::Params(format!("{} texels are not the {} the atlas covers", texels.texels.len(), coverage.texels.len())));
    }
    let chart = texel_charts(&texels.atlas, &coverage);
    let rows = TexelRowsMut { total: &mut texels.total, bounces: &mut texels.bounces, noise: &mut texels.noise };
    denoise_texels(&texels.texels, texels.atlas.width, &chart, &texels.covered_area, rows, stride, k);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atlas::coverage::clip_to_texel;
    use crate::trace::BuildQuality;
    use crate::verify::{plane_point_reference, shapes, Y00};
    use glam::{DVec3, Vec3};

    fn bake(mesh: &Mesh, params: &BakeParams, texel_size: f32, points: u32) -> (TransferResult, TexelTransfer) {
        bake_sampled(mesh, params, texel_size, TexelSampling::uniform(points, params.rays))
    }

    fn bake_sampled(mesh: &Mesh, params: &BakeParams, texel_size: f32, sampling: TexelSampling) -> (TransferResult, TexelTransfer) {
        let surfaces = Surfaces::resolve(mesh, &[]).unwrap();
        let scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
        let atlas = Atlas::unwrap(mesh, texel_size).unwrap();
        bake_texels_for(mesh, &scene, &surfaces, params, atlas, sampling, None).unwrap()
    }

    /// The plane under a sphere (`radius` at `height`) and the exact
    /// transfer of each plane texel wholly clear of the horizon, averaged
    /// over its footprint (a 4 × 4 grid in each clipped triangle part).
    struct PlaneUnderSphere {
        mesh: Mesh,
        order: usize,
        /// Covered texel index and its exact coefficients.
        references: Vec<(usize, Vec<f64>)>,
    }

    impl PlaneUnderSphere {
        fn new(order: usize, texel_size: f32, radius: f32, height: f32) -> PlaneUnderSphere {
            let mut mesh = shapes::plane_grid(8, 4.0);
            let plane_triangles = mesh.triangle_count();
            let mut sphere = shapes::icosphere(4);
            shapes::transform(&mut sphere, radius, Vec3::new(0.0, height, 0.0));
            shapes::append(&mut mesh, &sphere);
            let centre = DVec3::new(0.0, height as f64, 0.0);
            let effective_radius = radius as f64 * (1.0 + (1.0 - 0.001)) / 2.0;
            let coeffs = crate::sh::coeff_count(order);
            let atlas = Atlas::unwrap(&mesh, texel_size).unwrap();
            let coverage = Coverage::of(&atlas);
            let mut references: Vec<(usize, Vec<f64>)> = Vec::new();
            for i in 0..coverage.len() {
                let entries = coverage.start[i] as usize..coverage.start[i + 1] as usize;
                if entries.clone().any(|e| coverage.triangle[e] as usize >= plane_triangles) {
                    continue;
                }
                let (x, y) = (coverage.texels[i] % atlas.width, coverage.texels[i] / atlas.width);
                let mut reference = vec![0.0f64; coeffs];
                let (mut area, mut above) = (0.0f64, true);
                for e in entries {
                    let t = coverage.triangle[e] as usize;
                    let uv = atlas.triangle_uv(t).map(|p| p.as_dvec2());
                    let polygon = clip_to_texel(atlas.triangle_uv(t), x, y);
                    let part = crate::atlas::coverage::polygon_area(&polygon);
                    let (lo, hi) = polygon.iter().fold((polygon[0], polygon[0]), |(l, h), &p| (l.min(p), h.max(p)));
                    let det = (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]);
                    let [pa, pb, pc] = mesh.triangle_positions(t).map(|q| q.as_dvec3());
                    let samples: Vec<DVec3> = (0..16)
                        .map(|k| lo + (hi - lo) * glam::DVec2::new(((k % 4) as f64 + 0.5) / 4.0, ((k / 4) as f64 + 0.5) / 4.0))
                        .filter(|&p| polygon_contains(&polygon, p))
                        .map(|p| {
                            let l1 = (p - uv[0]).perp_dot(uv[2] - uv[0]) / det;
                            let l2 = (uv[1] - uv[0]).perp_dot(p - uv[0]) / det;
                            pa * (1.0 - l1 - l2) + pb * l1 + pc * l2
                        })
                        .collect();
                    for x in &samples {
                        let to_centre = centre - *x;
                        let alpha = (effective_radius / to_centre.length()).asin();
                        let beta = to_centre.normalize().dot(DVec3::Y).acos();
                        above &= alpha + beta <= 88f64.to_radians();
                        let r = plane_point_reference(order, *x, centre, effective_radius);
                        let w = part / samples.len() as f64;
                        reference.iter_mut().zip(&r).for_each(|(s, r)| *s += w * r);
                    }
                    area += if samples.is_empty() { 0.0 } else { part };
                }
                if above && area > 0.0 {
                    references.push((i, reference.iter().map(|r| r / area).collect()));
                }
            }
            PlaneUnderSphere { mesh, order, references }
        }

        /// The largest DC error and the RMS error over all coefficients, of the texels compared.
        fn errors(&self, texels: &TexelTransfer) -> (f64, f64) {
            let coeffs = crate::sh::coeff_count(self.order);
            let (mut max_dc, mut sum_sq) = (0.0f64, 0.0f64);
            for (i, reference) in &self.references {
                let got = texels.coefficients(*i, 0, 1, coeffs);
                for k in 0..coeffs {
                    let e = got[k] as f64 - reference[k];
                    sum_sq += e * e;
                    if k == 0 {
                        max_dc = max_dc.max(e.abs());
                    }
                }
            }
            (max_dc, (sum_sq / (self.references.len() * coeffs) as f64).sqrt())
        }

        /// The RMS error of the DC alone.
        fn dc_rms(&self, texels: &TexelTransfer) -> f64 {
            let coeffs = crate::sh::coeff_count(self.order);
            let sum_sq: f64 = self.references.iter().map(|(i, r)| (texels.coefficients(*i, 0, 1, coeffs)[0] as f64 - r[0]).powi(2)).sum();
            (sum_sq / self.references.len() as f64).sqrt()
        }
    }

    /// The plane under a sphere (radius 0.5 at height 1): each plane texel's
    /// coefficients against the exact transfer averaged over the same
    /// footprint (a 4 × 4 grid in each clipped triangle part), where the
    /// occluder's cap stays above the horizon; the error falls with rays.
    #[test]
    fn texel_transfer_under_a_sphere_converges_to_the_closed_form_per_texel() {
        let scene = PlaneUnderSphere::new(3, 0.1, 0.5, 1.0);
        let bake_at = |rays: u32| {
            let params = BakeParams { order: scene.order, rays, seed: 5, adaptive: 0.0, ..BakeParams::default() };
            bake(&scene.mesh, &params, 0.1, 4).1
        };
        let (coarse, fine) = (bake_at(32), bake_at(512));
        assert_eq!(coarse.atlas, fine.atlas, "the same mesh unwraps the same");
        assert_eq!(Coverage::of(&fine.atlas).texels, fine.texels);
        assert!(scene.references.len() > 500, "{} plane texels compared", scene.references.len());
        let ((coarse_dc, coarse_rms), (fine_dc, fine_rms)) = (scene.errors(&coarse), scene.errors(&fine));
        eprintln!("32 rays: DC max {coarse_dc:.2e}, RMS {coarse_rms:.2e}; 512 rays: DC max {fine_dc:.2e}, RMS {fine_rms:.2e}");
        // 4 points × 512 rays a texel: RMS within the vertex check's 1.5e-3; the
        // largest DC error of ~1,000 texels within 3e-3 (the vertex check: 2e-3 at 1,024 rays).
        assert!(fine_dc < 3e-3 && fine_rms < 1.5e-3, "DC max {fine_dc}, RMS {fine_rms}");
        assert!(fine_rms < 0.5 * coarse_rms, "RMS {fine_rms} at 512 rays against {coarse_rms} at 32");
    }

    /// Under the sphere only the texels that see part of it have a noisy DC
    /// (the open sky's DC is the same on every ray): `--texel-adaptive`
    /// puts its points there. At the same points in all (1 a texel and as
    /// many more placed as 2 a texel add, against 2 a texel), the DC's RMS error against the
    /// closed form falls, and the texels converge as a uniform bake does.
    #[test]
    fn adaptive_texel_points_lower_the_error_where_the_sphere_shadows() {
        // A small, low sphere: its shadow's noise is near it; the far plane
        // sees it at a sliver of its sky.
        let scene = PlaneUnderSphere::new(2, 0.1, 0.2, 0.3);
        let run = |rays: u32, sampling: TexelSampling| {
            let params = BakeParams { order: scene.order, rays, seed: 5, adaptive: 0.0, ..BakeParams::default() };
            bake_sampled(&scene.mesh, &params, 0.1, sampling).1
        };
        let uniform = run(16, TexelSampling::uniform(2, 16));
        let base = run(16, TexelSampling::uniform(1, 16));
        // Every footprint part takes a point: 1 a texel is more than half of 2.
        let share = (uniform.points - base.points) as f32 / base.points as f32;
        let adaptive = run(16, TexelSampling { adaptive: share, ..TexelSampling::uniform(1, 16) });
        assert_eq!(uniform.texels, adaptive.texels);
        assert!(adaptive.points_added > 0 && adaptive.points_added <= base.points, "{} added to {}", adaptive.points_added, base.points);
        assert_eq!(adaptive.points, base.points + adaptive.points_added);
        assert!(adaptive.points <= uniform.points, "{} points against {}", adaptive.points, uniform.points);
        let (uniform_dc, adaptive_dc) = (scene.dc_rms(&uniform), scene.dc_rms(&adaptive));
        eprintln!("DC RMS: 2 points a texel {uniform_dc:.3e}, 1 and adaptive {adaptive_dc:.3e}, 1 {:.3e}", scene.dc_rms(&base));
        assert!(adaptive_dc < 0.85 * uniform_dc, "DC RMS {adaptive_dc} adaptive against {uniform_dc} uniform");
        let fine = run(512, TexelSampling { adaptive: 1.0, ..TexelSampling::uniform(2, 512) });
        let (fine_dc, fine_rms) = scene.errors(&fine);
        assert!(fine_dc < 3e-3 && fine_rms < 1.5e-3, "DC max {fine_dc}, RMS {fine_rms}");
    }

    /// With extra texel points, later bounces gather bounce 0's hit records
    /// (reordered with the points) to the same bits as re-tracing them, on
    /// any thread count, and the integrating sphere's series holds.
    #[test]
    fn adaptive_texel_bounces_gather_what_they_retrace() {
        let (albedo, cap) = (0.6f32, 0.8f32);
        let (mesh, f) = shapes::integrating_sphere(3, albedo, cap, shapes::Opening::Hole);
        let sampling = TexelSampling { adaptive: 1.0, ..TexelSampling::uniform(2, 64) };
        let run = |threads: usize, hit_cache_bytes: u64| {
            let params =
                BakeParams { order: 1, rays: 64, seed: 3, bounces: 2, store_bounces: true, hit_cache_bytes, ..BakeParams::default() };
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| bake_sampled(&mesh, &params, 0.05, sampling).1)
        };
        let cached = run(2, BakeParams::default().hit_cache_bytes);
        assert!(cached.points_added > 0);
        let bits = |t: &TexelTransfer| t.bounces.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&run(2, 0)), bits(&cached), "re-traced against gathered");
        assert_eq!(bits(&run(1, BakeParams::default().hit_cache_bytes)), bits(&cached), "one thread against two");
        assert_texels_follow_the_series(&cached, albedo, f);
    }

    fn polygon_contains(polygon: &[glam::DVec2], p: glam::DVec2) -> bool {
        let n = polygon.len();
        let sign = |i: usize| (polygon[(i + 1) % n] - polygon[i]).perp_dot(p - polygon[i]);
        let first = sign(0);
        (0..n).all(|i| sign(i) * first >= -1e-12)
    }

    /// An integrating sphere (open cap): every wall texel's DC per bounce is
    /// y00·f·(ρ(1 − f))^b, whatever its place; bounces read the texels'
    /// previous bounce.
    #[test]
    fn texel_bounces_in_an_integrating_sphere_match_the_series() {
        let (albedo, cap) = (0.6f32, 0.8f32);
        let (mesh, f) = shapes::integrating_sphere(3, albedo, cap, shapes::Opening::Hole);
        let params = BakeParams { order: 1, rays: 64, seed: 3, bounces: 2, store_bounces: true, ..BakeParams::default() };
        let (_, texels) = bake(&mesh, &params, 0.05, 4);
        assert_texels_follow_the_series(&texels, albedo, f);
    }

    /// Each stored bounce b of an order-1 texel bake of the integrating
    /// sphere: its area-weighted mean DC is y00·f·(ρ(1 − f))^b within 1.5%.
    fn assert_texels_follow_the_series(texels: &TexelTransfer, albedo: f32, f: f64) {
        let coeffs = crate::sh::coeff_count(1);
        let channels = texels.total.len() / texels.texels.len() / coeffs;
        let area: f64 = texels.covered_area.iter().map(|&a| a as f64).sum();
        for (b, layer) in texels.bounces.iter().enumerate() {
            let mean: f64 =
                (0..texels.texels.len()).map(|i| texels.covered_area[i] as f64 * layer[i * channels * coeffs] as f64).sum::<f64>() / area;
            let expected = Y00 * f * (albedo as f64 * (1.0 - f)).powi(b as i32);
            assert!((mean / expected - 1.0).abs() < 0.015, "bounce {b}: texel mean {mean}, expected {expected}");
        }
    }

    /// Fewer rays per vertex point (`--vertex-rays`) leave the texels' bounce 0
    /// the same bits (it reads no vertex), cut the vertices' rays in the same
    /// ratio, and keep the texels' bounces on the integrating sphere's series
    /// (they read texels at hits; vertices only on back sides).
    #[test]
    fn fewer_vertex_rays_leave_the_texels_bounce_zero_and_series() {
        let (albedo, cap) = (0.6f32, 0.8f32);
        let (mesh, f) = shapes::integrating_sphere(3, albedo, cap, shapes::Opening::Hole);
        let params = BakeParams { order: 1, rays: 64, seed: 3, bounces: 2, store_bounces: true, ..BakeParams::default() };
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let atlas = Atlas::unwrap(&mesh, 0.05).unwrap();
        let run = |vertex_rays: u32| {
            bake_texels_for(&mesh, &scene, &surfaces, &params, atlas.clone(), TexelSampling::uniform(4, vertex_rays), None).unwrap()
        };
        let ((all_v, all_t), (few_v, few_t)) = (run(64), run(8));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&few_t.bounces[0]), bits(&all_t.bounces[0]), "the texels' bounce 0");
        assert_eq!(few_t.rays, all_t.rays);
        assert_eq!(few_v.stats.points, all_v.stats.points);
        assert_eq!(few_v.stats.rays_per_bounce[0] * 8, all_v.stats.rays_per_bounce[0]);
        assert_ne!(bits(&few_v.total), bits(&all_v.total), "the vertices took other rays");
        assert_texels_follow_the_series(&few_t, albedo, f);
    }

    /// The same texel bake on one thread and on two is the same bytes.
    #[test]
    fn texel_bakes_do_not_depend_on_the_thread_count() {
        let mut mesh = shapes::plane_grid(4, 2.0);
        let mut sphere = shapes::icosphere(2);
        shapes::transform(&mut sphere, 0.3, Vec3::new(0.2, 0.5, 0.0));
        shapes::append(&mut mesh, &sphere);
        let params = BakeParams { order: 2, rays: 16, seed: 9, bounces: 1, ..BakeParams::default() };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| bake(&mesh, &params, 0.05, 3).1)
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one.texels, two.texels);
        assert_eq!(one.total.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), two.total.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        assert!(one.total.iter().any(|&x| x != 0.0));
    }
}
