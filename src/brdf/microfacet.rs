//! GGX (Trowbridge–Reitz) microfacets: the distribution, Smith's masking, the
//! dielectric Fresnel term, and sampling of the visible normals (Heitz 2018).
//! Shared by the analytic coating and the lobe the MERL sampler fits.

use super::frame::{cosine_pdf, cosine_sample, reflect};
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, TAU};

/// GGX normal distribution `D(h)` for roughness `alpha` (per unit solid angle of `h`).
#[inline]
pub fn ggx_d(h: Vec3, alpha: f32) -> f32 {
    if h.z <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let d = h.z * h.z * (a2 - 1.0) + 1.0;
    a2 * FRAC_1_PI / (d * d)
}

/// Smith's Λ for GGX: the masking of direction `w` is `1 / (1 + Λ(w))`.
#[inline]
pub fn smith_lambda(w: Vec3, alpha: f32) -> f32 {
    let cos2 = w.z * w.z;
    if w.z <= 0.0 {
        return f32::INFINITY;
    }
    let tan2 = (1.0 - cos2).max(0.0) / cos2;
    0.5 * ((1.0 + alpha * alpha * tan2).sqrt() - 1.0)
}

/// Smith masking of one direction.
#[inline]
pub fn smith_g1(w: Vec3, alpha: f32) -> f32 {
    1.0 / (1.0 + smith_lambda(w, alpha))
}

/// Height-correlated Smith masking-shadowing; the sum `Λi + Λo` is formed
/// first so that swapping the directions gives the same bits (reciprocity).
#[inline]
pub fn smith_g2(wi: Vec3, wo: Vec3, alpha: f32) -> f32 {
    1.0 / (1.0 + (smith_lambda(wi, alpha) + smith_lambda(wo, alpha)))
}

/// Unpolarised Fresnel reflectance of a dielectric of index `ior` (outside
/// index 1) at incidence cosine `cos_i`: 4 % at normal incidence for 1.5.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, ior: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (ior * ior);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - ior * cos_t) / (cos_i + ior * cos_t);
    let rp = (ior * cos_i - cos_t) / (ior * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// A microfacet normal drawn from the GGX distribution of normals visible
/// from `wo` (`wo.z > 0`), `D_wo(h) = G1(wo) max(0, wo·h) D(h) / wo.z`
/// (Heitz 2018, "Sampling the GGX distribution of visible normals").
pub fn sample_visible_normal(wo: Vec3, alpha: f32, u: [f32; 2]) -> Vec3 {
    // Stretch to the hemisphere configuration (alpha = 1).
    let v = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2 > 0.0 { Vec3::new(-v.y, v.x, 0.0) / len2.sqrt() } else { Vec3::X };
    let t2 = v.cross(t1);
    // A point on the projected disk, warped toward the visible half.
    let r = u[0].sqrt();
    let (sin_p, cos_p) = (TAU * u[1]).sin_cos();
    let p1 = r * cos_p;
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sin_p;
    let n = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * v;
    // Unstretch.
    Vec3::new(alpha * n.x, alpha * n.y, n.z.max(0.0)).normalize()
}

/// `wi` by reflecting `wo` about a visible normal; `None` when it points below
/// the surface (the sample is lost, which [`reflection_pdf`] accounts for).
pub fn sample_reflection(wo: Vec3, alpha: f32, u: [f32; 2]) -> Option<Vec3> {
    let h = sample_visible_normal(wo, alpha, u);
    let wi = reflect(wo, h);
    (wi.z > 0.0 && wi.is_finite()).then_some(wi)
}

/// Density per unit solid angle of `wi` under [`sample_reflection`]:
/// `D_wo(h) / (4 wo·h) = G1(wo) D(h) / (4 wo.z)` with `h` the half vector.
pub fn reflection_pdf(wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let h = (wi + wo).normalize();
    smith_g1(wo, alpha) * ggx_d(h, alpha) / (4.0 * wo.z)
}

/// The two-strategy sampler the analytic coating and the MERL fit share:
/// with probability `p_lobe` a GGX reflection of roughness `alpha`, else a
/// cosine-weighted direction. One `u` serves both: `u[0]` picks, then is rescaled.
pub fn sample_lobe_or_cosine(wo: Vec3, alpha: f32, p_lobe: f32, u: [f32; 2]) -> Option<Vec3> {
    if wo.z <= 0.0 {
        return None;
    }
    if u[0] < p_lobe {
        sample_reflection(wo, alpha, [u[0] / p_lobe, u[1]])
    } else {
        let wi = cosine_sample([((u[0] - p_lobe) / (1.0 - p_lobe)).min(1.0 - f32::EPSILON), u[1]]);
        (wi.z > 0.0).then_some(wi)
    }
}

/// The exact density of [`sample_lobe_or_cosine`]: the mixture of both densities.
pub fn lobe_or_cosine_pdf(wo: Vec3, wi: Vec3, alpha: f32, p_lobe: f32) -> f32 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    p_lobe * reflection_pdf(wo, wi, alpha) + (1.0 - p_lobe) * cosine_pdf(wi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ggx_d_projected_integrates_to_one_and_fresnel_is_four_percent_at_normal_incidence() {
        // ∫ D(h) cos θh dωh = 1, midpoint rule in (cos θ, φ) (D is isotropic).
        for alpha in [0.1f32, 0.2, 0.5] {
            let n = 20_000;
            let sum: f64 = (0..n)
                .map(|k| {
                    let mu = (k as f32 + 0.5) / n as f32;
                    let h = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                    f64::from(ggx_d(h, alpha) * mu) * std::f64::consts::TAU / n as f64
                })
                .sum();
            assert!((sum - 1.0).abs() < 1e-3, "alpha {alpha}: {sum}");
        }
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(0.0, 1.5), 1.0);
    }

    #[test]
    fn visible_normals_face_the_viewer() {
        let wo = Vec3::new(0.9, 0.1, 0.2).normalize();
        for i in 0..64 {
            let u = [(i as f32 + 0.5) / 64.0, ((i * 37) % 64) as f32 / 64.0];
            let h = sample_visible_normal(wo, 0.3, u);
            assert!(h.z >= 0.0 && wo.dot(h) >= -1e-6 && (h.length() - 1.0).abs() < 1e-5, "{h}");
        }
    }
}
