//! The local shading frame every BRDF works in: the normal is +Z, and both
//! directions (`wi` toward the light, `wo` toward the eye) point away from the
//! surface and are unit length.

use glam::Vec3;

/// Polar angle from the normal in radians; `atan2`, not `acos`, so it stays
/// accurate near the normal where specular peaks sit.
#[inline]
pub fn theta(w: Vec3) -> f32 {
    w.x.hypot(w.y).atan2(w.z)
}

/// Azimuth in radians, in [−π, π]; exactly 0 on the normal (whatever the
/// signs of the zeros), so samplers and lookups agree there.
#[inline]
pub fn phi(w: Vec3) -> f32 {
    if w.x == 0.0 && w.y == 0.0 {
        0.0
    } else {
        w.y.atan2(w.x)
    }
}

/// `|φ(a) − φ(b)|` folded into [0, π]: 0 when the directions lie on the same
/// side of the normal (retro-reflection), π for the mirror configuration.
/// Symmetric in `a` and `b`; a direction on the normal has azimuth 0, the
/// same convention the samplers use for `wo` there.
#[inline]
pub fn delta_phi(a: Vec3, b: Vec3) -> f32 {
    let d = (phi(a) - phi(b)).abs();
    if d > std::f32::consts::PI {
        std::f32::consts::TAU - d
    } else {
        d
    }
}

/// Unit direction at polar angle `theta` and azimuth `phi` (radians).
#[inline]
pub fn from_spherical(theta: f32, phi: f32) -> Vec3 {
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    Vec3::new(sin_t * cos_p, sin_t * sin_p, cos_t)
}

/// Unit direction with `cos θ = mu` and azimuth `phi`: the map the samplers
/// and quadratures use, uniform cells in (cos θ, φ) having equal solid angle.
#[inline]
pub fn from_mu_phi(mu: f32, phi: f32) -> Vec3 {
    let sin_t = (1.0 - mu * mu).max(0.0).sqrt();
    let (sin_p, cos_p) = phi.sin_cos();
    Vec3::new(sin_t * cos_p, sin_t * sin_p, mu)
}

/// `w` reflected about the unit vector `h`.
#[inline]
pub fn reflect(w: Vec3, h: Vec3) -> Vec3 {
    2.0 * w.dot(h) * h - w
}

/// Both directions strictly above the surface: BRDFs are zero otherwise.
#[inline]
pub fn both_above(wi: Vec3, wo: Vec3) -> bool {
    wi.z > 0.0 && wo.z > 0.0
}

/// Cosine-weighted direction (pdf = cos θ / π) from `u` in [0,1)² (Malley).
#[inline]
pub fn cosine_sample(u: [f32; 2]) -> Vec3 {
    let r = u[0].sqrt();
    let (sin_p, cos_p) = (std::f32::consts::TAU * u[1]).sin_cos();
    Vec3::new(r * cos_p, r * sin_p, (1.0 - u[0]).max(0.0).sqrt())
}

/// The density of [`cosine_sample`] per unit solid angle.
#[inline]
pub fn cosine_pdf(wi: Vec3) -> f32 {
    wi.z.max(0.0) * std::f32::consts::FRAC_1_PI
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_round_trip_and_delta_phi_is_the_azimuth_gap() {
        let a = from_spherical(0.3, 2.9);
        let b = from_spherical(1.2, -2.9);
        assert!((theta(a) - 0.3).abs() < 1e-6 && (phi(a) - 2.9).abs() < 1e-6);
        // 2.9 and −2.9 are 2π − 5.8 = 0.4832 apart across ±π.
        assert!((delta_phi(a, b) - (std::f32::consts::TAU - 5.8)).abs() < 1e-5);
        // On the normal the azimuth is 0, whatever the zeros' signs.
        assert_eq!(phi(Vec3::new(-0.0, 0.0, 1.0)), 0.0);
        assert!((delta_phi(Vec3::Z, b) - 2.9).abs() < 1e-6);
        assert_eq!(delta_phi(a, b), delta_phi(b, a));
        let w = Vec3::new(0.6, 0.0, 0.8);
        assert!((reflect(w, Vec3::Z) - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-7);
        assert!((delta_phi(w, reflect(w, Vec3::Z)) - std::f32::consts::PI).abs() < 1e-6);
    }
}
