//! What the viewer draws behind the geometry and through the glass: the
//! environment map at full resolution, or the Preetham sky (with the sun disc
//! for a time-lapse step), in the lighting's radiance units and turned like
//! the lighting.
//!
//! The GPU side is a full-screen triangle at the far plane (backdrop.wgsl):
//! per pixel the view ray's direction `d`, turned into the environment's frame
//! (`Rᵀ·d`, R the environment rotation), then radiance. This module holds the
//! parameters, the uniform block, and [`radiance`], the CPU evaluation the
//! tests compare the GPU with.

use glam::{Mat3, Vec3};

use crate::sh::{equirect_uv, EquirectImage};
use crate::sky::preetham::PreethamSky;

/// Mean apparent angular radius of the sun disc, degrees.
pub const SUN_ANGULAR_RADIUS_DEG: f64 = 0.2666;
/// Largest finite binary16 value: the HDR target saturates here, so the
/// backdrop is clamped to it (only the sun disc, ~10⁹ cd/m², gets there; it is
/// white on any display anyway).
pub const HDR_MAX: f32 = 65504.0;

/// What is drawn where no geometry is.
#[derive(Clone, Debug, PartialEq)]
pub enum Backdrop {
    /// Zero radiance (synthetic lighting without a sky).
    Black,
    /// The scene's equirect map ([`super::PreparedScene::environment`]) turned
    /// by `rotation`: what the map shows at direction d is drawn at `R·d`.
    EnvMap { rotation: Mat3 },
    /// The Preetham sky.
    Sky(SkyBackdrop),
}

/// A Preetham sky as drawn: its sun, zenith and turbidity, a radiance scale,
/// the sun disc, and the turn applied to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkyBackdrop {
    /// Direction toward the sun and the zenith, in the sky's own frame.
    pub sun: Vec3,
    pub up: Vec3,
    pub turbidity: f32,
    /// Radiance multiplier (1 = the sky module's units, cd/m²).
    pub scale: f32,
    /// Sun irradiance on a plane facing it (the bundle's `sun_rgb`), drawn as a
    /// uniform disc of radiance `E / Ω`; `None` draws no disc.
    pub sun_irradiance: Option<[f32; 3]>,
    /// Turn of the sky, as [`Backdrop::EnvMap`]'s.
    pub rotation: Mat3,
}

/// Solid angle of the sun disc, steradians.
pub fn sun_solid_angle() -> f64 {
    2.0 * std::f64::consts::PI * (1.0 - SUN_ANGULAR_RADIUS_DEG.to_radians().cos())
}

impl SkyBackdrop {
    /// The sky model, `None` when the sun is at or below the horizon (night: black).
    fn model(&self) -> Option<PreethamSky> {
        PreethamSky::new(self.sun.as_dvec3(), self.up.as_dvec3(), f64::from(self.turbidity))
    }

    /// Radiance of the sun disc (scaled), zero without a disc.
    fn disc_radiance(&self) -> [f32; 3] {
        let solid_angle = sun_solid_angle();
        self.sun_irradiance.map_or([0.0; 3], |e| e.map(|c| (f64::from(c) / solid_angle) as f32 * self.scale))
    }
}

/// Radiance drawn along the unit world direction `world_dir`, as the GPU draws
/// it: the environment map bilinearly between texel centres (wrapping in
/// longitude, clamped at the poles), the sky from the sky module's f64 model
/// plus the disc, clamped to [`HDR_MAX`].
pub fn radiance(backdrop: &Backdrop, environment: Option<&EquirectImage>, world_dir: Vec3) -> [f32; 3] {
    let value = match backdrop {
        Backdrop::Black => [0.0; 3],
        Backdrop::EnvMap { rotation } => environment.map_or([0.0; 3], |image| bilinear(image, rotation.transpose() * world_dir)),
        Backdrop::Sky(sky) => {
            let dir = (sky.rotation.transpose() * world_dir).as_dvec3().normalize();
            match sky.model() {
                None => [0.0; 3],
                Some(model) => {
                    let (_, sun) = model.frame();
                    let disc = if dir.dot(sun) >= SUN_ANGULAR_RADIUS_DEG.to_radians().cos() { sky.disc_radiance() } else { [0.0; 3] };
                    let sky_rgb = model.radiance_rgb(dir);
                    std::array::from_fn(|c| sky_rgb[c] as f32 * sky.scale + disc[c])
                }
            }
        }
    };
    value.map(|c| c.min(HDR_MAX))
}

/// Bilinear lookup between texel centres (what backdrop.wgsl does with `textureLoad`).
fn bilinear(image: &EquirectImage, dir: Vec3) -> [f32; 3] {
    let (w, h) = (image.width as i64, image.height as i64);
    let (u, v) = equirect_uv(dir.as_dvec3().normalize());
    let (x, y) = (u * w as f64 - 0.5, v * h as f64 - 0.5);
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = ((x - fx) as f32, (y - fy) as f32);
    let texel = |col: i64, row: i64| image.rgb[(row.clamp(0, h - 1) * w + col.rem_euclid(w)) as usize];
    let (x0, y0) = (fx as i64, fy as i64);
    let (a, b, c, d) = (texel(x0, y0), texel(x0 + 1, y0), texel(x0, y0 + 1), texel(x0 + 1, y0 + 1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * tx;
        let bottom = c[k] + (d[k] - c[k]) * tx;
        top + (bottom - top) * ty
    })
}

/// `image` halved (2×2 box average) until both sides fit `max_side`: the GPU
/// texture limit (8192 on most devices) is below the largest maps we read.
pub fn fit_to_texture(image: &EquirectImage, max_side: u32) -> std::borrow::Cow<'_, EquirectImage> {
    let mut current = std::borrow::Cow::Borrowed(image);
    while current.width > max_side.max(1) || current.height > max_side.max(1) {
        let (w, h) = ((current.width / 2).max(1), (current.height / 2).max(1));
        let at = |x: u32, y: u32| current.rgb[(y.min(current.height - 1) * current.width + x.min(current.width - 1)) as usize];
        let rgb = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let quad = [at(2 * x, 2 * y), at(2 * x + 1, 2 * y), at(2 * x, 2 * y + 1), at(2 * x + 1, 2 * y + 1)];
                std::array::from_fn(|c| quad.iter().map(|p| p[c]).sum::<f32>() / 4.0)
            })
            .collect();
        current = std::borrow::Cow::Owned(EquirectImage { width: w, height: h, rgb });
    }
    current
}

/// Uniform block of backdrop.wgsl (16 vec4 = 256 bytes), as 32-bit words.
///
/// `forward`, `right`, `up`: the camera basis with `right`, `up` scaled so
/// that `forward + x·right + y·up` is the ray through NDC `(x, y)`.
pub(super) fn uniform_words(backdrop: &Backdrop, env_size: (u32, u32), basis: (Vec3, Vec3, Vec3)) -> Vec<u32> {
    let mut f = Vec::with_capacity(64);
    let (forward, right, up) = basis;
    for v in [forward, right, up] {
        f.extend([v.x, v.y, v.z, 0.0]);
    }
    let (mode, rotation, sky) = match backdrop {
        Backdrop::Black => (0u32, Mat3::IDENTITY, None),
        Backdrop::EnvMap { rotation } => (1, *rotation, None),
        Backdrop::Sky(sky) => match sky.model() {
            Some(model) => (2, sky.rotation, Some((model, sky))),
            None => (0, Mat3::IDENTITY, None),
        },
    };
    // Columns of R: component i of Rᵀ·d is column_i · d.
    for column in [rotation.x_axis, rotation.y_axis, rotation.z_axis] {
        f.extend([column.x, column.y, column.z, 0.0]);
    }
    let mut words: Vec<u32> = f.iter().map(|x| x.to_bits()).collect();
    words.extend([mode, env_size.0, env_size.1, 0]);
    let mut g: Vec<f32> = Vec::with_capacity(36);
    match sky {
        Some((model, sky)) => {
            for [a, b, c, d, e, s] in model.perez_parameters() {
                g.extend([a, b, c, d, e, s, 0.0, 0.0].map(|x| x as f32));
            }
            let (zenith, sun) = model.frame();
            let cos_radius = SUN_ANGULAR_RADIUS_DEG.to_radians().cos();
            g.extend([sun.x, sun.y, sun.z, cos_radius].map(|x| x as f32));
            g.extend([zenith.x as f32, zenith.y as f32, zenith.z as f32, sky.scale]);
            let disc = sky.disc_radiance();
            g.extend([disc[0], disc[1], disc[2], 0.0]);
        }
        None => g.resize(36, 0.0),
    }
    words.extend(g.iter().map(|x| x.to_bits()));
    words
}

/// Bytes of uniform_words.
pub(super) const UNIFORM_BYTES: u64 = 256;

/// The sRGB matrix the shader uses, checked against the sky module's (same
/// numbers, rows), so the two cannot drift apart.
#[cfg(test)]
const XYZ_TO_SRGB_IN_SHADER: [[f64; 3]; 3] =
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sky::sun_color::xyz_to_linear_srgb;
    use glam::DVec3;

    #[test]
    fn shader_matrix_is_the_sky_modules() {
        for (i, axis) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
            let column = xyz_to_linear_srgb(axis.to_array());
            for r in 0..3 {
                assert_eq!(column[r], XYZ_TO_SRGB_IN_SHADER[r][i]);
            }
        }
        let source = include_str!("backdrop.wgsl");
        assert!(source.contains("3.2404542, -0.9692660, 0.0556434"), "backdrop.wgsl's matrix columns changed");
    }

    #[test]
    fn bilinear_hits_texel_centres_and_wraps() {
        // 4×2 map: texel (col, row) = col + 10·row.
        let rgb = (0..8).map(|i| [(i % 4) as f32 + 10.0 * (i / 4) as f32; 3]).collect();
        let image = EquirectImage { width: 4, height: 2, rgb };
        // Centre of texel (2, 0): u = 2.5/4, v = 0.5/2.
        let centre = crate::sh::equirect_direction(2.5 / 4.0, 0.25).as_vec3();
        assert!((bilinear(&image, centre)[0] - 2.0).abs() < 1e-4);
        // Halfway between column 3 and column 0 (across the seam) on row 1: (3 + 0)/2 + 10.
        let seam = crate::sh::equirect_direction(0.0, 0.75).as_vec3();
        assert!((bilinear(&image, seam)[0] - 11.5).abs() < 1e-4, "{:?}", bilinear(&image, seam));
    }

    #[test]
    fn sun_disc_carries_the_sun_irradiance() {
        // Integrating the disc radiance over the disc gives back E (uniform disc).
        let sky = SkyBackdrop {
            sun: Vec3::new(0.0, 1.0, 0.0),
            up: Vec3::Y,
            turbidity: 3.0,
            scale: 1.0,
            sun_irradiance: Some([1.0e5, 9.0e4, 8.0e4]),
            rotation: Mat3::IDENTITY,
        };
        let disc = sky.disc_radiance();
        assert!((f64::from(disc[0]) * sun_solid_angle() / 1.0e5 - 1.0).abs() < 1e-6);
        // Drawn clamped to the HDR target's ceiling.
        assert_eq!(radiance(&Backdrop::Sky(sky), None, Vec3::Y), [HDR_MAX; 3]);
        // The turn: with the sky turned 90° about +X, its zenith is drawn at R·up = +Z.
        let turned = SkyBackdrop { rotation: Mat3::from_rotation_x(90f32.to_radians()), sun_irradiance: None, ..sky };
        let at_z = radiance(&Backdrop::Sky(turned), None, Vec3::Z);
        let zenith = radiance(&Backdrop::Sky(SkyBackdrop { sun_irradiance: None, ..sky }), None, Vec3::Y);
        assert!((at_z[1] - zenith[1]).abs() < 1e-3 * zenith[1], "{at_z:?} vs {zenith:?}");
    }

    #[test]
    fn backdrop_turns_like_the_lighting() {
        // Projecting what is drawn (the map turned by R) onto SH gives the map's SH turned by R.
        let tau = std::f32::consts::TAU;
        let rgb = (0..32u32)
            .flat_map(|row| (0..64u32).map(move |col| ((col as f32 + 0.5) / 64.0, (row as f32 + 0.5) / 32.0)))
            .map(|(u, v)| [0.5 + 0.4 * (tau * u).sin(), 0.2 + 0.7 * v, 0.45 + 0.35 * (tau * u).cos()])
            .collect();
        let image = EquirectImage { width: 64, height: 32, rgb };
        let rotation = crate::view::lighting::car_to_env_rotation(40.0, 15.0, -5.0);
        let order = 3;
        let turned = crate::view::lighting::rotate_sh(&crate::sh::project_equirect(&image, order), order, rotation);
        let backdrop = Backdrop::EnvMap { rotation };
        let drawn = crate::sh::project_function(order, 128, |d| radiance(&backdrop, Some(&image), d.as_vec3()).map(f64::from));
        let scale = turned[0][1].abs();
        for (i, (a, b)) in turned.iter().zip(&drawn).enumerate() {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-2 * scale, "coefficient {i}, channel {c}: {} vs {}", a[c], b[c]);
            }
        }
    }

    #[test]
    fn halving_keeps_the_mean() {
        let rgb: Vec<[f32; 3]> = (0..64).map(|i| [i as f32, 1.0, 2.0]).collect();
        let image = EquirectImage { width: 16, height: 4, rgb };
        let small = fit_to_texture(&image, 4);
        assert_eq!((small.width, small.height), (4, 1));
        let mean = |im: &EquirectImage| im.rgb.iter().map(|p| p[0]).sum::<f32>() / im.rgb.len() as f32;
        assert!((mean(&small) - mean(&image)).abs() < 1e-4);
    }
}
