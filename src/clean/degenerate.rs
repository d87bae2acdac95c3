//! Degenerate triangles: a collapsed corner (two corners on one point) or a height
//! below the weld tolerance, i.e. a triangle thinner than what welding treats as
//! one position.
//!
//! Removing a thin triangle with three distinct corners leaves a T-junction at its
//! middle corner; the zip step closes it.

use super::work::Work;

/// Marks degenerate live triangles removed; returns (count, their total area).
///
/// A triangle is degenerate when two corners share a point, or when twice its area
/// divided by its longest side (its smallest height) is at most `height_tol`.
pub(crate) fn remove_degenerate(work: &mut Work, height_tol: f32) -> (usize, f64) {
    let mut count = 0;
    let mut area = 0.0;
    for t in 0..work.tris.len() {
        if !work.tri_alive[t] {
            continue;
        }
        if is_degenerate(work, t, height_tol as f64) {
            work.tri_alive[t] = false;
            count += 1;
            area += work.tri_area(t);
        }
    }
    (count, area)
}

/// True when triangle `t` has a collapsed corner or a smallest height `<= height_tol`.
pub(crate) fn is_degenerate(work: &Work, t: usize, height_tol: f64) -> bool {
    let [a, b, c] = work.tri_points(t);
    if a == b || b == c || c == a {
        return true;
    }
    let p = work.tri_positions(t).map(|p| p.as_dvec3());
    let longest = (p[1] - p[0]).length().max((p[2] - p[1]).length()).max((p[0] - p[2]).length());
    let twice_area = (p[1] - p[0]).cross(p[2] - p[0]).length();
    twice_area <= height_tol * longest
}
