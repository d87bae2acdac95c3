//! Texel density per chart for a bake (`--texel-levels`): a pilot bake on
//! an atlas at the coarsest size measures each chart
//! ([`crate::atlas::density`]), the budget picks each chart's level, and the
//! pilot's charts are repacked at those sizes for the bake itself.
//!
//! The pilot is cheap by construction: `2^(levels-1)` times coarser texels
//! on a side, a quarter of the rays and bounce 0 only for transfer (where
//! the light's edges are, and no vertex), and for the sun 4 points a texel, enough to see an
//! edge cross it.

use std::time::Instant;

use glam::Vec3;

use super::texel_sun::sun_chart_detail;
use super::texels::{bake_texels_for, transfer_chart_detail};
use super::{BakeError, BakeParams, DirectionPattern, SunParams, Surfaces, TexelSunPlan};
use crate::atlas::density::{choose_levels, ChartDetail, DensityChoice, MAX_LEVELS};
use crate::atlas::Atlas;
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

/// Points per pilot texel of a sun pilot: enough to see that an edge
/// crosses it (a lit share strictly between 0 and 1), a quarter of the
/// final bake's points at one point per finest texel and three levels.
const SUN_PILOT_POINTS: u32 = 4;

/// `--texel-levels N` with its budget.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensityRequest {
    /// Texel sizes `L … 2^(levels-1) L` (2 ..= [`MAX_LEVELS`]).
    pub levels: u32,
    /// Largest estimated relative L2 error of the texels' resolution.
    pub budget: f64,
}

/// What a density choice did (the bundle's META `texels.density`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DensityReport {
    pub levels: u32,
    pub budget: f64,
    /// What the estimate measures.
    pub norm: &'static str,
    pub pilot_texel_size: f32,
    pub pilot_covered: usize,
    pub pilot_rays: u64,
    pub pilot_seconds: f64,
    pub charts: u32,
    pub charts_per_level: Vec<u32>,
    pub estimated_error: f64,
    pub coarsest_error: f64,
    pub texel_area: f64,
    pub finest_texel_area: f64,
    /// Per chart of the pilot's atlas, its level ([`DensityChoice::levels`]):
    /// what a sharded bake's later rounds repack the pilot's atlas by
    /// ([`atlas_at_levels`]); not in the bundle.
    #[serde(skip)]
    pub chart_levels: Vec<u8>,
}

impl DensityReport {
    /// The bundle's record of the choice: the report without its seconds,
    /// so that the same bake gives the same bytes.
    pub fn meta(&self) -> serde_json::Value {
        let mut meta = serde_json::to_value(self).unwrap_or_default();
        if let Some(m) = meta.as_object_mut() {
            m.remove("pilot_seconds");
        }
        meta
    }

    /// One line for a command's report.
    pub fn summary(&self) -> String {
        let finest = self.pilot_texel_size / (1u32 << (self.levels - 1)) as f32;
        format!(
            "texel density: {} sizes {}..{} m; charts per size, coarsest first: {:?} of {}; estimated resolution error {:.2}% ({:.2}% all coarsest; budget {:.2}%, {}), {:.0} texels ({:.0} all finest); pilot: {} texels, {} rays, {:.2}s",
            self.levels,
            finest,
            self.pilot_texel_size,
            self.charts_per_level,
            self.charts,
            100.0 * self.estimated_error,
            100.0 * self.coarsest_error,
            100.0 * self.budget,
            self.norm,
            self.texel_area,
            self.finest_texel_area,
            self.pilot_covered,
            self.pilot_rays,
            self.pilot_seconds
        )
    }
}

impl DensityRequest {
    pub fn check(&self) -> Result<(), BakeError> {
        if !(2..=MAX_LEVELS).contains(&self.levels) {
            return Err(BakeError::Params(format!("texel levels {}: expected 2..={MAX_LEVELS}", self.levels)));
        }
        if !(self.budget.is_finite() && self.budget >= 0.0) {
            return Err(BakeError::Params(format!("texel budget {}: expected a finite error ≥ 0", self.budget)));
        }
        Ok(())
    }

    /// The pilot's texel size for finest size `finest`.
    pub fn pilot_size(&self, finest: f32) -> f32 {
        finest * (1u32 << (self.levels - 1)) as f32
    }

    fn report(
        &self,
        pilot: &Atlas,
        covered: usize,
        rays: u64,
        started: Instant,
        choice: &DensityChoice,
        norm: &'static str,
    ) -> DensityReport {
        DensityReport {
            levels: self.levels,
            budget: self.budget,
            norm,
            pilot_texel_size: pilot.texel_size,
            pilot_covered: covered,
            pilot_rays: rays,
            pilot_seconds: started.elapsed().as_secs_f64(),
            charts: pilot.chart_count,
            charts_per_level: choice.charts_per_level.clone(),
            estimated_error: choice.estimated_error,
            coarsest_error: choice.coarsest_error,
            texel_area: choice.texel_area,
            finest_texel_area: choice.finest_texel_area,
            chart_levels: choice.levels.clone(),
        }
    }
}

fn unwrap_pilot(mesh: &Mesh, finest: f32, request: &DensityRequest) -> Result<Atlas, BakeError> {
    request.check()?;
    // Every chart may end at the finest size: refused where a uniform atlas at it would be.
    Atlas::check_texel_count(mesh, finest).map_err(|e| BakeError::Params(e.to_string()))?;
    Atlas::unwrap(mesh, request.pilot_size(finest)).map_err(|e| BakeError::Params(format!("pilot atlas: {e}")))
}

/// The atlas a transfer density choice of `levels` made (per chart of the
/// pilot's atlas, [`DensityReport::chart_levels`]), without the pilot's
/// bake: the pilot's atlas unwrapped again and repacked. A sharded bake's
/// later rounds, which trace nothing, make their atlas so.
pub fn atlas_at_levels(mesh: &Mesh, finest: f32, request: &DensityRequest, levels: &[u8]) -> Result<Atlas, BakeError> {
    let pilot = unwrap_pilot(mesh, finest, request)?;
    if levels.len() != pilot.chart_count as usize || levels.iter().any(|&l| u32::from(l) >= request.levels) {
        return Err(BakeError::Params(format!(
            "{} chart levels for a pilot atlas of {} charts at {} levels",
            levels.len(),
            pilot.chart_count,
            request.levels
        )));
    }
    pilot.with_chart_scales(levels).map_err(|e| BakeError::Params(format!("repacking the atlas: {e}")))
}

fn repack(pilot: &Atlas, detail: &ChartDetail, request: &DensityRequest) -> Result<(Atlas, DensityChoice), BakeError> {
    let choice = choose_levels(detail, request.levels, request.budget);
    let atlas = pilot.with_chart_scales(&choice.levels).map_err(|e| BakeError::Params(format!("repacking the atlas: {e}")))?;
    Ok((atlas, choice))
}

/// The atlas of a transfer bake with texels no finer than `finest`, each
/// chart's size picked by a transfer pilot (`points_per_texel` points a
/// pilot texel, `params` with a quarter of the rays, bounce 0).
pub fn transfer_density_atlas(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    finest: f32,
    points_per_texel: u32,
    request: &DensityRequest,
) -> Result<(Atlas, DensityReport), BakeError> {
    let started = Instant::now();
    let pilot_atlas = unwrap_pilot(mesh, finest, request)?;
    let pilot_params = BakeParams {
        rays: (params.rays / 4).clamp(16.min(params.rays), params.rays),
        bounces: 0,
        store_bounces: false,
        adaptive: 0.0,
        denoise: 0.0,
        quiet: true,
        ..*params
    };
    // Bounce 0 of the texels reads no vertex: the pilot bakes none.
    let no_vertices = vec![false; mesh.triangle_count()];
    let (vertices, pilot) = bake_texels_for(
        mesh,
        scene,
        surfaces,
        &pilot_params,
        pilot_atlas.clone(),
        super::texels::TexelSampling::uniform(points_per_texel, pilot_params.rays),
        Some(&no_vertices),
    )?;
    let detail = transfer_chart_detail(&pilot, vertices.channels, crate::sh::coeff_count(vertices.order));
    let (atlas, choice) = repack(&pilot_atlas, &detail, request)?;
    let report = request.report(
        &pilot_atlas,
        pilot.texels.len(),
        pilot.rays_traced,
        started,
        &choice,
        "relative L2 over texels of the transfer's DC (channel mean), by area",
    );
    Ok((atlas, report))
}

/// The atlas of a texel sun bake with texels no finer than `finest`, each
/// chart's size picked by a sun pilot ([`SUN_PILOT_POINTS`] points a pilot
/// texel, the same suns).
pub fn sun_density_atlas(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    params: &SunParams,
    finest: f32,
    request: &DensityRequest,
    charts_from: Option<&Atlas>,
) -> Result<(Atlas, DensityReport), BakeError> {
    let started = Instant::now();
    // Beside a texel transfer's atlas the pilot repacks its charts when the sizes allow, instead of unwrapping anew.
    let repacked = charts_from.and_then(|a| a.with_texel_size(request.pilot_size(finest)));
    let pilot_atlas = match repacked {
        Some(atlas) => {
            request.check()?;
            Atlas::check_texel_count(mesh, finest).map_err(|e| BakeError::Params(e.to_string()))?;
            atlas.map_err(|e| BakeError::Params(format!("pilot atlas: {e}")))?
        }
        None => unwrap_pilot(mesh, finest, request)?,
    };
    let quiet = SunParams { quiet: true, ..*params };
    let plan = TexelSunPlan::new(mesh, &pilot_atlas, SUN_PILOT_POINTS, DirectionPattern::Sobol, suns, &quiet)?;
    let traced = plan.trace(mesh, scene, surfaces, 0..plan.texel_count());
    let masks = plan.finish(traced, 0.0);
    let detail = sun_chart_detail(&masks, &pilot_atlas, suns.len());
    let (atlas, choice) = repack(&pilot_atlas, &detail, request)?;
    let report = request.report(
        &pilot_atlas,
        masks.texels.len(),
        masks.stats.rays,
        started,
        &choice,
        "relative L2 over texels and steps of the lit share, by area",
    );
    Ok((atlas, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::texels::bake_texels;
    use crate::bake::Mode;
    use crate::trace::BuildQuality;
    use crate::verify::shapes;

    /// A 2 m floor under a 0.5 m roof 0.3 m up, and a 1 m board 5 m away
    /// with nothing around it; the number of the floor's and the roof's triangles.
    fn floor_roof_and_board() -> (Mesh, usize, usize) {
        let mut mesh = shapes::plane_grid(4, 2.0);
        let floor = mesh.triangle_count();
        let mut roof = shapes::plane_grid(1, 0.5);
        shapes::transform(&mut roof, 1.0, Vec3::new(0.0, 0.3, 0.0));
        shapes::append(&mut mesh, &roof);
        let roof_end = mesh.triangle_count();
        let mut board = shapes::plane_grid(2, 1.0);
        shapes::transform(&mut board, 1.0, Vec3::new(5.0, 0.0, 0.0));
        shapes::append(&mut mesh, &board);
        (mesh, floor, roof_end)
    }

    /// World units per texel of triangle `t` in `atlas`.
    fn texel_size_of(mesh: &Mesh, atlas: &Atlas, t: usize) -> f64 {
        let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
        let world = 0.5 * (b - a).cross(c - a).length();
        let [p, q, r] = atlas.triangle_uv(t);
        (world / (0.5 * f64::from((q - p).perp_dot(r - p).abs()))).sqrt()
    }

    /// Under the sun, only the floor has texels a shadow edge crosses: with
    /// no error allowed, the roof and the board (always wholly lit by day)
    /// stay at the pilot's 0.1 m, and the floor's chart goes to the finest
    /// 0.025 m where the roof's shadow falls; the estimate halves (two
    /// halvings of the only chart with error).
    #[test]
    fn the_sun_pilot_refines_the_chart_a_shadow_edge_crosses_and_leaves_the_evenly_lit_ones_coarse() {
        let (mesh, floor, roof_end) = floor_roof_and_board();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let suns = [Some(Vec3::new(0.35, 1.0, -0.2).normalize()), Some(Vec3::new(-0.6, 0.8, 0.1).normalize()), None];
        let params = SunParams { mode: Mode::Open, seed: 3, ..SunParams::default() };
        let request = DensityRequest { levels: 3, budget: 0.0 };
        let (atlas, report) = sun_density_atlas(&mesh, &scene, &surfaces, &suns, &params, 0.025, &request, None).unwrap();
        assert_eq!(report.pilot_texel_size, 0.1);
        assert!(report.coarsest_error > 0.0 && (report.estimated_error - report.coarsest_error / 2.0).abs() < 1e-9, "{report:?}");
        for t in floor..mesh.triangle_count() {
            let size = texel_size_of(&mesh, &atlas, t);
            assert!((size / 0.1 - 1.0).abs() < 0.15, "roof or board triangle {t} at {size} m texels, not the pilot's 0.1");
        }
        let finest = (0..floor).filter(|&t| (texel_size_of(&mesh, &atlas, t) / 0.025 - 1.0).abs() < 0.15).count();
        let floor_charts: std::collections::BTreeSet<u32> = (0..floor).map(|t| atlas.triangle_chart[t]).collect();
        assert!(finest > 0 && floor_charts.iter().all(|c| !(floor..roof_end).any(|t| atlas.triangle_chart[t] == *c)));
        // Same inputs, same atlas.
        assert_eq!(atlas, sun_density_atlas(&mesh, &scene, &surfaces, &suns, &params, 0.025, &request, None).unwrap().0);
    }

    /// The transfer pilot's detail: the floor under the roof (its contact
    /// shadow) carries nearly all of it per unit of area, the lone board,
    /// whose transfer is even, next to none once the noise is taken off.
    #[test]
    fn the_transfer_pilot_finds_the_contact_shadow_and_not_the_noise() {
        let (mesh, floor, _) = floor_roof_and_board();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let params = BakeParams { order: 2, rays: 64, seed: 5, bounces: 0, adaptive: 0.0, ..BakeParams::default() };
        let pilot = Atlas::unwrap(&mesh, 0.1).unwrap();
        let (vertices, texels) = bake_texels(&mesh, &scene, &surfaces, &params, pilot.clone(), 4).unwrap();
        let detail = transfer_chart_detail(&texels, vertices.channels, 4);
        let chart_of = |t: usize| pilot.triangle_chart[t] as usize;
        let per_area = |c: usize| detail.error[c] / detail.area[c].max(1e-9);
        let floor_detail = (0..floor).map(chart_of).map(per_area).fold(0.0, f64::max);
        let board_detail = (mesh.triangle_count() - 8..mesh.triangle_count()).map(chart_of).map(per_area).fold(0.0, f64::max);
        assert!(floor_detail > 20.0 * board_detail.max(1e-12), "floor {floor_detail}, board {board_detail}");
        let request = DensityRequest { levels: 2, budget: 0.0 };
        let (atlas, report) = transfer_density_atlas(&mesh, &scene, &surfaces, &params, 0.05, 4, &request).unwrap();
        assert_eq!(report.pilot_texel_size, 0.1);
        let fine = (0..floor).filter(|&t| (texel_size_of(&mesh, &atlas, t) / 0.05 - 1.0).abs() < 0.15).count();
        assert!(fine > 0, "no floor triangle at the finest size");
    }
}
