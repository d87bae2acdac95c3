//! What a reflected ray meets: the PRT-lit interior (seed 000 §4.3: "the
//! luminance value is linearly interpolated based on the PRT computation for
//! vertices of a mesh element intersected by the reflected ray"), glass that
//! it passes through, and, beyond, the environment.
//!
//! A hit on an opaque triangle returns `albedo · Σ_c w_c E(v_c)`, the
//! barycentric blend of the corners' `E(v) = Σ_i L_i t_i(v)` (the bundle's
//! total transfer: every bounce), plus the sun's direct light at the hit
//! point (a shadow ray through the glass), since the SH lighting holds the sky
//! without the sun disk. The sun's light after one or more bounces inside is
//! not included (it would need the sun in the transfer's lighting; docs/panel.md).

use glam::Vec3;

use super::environment::{Environment, Sun};
use crate::bake::Surfaces;
use crate::mesh::Mesh;
use crate::trace::{Hit, RayQuery, Scene};

/// Panes of glass a ray may pass through before it counts as blocked
/// (windscreen + a side window + a far window is three).
pub const MAX_GLASS_LAYERS: u32 = 8;

/// The radiance a ray brings back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Arrival {
    /// Radiance without the sun disk (environment or interior).
    pub radiance: [f32; 3],
    /// Product of the glass transmittances when the ray left the scene, 0 when it stopped on a surface.
    pub sky_transmittance: f32,
    /// The ray passed through at least one window.
    pub through_window: bool,
    /// Queries traced for it: the first ray, its continuations through
    /// glass, and the shadow ray toward the sun from a lit surface hit.
    pub queries: u32,
}

/// The PRT-lit interior a gather reads.
pub struct Interior<'a> {
    pub scene: &'a Scene,
    pub mesh: &'a Mesh,
    pub surfaces: &'a Surfaces,
    /// `E(v) = Σ_i L_i t_i(v)` per vertex, RGB.
    pub vertex_light: Vec<[f32; 3]>,
    /// Both sides of a surface carry PRT light (a window-mode bake: each
    /// its share, [`Interior::side_shares`]); otherwise, as the open-mode
    /// bake gathers, a surface's back is black.
    pub two_sided: bool,
    /// A texel bundle: its texels' light (`Σ_i L_i t_i`), read at a hit as
    /// the viewer reads it; the vertices' serves triangles in no chart.
    pub texel_light: Option<crate::atlas::lightmap::LightmapLight>,
    /// A window-mode bundle's front-side shares: the side a ray meets shows
    /// its share of the PRT light, as the viewer draws it.
    pub side_shares: SideShares,
}

/// Front-side shares of a bundle's receivers (`bake::side_share`; sections
/// SIDE and TSID). Empty: both sides show all of a receiver's light.
#[derive(Clone, Debug, Default)]
pub struct SideShares {
    /// Per vertex.
    pub vertices: Vec<f32>,
    /// Per texel, read where the texels' light is read (the share in every channel).
    pub texels: Option<crate::atlas::lightmap::LightmapLight>,
}

impl SideShares {
    /// The shares of a bundle's vertex transfer and, in texel mode, of its texels'.
    pub fn of(vertices: &crate::bundle::Transfer, texels: Option<(&crate::atlas::Atlas, &[u32], &crate::bundle::Transfer)>) -> SideShares {
        let texels = texels.filter(|(_, ids, t)| t.front_share.len() == ids.len()).map(|(atlas, ids, transfer)| {
            let stride = (transfer.order * transfer.order * transfer.channels).max(1) as usize;
            let holds: Vec<bool> = transfer.total().chunks_exact(stride).map(|row| row.iter().any(|&x| x != 0.0)).collect();
            let shares: Vec<[f32; 3]> = transfer.front_share.iter().map(|&s| [s; 3]).collect();
            crate::atlas::lightmap::LightmapLight::new(atlas, ids, &shares, &holds)
        });
        SideShares { vertices: vertices.front_share.clone(), texels }
    }

    /// The share of the light of triangle `t` at barycentrics (u, v) on the
    /// side a ray meets (`back_face`: the back of the triangle's face).
    fn seen(&self, mesh: &Mesh, t: usize, u: f32, v: f32, back_face: bool) -> f32 {
        let front = match self.texels.as_ref().and_then(|l| l.at(t, u, v)) {
            Some(share) => Some(share[0]),
            None if self.vertices.is_empty() => None,
            None => {
                let [a, b, c] = mesh.triangle(t).map(|i| self.vertices[i as usize]);
                Some((1.0 - u - v) * a + u * b + v * c)
            }
        };
        crate::bake::side_share::seen_side_share(front, !back_face)
    }
}

/// `Σ_i L_i t_i(v)` for every vertex of a `[vertex][channel][coeff]` transfer
/// with `channels` 1 or 3 (grey transfer applies to every colour channel).
pub fn vertex_light(total: &[f32], order: usize, channels: usize, lighting: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let n = order * order;
    total
        .chunks_exact(n * channels)
        .map(|row| {
            let mut e = [0.0f32; 3];
            for (c, e) in e.iter_mut().enumerate() {
                let t = &row[if channels == 3 { c * n } else { 0 }..][..n];
                *e = t.iter().zip(lighting).map(|(t, l)| t * l[c]).sum();
            }
            e
        })
        .collect()
}

/// A texel bundle's light under `lighting` ([`Interior::texel_light`]):
/// each covered texel's `Σ_i L_i t_i` from its `[texel][channel][coeff]`
/// row, held where the row is not all zero (as the viewer decides).
pub fn texel_light(
    atlas: &crate::atlas::Atlas,
    texels: &[u32],
    rows: &[f32],
    order: usize,
    channels: usize,
    lighting: &[[f32; 3]],
) -> crate::atlas::lightmap::LightmapLight {
    let irradiance = vertex_light(rows, order, channels, lighting);
    let holds: Vec<bool> = rows.chunks_exact((order * order * channels).max(1)).map(|row| row.iter().any(|&x| x != 0.0)).collect();
    crate::atlas::lightmap::LightmapLight::new(atlas, texels, &irradiance, &holds)
}

impl<'a> Interior<'a> {
    /// An interior for visibility alone (glass, glare searches): no PRT
    /// light, both sides of a surface alike.
    pub fn unlit(scene: &'a Scene, mesh: &'a Mesh, surfaces: &'a Surfaces) -> Interior<'a> {
        Interior { scene, mesh, surfaces, vertex_light: Vec::new(), two_sided: true, texel_light: None, side_shares: SideShares::default() }
    }
}

impl Interior<'_> {
    /// Follows a ray from `origin` (on a surface of geometric normal
    /// `face_normal`) along unit `dir` through up to [`MAX_GLASS_LAYERS`] windows.
    pub fn trace(&self, env: &Environment, origin: Vec3, face_normal: Vec3, dir: Vec3) -> Arrival {
        let first = self.first_ray(origin, face_normal, dir);
        self.trace_from(env, &first, self.scene.closest_hit(first.origin, dir, first.t_max))
    }

    /// The first ray of [`Interior::trace`]: from `origin` pushed off its surface, along unit `dir`.
    pub fn first_ray(&self, origin: Vec3, face_normal: Vec3, dir: Vec3) -> RayQuery {
        RayQuery { origin: self.scene.offset_origin(origin, face_normal, dir), direction: dir, t_max: f32::INFINITY }
    }

    /// [`Interior::trace`] once its first ray (`first`, from [`Interior::first_ray`])
    /// has been traced, in a batch or alone, to `first_hit`.
    pub fn trace_from(&self, env: &Environment, first: &RayQuery, first_hit: Option<Hit>) -> Arrival {
        let (mut from, dir) = (first.origin, first.direction);
        let mut next_hit = first_hit;
        let mut transmittance = 1.0f32;
        let mut queries = 1;
        for layer in 0..=MAX_GLASS_LAYERS {
            let Some(hit) = next_hit else {
                let radiance = env.radiance(dir).map(|c| c * transmittance);
                return Arrival { radiance, sky_transmittance: transmittance, through_window: layer > 0, queries };
            };
            let point = from + dir * hit.t;
            let normal = self.scene.face_normal(hit.triangle);
            match self.surfaces.window_transmittance[hit.triangle as usize] {
                Some(tau) if layer < MAX_GLASS_LAYERS => {
                    transmittance *= tau;
                    if transmittance <= 0.0 {
                        break;
                    }
                    from = self.scene.offset_origin(point, normal, dir);
                    next_hit = self.scene.closest_hit(from, dir, f32::INFINITY);
                    queries += 1;
                }
                Some(_) => break,
                None if hit.back_face && !self.two_sided => {
                    return Arrival { radiance: [0.0; 3], sky_transmittance: 0.0, through_window: layer > 0, queries };
                }
                None => {
                    let share = self.side_shares.seen(self.mesh, hit.triangle as usize, hit.u, hit.v, hit.back_face);
                    let (mut radiance, shadow_queries) = self.surface_radiance(env, hit.triangle, hit.u, hit.v, point, normal, dir, share);
                    radiance.iter_mut().for_each(|c| *c *= transmittance);
                    return Arrival { radiance, sky_transmittance: 0.0, through_window: layer > 0, queries: queries + shadow_queries };
                }
            }
        }
        Arrival { radiance: [0.0; 3], sky_transmittance: 0.0, through_window: true, queries }
    }

    /// Radiance leaving opaque triangle `t` at barycentrics (u, v) toward
    /// the ray's origin, and the queries its shadow rays toward the sun took;
    /// `share` of the PRT light is the seen side's.
    #[allow(clippy::too_many_arguments)] // one hit's fields
    fn surface_radiance(
        &self,
        env: &Environment,
        t: u32,
        u: f32,
        v: f32,
        point: Vec3,
        face_normal: Vec3,
        dir: Vec3,
        share: f32,
    ) -> ([f32; 3], u32) {
        let albedo = self.surfaces.albedo[t as usize];
        let mut light = match self.texel_light.as_ref().and_then(|l| l.at(t as usize, u, v)) {
            Some(light) => light,
            None => {
                let [a, b, c] = self.mesh.triangle(t as usize).map(|i| self.vertex_light[i as usize]);
                let w0 = 1.0 - u - v;
                [0, 1, 2].map(|k| w0 * a[k] + u * b[k] + v * c[k])
            }
        };
        light.iter_mut().for_each(|l| *l *= share);
        let mut queries = 0;
        if let Some(sun) = &env.sun {
            // The side the ray sees.
            let seen = if face_normal.dot(dir) < 0.0 { face_normal } else { -face_normal };
            let cosine = seen.dot(sun.direction);
            if cosine > 0.0 {
                let (tau, _, n) = self.sky_transmittance_counted(point, face_normal, sun.direction);
                queries = n;
                if tau > 0.0 {
                    for k in 0..3 {
                        light[k] += tau * cosine * sun.irradiance[k] / std::f32::consts::PI;
                    }
                }
            }
        }
        ([albedo[0] * light[0], albedo[1] * light[1], albedo[2] * light[2]], queries)
    }

    /// Glass transmittance from a surface point toward unit `dir` out of the
    /// scene (0 when an opaque surface blocks it), and whether it crossed glass.
    pub fn sky_transmittance(&self, origin: Vec3, face_normal: Vec3, dir: Vec3) -> (f32, bool) {
        let (transmittance, crossed_glass, _) = self.sky_transmittance_counted(origin, face_normal, dir);
        (transmittance, crossed_glass)
    }

    /// [`Interior::sky_transmittance`] and the queries it traced.
    fn sky_transmittance_counted(&self, origin: Vec3, face_normal: Vec3, dir: Vec3) -> (f32, bool, u32) {
        let mut from = self.scene.offset_origin(origin, face_normal, dir);
        let mut transmittance = 1.0f32;
        for layer in 0..=MAX_GLASS_LAYERS {
            let Some(hit) = self.scene.closest_hit(from, dir, f32::INFINITY) else {
                return (transmittance, layer > 0, layer + 1);
            };
            match self.surfaces.window_transmittance[hit.triangle as usize] {
                Some(tau) if layer < MAX_GLASS_LAYERS && tau > 0.0 => {
                    transmittance *= tau;
                    from = self.scene.offset_origin(from + dir * hit.t, self.scene.face_normal(hit.triangle), dir);
                }
                _ => return (0.0, true, layer + 1),
            }
        }
        (0.0, true, MAX_GLASS_LAYERS + 1)
    }

    /// The sun strategy's light: the disk's radiance times the glass toward
    /// it, whether it crossed glass, and the queries traced.
    pub fn sun_arrival(&self, sun: &Sun, origin: Vec3, face_normal: Vec3, dir: Vec3) -> (f32, bool, u32) {
        if !sun.contains(dir) {
            return (0.0, false, 0);
        }
        self.sky_transmittance_counted(origin, face_normal, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{BakeParams, Mode};
    use crate::trace::BuildQuality;
    use crate::verify::{plane_point_reference, shapes};
    use glam::DVec3;

    /// A 4 m floor of two triangles under a sphere (radius 0.5, centre 1 m
    /// up), baked in texels of 10 cm: a gather ray that meets the floor
    /// under the sphere reads the texels' light, the sphere's shadow, within
    /// 2% of the closed form (0.14% seen), where the floor's four corner
    /// vertices, which see nearly the open sky, read 22% too much.
    #[test]
    fn a_texel_bundle_lights_the_gather_from_its_texels() {
        let (radius, height) = (0.5f32, 1.0f32);
        let mut mesh = shapes::plane_grid(1, 4.0);
        let mut sphere = shapes::icosphere(4);
        shapes::transform(&mut sphere, radius, Vec3::new(0.0, height, 0.0));
        shapes::append(&mut mesh, &sphere);
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let params = BakeParams { order: 2, rays: 256, seed: 3, mode: Mode::Open, adaptive: 0.0, ..BakeParams::default() };
        let atlas = crate::atlas::Atlas::unwrap(&mesh, 0.1).unwrap();
        let (vertices, texels) = crate::bake::texels::bake_texels(&mesh, &scene, &surfaces, &params, atlas, 8).unwrap();
        // A constant sky of radiance 1: L_00 = 2√π.
        let mut lighting = vec![[0.0f32; 3]; 4];
        lighting[0] = [2.0 * std::f32::consts::PI.sqrt(); 3];
        let env = Environment::sh(2, lighting.clone(), 0.0);
        let interior = |texel_light| Interior {
            scene: &scene,
            mesh: &mesh,
            surfaces: &surfaces,
            vertex_light: vertex_light(&vertices.total, 2, vertices.channels, &lighting),
            two_sided: false,
            texel_light,
            side_shares: SideShares::default(),
        };
        let read = texel_light(&texels.atlas, &texels.texels, &texels.total, 2, vertices.channels, &lighting);
        let (from_texels, from_vertices) = (interior(Some(read)), interior(None));
        let albedo = surfaces.albedo[0][0];
        // Straight down between the sphere and the floor, at (0.1, 0, 0.2).
        let x = Vec3::new(0.1, 0.0, 0.2);
        let down = |i: &Interior| i.trace(&env, x + Vec3::Y * 0.3, Vec3::Y, -Vec3::Y).radiance[0] / albedo;
        let reference = plane_point_reference(2, x.as_dvec3(), DVec3::new(0.0, height as f64, 0.0), radius as f64);
        let expected = (lighting[0][0] as f64 * reference[0]) as f32;
        let (got, vertex) = (down(&from_texels), down(&from_vertices));
        eprintln!("irradiance under the sphere: texels {got}, vertices {vertex}, closed form {expected}");
        assert!((got / expected - 1.0).abs() < 0.02, "texels read {got}, the closed form is {expected}");
        assert!(vertex > 1.15 * expected, "the corner vertices read {vertex}: the test does not tell texels from vertices");
    }
}
