//! The LCD panel's final-gathered texture in the viewer (seed 000
//! §3.1, §4.3; docs/viewer.md "The panel"): the panel's triangles are drawn
//! with their PRT shading plus, per texel of the panel's [`PanelLayout`], the
//! reflected radiance that [`crate::panel::PanelGather`] gathered from the
//! viewer's eye under the viewer's light (same units as the PRT shading).
//!
//! The gather is progressive: pass 1 takes [`FIRST_PASS_SAMPLES`] per texel (a
//! rough image), each later pass doubles the total, at most
//! [`MAX_PASS_INCREMENT`] more per pass, so a moving eye waits for at most one
//! short pass before the gather restarts ([`super::panel_worker`]).

use glam::{Vec2, Vec3};

use super::backdrop::{Backdrop, SkyBackdrop};
use super::layers::LayerSelection;
use super::FrameSettings;
use crate::bake::Surfaces;
use crate::brdf::PanelBrdf;
use crate::bundle::{Bundle, Transfer};
use crate::mesh::Mesh;
use crate::panel::{layout, select_panel, Environment, GatherOptions, Interior, Light, PanelGather, PanelLayout, Sun, TexelResult};
use crate::sh::EquirectImage;
use crate::sky::preetham::PreethamSky;
use crate::trace::{BuildQuality, Scene};

/// Texels along the panel's long side (square texels): 128 × 64 on the demo's LCD.
pub const TEXELS_LONG_SIDE: u32 = 128;
/// Samples per texel of the first, rough pass.
pub const FIRST_PASS_SAMPLES: u32 = 2;
/// Most samples a pass adds (bounds how long a moving eye waits for a restart).
pub const MAX_PASS_INCREMENT: u32 = 32;
/// Samples per texel at which the interactive viewer stops refining.
pub const INTERACTIVE_SAMPLES: u32 = 256;

/// Samples per texel after `passes` passes: 2, 4, 8, 16, 32, 64, 96, 128, …
/// (0 for no pass), at most [`crate::panel::gather::MAX_SAMPLES`].
pub fn samples_after(passes: u32) -> u32 {
    let mut samples = 0u32;
    for pass in 0..passes {
        samples = if pass == 0 { FIRST_PASS_SAMPLES } else { samples + samples.min(MAX_PASS_INCREMENT) };
        if samples >= crate::panel::gather::MAX_SAMPLES {
            return crate::panel::gather::MAX_SAMPLES;
        }
    }
    samples
}

/// Passes until `samples` per texel are reached (the screenshot default is [`INTERACTIVE_SAMPLES`]'s: 12).
pub fn passes_for(samples: u32) -> u32 {
    (1..=crate::panel::gather::MAX_SAMPLES).find(|&p| samples_after(p) >= samples.min(crate::panel::gather::MAX_SAMPLES)).unwrap_or(1)
}

/// Which triangles are the panel and how texels lie over them.
#[derive(Clone, Debug)]
pub struct PanelMapping {
    /// Mesh triangles of the panel, ascending.
    pub triangles: Vec<u32>,
    pub layout: PanelLayout,
}

impl PanelMapping {
    /// The panel of `mesh`: triangles whose material or group matches `pattern`, or
    /// the panel-role materials when `None`; texels `texels` or [`TEXELS_LONG_SIDE`]
    /// along the long side. `Ok(None)` when no pattern was given and no material has the panel role.
    pub fn find(
        mesh: &Mesh,
        pattern: Option<&str>,
        texels: Option<(u32, u32)>,
        path: &std::path::Path,
    ) -> Result<Option<PanelMapping>, String> {
        let triangles = match select_panel(mesh, pattern, path) {
            Ok(t) => t,
            Err(crate::panel::PanelError::NoPanel { .. }) if pattern.is_none() => return Ok(None),
            Err(e) => return Err(e.to_string()),
        };
        let (width, height) = texels.unwrap_or_else(|| layout::default_texels(mesh, &triangles, TEXELS_LONG_SIDE));
        let layout = PanelLayout::new(mesh, &triangles, width, height, path).map_err(|e| e.to_string())?;
        Ok(Some(PanelMapping { triangles, layout }))
    }

    /// The texture coordinate of mesh vertex `v`: its place on the texel grid over (W, H), in [0,1]².
    pub fn texcoord(&self, mesh: &Mesh, v: u32) -> [f32; 2] {
        let texel = self.layout.texel_coord(mesh, v);
        [texel.x / self.layout.width as f32, texel.y / self.layout.height as f32]
    }
}

/// The panel's reflected radiance per texel, linear RGB, row-major (row 0 at the top).
#[derive(Clone, Debug, PartialEq)]
pub struct PanelTexture {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    /// Samples per texel behind it (0: a black texture).
    pub samples: u32,
    /// The request it answers ([`PanelRequest::generation`]).
    pub generation: u64,
}

impl PanelTexture {
    pub fn black(width: u32, height: u32) -> PanelTexture {
        PanelTexture { width, height, rgb: vec![[0.0; 3]; width as usize * height as usize], samples: 0, generation: 0 }
    }

    /// The texture of a gather's results. A texel whose centre misses the panel
    /// takes the value of a neighbour that has one (repeatedly: left, right, up,
    /// down), so that pixels along the panel's edge, whose coordinate falls in
    /// such a texel, show the nearby reflection rather than black.
    pub fn from_results(results: &[Option<TexelResult>], width: u32, height: u32, samples: u32) -> PanelTexture {
        let (w, h) = (width as usize, height as usize);
        let mut rgb: Vec<Option<[f32; 3]>> = results.iter().map(|r| r.map(|r| r.radiance)).collect();
        while rgb.iter().any(Option::is_none) && rgb.iter().any(Option::is_some) {
            let previous = rgb.clone();
            for (i, texel) in rgb.iter_mut().enumerate().filter(|(_, t)| t.is_none()) {
                let (x, y) = (i % w, i / w);
                let neighbours = [(x > 0).then(|| i - 1), (x + 1 < w).then(|| i + 1), (y > 0).then(|| i - w), (y + 1 < h).then(|| i + w)];
                *texel = neighbours.into_iter().flatten().find_map(|j| previous[j]);
            }
        }
        PanelTexture { width, height, rgb: rgb.into_iter().map(|t| t.unwrap_or([0.0; 3])).collect(), samples, generation: 0 }
    }

    /// The texel under texture coordinate `texcoord` (nearest, clamped), as the shader looks it up.
    pub fn at(&self, texcoord: Vec2) -> [f32; 3] {
        let x = ((texcoord.x * self.width as f32).floor() as i64).clamp(0, self.width as i64 - 1) as usize;
        let y = ((texcoord.y * self.height as f32).floor() as i64).clamp(0, self.height as i64 - 1) as usize;
        self.rgb[y * self.width as usize + x]
    }
}

/// What the gather depends on: the eye and the frame's light; a change restarts it.
#[derive(Clone, Debug, PartialEq)]
pub struct PanelRequest {
    /// The eye in the car's (the mesh's) frame.
    pub eye: Vec3,
    /// The frame's SH lighting (car frame) and backdrop ([`FrameSettings`]).
    pub lighting: Vec<[f32; 3]>,
    pub backdrop: Backdrop,
    pub layers: LayerSelection,
    /// Numbers requests so that late textures of an older one are dropped.
    pub generation: u64,
}

impl PanelRequest {
    pub fn new(eye: Vec3, settings: &FrameSettings, layers: &LayerSelection, generation: u64) -> PanelRequest {
        PanelRequest { eye, lighting: settings.lighting.clone(), backdrop: settings.backdrop.clone(), layers: layers.clone(), generation }
    }

    /// Whether `other` asks for the same gather (the generation aside).
    pub fn same_gather(&self, other: &PanelRequest) -> bool {
        self.eye == other.eye && self.lighting == other.lighting && self.backdrop == other.backdrop && self.layers == other.layers
    }
}

/// The light a reflected ray meets outside, as the viewer draws it: the
/// backdrop's sky (built in the car's frame, with the sun disc when drawn) or
/// map (turned as drawn); for a black backdrop, the SH lighting itself (the
/// synthetic light the PRT shading uses).
fn sky_environment(backdrop: &SkyBackdrop, lighting: &[[f32; 3]], order: usize) -> Environment {
    let to_car = backdrop.rotation;
    let (sun, up) = ((to_car * backdrop.sun).normalize(), (to_car * backdrop.up).normalize());
    match PreethamSky::new(sun.as_dvec3(), up.as_dvec3(), f64::from(backdrop.turbidity)) {
        Some(sky) => Environment {
            light: Light::Preetham(sky),
            sun: backdrop.sun_irradiance.map(|e| Sun::new(sun, e, crate::panel::SUN_ANGULAR_RADIUS_DEG)),
            to_world: glam::Mat3::IDENTITY,
            yaw_deg: 0.0,
        },
        // Night: no sky model; the (dark) SH lighting.
        None => Environment::sh(order, lighting.to_vec(), 0.0),
    }
}

/// Everything the panel gather reads, owned (so a worker thread can hold it).
pub struct PanelSource {
    mesh: Mesh,
    scene: Scene,
    surfaces: Surfaces,
    layout: PanelLayout,
    brdf: PanelBrdf,
    transfer: Transfer,
    two_sided: bool,
    /// The env map as an [`Environment`], turned per request.
    map: Option<Environment>,
    /// The transfer summed for the last layer selection.
    selected: Option<(LayerSelection, Vec<f32>)>,
    /// A texel bundle's atlas, covered texels and their transfer, and that
    /// transfer summed for the last layer selection: the interior's light.
    texels: Option<(crate::atlas::Atlas, Vec<u32>, Transfer)>,
    selected_texels: Option<(LayerSelection, Vec<f32>)>,
    pub seed: u32,
}

impl PanelSource {
    /// Builds the ray-tracing scene of `bundle` for the panel of `mapping`;
    /// `environment` is the viewer's env map, if it lights the scene.
    pub fn new(bundle: &Bundle, mapping: &PanelMapping, environment: Option<EquirectImage>) -> Result<PanelSource, String> {
        let transfer = bundle.transfer.clone().ok_or("the bundle has no transfer (bake it first)")?;
        let mesh = bundle.mesh.clone();
        let surfaces = Surfaces::resolve(&mesh, &bundle.window_patterns()).map_err(|e| format!("META window_patterns: {e}"))?;
        let scene = Scene::build(&mesh, BuildQuality::Sah).map_err(|e| e.to_string())?;
        Ok(PanelSource {
            mesh,
            scene,
            surfaces,
            layout: mapping.layout.clone(),
            brdf: PanelBrdf::default(),
            transfer,
            two_sided: bundle.is_window_mode(),
            map: environment.map(|image| Environment::map(image, 0.0)),
            selected: None,
            texels: bundle.texels.as_ref().and_then(|t| Some((t.atlas.clone(), t.texels.clone(), t.transfer.clone()?))),
            selected_texels: None,
            seed: 1,
        })
    }

    pub fn layout(&self) -> &PanelLayout {
        &self.layout
    }

    /// Gathers for `request`, `passes` passes ([`samples_after`]), calling
    /// `after_pass` with each pass's texture; it returns `false` to stop early.
    /// Runs on the current rayon pool; the textures do not depend on its size.
    pub fn gather(&mut self, request: &PanelRequest, passes: u32, mut after_pass: impl FnMut(PanelTexture) -> bool) {
        let order = self.transfer.order as usize;
        if self.selected.as_ref().is_none_or(|(layers, _)| *layers != request.layers) {
            self.selected = Some((request.layers.clone(), request.layers.combine(&self.transfer)));
        }
        let built;
        let env = match (&request.backdrop, self.map.as_mut()) {
            (Backdrop::EnvMap { rotation }, Some(map)) => {
                // The backdrop draws the map's direction d at R·d: the car sees along d what the map holds at Rᵀ·d.
                map.to_world = rotation.transpose();
                &*map
            }
            (Backdrop::Sky(sky), _) => {
                built = sky_environment(sky, &request.lighting, order);
                &built
            }
            _ => {
                built = Environment::sh(order, request.lighting.clone(), 0.0);
                &built
            }
        };
        let selected = self.selected.as_ref().map_or(&[][..], |(_, t)| t);
        let vertex_light = crate::panel::interior::vertex_light(selected, order, self.transfer.channels as usize, &request.lighting);
        // A texel bundle: the interior's light from its texels, as the frame draws it.
        let texel_light = match &self.texels {
            Some((atlas, texels, transfer)) if transfer.order == self.transfer.order => {
                if self.selected_texels.as_ref().is_none_or(|(layers, _)| *layers != request.layers) {
                    self.selected_texels = Some((request.layers.clone(), request.layers.combine(transfer)));
                }
                let rows = self.selected_texels.as_ref().map_or(&[][..], |(_, t)| t);
                Some(crate::panel::interior::texel_light(atlas, texels, rows, order, transfer.channels as usize, &request.lighting))
            }
            _ => None,
        };
        let interior = Interior {
            scene: &self.scene,
            mesh: &self.mesh,
            surfaces: &self.surfaces,
            vertex_light,
            two_sided: self.two_sided,
            texel_light,
            side_shares: crate::panel::SideShares::of(&self.transfer, self.texels.as_ref().map(|(a, ids, t)| (a, &ids[..], t))),
        };
        let options = GatherOptions { seed: self.seed, ..GatherOptions::default() };
        let mut gather = PanelGather::new(&interior, env, &self.brdf, &self.layout, request.eye, options);
        for pass in 1..=passes {
            let target = samples_after(pass);
            gather.refine(target - gather.samples());
            let mut texture = PanelTexture::from_results(&gather.results(), self.layout.width, self.layout.height, gather.samples());
            texture.generation = request.generation;
            if !after_pass(texture) || target >= crate::panel::gather::MAX_SAMPLES {
                return;
            }
        }
    }

    /// The texture after `passes` passes (headless screenshots, tests).
    pub fn texture(&mut self, request: &PanelRequest, passes: u32) -> PanelTexture {
        let mut last = PanelTexture::black(self.layout.width, self.layout.height);
        self.gather(request, passes, |texture| {
            last = texture;
            true
        });
        last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sky the panel reflects is the sky the backdrop draws: same radiance
    /// along every car-frame direction (the disc aside), the sun where the disc is, for a turned car.
    #[test]
    fn reflected_sky_is_the_drawn_sky() {
        let rotation = super::super::lighting::car_to_env_rotation(40.0, 10.0, -5.0);
        let sun = Vec3::new(0.3, 0.5, -0.8).normalize();
        let sky = SkyBackdrop { sun, up: Vec3::Y, turbidity: 3.0, scale: 1.0, sun_irradiance: Some([9e4, 8e4, 7e4]), rotation };
        let env = sky_environment(&sky, &[[0.0; 3]], 1);
        let drawn = Backdrop::Sky(sky);
        let disc = env.sun.expect("the disc is drawn, so it is reflected");
        assert!(disc.direction.dot(rotation * sun) > 1.0 - 1e-6);
        assert_eq!(disc.irradiance, [9e4, 8e4, 7e4]);
        let mut compared = 0;
        for k in 0..500u32 {
            let (a, b) = crate::sampling::sample_2d(crate::sampling::DirectionPattern::Sobol, k, 0, 7);
            let z = 1.0 - 2.0 * a;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let d = Vec3::new(r * (std::f32::consts::TAU * b).cos(), r * (std::f32::consts::TAU * b).sin(), z);
            if disc.contains(d) {
                continue;
            }
            let (want, got) = (super::super::backdrop::radiance(&drawn, None, d), env.radiance(d));
            for c in 0..3 {
                assert!((want[c] - got[c]).abs() <= 1e-4 * want[c].abs().max(1.0), "{d}: drawn {want:?}, reflected {got:?}");
            }
            compared += 1;
        }
        assert!(compared > 490);
    }

    #[test]
    fn passes_double_then_add_at_most_the_increment() {
        let schedule: Vec<u32> = (0..=12).map(samples_after).collect();
        assert_eq!(schedule, [0, 2, 4, 8, 16, 32, 64, 96, 128, 160, 192, 224, 256]);
        assert_eq!(passes_for(INTERACTIVE_SAMPLES), 12);
        assert_eq!(passes_for(1), 1);
        assert_eq!(samples_after(u32::MAX), crate::panel::gather::MAX_SAMPLES);
    }

    #[test]
    fn texels_off_the_panel_take_a_neighbour_and_lookup_is_nearest() {
        let texel = |v: f32| Some(TexelResult { radiance: [v; 3], through_windows: [0.0; 3], from_sky: [0.0; 3], luminance_error: 0.0 });
        // 3 × 2: only (0,0) = 1 and (2,1) = 5 are on the panel.
        let results = [texel(1.0), None, None, None, None, texel(5.0)];
        let t = PanelTexture::from_results(&results, 3, 2, 4);
        let values: Vec<f32> = t.rgb.iter().map(|c| c[0]).collect();
        // (1,0) takes its left neighbour; (2,0) its lower one; (0,1) its upper; (1,1) its right.
        assert_eq!(values, [1.0, 1.0, 5.0, 1.0, 5.0, 5.0]);
        assert_eq!(t.at(Vec2::new(0.99, 0.49))[0], 5.0);
        assert_eq!(t.at(Vec2::new(0.34, 0.51))[0], 5.0);
        assert_eq!(t.at(Vec2::new(-0.2, 1.7))[0], 1.0, "clamped to the edge");
        let none = PanelTexture::from_results(&[None, None], 2, 1, 0);
        assert_eq!(none.rgb, vec![[0.0; 3]; 2]);
    }
}
