//! Spherical harmonics: basis evaluation, projection of environment maps and
//! analytic functions, rotation, and per-band kernels (clamped cosine,
//! anti-ringing windows).
//!
//! Conventions (full text in docs/conventions.md):
//! - real, orthonormal SH **without** the Condon–Shortley phase:
//!   y_1,−1 = +0.488603·y, y_1,0 = +0.488603·z, y_1,1 = +0.488603·x;
//! - SH polar axis is world +Z (θ from +Z, φ from +X toward +Y), although the
//!   world is +Y up;
//! - coefficient index `i = l(l+1)+m`; "order n" means bands `l < n`, n²
//!   coefficients;
//! - equirect maps: row 0 is up (+Y), the image centre looks toward −Z,
//!   u = 0.75 toward +X;
//! - RGB coefficients are `[f32; 3]` per index; multi-channel flat buffers are
//!   interleaved `[coeff][channel]`.

mod basis;
mod envmap;
mod kernel;
mod quadrature;
mod rgbe;
mod rotate;

pub use basis::{band_of_index, coeff_count, eval_basis, eval_basis_f64, evaluate, evaluate_rgb, sh_index, MAX_ORDER};
pub use envmap::{equirect_direction, equirect_uv, load_equirect, project_equirect, EnvMapError, EquirectImage};
pub use kernel::{apply_window, clamped_cosine_kernel, convolve_clamped_cosine, convolve_clamped_cosine_rgb, window_weights, Window};
pub use quadrature::{gauss_legendre, project_function};
pub use rgbe::{HdrProblem, MAX_PIXELS};
pub use rotate::ShRotation;
