//! The default panel BRDF: a black LCD under an anti-glare (AG) film.
//!
//! `f = haze / π + D(h) G2(wi, wo) F(wi·h) / (4 cos θi cos θo)`: a Lambertian
//! haze (light scattered back out of the dark pixel matrix) plus a rough GGX
//! reflection off the film's polymer surface with the dielectric Fresnel term.
//! The film's embossed micro-relief is what the roughness stands for: it
//! spreads the mirror image of a bright window into a broad glow.

use super::frame::both_above;
use super::microfacet::{fresnel_dielectric, ggx_d, lobe_or_cosine_pdf, sample_lobe_or_cosine, smith_g2};
use super::{Brdf, BrdfError, BrdfSample};
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Parameters of the anti-glare coating (docs/panel.md explains the defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AntiGlare {
    /// Albedo of the Lambertian haze per RGB channel (default 0.03: a black panel).
    pub haze_albedo: [f32; 3],
    /// GGX roughness α of the film's surface (default 0.2).
    pub alpha: f32,
    /// Refractive index of the film (default 1.5: 4 % reflectance at normal incidence).
    pub ior: f32,
}

impl Default for AntiGlare {
    fn default() -> Self {
        AntiGlare { haze_albedo: [0.03; 3], alpha: 0.2, ior: 1.5 }
    }
}

impl AntiGlare {
    /// Checks the ranges: haze in [0, 1], α in [0.01, 1], index in (1, 3].
    pub fn new(haze_albedo: [f32; 3], alpha: f32, ior: f32) -> Result<AntiGlare, BrdfError> {
        let bad = |message: String| Err(BrdfError::Parameter { message });
        if haze_albedo.iter().any(|a| !(0.0..=1.0).contains(a)) {
            return bad(format!("anti-glare haze albedo {haze_albedo:?} must lie in [0, 1]"));
        }
        if !(0.01..=1.0).contains(&alpha) {
            return bad(format!("anti-glare roughness {alpha} must lie in [0.01, 1]"));
        }
        if !(ior > 1.0 && ior <= 3.0) {
            return bad(format!("anti-glare refractive index {ior} must lie in (1, 3]"));
        }
        Ok(AntiGlare { haze_albedo, alpha, ior })
    }

    /// Probability of drawing from the specular lobe rather than the cosine:
    /// the Fresnel reflectance seen from `wo` against the haze, so grazing
    /// views (where the film mirrors) spend their samples on the lobe.
    fn specular_probability(&self, wo: Vec3) -> f32 {
        let specular = fresnel_dielectric(wo.z, self.ior);
        let haze = self.haze_albedo.iter().copied().fold(0.0, f32::max);
        (specular / (specular + haze)).clamp(0.05, 0.95)
    }
}

impl Brdf for AntiGlare {
    fn eval(&self, wi: Vec3, wo: Vec3) -> [f32; 3] {
        if !both_above(wi, wo) {
            return [0.0; 3];
        }
        let h = (wi + wo).normalize();
        // wi·h = wo·h in exact arithmetic; their mean keeps f(wi, wo) and
        // f(wo, wi) bit-identical.
        let cos_d = 0.5 * (wi.dot(h) + wo.dot(h));
        let specular = ggx_d(h, self.alpha) * smith_g2(wi, wo, self.alpha) * fresnel_dielectric(cos_d, self.ior) / (4.0 * (wi.z * wo.z));
        self.haze_albedo.map(|a| a * FRAC_1_PI + specular)
    }

    fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BrdfSample> {
        let wi = sample_lobe_or_cosine(wo, self.alpha, self.specular_probability(wo), u)?;
        let pdf = self.pdf(wo, wi);
        (pdf > 0.0).then_some(BrdfSample { wi, pdf })
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        lobe_or_cosine_pdf(wo, wi, self.alpha, self.specular_probability(wo))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::*;

    #[test]
    fn sampling_is_unbiased() {
        check_unbiased("analytic", &AntiGlare::default(), &THETA_OUT_DEG);
        check_unbiased("analytic tinted", &tinted_coating(), &[45.0]);
    }

    #[test]
    fn pdf_integrates_to_at_most_one_and_matches_the_samples() {
        check_pdf("analytic", &AntiGlare::default(), &THETA_OUT_DEG, None);
    }

    #[test]
    fn reciprocity_is_exact() {
        let brdf = tinted_coating();
        let mut checked = 0;
        for i in 0..20_000 {
            let [a, b] = uniform_pair(7, i);
            let [c, d] = uniform_pair(8, i);
            let wi = super::super::frame::from_mu_phi(a, std::f32::consts::TAU * b);
            let wo = super::super::frame::from_mu_phi(c, std::f32::consts::TAU * d);
            assert_eq!(brdf.eval(wi, wo), brdf.eval(wo, wi), "wi {wi} wo {wo}");
            checked += 1;
        }
        assert_eq!(checked, 20_000);
    }

    #[test]
    fn albedo_stays_below_one_at_every_angle() {
        let report = super::super::EnergyReport::of(&AntiGlare::default());
        let (deg, worst) = report.worst();
        println!("analytic max albedo {:.4} at theta_out {deg}", worst.max());
        for (deg, albedo) in &report.rows {
            println!("  theta_out {deg:>4}: albedo {:.4}", albedo.rgb[0]);
        }
        assert!(!worst.exceeds_one());
        assert!(report.warning("antiglare").is_none());
        // The report's grid agrees with a 4x finer one.
        for deg in [0.0f32, 80.0, 89.0] {
            let wo = wo_at(deg);
            let coarse = AntiGlare::default().albedo(wo).rgb[0] as f64;
            let fine = super::super::albedo_quadrature(&AntiGlare::default(), wo, 512, 1024)[0];
            println!(
                "analytic theta_out {deg}: report grid {coarse:.6} vs 4x finer {fine:.6} ({:.1e} relative)",
                (coarse - fine).abs() / fine
            );
            assert!((coarse - fine).abs() < 3e-3 * fine, "theta_out {deg}: {coarse} vs {fine}");
        }
    }

    #[test]
    fn parameters_out_of_range_are_refused() {
        assert!(AntiGlare::new([0.03; 3], 0.0, 1.5).is_err());
        assert!(AntiGlare::new([0.03; 3], 0.2, 1.0).is_err());
        assert!(AntiGlare::new([f32::NAN, 0.0, 0.0], 0.2, 1.5).is_err());
        assert!(AntiGlare::new([0.03; 3], f32::NAN, 1.5).is_err());
    }
}
