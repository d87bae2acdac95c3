//! Receivers: where the estimators' values live. A sample point on a
//! triangle adds what it sees to receivers, each with a weight; a later
//! bounce reads receivers at a hit point. Transfer, gather and the sun
//! vote go through these functions and never name a vertex.
//!
//! The one kind today is the vertex: its value is the hat-weighted mean
//! over its one-ring (docs/conventions.md, "Per-vertex transfer"), so a
//! point adds to its triangle's three corners with its barycentrics times
//! the area it stands for, and a hit reads the three corners' rows,
//! barycentrically. A texel of a lightmap atlas is the other kind the
//! functions are shaped for: a point adds to the texel whose footprint holds
//! it, and a hit reads texels bilinearly.

use glam::Vec3;

use crate::mesh::Mesh;

/// The receivers of a bake over one mesh (the plan's, twins included).
#[derive(Clone, Copy)]
pub(crate) struct Receivers<'a> {
    mesh: &'a Mesh,
}

impl<'a> Receivers<'a> {
    /// One receiver per vertex of `mesh`.
    pub(crate) fn vertices(mesh: &'a Mesh) -> Receivers<'a> {
        Receivers { mesh }
    }

    pub(crate) fn count(&self) -> usize {
        self.mesh.vertex_count()
    }

    /// The receivers a point on triangle `t` adds to, one per weight of
    /// [`point_weights`].
    #[inline]
    pub(crate) fn of_triangle(&self, t: u32) -> [u32; 3] {
        self.mesh.triangle(t as usize)
    }

    /// Per triangle, the receivers a hit on it reads (three each, weighted
    /// by the hit's barycentrics): the gather's table.
    pub(crate) fn hit_table(&self) -> &'a [u32] {
        &self.mesh.indices
    }

    /// The shading normal a receiver faces along (the sun's facing test).
    #[inline]
    pub(crate) fn normal(&self, receiver: usize) -> Vec3 {
        self.mesh.normals[receiver]
    }
}

/// What a sample at barycentrics `b`, one of `count` in a triangle of area
/// `area`, adds to the weight of each receiver of [`Receivers::of_triangle`]:
/// its hat value there times the area it stands for. Over the samples,
/// Σ w·t / Σ w estimates each vertex's hat-weighted mean over its one-ring
/// whatever the sample counts; the transfer and the sun vote share it.
#[inline]
pub(crate) fn point_weights(b: [f32; 3], area: f32, count: u32) -> [f32; 3] {
    let share = area / count as f32;
    b.map(|x| x * share)
}

/// For each receiver, the (item, slot) pairs that add to it, in item order:
/// item `k` is a point set on triangle `triangles[k]`, and slot `j` its
/// weight toward `of_triangle(..)[j]`. A receiver sums its points in this
/// order, so the sum does not depend on how items were split into tasks.
pub(crate) struct Adjacency {
    /// `entries[offsets[r]..offsets[r + 1]]` add to receiver r.
    pub(crate) offsets: Vec<u32>,
    /// `(item, slot)`.
    pub(crate) entries: Vec<(u32, u8)>,
}

impl Adjacency {
    pub(crate) fn build(receivers: &Receivers, triangles: &[u32]) -> Adjacency {
        let count = receivers.count();
        let mut offsets = vec![0u32; count + 1];
        for &t in triangles {
            for r in receivers.of_triangle(t) {
                offsets[r as usize + 1] += 1;
            }
        }
        for r in 0..count {
            offsets[r + 1] += offsets[r];
        }
        let mut fill = offsets.clone();
        let mut entries = vec![(0u32, 0u8); offsets[count] as usize];
        for (item, &t) in triangles.iter().enumerate() {
            for (slot, r) in receivers.of_triangle(t).into_iter().enumerate() {
                let at = &mut fill[r as usize];
                entries[*at as usize] = (item as u32, slot as u8);
                *at += 1;
            }
        }
        Adjacency { offsets, entries }
    }

    /// The (item, slot) pairs of receiver `r`.
    pub(crate) fn of(&self, r: usize) -> &[(u32, u8)] {
        &self.entries[self.offsets[r] as usize..self.offsets[r + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::verify::shapes;

    /// Whole rotation triples give each receiver of a triangle a third of
    /// the area, and a vertex's entries list every triangle around it once.
    #[test]
    fn point_weights_share_the_area_and_the_adjacency_lists_each_ring() {
        let b = [0.6f32, 0.3, 0.1];
        let rotations = [b, [b[1], b[2], b[0]], [b[2], b[0], b[1]]];
        let mut total = [0.0f32; 3];
        for r in rotations {
            let w = point_weights(r, 1.5, 3);
            total.iter_mut().zip(w).for_each(|(t, w)| *t += w);
        }
        assert!(total.iter().all(|&t| (t - 0.5).abs() < 1e-6), "{total:?}");

        let mesh = shapes::plane_grid(3, 1.0);
        let receivers = Receivers::vertices(&mesh);
        let triangles: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        let adjacency = Adjacency::build(&receivers, &triangles);
        for v in 0..mesh.vertex_count() {
            let around: Vec<u32> = (0..mesh.triangle_count() as u32).filter(|&t| mesh.triangle(t as usize).contains(&(v as u32))).collect();
            let listed: Vec<u32> = adjacency.of(v).iter().map(|&(item, _)| item).collect();
            assert_eq!(listed, around, "vertex {v}");
            for &(item, slot) in adjacency.of(v) {
                assert_eq!(receivers.of_triangle(triangles[item as usize])[slot as usize], v as u32);
            }
        }
    }
}
