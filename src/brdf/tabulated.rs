//! A measured isotropic BRDF tabulated on a (θ_in, θ_out, Δφ) grid (the text
//! format of `text_format`), interpolated multi-linearly in the three angles
//! as seed 000 does ("bilinear interpolation" of 1° data), and importance
//! sampled by tabulated CDFs per θ_out row.
//!
//! Sampling for a `wo` between rows k and k+1 (weight t toward k+1): pick a
//! row with probabilities (1−t, t), then a θ_in cell from the row's marginal,
//! then a Δφ cell from its conditional, uniform in (cos θ, φ) inside the cell,
//! and a side (±Δφ) with probability ½ each. Cell weights are
//! `mean of the 4 corner values × mean cos θ × solid angle`, which is > 0
//! wherever the interpolated BRDF is, so the estimator stays unbiased. The
//! density is the two rows' densities mixed by (1−t, t).

use super::frame::{both_above, delta_phi, from_mu_phi, phi, theta};
use super::sampling::DiscreteTables;
use super::text_format::{parse_table, TableGrid};
use super::{read_brdf_file, Brdf, BrdfError, BrdfSample};
use glam::Vec3;
use std::path::Path;

/// A tabulated isotropic BRDF with its sampling tables.
#[derive(Clone)]
pub struct TabulatedBrdf {
    grid: TableGrid,
    sampler: CellSampler,
}

/// The CDFs over the cells between grid nodes (extended to 0°–90° in θ_in
/// and 0°–180° in Δφ, so the cells cover the whole hemisphere).
#[derive(Clone, Debug)]
struct CellSampler {
    /// cos θ at the θ_in cell edges, decreasing.
    mu_edges: Vec<f32>,
    /// Width in cos θ of each θ_in cell.
    mu_width: Vec<f32>,
    /// Δφ cell edges in radians, increasing over [0, π].
    phi_edges: Vec<f32>,
    /// Width in radians of each Δφ cell.
    phi_width: Vec<f32>,
    /// Per θ_out row: the marginal over θ_in cells.
    theta_cells: DiscreteTables,
    /// Per (θ_out row, θ_in cell): the conditional over Δφ cells.
    phi_cells: DiscreteTables,
}

impl TabulatedBrdf {
    /// Reads and parses a table file (at most `Limit::Brdf` bytes).
    pub fn load(path: &Path) -> Result<TabulatedBrdf, BrdfError> {
        let bytes = read_brdf_file(path)?;
        TabulatedBrdf::parse(&bytes, path)
    }

    /// Parses table bytes; `path` names the source in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<TabulatedBrdf, BrdfError> {
        Ok(TabulatedBrdf::from_grid(parse_table(bytes, path)?))
    }

    /// Builds the sampler of a checked grid (axes increasing within their
    /// ranges, values finite and ≥ 0, as `parse_table` guarantees).
    fn from_grid(grid: TableGrid) -> TabulatedBrdf {
        let sampler = CellSampler::build(&grid);
        TabulatedBrdf { grid, sampler }
    }

    /// Number of nodes along (θ_in, θ_out, Δφ).
    pub fn grid_size(&self) -> [usize; 3] {
        [self.grid.theta_in_deg.len(), self.grid.theta_out_deg.len(), self.grid.delta_phi_deg.len()]
    }

    /// The largest relative asymmetry `|f(a, b, Δφ) − f(b, a, Δφ)| / max f`
    /// over the table, when θ_in and θ_out share their nodes (else `None`):
    /// 0 for a reciprocal table.
    pub fn reciprocity_error(&self) -> Option<f32> {
        let g = &self.grid;
        if g.theta_in_deg != g.theta_out_deg {
            return None;
        }
        let (n, n_phi) = (g.theta_in_deg.len(), g.delta_phi_deg.len());
        let largest = g.values.iter().flatten().copied().fold(0.0f32, f32::max);
        let mut worst = 0.0f32;
        for a in 0..n {
            for b in 0..a {
                for p in 0..n_phi {
                    let (x, y) = (g.values[(a * n + b) * n_phi + p], g.values[(b * n + a) * n_phi + p]);
                    (0..3).for_each(|c| worst = worst.max((x[c] - y[c]).abs()));
                }
            }
        }
        Some(if largest > 0.0 { worst / largest } else { 0.0 })
    }

    /// Density of `wi` within θ_out row `out`.
    fn row_pdf(&self, out: usize, theta_cell: usize, phi_cell: usize) -> f32 {
        let s = &self.sampler;
        let p = s.theta_cells.probability(out, theta_cell) * s.phi_cells.probability(out * s.mu_width.len() + theta_cell, phi_cell);
        // Each Δφ cell appears on both sides of wo's azimuth.
        p / (2.0 * s.mu_width[theta_cell] * s.phi_width[phi_cell])
    }
}

/// A summary: a 1° table has 1.5 M values.
impl std::fmt::Debug for TabulatedBrdf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TabulatedBrdf").field("grid_size", &self.grid_size()).finish_non_exhaustive()
    }
}

impl CellSampler {
    fn build(grid: &TableGrid) -> CellSampler {
        let theta_edges = cell_edges(&grid.theta_in_deg, 90.0);
        let phi_edges_deg = cell_edges(&grid.delta_phi_deg, 180.0);
        let mu_edges64: Vec<f64> = theta_edges.iter().map(|&t| f64::from(t).to_radians().cos()).collect();
        let phi_edges64: Vec<f64> = phi_edges_deg.iter().map(|&p| f64::from(p).to_radians()).collect();
        let (n_theta, n_phi) = (theta_edges.len() - 1, phi_edges_deg.len() - 1);
        let mu_width: Vec<f64> = mu_edges64.windows(2).map(|w| w[0] - w[1]).collect();
        let phi_width: Vec<f64> = phi_edges64.windows(2).map(|w| w[1] - w[0]).collect();
        let mean_mu: Vec<f64> = mu_edges64.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        // Luminance (channel mean) at every (θ_out row, θ_in edge, Δφ edge).
        let rows = grid.theta_out_deg.len();
        let mut corners = Vec::with_capacity(rows * theta_edges.len() * phi_edges_deg.len());
        for out in 0..rows {
            for &t in &theta_edges {
                for &p in &phi_edges_deg {
                    corners.push(row_value(grid, out, t, p).iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0);
                }
            }
        }
        let corner = |out: usize, t: usize, p: usize| corners[(out * (n_theta + 1) + t) * (n_phi + 1) + p];
        let cell_weight = |out: usize, t: usize, p: usize| {
            let mean = 0.25 * (corner(out, t, p) + corner(out, t, p + 1) + corner(out, t + 1, p) + corner(out, t + 1, p + 1));
            mean * mean_mu[t] * mu_width[t] * phi_width[p]
        };
        let phi_cells = DiscreteTables::build(rows * n_theta, n_phi, |row, p| cell_weight(row / n_theta, row % n_theta, p));
        let theta_cells = DiscreteTables::build(rows, n_theta, |out, t| phi_cells.total(out * n_theta + t));
        CellSampler {
            mu_edges: mu_edges64.iter().map(|&m| m as f32).collect(),
            mu_width: mu_width.iter().map(|&w| w as f32).collect(),
            phi_edges: phi_edges64.iter().map(|&p| p as f32).collect(),
            phi_width: phi_width.iter().map(|&w| w as f32).collect(),
            theta_cells,
            phi_cells,
        }
    }

    /// The θ_in cell holding `mu` (edges decreasing; an edge belongs to the cell below it in θ).
    fn theta_cell(&self, mu: f32) -> usize {
        self.mu_edges.partition_point(|&m| m >= mu).clamp(1, self.mu_width.len()) - 1
    }

    /// The Δφ cell holding `dphi` radians.
    fn phi_cell(&self, dphi: f32) -> usize {
        self.phi_edges.partition_point(|&e| e <= dphi).clamp(1, self.phi_width.len()) - 1
    }
}

impl Brdf for TabulatedBrdf {
    fn eval(&self, wi: Vec3, wo: Vec3) -> [f32; 3] {
        if !both_above(wi, wo) {
            return [0.0; 3];
        }
        let (ti, to, dp) = (theta(wi).to_degrees(), theta(wo).to_degrees(), delta_phi(wi, wo).to_degrees());
        let (o0, o1, t) = locate(&self.grid.theta_out_deg, to);
        let a = row_value(&self.grid, o0, ti, dp);
        if t == 0.0 {
            return a;
        }
        let b = row_value(&self.grid, o1, ti, dp);
        std::array::from_fn(|k| a[k] + (b[k] - a[k]) * t)
    }

    fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BrdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let s = &self.sampler;
        let (o0, o1, t) = locate(&self.grid.theta_out_deg, theta(wo).to_degrees());
        let stay = 1.0 - t;
        let (out, u0) = if u[0] < stay { (o0, u[0] / stay) } else { (o1, (u[0] - stay) / t) };
        let (theta_cell, along_mu) = s.theta_cells.sample(out, u0)?;
        let (phi_cell, along_phi) = s.phi_cells.sample(out * s.mu_width.len() + theta_cell, u[1])?;
        let mu = s.mu_edges[theta_cell] - along_mu * s.mu_width[theta_cell];
        let (side, along_phi) = if along_phi < 0.5 { (1.0, 2.0 * along_phi) } else { (-1.0, 2.0 * along_phi - 1.0) };
        let dphi = s.phi_edges[phi_cell] + along_phi * s.phi_width[phi_cell];
        let wi = from_mu_phi(mu, phi(wo) + side * dphi);
        let pdf = self.pdf(wo, wi);
        (wi.z > 0.0 && pdf > 0.0).then_some(BrdfSample { wi, pdf })
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if !both_above(wi, wo) {
            return 0.0;
        }
        let (o0, o1, t) = locate(&self.grid.theta_out_deg, theta(wo).to_degrees());
        let (theta_cell, phi_cell) = (self.sampler.theta_cell(wi.z), self.sampler.phi_cell(delta_phi(wi, wo)));
        let low = self.row_pdf(o0, theta_cell, phi_cell);
        if t == 0.0 {
            return low;
        }
        (1.0 - t) * low + t * self.row_pdf(o1, theta_cell, phi_cell)
    }
}

/// Bilinear value at θ_out node `out`, θ_in and Δφ in degrees (clamped to the grid).
fn row_value(grid: &TableGrid, out: usize, theta_in_deg: f32, delta_phi_deg: f32) -> [f32; 3] {
    let (i0, i1, ti) = locate(&grid.theta_in_deg, theta_in_deg);
    let (p0, p1, tp) = locate(&grid.delta_phi_deg, delta_phi_deg);
    let (n_in, n_phi) = (grid.theta_in_deg.len(), grid.delta_phi_deg.len());
    let at = |i: usize, p: usize| grid.values[(out * n_in + i) * n_phi + p];
    let (a, b, c, d) = (at(i0, p0), at(i0, p1), at(i1, p0), at(i1, p1));
    std::array::from_fn(|k| {
        let low = a[k] + (b[k] - a[k]) * tp;
        let high = c[k] + (d[k] - c[k]) * tp;
        low + (high - low) * ti
    })
}

/// Lower node, upper node and fraction of `x` between them; clamped to the
/// end nodes outside the grid (constant extrapolation).
fn locate(nodes: &[f32], x: f32) -> (usize, usize, f32) {
    let last = nodes.len() - 1;
    if x.is_nan() || x <= nodes[0] {
        return (0, 0, 0.0);
    }
    if x >= nodes[last] {
        return (last, last, 0.0);
    }
    let i = nodes.partition_point(|&n| n <= x) - 1;
    (i, i + 1, ((x - nodes[i]) / (nodes[i + 1] - nodes[i])).clamp(0.0, 1.0))
}

/// The nodes with the domain's ends added where missing: the edges of cells
/// that cover `[0, end]`.
fn cell_edges(nodes: &[f32], end: f32) -> Vec<f32> {
    let mut edges = Vec::with_capacity(nodes.len() + 2);
    if nodes[0] > 0.0 {
        edges.push(0.0);
    }
    edges.extend_from_slice(nodes);
    if nodes[nodes.len() - 1] < end {
        edges.push(end);
    }
    edges
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::{AntiGlare, EnergyReport};
    use super::*;
    use std::sync::OnceLock;

    /// The tinted coating on a 2° grid over the whole hemisphere, read back from a file.
    fn coating_table() -> &'static TabulatedBrdf {
        static TABLE: OnceLock<TabulatedBrdf> = OnceLock::new();
        TABLE.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("coating.brdf");
            std::fs::write(&path, table_text(&tinted_coating(), 2.0, (0.0, 90.0), (0.0, 180.0))).unwrap();
            TabulatedBrdf::load(&path).unwrap()
        })
    }

    /// Relative noise per sample of the albedo estimator `f cos / pdf` (the
    /// gather's), green channel, mean over viewing angles.
    fn relative_noise(brdf: &dyn Brdf) -> f64 {
        let angles = [0.0f32, 20.0, 40.0, 60.0, 75.0];
        let n = 20_000u32;
        angles
            .iter()
            .enumerate()
            .map(|(k, &deg)| {
                let mc = mc_albedo(brdf, wo_at(deg), n, 77 + k as u32);
                mc.sigma[1] * f64::from(n).sqrt() / mc.mean[1]
            })
            .sum::<f64>()
            / angles.len() as f64
    }

    #[test]
    fn a_table_samples_nearly_as_well_as_its_analytic_source() {
        let analytic = tinted_coating();
        for step in [2.0f32, 5.0] {
            let table =
                TabulatedBrdf::parse(table_text(&analytic, step, (0.0, 90.0), (0.0, 180.0)).as_bytes(), Path::new("t.brdf")).unwrap();
            let (a, t) = (relative_noise(&analytic), relative_noise(&table));
            println!("relative noise per sample: analytic {a:.3}, {step}° table {t:.3} ({:.2}x)", t / a);
            assert!(t < 1.6 * a, "{step}° table: {t} against the analytic {a}");
        }
    }

    #[test]
    fn sampling_is_unbiased() {
        check_unbiased("tabulated 2°", coating_table(), &THETA_OUT_DEG);
    }

    #[test]
    fn pdf_integrates_to_one_and_matches_the_samples() {
        check_pdf("tabulated 2°", coating_table(), &THETA_OUT_DEG, Some(1.0));
    }

    #[test]
    fn a_table_that_does_not_cover_the_hemisphere_is_still_sampled_without_bias() {
        // Nodes 10°..80° in θ and 30°..150° in Δφ: the end cells extend the
        // table's constant extrapolation to 0°–90° and 0°–180°.
        let text = table_text(&AntiGlare::default(), 10.0, (10.0, 80.0), (30.0, 150.0));
        let brdf = TabulatedBrdf::parse(text.as_bytes(), Path::new("partial.brdf")).unwrap();
        assert_eq!(brdf.grid_size(), [8, 8, 13]);
        check_unbiased("tabulated partial", &brdf, &[0.0, 45.0, 85.0]);
        check_pdf("tabulated partial", &brdf, &[0.0, 85.0], Some(1.0));
    }

    #[test]
    fn interpolation_hits_the_nodes_and_the_table_is_reciprocal() {
        let brdf = coating_table();
        let asymmetry = brdf.reciprocity_error().unwrap();
        println!("tabulated 2°: largest relative asymmetry of the table {asymmetry:.2e}");
        assert!(asymmetry < 1e-5);
        let analytic = tinted_coating();
        for (ti, to, p) in [(0.0f32, 0.0f32, 0.0f32), (20.0, 40.0, 180.0), (60.0, 60.0, 180.0), (30.0, 80.0, 90.0), (88.0, 10.0, 2.0)] {
            let wi = super::super::frame::from_spherical(ti.to_radians(), (p + 25.0).to_radians());
            let wo = super::super::frame::from_spherical(to.to_radians(), 25f32.to_radians());
            let (table, exact) = (brdf.eval(wi, wo), analytic.eval(wi, wo));
            let swapped = brdf.eval(wo, wi);
            for c in 0..3 {
                assert!((table[c] - exact[c]).abs() <= 1e-4 * exact[c] + 1e-7, "node ({ti}, {to}, {p}): {table:?} vs {exact:?}");
                assert!(
                    (table[c] - swapped[c]).abs() <= 1e-4 * table[c] + 1e-7,
                    "node ({ti}, {to}, {p}): {table:?} vs swapped {swapped:?}"
                );
            }
        }
        // Off the nodes, interpolation of a symmetric table on equal axes is symmetric too.
        let mut worst = 0.0f32;
        for i in 0..5000 {
            let [a, b] = uniform_pair(11, i);
            let [c, d] = uniform_pair(12, i);
            let wi = super::super::frame::from_mu_phi(a, std::f32::consts::TAU * b);
            let wo = super::super::frame::from_mu_phi(c, std::f32::consts::TAU * d);
            let (x, y) = (brdf.eval(wi, wo), brdf.eval(wo, wi));
            for k in 0..3 {
                worst = worst.max((x[k] - y[k]).abs() / x[k].max(1e-6));
            }
        }
        println!("tabulated 2°: off-node reciprocity, largest relative difference {worst:.2e}");
        assert!(worst < 1e-3);
    }

    #[test]
    fn the_table_reproduces_the_coating_albedo() {
        for deg in [0.0f32, 30.0, 60.0, 80.0] {
            let wo = wo_at(deg);
            let (table, exact) = (coating_table().albedo(wo).rgb, tinted_coating().albedo(wo).rgb);
            println!("tabulated 2° theta_out {deg}: albedo RGB {table:.5?} vs analytic {exact:.5?}");
            for c in 0..3 {
                assert!((table[c] - exact[c]).abs() < 0.01 * exact[c], "theta_out {deg} channel {c}: {table:?} vs {exact:?}");
            }
        }
    }

    #[test]
    fn a_table_reflecting_more_than_it_receives_loads_and_is_reported() {
        let text = "prtbake-brdf 1\ntheta_in_deg 0 90\ntheta_out_deg 0 90\ndelta_phi_deg 0\n\
                    0 0 0 0.5 0.5 0.5\n90 0 0 0.5 0.5 0.5\n0 90 0 0.5 0.5 0.5\n90 90 0 0.5 0.5 0.5\n";
        let brdf = TabulatedBrdf::parse(text.as_bytes(), Path::new("bright.brdf")).unwrap();
        let albedo = brdf.albedo(wo_at(30.0));
        assert!((albedo.rgb[0] - 0.5 * std::f32::consts::PI).abs() < 1e-3 && albedo.exceeds_one(), "{albedo:?}");
        let warning = EnergyReport::of(&brdf).warning("bright.brdf").unwrap();
        assert!(warning.starts_with("bright.brdf: directional albedo reaches 1.571"), "{warning}");
        check_unbiased("tabulated constant", &brdf, &[30.0]);
    }

    #[test]
    fn a_black_table_is_never_sampled() {
        let text = "prtbake-brdf 1\ntheta_in_deg 45\ntheta_out_deg 45\ndelta_phi_deg 90\n45 45 90 0 0 0\n";
        let brdf = TabulatedBrdf::parse(text.as_bytes(), Path::new("black.brdf")).unwrap();
        assert_eq!(brdf.sample(wo_at(30.0), [0.3, 0.6]), None);
        assert_eq!(brdf.pdf(wo_at(30.0), wo_at(50.0)), 0.0);
        assert_eq!(brdf.eval(wo_at(10.0), wo_at(50.0)), [0.0; 3]);
    }
}
