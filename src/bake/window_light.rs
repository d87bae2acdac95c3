//! The glass as a light source for bounce 0 in window mode
//! (`--window-sampling`): a window triangle is picked by area, then a
//! direction drawn uniformly over the solid angle it subtends (Arvo 1995,
//! "Stratified sampling of spherical triangles"); the draws are combined
//! with the cosine rays by multiple importance sampling (balance heuristic,
//! Veach 1997), so that neither strategy's bad case survives: cosine rays
//! rarely find a small distant pane, and directions aimed at the glass
//! waste draws on panes a point sees at grazing angles.
//!
//! Sampling by solid angle rather than by area keeps the light pdf bounded
//! next to the glass (by area it is `A |cos θ_w| / r²` in solid angle,
//! which made the old next-event estimator's weights explode as r → 0 on
//! the Ferrari, whose glass meets the body). Panes subtending less than
//! [`MIN_SOLID_ANGLE`] are sampled by area instead, where the spherical
//! formulas lose precision and the two pdfs agree anyway.

use glam::{DVec3, Vec3};

use super::surfaces::Surfaces;
use super::transfer::triangle_area;
use crate::mesh::Mesh;
use crate::sampling::square_to_triangle;

/// Below this solid angle (sr) a pane is sampled by area: the spherical
/// triangle's angles cancel to this many ulps of π in f64.
pub(crate) const MIN_SOLID_ANGLE: f64 = 1e-9;

/// The window triangles of a scene with their pick probabilities (by area).
pub(crate) struct WindowLights {
    triangles: Vec<u32>,
    /// Cumulative area fractions, last = 1.
    cdf: Vec<f64>,
    /// Per light, its pick probability (its share of the glass's area).
    probability: Vec<f64>,
    /// Per light, its corners: read per draw and per pdf, so kept together
    /// rather than fetched through the mesh's indices (the demo cabin's
    /// `--rays 32 --adaptive 0.25 --window-sampling` bake: 18.9 → 17.7 s).
    corners: Vec<[DVec3; 3]>,
    /// Per mesh triangle, its index in `triangles` (`u32::MAX`: not a light).
    light_of: Vec<u32>,
}

/// A direction toward the glass: where to look, how far the pane is along
/// it, and the light strategy's pdf (per steradian) of having drawn it.
pub(crate) struct WindowDraw {
    pub triangle: u32,
    pub direction: Vec3,
    pub distance: f32,
    pub pdf: f64,
}

impl WindowLights {
    /// `None` when no window triangle has area and transmits light.
    pub(crate) fn new(mesh: &Mesh, surfaces: &Surfaces) -> Option<WindowLights> {
        let triangles: Vec<u32> = (0..mesh.triangle_count() as u32)
            .filter(|&t| surfaces.window_transmittance[t as usize].is_some_and(|tau| tau > 0.0) && triangle_area(mesh, t) > 0.0)
            .collect();
        let mut cdf = Vec::with_capacity(triangles.len());
        let mut sum = 0.0f64;
        for &t in &triangles {
            sum += triangle_area(mesh, t) as f64;
            cdf.push(sum);
        }
        if sum <= 0.0 {
            return None;
        }
        cdf.iter_mut().for_each(|c| *c /= sum);
        let probability = triangles.iter().map(|&t| triangle_area(mesh, t) as f64 / sum).collect();
        let corners = triangles.iter().map(|&t| mesh.triangle_positions(t as usize).map(Vec3::as_dvec3)).collect();
        let mut light_of = vec![u32::MAX; mesh.triangle_count()];
        triangles.iter().enumerate().for_each(|(i, &t)| light_of[t as usize] = i as u32);
        Some(WindowLights { triangles, cdf, probability, corners, light_of })
    }

    /// The light whose cumulative area interval holds `u` ∈ [0,1).
    fn pick(&self, u: f32) -> usize {
        self.cdf.partition_point(|&c| c <= u as f64).min(self.triangles.len() - 1)
    }

    /// A light's pick probability and its corners relative to `origin`.
    fn light(&self, light: usize, origin: Vec3) -> (f64, [DVec3; 3]) {
        let origin = origin.as_dvec3();
        (self.probability[light], self.corners[light].map(|v| v - origin))
    }

    /// Draws a direction from `origin` toward the glass from three uniform
    /// numbers; `None` when the picked pane is seen edge-on (zero solid
    /// angle: no direction to draw).
    pub(crate) fn draw(&self, origin: Vec3, u_pick: f32, u1: f32, u2: f32) -> Option<WindowDraw> {
        let light = self.pick(u_pick);
        let triangle = self.triangles[light];
        let (pick, [a, b, c]) = self.light(light, origin);
        let omega = solid_angle(a, b, c);
        let direction = if omega >= MIN_SOLID_ANGLE {
            sample_spherical_triangle(a.normalize(), b.normalize(), c.normalize(), omega, u1 as f64, u2 as f64)?
        } else {
            let w = square_to_triangle(u1, u2).map(f64::from);
            (a * w[0] + b * w[1] + c * w[2]).try_normalize()?
        };
        let normal = (b - a).cross(c - a);
        let distance = a.dot(normal) / direction.dot(normal);
        if !(distance.is_finite() && distance > 0.0) {
            return None;
        }
        let pdf = pdf_given_pick(omega, normal, direction, distance) * pick;
        Some(WindowDraw { triangle, direction: direction.as_vec3(), distance: distance as f32, pdf })
    }

    /// The light strategy's pdf (per steradian) of direction `direction` from
    /// `origin`, whose ray first meets window triangle `triangle` at
    /// `distance`: the same rule [`WindowLights::draw`] follows.
    pub(crate) fn pdf(&self, origin: Vec3, triangle: u32, direction: Vec3, distance: f32) -> f64 {
        let light = self.light_of[triangle as usize];
        if light == u32::MAX {
            return 0.0;
        }
        let (pick, [a, b, c]) = self.light(light as usize, origin);
        let omega = solid_angle(a, b, c);
        let normal = (b - a).cross(c - a);
        pdf_given_pick(omega, normal, direction.as_dvec3(), distance as f64) * pick
    }
}

/// The pdf of `direction` given the pane (solid angle `omega`, normal
/// `normal` of length twice its area) was picked: uniform over its solid
/// angle, or by area below [`MIN_SOLID_ANGLE`] (`r² / (A |cos θ_w|)`).
fn pdf_given_pick(omega: f64, normal: DVec3, direction: DVec3, distance: f64) -> f64 {
    if omega >= MIN_SOLID_ANGLE {
        return 1.0 / omega;
    }
    let twice_area = normal.length();
    let cos_window = (normal.dot(direction) / twice_area).abs();
    if cos_window <= 0.0 {
        return 0.0;
    }
    distance * distance / (0.5 * twice_area * cos_window)
}

/// Solid angle of the triangle with corners `a, b, c` seen from the origin
/// (Van Oosterom & Strackee 1983): `tan(Ω/2) = |a·(b×c)| / (abc + (a·b)c + (a·c)b + (b·c)a)`.
pub(crate) fn solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c)).abs();
    let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    let omega = 2.0 * numerator.atan2(denominator);
    if omega.is_finite() {
        omega.max(0.0)
    } else {
        0.0
    }
}

/// A direction uniform over the spherical triangle of unit corners `a, b, c`
/// with solid angle `area` (Arvo 1995): `u1` picks the area of the
/// sub-triangle `a, b, ĉ` (ĉ on the arc from a to c), `u2` the point along
/// the arc from b to ĉ. `None` for a degenerate triangle.
fn sample_spherical_triangle(a: DVec3, b: DVec3, c: DVec3, area: f64, u1: f64, u2: f64) -> Option<DVec3> {
    // Interior angle α at `a`: between the planes through (a, b) and (a, c).
    let cos_alpha = a.cross(b).try_normalize()?.dot(a.cross(c).try_normalize()?).clamp(-1.0, 1.0);
    let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
    if sin_alpha <= 0.0 {
        return None;
    }
    // Arvo's equations, with Â = u1·area and cos c = a·b (the arc ab):
    // s = sin(Â − α), t = cos(Â − α), u = t − cos α, v = s + sin α cos c,
    // q = cos of the arc a ĉ = ((v t − u s) cos α − v) / ((v s + u t) sin α).
    let (s, t) = (u1 * area - cos_alpha.acos()).sin_cos();
    let u = t - cos_alpha;
    let v = s + sin_alpha * a.dot(b);
    let q = (((v * t - u * s) * cos_alpha - v) / ((v * s + u * t) * sin_alpha)).clamp(-1.0, 1.0);
    let c_hat = a * q + (c - a * c.dot(a)).try_normalize()? * (1.0 - q * q).max(0.0).sqrt();
    // Along the arc from b to ĉ, cos of the angle to b uniform in [ĉ·b, 1].
    let z = 1.0 - u2 * (1.0 - c_hat.dot(b));
    let direction = b * z + (c_hat - b * c_hat.dot(b)).try_normalize()? * (1.0 - z * z).max(0.0).sqrt();
    direction.try_normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corners() -> [DVec3; 3] {
        [DVec3::new(0.3, 1.0, -0.2), DVec3::new(-0.4, 0.8, 0.1), DVec3::new(0.1, 1.2, 0.5)]
    }

    /// Van Oosterom–Strackee against a brute-force count: directions uniform
    /// on the sphere (a Fibonacci lattice) that pass through the triangle.
    #[test]
    fn solid_angle_matches_a_lattice_count() {
        let [a, b, c] = corners();
        let n = 400_000;
        let normal = (b - a).cross(c - a);
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let mut inside = 0usize;
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let d = DVec3::new(r * (golden * i as f64).cos(), z, r * (golden * i as f64).sin());
            let t = a.dot(normal) / d.dot(normal);
            if t > 0.0 {
                let p = d * t;
                let inside_edge = |p0: DVec3, p1: DVec3| (p1 - p0).cross(p - p0).dot(normal) >= 0.0;
                inside += (inside_edge(a, b) && inside_edge(b, c) && inside_edge(c, a)) as usize;
            }
        }
        let counted = 4.0 * std::f64::consts::PI * inside as f64 / n as f64;
        let omega = solid_angle(a, b, c);
        assert!((omega - counted).abs() < 2e-3 * omega, "{omega} vs {counted}");
    }

    /// Arvo's sampler: every draw lies in the triangle, and the draws are
    /// uniform: the fraction landing in the sub-triangle (a, b, midpoint of
    /// bc) equals its share of the solid angle.
    #[test]
    fn spherical_triangle_draws_are_uniform_over_the_triangle() {
        let [a, b, c] = corners().map(DVec3::normalize);
        let omega = solid_angle(a, b, c);
        let m = ((b + c) * 0.5).normalize();
        let share = solid_angle(a, b, m) / omega;
        let n = 64u32;
        let mut in_sub = 0usize;
        for i in 0..n {
            for j in 0..n {
                let (u1, u2) = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                let d = sample_spherical_triangle(a, b, c, omega, u1, u2).expect("a direction");
                let normal = (b - a).cross(c - a);
                let p = d * (a.dot(normal) / d.dot(normal));
                let inside = |p0: DVec3, p1: DVec3| (p1 - p0).cross(p - p0).dot(normal) >= -1e-9;
                assert!(inside(a, b) && inside(b, c) && inside(c, a), "draw {d} outside");
                let n_sub = (b - a).cross(m - a);
                let in_plane = d * (a.dot(n_sub) / d.dot(n_sub));
                let inside_sub = |p0: DVec3, p1: DVec3| (p1 - p0).cross(in_plane - p0).dot(n_sub) >= 0.0;
                in_sub += (inside_sub(a, b) && inside_sub(b, m) && inside_sub(m, a)) as usize;
            }
        }
        let fraction = in_sub as f64 / (n * n) as f64;
        assert!((fraction - share).abs() < 0.01, "{fraction} of the draws in a sub-triangle holding {share} of the solid angle");
    }
}
