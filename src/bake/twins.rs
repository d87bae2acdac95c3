//! Back sides that reflect light: in open mode a diffuse sheet reflects on
//! the side the light arrives from, so a ray that meets a surface from
//! behind gathers what that surface's back side receives. Each triangle
//! whose back can be seen gets a twin for the bake: the same corners in
//! reversed order, on copies of its vertices with negated normals. Twins
//! are receivers only (sample points and rows of their own, appended after
//! the mesh's triangles and vertices); rays are traced against the mesh's
//! own triangles, and a hit on a twinned triangle's back face gathers from
//! its twin. Twin rows are never stored: a vertex's value stays its front
//! side's.
//!
//! A triangle gets no twin when its back cannot be lit, or when the scene
//! says so:
//! - its material or group is one-sided (`--one-sided`, [`Surfaces::one_sided`]);
//! - a coincident triangle of opposite winding already stands for its back
//!   (CAD models drawn double-sided);
//! - it belongs to a closed, consistently wound surface (every edge shared
//!   by exactly two of the surface's triangles in opposite directions): its
//!   back faces the solid's inside, where no point survives the inside test.

use std::collections::HashMap;

use super::surfaces::Surfaces;
use crate::mesh::Mesh;

/// No twin for this triangle.
pub(crate) const NO_TWIN: u32 = u32::MAX;

/// The twins of a bake: which triangles have one, and how the augmented
/// mesh's twin triangles and vertices map back to the mesh's.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Twins {
    /// Triangles of the mesh.
    pub(crate) triangles: usize,
    /// Vertices of the mesh.
    pub(crate) vertices: usize,
    /// Per mesh triangle, its twin's triangle index in the augmented mesh, or [`NO_TWIN`].
    pub(crate) twin_of: Vec<u32>,
    /// Per twin triangle (augmented index − `triangles`), the mesh triangle it mirrors.
    pub(crate) source_triangle: Vec<u32>,
    /// Per twin vertex (augmented index − `vertices`), the mesh vertex it copies.
    pub(crate) source_vertex: Vec<u32>,
}

impl Twins {
    /// No twins (window mode, vertex sampling, no bounces, or none needed).
    pub(crate) fn none(mesh: &Mesh) -> Twins {
        Twins {
            triangles: mesh.triangle_count(),
            vertices: mesh.vertex_count(),
            twin_of: vec![NO_TWIN; mesh.triangle_count()],
            ..Twins::default()
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.source_triangle.is_empty()
    }

    /// The mesh triangle a triangle of the augmented mesh lies on.
    #[inline]
    pub(crate) fn geometry_of(&self, t: u32) -> (u32, bool) {
        match (t as usize).checked_sub(self.triangles) {
            Some(k) => (self.source_triangle[k], true),
            None => (t, false),
        }
    }
}

/// Which of `sampled` triangles (neither windows nor degenerate) get a twin.
pub(crate) fn twinned_triangles(mesh: &Mesh, surfaces: &Surfaces, sampled: &[u32]) -> Vec<bool> {
    let mut twinned = vec![false; mesh.triangle_count()];
    for &t in sampled {
        twinned[t as usize] = !surfaces.one_sided[t as usize] && surfaces.window_transmittance[t as usize].is_none();
    }
    let keys = position_keys(mesh);
    // Drawn double-sided: the same three points wound the other way.
    let mut by_corners: HashMap<[u32; 3], Vec<(u32, bool)>> = HashMap::new();
    for t in 0..mesh.triangle_count() {
        let k = mesh.triangle(t).map(|v| keys[v as usize]);
        let (canonical, parity) = canonical_cycle(k);
        by_corners.entry(canonical).or_default().push((t as u32, parity));
    }
    for group in by_corners.values().filter(|g| g.len() > 1) {
        for &(t, parity) in group {
            if group.iter().any(|&(other, p)| other != t && p != parity) {
                twinned[t as usize] = false;
            }
        }
    }
    // Closed, consistently wound surfaces: their backs face their inside.
    for t in closed_surface_triangles(mesh, &keys) {
        twinned[t as usize] = false;
    }
    twinned
}

/// Per vertex, a key shared by every vertex at the same position (split
/// normals or UVs leave several vertices on one point).
fn position_keys(mesh: &Mesh) -> Vec<u32> {
    let mut ids: HashMap<[u32; 3], u32> = HashMap::with_capacity(mesh.vertex_count());
    mesh.positions
        .iter()
        .map(|p| {
            let bits = p.to_array().map(|c| if c == 0.0 { 0 } else { c.to_bits() });
            let next = ids.len() as u32;
            *ids.entry(bits).or_insert(next)
        })
        .collect()
}

/// The corners rotated so the smallest key comes first, sorted so that both
/// windings of one triangle give the same key; and which winding this is.
fn canonical_cycle(k: [u32; 3]) -> ([u32; 3], bool) {
    let first = (0..3).min_by_key(|&i| k[i]).unwrap_or(0);
    let rotated = [k[first], k[(first + 1) % 3], k[(first + 2) % 3]];
    if rotated[1] <= rotated[2] {
        (rotated, true)
    } else {
        ([rotated[0], rotated[2], rotated[1]], false)
    }
}

/// Triangles of closed, consistently wound surfaces: components (joined by
/// shared edges, on positions) every edge of which has exactly two of the
/// component's triangles, traversing it in opposite directions.
fn closed_surface_triangles(mesh: &Mesh, keys: &[u32]) -> Vec<u32> {
    let n = mesh.triangle_count();
    // Directed edges: (from, to) → triangles.
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::with_capacity(3 * n);
    let mut degenerate = vec![false; n];
    for t in 0..n {
        let k = mesh.triangle(t).map(|v| keys[v as usize]);
        if k[0] == k[1] || k[1] == k[2] || k[2] == k[0] {
            degenerate[t] = true;
            continue;
        }
        for i in 0..3 {
            edges.entry((k[i], k[(i + 1) % 3])).or_default().push(t as u32);
        }
    }
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let mut open = vec![false; n];
    for (&(a, b), forward) in &edges {
        let backward = edges.get(&(b, a));
        let manifold = forward.len() == 1 && backward.is_some_and(|back| back.len() == 1);
        if !manifold {
            forward.iter().for_each(|&t| open[t as usize] = true);
            continue;
        }
        let (x, y) = (find(&mut parent, forward[0]), find(&mut parent, backward.map_or(forward[0], |b| b[0])));
        if x != y {
            parent[x as usize] = y;
        }
    }
    let mut component_open: HashMap<u32, bool> = HashMap::new();
    for t in 0..n {
        let root = find(&mut parent, t as u32);
        let entry = component_open.entry(root).or_insert(false);
        *entry |= open[t] || degenerate[t];
    }
    (0..n as u32).filter(|&t| !degenerate[t as usize] && !component_open[&find(&mut parent, t)]).collect()
}

/// The mesh with a twin of every `twinned` triangle appended (reversed
/// winding, on copies of its vertices with negated normals) and the
/// surfaces of the augmented triangles; the map between them.
pub(crate) fn augment(mesh: &Mesh, surfaces: &Surfaces, twinned: &[bool]) -> (Mesh, Surfaces, Twins) {
    let (t_count, v_count) = (mesh.triangle_count(), mesh.vertex_count());
    let mut twin_vertex = vec![u32::MAX; v_count];
    let mut source_vertex = Vec::new();
    let mut source_triangle = Vec::new();
    let mut twin_of = vec![NO_TWIN; t_count];
    let mut aug = mesh.clone();
    let mut aug_surfaces = surfaces.clone();
    for t in (0..t_count).filter(|&t| twinned[t]) {
        let corners = mesh.triangle(t).map(|v| {
            let slot = &mut twin_vertex[v as usize];
            if *slot == u32::MAX {
                *slot = (v_count + source_vertex.len()) as u32;
                source_vertex.push(v);
            }
            *slot
        });
        twin_of[t] = (t_count + source_triangle.len()) as u32;
        source_triangle.push(t as u32);
        aug.indices.extend_from_slice(&[corners[0], corners[2], corners[1]]);
        aug.tri_material.push(mesh.tri_material[t]);
        aug.tri_group.push(mesh.tri_group[t]);
        aug_surfaces.window_transmittance.push(None);
        aug_surfaces.albedo.push(surfaces.albedo[t]);
        aug_surfaces.one_sided.push(false);
    }
    for &v in &source_vertex {
        let v = v as usize;
        aug.positions.push(mesh.positions[v]);
        aug.normals.push(-mesh.normals[v]);
        if !mesh.uvs.is_empty() {
            aug.uvs.push(mesh.uvs[v]);
        }
        if !mesh.lightmap_uvs.is_empty() {
            aug.lightmap_uvs.push(mesh.lightmap_uvs[v]);
        }
        if !mesh.colors.is_empty() {
            aug.colors.push(mesh.colors[v]);
        }
    }
    (aug, aug_surfaces, Twins { triangles: t_count, vertices: v_count, twin_of, source_triangle, source_vertex })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::verify::shapes;

    fn sampled(mesh: &Mesh) -> Vec<u32> {
        (0..mesh.triangle_count() as u32).collect()
    }

    #[test]
    fn sheets_get_twins_and_closed_or_double_drawn_surfaces_do_not() {
        // An open sheet: every triangle gets a twin.
        let sheet = shapes::plane_grid(2, 1.0);
        let s = Surfaces::resolve(&sheet, &[]).unwrap();
        assert!(twinned_triangles(&sheet, &s, &sampled(&sheet)).iter().all(|&t| t));
        // A closed icosphere: none.
        let ball = shapes::icosphere(1);
        let s = Surfaces::resolve(&ball, &[]).unwrap();
        assert!(twinned_triangles(&ball, &s, &sampled(&ball)).iter().all(|&t| !t));
        // A sheet drawn double-sided (a reversed copy on its own vertices): none.
        let mut double = shapes::plane_grid(2, 1.0);
        let (v, t) = (double.vertex_count() as u32, double.triangle_count());
        double.positions.extend_from_within(..);
        let normals: Vec<_> = double.normals.iter().map(|n| -*n).collect();
        double.normals.extend(normals);
        for k in 0..t {
            let [a, b, c] = double.triangle(k);
            double.indices.extend([a + v, c + v, b + v]);
            double.tri_material.push(0);
            double.tri_group.push(0);
        }
        let s = Surfaces::resolve(&double, &[]).unwrap();
        assert!(twinned_triangles(&double, &s, &sampled(&double)).iter().all(|&t| !t));
        // A one-sided material: none.
        let one = shapes::plane_grid(2, 1.0);
        let name = one.materials[0].name.clone();
        let s = Surfaces::resolve(&one, &[]).unwrap().with_one_sided(&one, &[name]).unwrap();
        assert!(twinned_triangles(&one, &s, &sampled(&one)).iter().all(|&t| !t));
    }

    #[test]
    fn twins_mirror_their_triangles_on_copied_vertices() {
        let sheet = shapes::plane_grid(1, 1.0);
        let s = Surfaces::resolve(&sheet, &[]).unwrap();
        let (aug, aug_s, twins) = augment(&sheet, &s, &[true, false]);
        assert_eq!((aug.triangle_count(), aug.vertex_count()), (3, 7));
        assert_eq!(twins.twin_of, vec![2, NO_TWIN]);
        assert_eq!(twins.geometry_of(2), (0, true));
        let [a, b, c] = sheet.triangle(0);
        let [ta, tb, tc] = aug.triangle(2);
        assert_eq!([ta, tb, tc].map(|v| twins.source_vertex[v as usize - 4]), [a, c, b]);
        assert_eq!(aug.normals[ta as usize], -sheet.normals[a as usize]);
        assert_eq!(aug_s.albedo.len(), 3);
        aug.validate().unwrap();
    }
}
