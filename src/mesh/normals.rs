//! Vertex normals: computed when a file has none, repaired where a file's are unusable.
//!
//! Weighting follows Thürmer & Wüthrich, "Computing vertex normals from polygonal
//! facets" (1998), combined with area weighting as in Jin, Lewis & West, "A
//! comparison of algorithms for vertex normal computation" (2005): each triangle
//! adds `cross(b - a, c - a) * angle_at_corner` to each of its corners, so large
//! faces count more and a vertex's normal does not depend on how a flat region
//! around it is split into triangles.

use glam::Vec3;

/// Normal given to a vertex that touches no triangle with non-zero area.
///
/// Such a vertex has no defined normal; +Y (up after loading) keeps the array
/// unit-length so later stages need no special case.
pub const FALLBACK_NORMAL: Vec3 = Vec3::Y;

/// Squared length below which a normal counts as zero (unusable).
const MIN_NORMAL_LENGTH_SQUARED: f32 = 1e-20;

/// Computes unit vertex normals, area-and-angle weighted, for a triangle list.
///
/// `indices` holds triples into `positions`; triples with an index out of range
/// are skipped (never a panic). Counter-clockwise triangles give outward normals.
/// Vertices touching only degenerate triangles (or none) get [`FALLBACK_NORMAL`].
pub fn compute_vertex_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for triangle in indices.chunks_exact(3) {
        let corners = [triangle[0] as usize, triangle[1] as usize, triangle[2] as usize];
        let (Some(&a), Some(&b), Some(&c)) = (positions.get(corners[0]), positions.get(corners[1]), positions.get(corners[2])) else {
            continue;
        };
        // Length is twice the area: the area weight.
        let face_normal = (b - a).cross(c - a);
        if !face_normal.is_finite() || face_normal.length_squared() < MIN_NORMAL_LENGTH_SQUARED {
            continue;
        }
        let points = [a, b, c];
        for k in 0..3 {
            let here = points[k];
            let angle = (points[(k + 1) % 3] - here).angle_between(points[(k + 2) % 3] - here);
            if angle.is_finite() {
                sums[corners[k]] += face_normal * angle;
            }
        }
    }
    sums.into_iter().map(|sum| sum.try_normalize().unwrap_or(FALLBACK_NORMAL)).collect()
}

/// |n|² of a normal already unit to f32 rounding (a few ulps of 1): such a
/// normal is kept bit for bit, since normalising it again can move it by an
/// ulp and a written-then-loaded mesh would no longer bake the same.
const UNIT_LENGTH_SQUARED_TOLERANCE: f32 = 4.0 * f32::EPSILON;

/// Makes `normals` unit length, replacing every zero or non-finite one by the
/// computed area-and-angle-weighted normal of that vertex.
///
/// Preconditions: `normals.len() == positions.len()` (extra entries are left alone,
/// missing ones are not added). Returns how many normals were replaced. Vertices
/// without a usable normal are how a loader marks "no normal in the file": put
/// `Vec3::NAN` there and this fills them in.
pub fn repair_normals(normals: &mut [Vec3], positions: &[Vec3], indices: &[u32]) -> usize {
    let is_bad = |n: &Vec3| !n.is_finite() || n.length_squared() < MIN_NORMAL_LENGTH_SQUARED;
    let bad_count = normals.iter().filter(|n| is_bad(n)).count();
    let computed = if bad_count > 0 { compute_vertex_normals(positions, indices) } else { Vec::new() };
    for (i, normal) in normals.iter_mut().enumerate() {
        if is_bad(normal) {
            *normal = computed.get(i).copied().unwrap_or(FALLBACK_NORMAL);
        } else if (normal.length_squared() - 1.0).abs() > UNIT_LENGTH_SQUARED_TOLERANCE {
            *normal = normal.normalize_or(FALLBACK_NORMAL);
        }
    }
    bad_count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Angle-weighting makes the normal independent of how a flat fan is split.
    #[test]
    fn flat_fan_gives_plane_normal_whatever_the_split() {
        // Centre vertex 0 with a fan of 5 unequal triangles in the z = 0 plane.
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.3, 1.0, 0.0),
            Vec3::new(-1.0, 0.2, 0.0),
            Vec3::new(-0.2, -1.0, 0.0),
            Vec3::new(0.9, -0.4, 0.0),
        ];
        let indices = vec![0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5, 0, 5, 1];
        let normals = compute_vertex_normals(&positions, &indices);
        for n in normals {
            assert!((n - Vec3::Z).length() < 1e-6, "{n}");
        }
    }

    /// A cube corner touches three faces; angle-and-area weighting gives the diagonal
    /// whatever the (here deliberately uneven) triangulation.
    #[test]
    fn corner_of_unevenly_split_faces_gets_diagonal() {
        // Three unit squares meeting at the origin corner, each split differently.
        let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let positions = vec![p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.), p(0., 0., 1.), p(1., 1., 0.), p(0., 1., 1.), p(1., 0., 1.)];
        // Faces outward-facing from the corner's point of view: normals -Z, -X, -Y.
        let indices = vec![
            0, 2, 4, 0, 4, 1, // z = 0 plane: split so both halves touch the corner
            0, 3, 2, 3, 5, 2, // x = 0 plane
            0, 1, 3, 1, 6, 3, // y = 0 plane
        ];
        let normals = compute_vertex_normals(&positions, &indices);
        let expected = Vec3::new(-1.0, -1.0, -1.0).normalize();
        assert!((normals[0] - expected).length() < 1e-6, "{}", normals[0]);
    }

    #[test]
    fn repair_replaces_only_bad_normals_and_normalizes_the_rest() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        let indices = vec![0, 1, 2];
        let mut normals = vec![Vec3::NAN, Vec3::ZERO, Vec3::new(0.0, 0.0, -5.0)];
        let repaired = repair_normals(&mut normals, &positions, &indices);
        assert_eq!(repaired, 2);
        assert_eq!(normals, vec![Vec3::Z, Vec3::Z, Vec3::NEG_Z]);
    }

    #[test]
    fn out_of_range_and_degenerate_triangles_do_not_panic() {
        let positions = vec![Vec3::ZERO, Vec3::X];
        let normals = compute_vertex_normals(&positions, &[0, 1, 7, 0, 0, 1]);
        assert_eq!(normals, vec![FALLBACK_NORMAL; 2]);
    }
}
