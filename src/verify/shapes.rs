//! Analytic test geometry: icospheres, planes, integrating spheres.

use std::collections::HashMap;

use glam::Vec3;

use crate::mesh::{Material, MaterialRole, Mesh};

/// A unit-radius icosphere subdivided `subdivisions` times
/// (10·4^s + 2 vertices), outward normals equal to positions.
pub fn icosphere(subdivisions: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *midpoints.entry(key).or_insert_with(|| {
                positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut positions);
            let bc = midpoint(b, c, &mut positions);
            let ca = midpoint(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let triangle_count = faces.len();
    Mesh {
        normals: positions.clone(),
        positions,
        indices: faces.into_iter().flatten().collect(),
        tri_material: vec![0; triangle_count],
        tri_group: vec![0; triangle_count],
        materials: vec![Material::opaque("sphere", 0.8)],
        groups: vec!["sphere".into()],
        ..Mesh::default()
    }
}

/// Moves and scales a mesh in place.
pub fn transform(mesh: &mut Mesh, scale: f32, offset: Vec3) {
    mesh.positions.iter_mut().for_each(|p| *p = *p * scale + offset);
}

/// Appends `other` to `mesh`, with its own materials and groups.
pub fn append(mesh: &mut Mesh, other: &Mesh) {
    let base = mesh.positions.len() as u32;
    let material_base = mesh.materials.len() as u16;
    let group_base = mesh.groups.len() as u32;
    mesh.positions.extend(&other.positions);
    mesh.normals.extend(&other.normals);
    mesh.indices.extend(other.indices.iter().map(|i| i + base));
    mesh.tri_material.extend(other.tri_material.iter().map(|m| m + material_base));
    mesh.tri_group.extend(other.tri_group.iter().map(|g| g + group_base));
    mesh.materials.extend(other.materials.iter().cloned());
    mesh.groups.extend(other.groups.iter().cloned());
}

/// A square grid of `cells`×`cells` quads in the XZ plane, side `size`,
/// centred at the origin, facing +Y.
pub fn plane_grid(cells: u32, size: f32) -> Mesh {
    let n = cells + 1;
    let mut positions = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            let x = (i as f32 / cells as f32 - 0.5) * size;
            let z = (j as f32 / cells as f32 - 0.5) * size;
            positions.push(Vec3::new(x, 0.0, z));
        }
    }
    let mut indices = Vec::with_capacity((cells * cells * 6) as usize);
    for j in 0..cells {
        for i in 0..cells {
            let a = j * n + i;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            // Counter-clockwise seen from +Y.
            indices.extend([a, c, b, b, c, d]);
        }
    }
    let triangle_count = indices.len() / 3;
    Mesh {
        normals: vec![Vec3::Y; positions.len()],
        positions,
        indices,
        tri_material: vec![0; triangle_count],
        tri_group: vec![0; triangle_count],
        materials: vec![Material::opaque("plane", 0.8)],
        groups: vec!["plane".into()],
        ..Mesh::default()
    }
}

/// How the opening of an integrating sphere is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Opening {
    /// Cap triangles kept, with a window material (window mode).
    Window,
    /// Cap triangles removed (open mode).
    Hole,
}

/// An integrating sphere: a unit icosphere facing inward (normals and winding
/// toward the centre) with albedo `albedo`, whose triangles with centroid
/// above height `cap_height` form the opening. Returns the mesh and the exact
/// area fraction of the opening.
pub fn integrating_sphere(subdivisions: u32, albedo: f32, cap_height: f32, opening: Opening) -> (Mesh, f64) {
    let sphere = icosphere(subdivisions);
    let mut mesh = Mesh {
        positions: sphere.positions.clone(),
        normals: sphere.normals.iter().map(|n| -*n).collect(),
        materials: vec![
            Material::opaque("wall", albedo),
            Material { name: "glass".into(), albedo: [0.0; 3], role: MaterialRole::Window, transmittance: 1.0 },
        ],
        groups: vec!["sphere".into()],
        ..Mesh::default()
    };
    let (mut wall_area, mut cap_area) = (0.0f64, 0.0f64);
    for t in 0..sphere.triangle_count() {
        let [a, b, c] = sphere.triangle(t);
        let [pa, pb, pc] = sphere.triangle_positions(t);
        let area = 0.5 * (pb - pa).cross(pc - pa).length() as f64;
        let in_cap = (pa + pb + pc).y / 3.0 > cap_height;
        if in_cap {
            cap_area += area;
            if opening == Opening::Hole {
                continue;
            }
        } else {
            wall_area += area;
        }
        // Reverse the winding so the front faces the centre.
        mesh.indices.extend([a, c, b]);
        mesh.tri_material.push(u16::from(in_cap));
        mesh.tri_group.push(0);
    }
    (mesh, cap_area / (cap_area + wall_area))
}

/// A floor grid (20×20 cells, side 2) and a 1 cm slab lying on it whose edge
/// passes `overhang` cells beyond the floor vertex column at x = 0 (negative:
/// short of it). With a positive overhang those vertices are covered: every
/// ray from them starts under the slab (seed 000 fig. 2). Returns the mesh and
/// the covered column's vertex indices.
pub fn covered_floor(overhang: f32) -> (Mesh, Vec<usize>) {
    let cells = 20;
    let size = 2.0;
    let cell = size / cells as f32;
    let mut mesh = plane_grid(cells, size);
    let covered: Vec<usize> = (0..=cells as usize).map(|j| j * (cells as usize + 1) + cells as usize / 2).collect();
    let (lo, hi) = (Vec3::new(-0.6, 0.0, -0.8), Vec3::new(overhang * cell, 0.01, 0.8));
    let mut slab = crate::fixtures::builder::MeshBuilder::new(vec![Material::opaque("slab", 0.5)]);
    slab.cuboid("slab", lo, hi, 40.0, 0);
    append(&mut mesh, &slab.mesh);
    (mesh, covered)
}

/// Appends the flat quad `corners` (two triangles, facing `(c1 − c0) × (c2 − c0)`).
pub fn push_quad(mesh: &mut Mesh, corners: [Vec3; 4], material: u16, group: u32) {
    let base = mesh.positions.len() as u32;
    let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]).normalize();
    mesh.positions.extend(corners);
    mesh.normals.extend([normal; 4]);
    mesh.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    mesh.tri_material.extend([material; 2]);
    mesh.tri_group.extend([group; 2]);
}

/// A closed 4 × 3 × 4 m room (x, y, z from 0; a floor of 0.25 m cells, the
/// ceiling and the other walls one quad each) whose
/// front wall (z = 0) is one sheet of 0.25 m cells with shared vertices and a
/// 1 × 1 m opening (x 1.5–2.5, y 1–2), and a window pane (material 1, the
/// window role) 0.19 m outside it, 5 cm larger than the opening on each side:
/// the window-halo fixture (docs/conventions.md "Window mode, outside
/// sides"). Returns the mesh and the front wall's vertex range.
pub fn room_with_pane_outside_opening() -> (Mesh, std::ops::Range<usize>) {
    let mut mesh = Mesh::default();
    let quad = |mesh: &mut Mesh, corners: [Vec3; 4], material: u16| push_quad(mesh, corners, material, material as u32);
    let v = Vec3::new;
    // The floor: 16 × 16 cells of 0.25 m (so a sun patch shows in vertex bits).
    let floor = plane_grid(16, 4.0);
    let floor_first = mesh.positions.len() as u32;
    mesh.positions.extend(floor.positions.iter().map(|p| *p + v(2., 0., 2.)));
    mesh.normals.extend(&floor.normals);
    mesh.indices.extend(floor.indices.iter().map(|i| i + floor_first));
    mesh.tri_material.extend(vec![0; floor.triangle_count()]);
    mesh.tri_group.extend(vec![0; floor.triangle_count()]);
    // Ceiling, back and side walls, one quad each.
    quad(&mut mesh, [v(0., 3., 0.), v(4., 3., 0.), v(4., 3., 4.), v(0., 3., 4.)], 0);
    quad(&mut mesh, [v(0., 0., 4.), v(0., 3., 4.), v(4., 3., 4.), v(4., 0., 4.)], 0);
    quad(&mut mesh, [v(0., 0., 0.), v(0., 3., 0.), v(0., 3., 4.), v(0., 0., 4.)], 0);
    quad(&mut mesh, [v(4., 0., 0.), v(4., 0., 4.), v(4., 3., 4.), v(4., 3., 0.)], 0);
    // The front wall: a 16 × 12 grid of shared vertices without the opening's 4 × 4 cells.
    let wall_first = mesh.positions.len() as u32;
    for j in 0..=12 {
        for i in 0..=16 {
            mesh.positions.push(v(0.25 * i as f32, 0.25 * j as f32, 0.0));
            mesh.normals.push(Vec3::Z);
        }
    }
    let wall_end = mesh.positions.len() as u32;
    let at = |i: u32, j: u32| wall_first + j * 17 + i;
    for j in 0..12 {
        for i in 0..16 {
            if (6..10).contains(&i) && (4..8).contains(&j) {
                continue;
            }
            mesh.indices.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            mesh.tri_material.extend([0; 2]);
            mesh.tri_group.extend([0; 2]);
        }
    }
    quad(&mut mesh, [v(1.45, 0.95, -0.19), v(1.45, 2.05, -0.19), v(2.55, 2.05, -0.19), v(2.55, 0.95, -0.19)], 1);
    let mut glass = Material::opaque("glass", 0.0);
    glass.role = MaterialRole::Window;
    mesh.materials = vec![Material::opaque("wall", 0.5), glass];
    mesh.groups = vec!["room".into(), "pane".into()];
    mesh.validate().expect("a valid room");
    (mesh, wall_first as usize..wall_end as usize)
}

/// The side of the room in [`room_with_walls_running_past`] (m).
pub const PAST_ROOM_SIZE: [f32; 3] = [4.0, 3.0, 4.0];

/// A closed 4 × 3 × 4 m room (x, y, z from 0) of six separate patches facing
/// inward, not welded to each other, where geometry runs past the walls as
/// in architectural models, where cutting is needed: the floor runs 0.17 m past
/// the back wall (z = 4) and the right wall (x = 4) 0.1 m past it. The floor
/// (4 × 4 cells) and the right wall (4 × 3 cells) have triangles that span
/// the back wall's plane, so their vertices inside the room share triangles
/// with the strips outside, which see the sky.
pub fn room_with_walls_running_past() -> Mesh {
    let mut mesh = Mesh { materials: vec![Material::opaque("wall", 0.5)], groups: vec!["room".into()], ..Mesh::default() };
    // A patch of nu × nv cells spanning origin + s·du + t·dv, facing du × dv.
    let patch = |mesh: &mut Mesh, origin: Vec3, du: Vec3, dv: Vec3, nu: u32, nv: u32| {
        let normal = du.cross(dv).normalize();
        let base = mesh.positions.len() as u32;
        for j in 0..=nv {
            for i in 0..=nu {
                mesh.positions.push(origin + du * (i as f32 / nu as f32) + dv * (j as f32 / nv as f32));
                mesh.normals.push(normal);
            }
        }
        let at = |i: u32, j: u32| base + j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                mesh.indices.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                mesh.tri_material.extend([0; 2]);
                mesh.tri_group.extend([0; 2]);
            }
        }
    };
    let v = Vec3::new;
    let [sx, sy, sz] = PAST_ROOM_SIZE;
    // Floor (+y), running 0.17 m past the back wall.
    patch(&mut mesh, v(0., 0., 0.), v(0., 0., sz + 0.17), v(sx, 0., 0.), 4, 4);
    // Ceiling (−y).
    patch(&mut mesh, v(0., sy, 0.), v(sx, 0., 0.), v(0., 0., sz), 2, 2);
    // Front wall z = 0 (+z) and back wall z = 4 (−z).
    patch(&mut mesh, v(0., 0., 0.), v(sx, 0., 0.), v(0., sy, 0.), 2, 2);
    patch(&mut mesh, v(0., 0., sz), v(0., sy, 0.), v(sx, 0., 0.), 2, 2);
    // Left wall x = 0 (+x) and right wall x = 4 (−x), running 0.1 m past the back wall.
    patch(&mut mesh, v(0., 0., 0.), v(0., sy, 0.), v(0., 0., sz), 2, 2);
    patch(&mut mesh, v(sx, 0., 0.), v(0., 0., sz + 0.1), v(0., sy, 0.), 4, 3);
    mesh.validate().expect("a valid room");
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_counts_and_validity() {
        let s = icosphere(4);
        assert_eq!(s.vertex_count(), 2562);
        assert_eq!(s.triangle_count(), 5120);
        s.validate().unwrap();
        // Winding is outward: every face normal agrees with its centroid.
        for t in 0..s.triangle_count() {
            let [a, b, c] = s.triangle_positions(t);
            assert!((b - a).cross(c - a).dot(a + b + c) > 0.0);
        }
    }

    #[test]
    fn integrating_sphere_faces_inward() {
        let (m, f) = integrating_sphere(3, 0.5, 0.8, Opening::Window);
        m.validate().unwrap();
        assert!(f > 0.05 && f < 0.15, "f = {f}");
        for t in 0..m.triangle_count() {
            let [a, b, c] = m.triangle_positions(t);
            assert!((b - a).cross(c - a).dot(a + b + c) < 0.0);
        }
    }
}
