//! The light outside the car, in the car's frame.
//!
//! `yaw` turns the car (counter-clockwise seen from above, about +Y, degrees)
//! under a fixed sky: a direction `d` of the car's frame looks toward world
//! direction `R_y(yaw) · d`. Radiance seen along `d` is the world's at `R d`;
//! the SH lighting of the interior is the world's rotated by `Rᵀ`.

use glam::{DVec3, Mat3, Vec3};

use crate::sh::{coeff_count, equirect_uv, evaluate_rgb, project_equirect, EquirectImage, ShRotation};
use crate::sky::{CieOvercast, PreethamSky};

/// Mean apparent radius of the sun, degrees (0.533° across).
pub const SUN_ANGULAR_RADIUS_DEG: f64 = 0.2666;

/// The sun disk, in the car's frame: uniform radiance over a cone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sun {
    /// Unit direction toward the sun's centre.
    pub direction: Vec3,
    /// Irradiance on a plane facing the sun (lux for the sky model), RGB.
    pub irradiance: [f32; 3],
    /// cos of the disk's angular radius.
    pub cos_radius: f64,
}

impl Sun {
    pub fn new(direction: Vec3, irradiance: [f32; 3], angular_radius_deg: f64) -> Sun {
        Sun { direction: direction.normalize(), irradiance, cos_radius: angular_radius_deg.to_radians().cos() }
    }
    /// Solid angle of the disk, `2π (1 − cos r)` (in f64: the difference is ~1e-5).
    pub fn solid_angle(&self) -> f64 {
        std::f64::consts::TAU * (1.0 - self.cos_radius)
    }
    /// Radiance of the disk, `E / Ω`.
    pub fn radiance(&self) -> [f32; 3] {
        let omega = self.solid_angle();
        self.irradiance.map(|e| (f64::from(e) / omega) as f32)
    }
    /// Whether unit `dir` lies within the disk.
    pub fn contains(&self, dir: Vec3) -> bool {
        f64::from(dir.dot(self.direction)) >= self.cos_radius
    }
    /// A direction uniform over the disk's cone from `u ∈ [0,1)²` (density `1/Ω`).
    pub fn sample(&self, u: [f32; 2]) -> Vec3 {
        let cos_theta = 1.0 - f64::from(u[0]) * (1.0 - self.cos_radius);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = std::f64::consts::TAU * f64::from(u[1]);
        let (t, b) = crate::sampling::tangent_frame(self.direction);
        let local = DVec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta);
        (t.as_dvec3() * local.x + b.as_dvec3() * local.y + self.direction.as_dvec3() * local.z).normalize().as_vec3()
    }
}

/// What lies outside the windows (without the sun disk, which is [`Environment::sun`]).
#[derive(Clone, Debug)]
pub enum Light {
    /// An equirect map in the world frame (docs/conventions.md), looked up at full resolution (nearest pixel).
    Map(EquirectImage),
    /// The Preetham clear sky, built in the car's frame (its sun is [`Environment::sun`]).
    Preetham(PreethamSky),
    /// The CIE overcast sky (no sun).
    Overcast(CieOvercast),
    /// A radiance given by SH coefficients (world frame), clamped at 0: smooth skies and tests.
    Sh { order: usize, coeffs: Vec<[f32; 3]> },
}

/// The environment as the panel gather sees it.
#[derive(Clone, Debug)]
pub struct Environment {
    pub light: Light,
    pub sun: Option<Sun>,
    /// Car frame → world (yaw about +Y).
    pub to_world: Mat3,
    pub yaw_deg: f32,
}

/// Rotation of the car by `yaw_deg` about +Y.
pub fn yaw_rotation(yaw_deg: f32) -> Mat3 {
    Mat3::from_rotation_y(yaw_deg.to_radians())
}

impl Environment {
    /// An environment map under a car turned by `yaw_deg`.
    pub fn map(image: EquirectImage, yaw_deg: f32) -> Environment {
        Environment { light: Light::Map(image), sun: None, to_world: yaw_rotation(yaw_deg), yaw_deg }
    }

    /// The Preetham sky and sun for world sun direction `sun_world` (toward
    /// the sun, +Y up), under a car turned by `yaw_deg`. `None` at night.
    pub fn clear_sky(sun_world: Vec3, turbidity: f64, yaw_deg: f32) -> Option<Environment> {
        let to_world = yaw_rotation(yaw_deg);
        let sun_car = to_world.transpose() * sun_world.normalize();
        let sky = PreethamSky::new(sun_car.as_dvec3(), DVec3::Y, turbidity)?;
        let lit = crate::sky::preetham_sky(sun_car, Vec3::Y, turbidity, 1);
        let sun = Sun::new(sun_car, lit.sun_rgb_irradiance, SUN_ANGULAR_RADIUS_DEG);
        Some(Environment { light: Light::Preetham(sky), sun: Some(sun), to_world, yaw_deg })
    }

    /// The CIE overcast sky of horizontal illuminance `lux` (the same under any yaw).
    pub fn overcast(lux: f64) -> Environment {
        let light = Light::Overcast(CieOvercast::from_horizontal_illuminance(lux, DVec3::Y));
        Environment { light, sun: None, to_world: Mat3::IDENTITY, yaw_deg: 0.0 }
    }

    /// A radiance given by SH coefficients in the world frame.
    pub fn sh(order: usize, coeffs: Vec<[f32; 3]>, yaw_deg: f32) -> Environment {
        Environment { light: Light::Sh { order, coeffs }, sun: None, to_world: yaw_rotation(yaw_deg), yaw_deg }
    }

    /// Radiance arriving from car-frame unit direction `dir` (the sun disk excluded).
    pub fn radiance(&self, dir: Vec3) -> [f32; 3] {
        match &self.light {
            Light::Map(image) => {
                let (u, v) = equirect_uv((self.to_world * dir).as_dvec3());
                let col = ((u * image.width as f64) as u32).min(image.width - 1);
                let row = ((v * image.height as f64) as u32).min(image.height - 1);
                image.rgb[row as usize * image.width as usize + col as usize]
            }
            Light::Preetham(sky) => sky.radiance_rgb(dir.as_dvec3()).map(|c| c as f32),
            Light::Overcast(sky) => sky.radiance_rgb(dir.as_dvec3()).map(|c| c as f32),
            Light::Sh { order, coeffs } => evaluate_rgb(coeffs, *order, self.to_world * dir).map(|c| c.max(0.0)),
        }
    }

    /// The environment (without the sun disk) as `order²` SH coefficients in
    /// the car's frame: the interior's lighting for the PRT transfer.
    pub fn sh_lighting(&self, order: usize) -> Vec<[f32; 3]> {
        let world = match &self.light {
            Light::Map(image) => project_equirect(image, order),
            // Built in the car's frame already.
            Light::Preetham(sky) => {
                return crate::sh::project_function(order, crate::sky::sky_sh::SKY_SAMPLES_PER_AXIS, |d| sky.radiance_rgb(d))
            }
            Light::Overcast(sky) => return sky.sh(order),
            Light::Sh { coeffs, .. } => (0..coeff_count(order)).map(|i| coeffs.get(i).copied().unwrap_or([0.0; 3])).collect(),
        };
        let mut car = vec![[0.0; 3]; world.len()];
        ShRotation::new(order, self.to_world.transpose()).apply_rgb(&world, &mut car);
        car
    }

    /// Short description for reports.
    pub fn describe(&self) -> String {
        let light = match &self.light {
            Light::Map(image) => format!("map {}x{}", image.width, image.height),
            Light::Preetham(_) => "Preetham clear sky".into(),
            Light::Overcast(sky) => format!("CIE overcast sky, {:.0} lx horizontal", sky.horizontal_illuminance()),
            Light::Sh { order, .. } => format!("SH order {order}"),
        };
        format!("{light}, yaw {}°{}", self.yaw_deg, if self.sun.is_some() { ", sun disk" } else { "" })
    }
}
