//! The MERL table's cells: 90 × 90 × 180 over `(θ_h, θ_d, φ_d)`, with θ_h
//! spaced on its square root so that cells crowd near the specular peak.
//! The table's lookup and the lobe fitted to it both place values here.

use std::f32::consts::{FRAC_PI_2, PI};

/// The angles `(θ_h, θ_d, φ_d)` of the centre of cell `(i_h, i_d, i_φ)`.
pub fn cell_centre(i_h: usize, i_d: usize, i_phi: usize) -> (f32, f32, f32) {
    let s = (i_h as f32 + 0.5) / 90.0;
    (s * s * FRAC_PI_2, (i_d as f32 + 0.5) / 90.0 * FRAC_PI_2, (i_phi as f32 + 0.5) / 180.0 * PI)
}
