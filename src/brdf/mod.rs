//! BRDFs of the LCD panel for the final gather (docs/panel.md):
//! an eye ray reaches a panel texel, and reflected rays are drawn from the
//! panel's BRDF (seed 000, section 4.3).
//!
//! Three BRDFs share the [`Brdf`] trait:
//! - [`AntiGlare`] (`analytic`): the default, an anti-glare coated black panel
//!   (Lambertian haze + a rough GGX dielectric lobe);
//! - [`TabulatedBrdf`] (`tabulated`, `text_format`): a measured isotropic table
//!   in a documented text format, interpolated multi-linearly as the paper does;
//! - [`MerlBrdf`] (`merl`, `merl_fit`): the MERL binary layout (Matusik et al. 2003).
//!
//! Directions are in the local frame (`frame`): normal +Z, `wi` and `wo` unit
//! and pointing away from the surface. Sampling takes explicit uniform numbers
//! and returns the exact density of what it draws, so `f · cos θi / pdf` is an
//! unbiased estimate of the reflected light.

pub mod analytic;
pub mod energy;
pub mod error;
pub mod frame;
pub mod merl;
mod merl_fit;
mod merl_grid;
pub mod microfacet;
pub mod sampling;
pub mod tabulated;
#[cfg(test)]
pub(crate) mod test_support;
pub mod text_format;

pub use analytic::AntiGlare;
pub use energy::{albedo_quadrature, pdf_quadrature, Albedo, EnergyReport, ALBEDO_GRID};
pub use error::BrdfError;
pub use merl::{FittedLobe, MerlBrdf};
pub use tabulated::TabulatedBrdf;

use glam::Vec3;
use std::path::Path;

/// A direction drawn by [`Brdf::sample`] and its density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrdfSample {
    /// Unit direction toward the light, `wi.z > 0`.
    pub wi: Vec3,
    /// Density per unit solid angle of drawing `wi`, `> 0`; equals `pdf(wo, wi)`.
    pub pdf: f32,
}

/// A reflectance function of an opaque surface, in the local frame.
pub trait Brdf: Send + Sync {
    /// `f(wi, wo)` per RGB channel, in 1/sr; zero when either direction is
    /// at or below the surface.
    fn eval(&self, wi: Vec3, wo: Vec3) -> [f32; 3];

    /// Draws `wi` for the eye direction `wo` from `u` in [0,1)². `None` when
    /// the draw is lost (below the surface, or a black BRDF): the estimator
    /// then counts zero, which the density already accounts for.
    fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BrdfSample>;

    /// Density per unit solid angle with which [`Brdf::sample`] draws `wi`;
    /// integrates to at most 1 over the upper hemisphere.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32;

    /// Directional albedo `∫ f cos θi dωi` by quadrature on [`ALBEDO_GRID`]
    /// (for reports: see [`EnergyReport`]).
    fn albedo(&self, wo: Vec3) -> Albedo {
        let a = albedo_quadrature(self, wo, ALBEDO_GRID.0, ALBEDO_GRID.1);
        Albedo { rgb: a.map(|x| x as f32) }
    }
}

/// The BRDF of the panel: whichever of the three kinds was chosen.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)] // one per panel; the tables themselves live on the heap
pub enum PanelBrdf {
    AntiGlare(AntiGlare),
    Tabulated(TabulatedBrdf),
    Merl(MerlBrdf),
}

impl Default for PanelBrdf {
    fn default() -> Self {
        PanelBrdf::AntiGlare(AntiGlare::default())
    }
}

impl PanelBrdf {
    /// Loads a measured BRDF: a MERL file when the name ends in `.binary` (as
    /// the MERL database names them), the text table otherwise.
    pub fn load(path: &Path) -> Result<PanelBrdf, BrdfError> {
        let is_merl = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("binary"));
        if is_merl {
            MerlBrdf::load(path).map(PanelBrdf::Merl)
        } else {
            TabulatedBrdf::load(path).map(PanelBrdf::Tabulated)
        }
    }

    fn inner(&self) -> &dyn Brdf {
        match self {
            PanelBrdf::AntiGlare(b) => b,
            PanelBrdf::Tabulated(b) => b,
            PanelBrdf::Merl(b) => b,
        }
    }
}

impl Brdf for PanelBrdf {
    fn eval(&self, wi: Vec3, wo: Vec3) -> [f32; 3] {
        self.inner().eval(wi, wo)
    }
    fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BrdfSample> {
        self.inner().sample(wo, u)
    }
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.inner().pdf(wo, wi)
    }
}

/// Reads a BRDF file through the bounded reader (`Limit::Brdf`).
fn read_brdf_file(path: &Path) -> Result<Vec<u8>, BrdfError> {
    crate::files::read_limited(path, crate::files::Limit::Brdf).map_err(|source| BrdfError::Read { path: path.to_path_buf(), source })
}
