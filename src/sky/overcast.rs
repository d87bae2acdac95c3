//! The CIE standard overcast sky (Moon & Spencer 1942; CIE S 011/E:2003 sky
//! type 1): luminance depends on the height above the horizon only,
//! `L(θ) = L_z (1 + 2 cos θ) / 3` with θ from the zenith, no sun. Grey
//! (equal RGB, Y = luminance in cd/m²); the ground below the horizon is black,
//! as for the Preetham sky.

use glam::DVec3;

use crate::sh::project_function;

/// Horizontal illuminance of a typical overcast day, lux (CIE overcast skies
/// give 5–20 klux at mid latitudes by day; 10 klux is the usual design value).
pub const TYPICAL_OVERCAST_LUX: f64 = 10_000.0;

/// An overcast sky of zenith luminance `zenith_cd_m2`, about `up`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CieOvercast {
    pub zenith_cd_m2: f64,
    pub up: DVec3,
}

impl CieOvercast {
    /// The sky whose horizontal illuminance is `lux`: `E_h = (7π/9) L_z`
    /// (the integral of `L(θ) cos θ` over the upper hemisphere).
    pub fn from_horizontal_illuminance(lux: f64, up: DVec3) -> CieOvercast {
        CieOvercast { zenith_cd_m2: lux * 9.0 / (7.0 * std::f64::consts::PI), up: up.normalize() }
    }

    /// Horizontal illuminance in lux, `(7π/9) L_z`.
    pub fn horizontal_illuminance(&self) -> f64 {
        7.0 * std::f64::consts::PI / 9.0 * self.zenith_cd_m2
    }

    /// Luminance (grey RGB, cd/m²) along unit `dir`; zero at and below the horizon.
    pub fn radiance_rgb(&self, dir: DVec3) -> [f64; 3] {
        let cos_theta = dir.dot(self.up);
        if cos_theta.is_nan() || cos_theta <= 0.0 {
            return [0.0; 3];
        }
        [self.zenith_cd_m2 * (1.0 + 2.0 * cos_theta) / 3.0; 3]
    }

    /// The sky projected onto `order²` SH coefficients (`L_i = ∫ L y_i dω`).
    pub fn sh(&self, order: usize) -> Vec<[f32; 3]> {
        project_function(order, super::sky_sh::SKY_SAMPLES_PER_AXIS, |d| self.radiance_rgb(d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Closed forms: L(zenith) = L_z, L(horizon) = L_z/3, and the SH DC term
    /// `L_00 = ∫ L y_00 dω = (1/√(4π)) · (2π L_z/3) ∫₀¹ (1 + 2μ) dμ = (4π L_z/3)/√(4π)`,
    /// the horizontal illuminance from SH bands 0–1 (`π L_00 y_00 + (2π/3) L_1,0 y_1,0(up)`)
    /// within the truncation error (the kernel's band 2 is non-zero: compare at order 3).
    #[test]
    fn overcast_sky_matches_its_closed_forms() {
        let sky = CieOvercast::from_horizontal_illuminance(TYPICAL_OVERCAST_LUX, DVec3::Y);
        assert!((sky.horizontal_illuminance() - TYPICAL_OVERCAST_LUX).abs() < 1e-9 * TYPICAL_OVERCAST_LUX);
        assert!((sky.radiance_rgb(DVec3::Y)[1] - sky.zenith_cd_m2).abs() < 1e-9 * sky.zenith_cd_m2);
        let near_horizon = DVec3::new(1.0, 1e-9, 0.0).normalize();
        assert!((sky.radiance_rgb(near_horizon)[0] - sky.zenith_cd_m2 / 3.0).abs() < 1e-6 * sky.zenith_cd_m2);
        assert_eq!(sky.radiance_rgb(DVec3::NEG_Y), [0.0; 3]);
        let sh = sky.sh(3);
        let dc = 4.0 * PI * sky.zenith_cd_m2 / 3.0 / (4.0 * PI).sqrt();
        assert!((f64::from(sh[0][1]) - dc).abs() < 2e-3 * dc, "{} vs {dc}", sh[0][1]);
        // Irradiance on an upward plane from order-3 SH: Σ Â_l L_lm y_lm(up).
        let mut basis = [0.0f32; 9];
        crate::sh::eval_basis(3, glam::Vec3::Y, &mut basis);
        let kernel = [PI, 2.0 * PI / 3.0, PI / 4.0];
        let e: f64 = (0..9).map(|i| kernel[(i as f64).sqrt() as usize] * f64::from(sh[i][1]) * f64::from(basis[i])).sum();
        // Order 3 truncates a hemisphere-cut function: a few per cent off.
        assert!((e - TYPICAL_OVERCAST_LUX).abs() < 0.05 * TYPICAL_OVERCAST_LUX, "{e}");
    }
}
