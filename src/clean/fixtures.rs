//! Deterministic meshes with known, counted defects, for tests, benches and the
//! `prtbake fixtures` subcommand (and the baker's light-leak test: [`cracked_box`]).
//!
//! Every fixture is built from exact small numbers, carries the parameters it is
//! meant to be cleaned with and the exact repairs expected. Attributes are linear
//! functions of position ([`uv_at`], [`color_at`]) so that a test can check that
//! every output vertex still carries the right ones, split vertices included.

use super::CleanParams;
use crate::mesh::{Material, MaterialRole, Mesh};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The repairs and properties expected from cleaning a fixture.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Expected {
    pub degenerate_removed: usize,
    pub duplicates_removed: usize,
    pub flipped_duplicates_removed: usize,
    pub near_duplicates_removed: usize,
    pub covered_coplanar_removed: usize,
    pub tjunctions_fixed: usize,
    pub zipped_edges: usize,
    pub edges_split: usize,
    pub slivers_fixed: usize,
    pub triangles_flipped: usize,
    pub unorientable_components: usize,
    /// Sum of the reported partial overlap areas.
    pub partial_overlap_area: f64,
    /// `None` where the count depends on incidental merges.
    pub welded_vertices: Option<usize>,
    pub output_triangles: usize,
    /// The fixture's true boundary: 0 for a closed surface.
    pub boundary_edges_after: usize,
    /// The designed area: the union of the surface the designer meant (cracks closed).
    pub area: f64,
}

/// A mesh, the parameters to clean it with, and what cleaning must report.
#[derive(Clone, Debug)]
pub struct Fixture {
    pub name: &'static str,
    pub mesh: Mesh,
    pub params: CleanParams,
    pub expected: Expected,
}

/// Texture coordinates of every fixture vertex: a linear function of position.
pub fn uv_at(p: Vec3) -> Vec2 {
    Vec2::new(0.25 * p.x + 0.125 * p.y, 0.25 * p.z - 0.0625 * p.y)
}

/// Lightmap coordinates (`TEXCOORD_1`) of every fixture vertex: another
/// linear function of position, so a repair's interpolation keeps it exact.
pub fn lightmap_at(p: Vec3) -> Vec2 {
    Vec2::new(0.5 + 0.0625 * p.x - 0.03125 * p.z, 0.5 + 0.0625 * p.y + 0.03125 * p.x)
}

/// Vertex colour of every fixture vertex: a linear function of position.
pub fn color_at(p: Vec3) -> [f32; 3] {
    [0.5 + 0.05 * p.x, 0.5 + 0.05 * p.y, 0.5 + 0.05 * p.z]
}

/// Every fixture that cleans successfully (not [`fixture_nan_vertex`], nor [`large_torus`]).
pub fn all_fixtures() -> Vec<Fixture> {
    vec![
        fixture_exact_duplicate(),
        fixture_flipped_duplicate(),
        fixture_near_duplicate(),
        fixture_coplanar_double_tessellation(),
        fixture_partial_overlap(),
        fixture_cylinder_crack(),
        fixture_tjunction_strip(),
        fixture_slivers(),
        fixture_cracked_box(),
        fixture_long_edges(),
        fixture_orientation(),
    ]
}

/// Builds fixture meshes vertex by vertex.
struct Builder {
    mesh: Mesh,
}

impl Builder {
    fn new(materials: Vec<Material>) -> Builder {
        Builder { mesh: Mesh { materials, ..Mesh::default() } }
    }

    fn group(&mut self, name: &str) -> u32 {
        self.mesh.groups.push(name.to_string());
        (self.mesh.groups.len() - 1) as u32
    }

    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.mesh.positions.push(p);
        self.mesh.normals.push(n);
        self.mesh.uvs.push(uv_at(p));
        self.mesh.lightmap_uvs.push(lightmap_at(p));
        self.mesh.colors.push(color_at(p));
        (self.mesh.positions.len() - 1) as u32
    }

    /// Adds a triangle as given (winding untouched).
    fn tri(&mut self, v: [u32; 3], material: u16, group: u32) {
        self.mesh.indices.extend_from_slice(&v);
        self.mesh.tri_material.push(material);
        self.mesh.tri_group.push(group);
    }

    /// Adds a triangle wound counter-clockwise around `facing`.
    fn tri_facing(&mut self, [a, b, c]: [u32; 3], facing: Vec3, material: u16, group: u32) {
        let p = |v: u32| self.mesh.positions[v as usize];
        let n = (p(b) - p(a)).cross(p(c) - p(a));
        let v = if n.dot(facing) >= 0.0 { [a, b, c] } else { [a, c, b] };
        self.tri(v, material, group);
    }

    #[allow(clippy::too_many_arguments)]
    /// A grid of `nu × nv` quads spanning `origin + s·du + t·dv` (s, t in 0..=1),
    /// facing `du × dv`, two triangles per quad. Returns the vertex ids, row-major.
    fn grid(&mut self, origin: Vec3, du: Vec3, dv: Vec3, nu: usize, nv: usize, material: u16, group: u32) -> Vec<u32> {
        let n = du.cross(dv).normalize();
        let mut ids = Vec::new();
        for j in 0..=nv {
            for i in 0..=nu {
                let p = origin + du * (i as f32 / nu as f32) + dv * (j as f32 / nv as f32);
                ids.push(self.vertex(p, n));
            }
        }
        let at = |i: usize, j: usize| ids[j * (nu + 1) + i];
        for j in 0..nv {
            for i in 0..nu {
                let (v00, v10, v11, v01) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                self.tri([v00, v10, v11], material, group);
                self.tri([v00, v11, v01], material, group);
            }
        }
        ids
    }

    /// Copies triangle `t` with fresh vertices, each moved by `offset(k)` (k = corner).
    fn copy_tri(&mut self, t: usize, reverse: bool, offset: impl Fn(usize) -> Vec3) {
        let src = self.mesh.triangle(t);
        let mut v = [0u32; 3];
        for k in 0..3 {
            let s = src[k] as usize;
            let n = self.mesh.normals[s];
            v[k] = self.vertex(self.mesh.positions[s] + offset(k), if reverse { -n } else { n });
        }
        if reverse {
            v.swap(1, 2);
        }
        self.tri(v, self.mesh.tri_material[t], self.mesh.tri_group[t]);
    }

    /// Copies triangle `t` reusing its vertex ids, rotated by `rotate` corners, optionally reversed.
    fn repeat_tri(&mut self, t: usize, rotate: usize, reverse: bool) {
        let s = self.mesh.triangle(t);
        let mut v = [s[rotate % 3], s[(rotate + 1) % 3], s[(rotate + 2) % 3]];
        if reverse {
            v.swap(1, 2);
        }
        self.tri(v, self.mesh.tri_material[t], self.mesh.tri_group[t]);
    }

    fn area(&self) -> f64 {
        (0..self.mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = self.mesh.triangle_positions(t).map(|p| p.as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }
}

fn materials() -> Vec<Material> {
    vec![
        Material::opaque("paint", 0.6),
        Material { name: "glass".into(), albedo: [0.9; 3], role: MaterialRole::Window, transmittance: 0.8 },
        Material { name: "screen".into(), albedo: [0.1; 3], role: MaterialRole::Panel, transmittance: 1.0 },
    ]
}

/// A 4 × 4 grid of unit quads in the plane y = 0, facing +y: 32 triangles,
/// 16 boundary edges, area 16.
fn plane_grid(b: &mut Builder) {
    let g = b.group("plate");
    b.grid(Vec3::ZERO, Vec3::X * 4.0, Vec3::NEG_Z * 4.0, 4, 4, 0, g);
}

fn plane_expected() -> Expected {
    Expected { output_triangles: 32, boundary_edges_after: 16, area: 16.0, ..Expected::default() }
}

/// A grid plus three exact duplicates: two reuse the vertex ids (one rotated),
/// one has its own bit-identical vertices.
pub fn fixture_exact_duplicate() -> Fixture {
    let mut b = Builder::new(materials());
    plane_grid(&mut b);
    b.repeat_tri(5, 0, false);
    b.repeat_tri(10, 1, false);
    b.copy_tri(20, false, |_| Vec3::ZERO);
    let expected = Expected { duplicates_removed: 3, welded_vertices: Some(3), ..plane_expected() };
    Fixture { name: "exact_duplicate", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// A grid plus three flipped duplicates: two reuse the vertex ids, one has its own
/// vertices with negated normals (a two-sided export).
pub fn fixture_flipped_duplicate() -> Fixture {
    let mut b = Builder::new(materials());
    plane_grid(&mut b);
    b.repeat_tri(5, 0, true);
    b.repeat_tri(10, 2, true);
    b.copy_tri(20, true, |_| Vec3::ZERO);
    let expected = Expected { flipped_duplicates_removed: 3, welded_vertices: Some(0), ..plane_expected() };
    Fixture { name: "flipped_duplicate", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// A grid plus three copies whose vertices are moved by 1e-7 of the diagonal:
/// duplicates only after welding.
pub fn fixture_near_duplicate() -> Fixture {
    let mut b = Builder::new(materials());
    plane_grid(&mut b);
    let jitter = 1e-7 * 32f32.sqrt();
    let dirs = [Vec3::new(1.0, -1.0, 1.0), Vec3::new(-1.0, 1.0, 1.0), Vec3::new(1.0, 1.0, -1.0)];
    for t in [5, 10, 20] {
        b.copy_tri(t, false, |k| dirs[k].normalize() * jitter);
    }
    let expected = Expected { duplicates_removed: 3, near_duplicates_removed: 3, welded_vertices: Some(9), ..plane_expected() };
    Fixture { name: "near_duplicate", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// One 2 × 2 square tessellated twice in the same plane: 2 × 2 quads (8 triangles,
/// kept: lower indices) and 3 × 3 quads (18 triangles, covered).
pub fn fixture_coplanar_double_tessellation() -> Fixture {
    let mut b = Builder::new(materials());
    let (ga, gb) = (b.group("patch_a"), b.group("patch_b"));
    b.grid(Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 2, 2, 0, ga);
    b.grid(Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 3, 3, 0, gb);
    let expected = Expected {
        covered_coplanar_removed: 18,
        welded_vertices: Some(4),
        output_triangles: 8,
        boundary_edges_after: 8,
        area: 4.0,
        ..Expected::default()
    };
    Fixture { name: "coplanar_double_tessellation", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// Two coplanar 2 × 2 squares overlapping on a unit square: nothing is covered,
/// two triangle pairs overlap by 0.5 each (reported, kept).
pub fn fixture_partial_overlap() -> Fixture {
    let mut b = Builder::new(materials());
    let (ga, gb) = (b.group("square_a"), b.group("square_b"));
    b.grid(Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 1, 1, 0, ga);
    b.grid(Vec3::new(1.0, 0.0, -1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 1, 1, 2, gb);
    let expected = Expected {
        partial_overlap_area: 1.0,
        welded_vertices: Some(0),
        output_triangles: 4,
        boundary_edges_after: 8,
        area: 8.0,
        ..Expected::default()
    };
    Fixture { name: "partial_overlap", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// Number of sides of the prism in [`fixture_cylinder_crack`].
const CYLINDER_SIDES: usize = 12;

/// An open 12-sided cylinder (radius 1, height 2) of two patches: the lower half
/// with 12 segments around (opaque), the upper half with 36 (glass), lifted by a
/// crack of 1e-5 of the height. The seam has 24 T-junctions; the designed surface
/// is closed along it, open at both rims (12 + 36 boundary edges).
pub fn fixture_cylinder_crack() -> Fixture {
    let height = 2.0f32;
    let crack = 1e-5 * height;
    let corner = |k: usize| {
        let a = 2.0 * PI * (k % CYLINDER_SIDES) as f32 / CYLINDER_SIDES as f32;
        Vec3::new(a.sin(), 0.0, a.cos())
    };
    let mut b = Builder::new(materials());
    let (g_low, g_high) = (b.group("body_low"), b.group("body_high"));
    let band = |b: &mut Builder, around: usize, y0: f32, y1: f32, material: u16, group: u32| {
        let per_side = around / CYLINDER_SIDES;
        let rows = 2;
        let mut ids = vec![vec![0u32; around]; rows + 1];
        for (r, row) in ids.iter_mut().enumerate() {
            let y = y0 + (y1 - y0) * r as f32 / rows as f32;
            for (i, id) in row.iter_mut().enumerate() {
                let (side, j) = (i / per_side, i % per_side);
                let p = corner(side).lerp(corner(side + 1), j as f32 / per_side as f32);
                *id = b.vertex(Vec3::new(p.x, y, p.z), Vec3::new(p.x, 0.0, p.z).normalize());
            }
        }
        for r in 0..rows {
            for i in 0..around {
                let (v00, v10) = (ids[r][i], ids[r][(i + 1) % around]);
                let (v01, v11) = (ids[r + 1][i], ids[r + 1][(i + 1) % around]);
                let out = b.mesh.positions[v00 as usize] * Vec3::new(1.0, 0.0, 1.0);
                b.tri_facing([v00, v10, v11], out, material, group);
                b.tri_facing([v00, v11, v01], out, material, group);
            }
        }
    };
    band(&mut b, CYLINDER_SIDES, 0.0, height / 2.0, 0, g_low);
    band(&mut b, 3 * CYLINDER_SIDES, height / 2.0 + crack, height, 1, g_high);
    let side = 2.0 * (PI as f64 / CYLINDER_SIDES as f64).sin();
    let expected = Expected {
        tjunctions_fixed: 2 * CYLINDER_SIDES,
        zipped_edges: 4 * CYLINDER_SIDES,
        output_triangles: 4 * CYLINDER_SIDES + 2 * CYLINDER_SIDES + 12 * CYLINDER_SIDES,
        boundary_edges_after: 4 * CYLINDER_SIDES,
        area: CYLINDER_SIDES as f64 * side * height as f64,
        ..Expected::default()
    };
    Fixture { name: "cylinder_crack", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// Two coplanar strips side by side, 1 × 3 and 1 × 2 quads, meeting along x = 1:
/// three T-junctions (z = 1, 1.5, 2), no gap.
pub fn fixture_tjunction_strip() -> Fixture {
    let mut b = Builder::new(materials());
    let (ga, gb) = (b.group("strip_a"), b.group("strip_b"));
    b.grid(Vec3::ZERO, Vec3::X, Vec3::NEG_Z * 3.0, 1, 3, 0, ga);
    b.grid(Vec3::X, Vec3::X, Vec3::NEG_Z * 3.0, 1, 2, 0, gb);
    let expected = Expected {
        tjunctions_fixed: 3,
        zipped_edges: 5,
        welded_vertices: Some(5),
        output_triangles: 13,
        boundary_edges_after: 9,
        area: 6.0,
        ..Expected::default()
    };
    Fixture { name: "tjunction_strip", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// An 8 × 1 rectangle triangulated as two fans (from the corners of one diagonal):
/// 16 triangles, 10 of them slivers under 5 degrees. Flips turn it into unit
/// squares (smallest angle 45 degrees).
pub fn fixture_slivers() -> Fixture {
    let mut b = Builder::new(materials());
    let g = b.group("fan");
    let n = 8;
    let bottom: Vec<u32> = (0..=n).map(|i| b.vertex(Vec3::new(i as f32, 0.0, 0.0), Vec3::Y)).collect();
    let top: Vec<u32> = (0..=n).map(|i| b.vertex(Vec3::new(i as f32, 0.0, -1.0), Vec3::Y)).collect();
    for i in 0..n {
        b.tri_facing([bottom[0], top[i], top[i + 1]], Vec3::Y, 0, g);
        b.tri_facing([top[n], bottom[i], bottom[i + 1]], Vec3::Y, 0, g);
    }
    let slivers = (0..b.mesh.triangle_count())
        .filter(|&t| super::work::min_angle(b.mesh.triangle_positions(t).map(|p| p.as_dvec3())) < 5f64.to_radians())
        .count();
    let expected = Expected {
        slivers_fixed: slivers,
        welded_vertices: Some(0),
        output_triangles: 16,
        boundary_edges_after: 18,
        area: 8.0,
        ..Expected::default()
    };
    Fixture { name: "slivers", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// A mesh whose vertex 5 has a NaN coordinate: cleaning must refuse it, naming vertex 5.
pub fn fixture_nan_vertex() -> Mesh {
    let mut b = Builder::new(materials());
    plane_grid(&mut b);
    b.mesh.positions[5].y = f32::NAN;
    b.mesh
}

/// [`cracked_box`] with a crack of 1e-4 of the box's size.
pub fn fixture_cracked_box() -> Fixture {
    cracked_box(1e-4)
}

/// A closed unit cube, outward, hard-edged (each face has its own vertices), made
/// of two patches: the bottom and four sides at 2 × 2 quads per face, and the top
/// at 3 × 3 quads lifted by `crack` (a fraction of the size). Light leaks through
/// the crack until it is zipped: 4 corner welds and 12 T-junctions close it.
pub fn cracked_box(crack: f32) -> Fixture {
    let mut b = Builder::new(materials());
    let (ga, gb) = (b.group("box_body"), b.group("box_lid"));
    let [bottom_and_sides @ .., _top] = cube_faces(Vec3::ZERO);
    for (origin, du, dv) in bottom_and_sides {
        b.grid(origin, du, dv, 2, 2, 0, ga);
    }
    b.grid(Vec3::new(0.0, 1.0 + crack, 0.0), Vec3::Z, Vec3::X, 3, 3, 1, gb);
    let expected = Expected {
        tjunctions_fixed: 12,
        zipped_edges: 20,
        output_triangles: 5 * 8 + 18 + 12,
        boundary_edges_after: 0,
        area: 6.0,
        ..Expected::default()
    };
    Fixture { name: "cracked_box", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// A 4 × 4 square as two triangles, cleaned with `max_edge = 1`: three passes of
/// midpoint splits (5 + 16 + 16 edges) give 64 right isosceles triangles.
pub fn fixture_long_edges() -> Fixture {
    let mut b = Builder::new(materials());
    let g = b.group("slab");
    b.grid(Vec3::ZERO, Vec3::X * 4.0, Vec3::NEG_Z * 4.0, 1, 1, 2, g);
    let expected = Expected {
        edges_split: 37,
        welded_vertices: Some(0),
        output_triangles: 64,
        boundary_edges_after: 16,
        area: 16.0,
        ..Expected::default()
    };
    let params = CleanParams { max_edge: Some(1.0), ..CleanParams::default() };
    Fixture { name: "long_edges", mesh: b.mesh, params, expected }
}

/// Three components: a closed box (2 × 2 quads per face) with three triangles
/// wound inward, a closed box turned inside out (12 triangles, inward normals), and
/// a Möbius strip of 12 quads, which cannot be oriented (reported, left as is).
pub fn fixture_orientation() -> Fixture {
    let mut b = Builder::new(materials());
    let (g1, g2, g3) = (b.group("box"), b.group("inside_out"), b.group("moebius"));
    for (origin, du, dv) in cube_faces(Vec3::ZERO) {
        b.grid(origin, du, dv, 2, 2, 0, g1);
    }
    for t in [3, 22, 41] {
        let v = b.mesh.triangle(t);
        b.mesh.indices[3 * t..3 * t + 3].copy_from_slice(&[v[0], v[2], v[1]]);
    }
    let first = b.mesh.triangle_count();
    for (origin, du, dv) in cube_faces(Vec3::new(3.0, 0.0, 0.0)) {
        b.grid(origin, dv, du, 1, 1, 0, g2); // dv × du: inward
    }
    let inside_out = b.mesh.triangle_count() - first;
    moebius_strip(&mut b, Vec3::new(0.0, 0.0, 5.0), 12, g3);
    let area = b.area();
    let expected = Expected {
        triangles_flipped: 3 + inside_out,
        unorientable_components: 1,
        welded_vertices: Some(0),
        output_triangles: b.mesh.triangle_count(),
        boundary_edges_after: 24,
        area,
        ..Expected::default()
    };
    Fixture { name: "orientation", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// The faces of the unit cube at `o` as (origin, du, dv), `du × dv` outward:
/// bottom, back, front, left, right, top.
fn cube_faces(o: Vec3) -> [(Vec3, Vec3, Vec3); 6] {
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    [(o, x, z), (o, y, x), (o + z, x, y), (o, z, y), (o + x, y, z), (o + y, z, x)]
}

/// A Möbius strip of `segments` quads (radius 2, width 1) centred at `centre`.
fn moebius_strip(b: &mut Builder, centre: Vec3, segments: usize, group: u32) {
    let point = |i: usize, w: f32| {
        let u = 2.0 * PI * i as f32 / segments as f32;
        let r = 2.0 + w * (u / 2.0).cos();
        centre + Vec3::new(r * u.cos(), w * (u / 2.0).sin(), r * u.sin())
    };
    let mut ids = Vec::new();
    for i in 0..segments {
        for w in [-0.5, 0.5] {
            let p = point(i, w);
            let n = (point(i + 1, w) - p).cross(point(i, -w) - p).normalize_or_zero();
            ids.push(b.vertex(p, n));
        }
    }
    // Column `segments` is column 0 with its two sides swapped: the half twist.
    let at = |i: usize, side: usize| if i < segments { ids[2 * i + side] } else { ids[1 - side] };
    for i in 0..segments {
        let (a, bb, c, d) = (at(i, 0), at(i + 1, 0), at(i + 1, 1), at(i, 1));
        b.tri([a, bb, c], 0, group);
        b.tri([a, c, d], 0, group);
    }
}

/// A closed torus of at least `min_triangles` triangles as a triangle soup (every
/// triangle has its own three vertices, as STL files do), with every 50th triangle
/// duplicated and every 97th duplicated flipped. For the speed tests and benches.
pub fn large_torus(min_triangles: usize) -> Fixture {
    let nv = ((min_triangles as f64 / 2.0 / 1.6).sqrt().ceil() as usize).max(3);
    let nu = ((min_triangles as f64 / 2.0 / nv as f64).ceil() as usize).max(3);
    let (major, minor) = (3.0f32, 1.0f32);
    let at = |i: usize, j: usize| {
        let (u, v) = (2.0 * PI * (i % nu) as f32 / nu as f32, 2.0 * PI * (j % nv) as f32 / nv as f32);
        let n = Vec3::new(v.cos() * u.cos(), v.sin(), v.cos() * u.sin());
        (Vec3::new(major * u.cos(), 0.0, major * u.sin()) + minor * n, n)
    };
    let mut b = Builder::new(materials());
    let g = b.group("torus");
    let mut base = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let quad = [at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)];
            base.push([quad[0], quad[1], quad[2]]);
            base.push([quad[0], quad[2], quad[3]]);
        }
    }
    let push = |b: &mut Builder, tri: &[(Vec3, Vec3); 3], flip: bool| {
        let mut v = tri.map(|(p, n)| b.vertex(p, if flip { -n } else { n }));
        if flip {
            v.swap(1, 2);
        }
        b.tri(v, 0, g);
    };
    for tri in &base {
        push(&mut b, tri, false);
    }
    let area = b.area();
    let (mut dups, mut flips) = (0, 0);
    for (t, tri) in base.iter().enumerate() {
        if t % 50 == 0 {
            push(&mut b, tri, false);
            dups += 1;
        }
        if t % 97 == 0 {
            push(&mut b, tri, true);
            flips += 1;
        }
    }
    let expected = Expected {
        duplicates_removed: dups,
        flipped_duplicates_removed: flips,
        output_triangles: base.len(),
        boundary_edges_after: 0,
        area,
        ..Expected::default()
    };
    Fixture { name: "large_torus", mesh: b.mesh, params: CleanParams::default(), expected }
}

/// The shapes of high-valence fans, for the clean-up's scaling tests and benches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FanShape {
    /// A unit disc in the plane y = 0: `n` triangles around its centre, the rim a
    /// circle (every triangle a sliver with a 360°/n apex angle once n > 72).
    Disc,
    /// The side of a cone (unit radius, unit height, open base): `n` triangles around the apex.
    Cone,
    /// One convex `n`-gon face on the unit circle triangulated as the OBJ loader
    /// does it, as a fan from its first corner: `n - 2` triangles.
    Polygon,
    /// A closed cone: the side of [`FanShape::Cone`] and its base, a fan of `n`
    /// triangles around the base's centre; outward normals from the faces
    /// (the apex's faces +y). `2n` triangles, apex and base centre of valence `n`.
    ClosedCone,
}

/// A fan of `n` rim points (see [`FanShape`]); every vertex normal faces +y
/// (but the closed cone's).
pub fn fan(shape: FanShape, n: usize) -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("fan");
    let rim: Vec<u32> = (0..n)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            b.vertex(Vec3::new(a.cos() as f32, 0.0, -a.sin() as f32), Vec3::Y)
        })
        .collect();
    let apex = match shape {
        FanShape::Disc => Some(b.vertex(Vec3::ZERO, Vec3::Y)),
        FanShape::Cone | FanShape::ClosedCone => Some(b.vertex(Vec3::Y, Vec3::Y)),
        FanShape::Polygon => None,
    };
    match apex {
        Some(apex) => (0..n).for_each(|i| b.tri([apex, rim[i], rim[(i + 1) % n]], 0, g)),
        None => (1..n - 1).for_each(|i| b.tri([rim[0], rim[i], rim[i + 1]], 0, g)),
    }
    if shape == FanShape::ClosedCone {
        let centre = b.vertex(Vec3::ZERO, Vec3::NEG_Y);
        (0..n).for_each(|i| b.tri([centre, rim[(i + 1) % n], rim[i]], 0, g));
        b.mesh.normals = crate::mesh::compute_vertex_normals(&b.mesh.positions, &b.mesh.indices);
    }
    b.mesh
}

/// Two unit-thick quads crossing in an X (issue 20, cutting): quad A in the
/// plane y = 0 (x, z in −1..1, facing +y, diagonal (−1, 0, 1)–(1, 0, −1)) and
/// quad B in the plane x = 0 (y in −1..2, z in −1..1, facing −x, diagonal
/// (0, −1, 1)–(0, 2, −1)). They cross along x = y = 0, z in −1..1, which A's
/// diagonal meets at z = 0 and B's at z = 1/3: three segments (z from −1 to 0,
/// 0 to 1/3, 1/3 to 1) and 16 pieces (see `clean::tests`).
pub fn crossing_quads() -> Mesh {
    let mut b = Builder::new(materials());
    let (ga, gb) = (b.group("quad_a"), b.group("quad_b"));
    b.grid(Vec3::new(-1.0, 0.0, 1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 1, 1, 0, ga);
    b.grid(Vec3::new(0.0, -1.0, 1.0), Vec3::Y * 3.0, Vec3::NEG_Z * 2.0, 1, 1, 0, gb);
    b.mesh
}

/// A floor quad (y = 0, x and z in −1..1, facing +y, diagonal (−1, 0, 1)–(1,
/// 0, −1)) and a wall quad standing on it (z = 0.25, x in −1.5..1.5, y in
/// 0..1, facing +z) whose bottom edge crosses the whole floor: a T-contact
/// along a line, the floor-under-wall case. The floor is cut along z = 0.25
/// (two segments, meeting on its diagonal at x = −0.25); the wall's bottom
/// edge takes the three points where it meets the floor's edges.
pub fn wall_on_floor() -> Mesh {
    let mut b = Builder::new(materials());
    let (gf, gw) = (b.group("floor"), b.group("wall"));
    b.grid(Vec3::new(-1.0, 0.0, 1.0), Vec3::X * 2.0, Vec3::NEG_Z * 2.0, 1, 1, 0, gf);
    b.grid(Vec3::new(-1.5, 0.0, 0.25), Vec3::X * 3.0, Vec3::Y, 1, 1, 0, gw);
    b.mesh
}

/// A floor triangle and a small wall triangle standing inside it (bottom edge
/// from (−0.5, 0, 0) to (0.5, 0, 0)): the wall ends inside the floor, so the
/// floor is slit along the edge, not separated.
pub fn wall_inside_floor_triangle() -> Mesh {
    let mut b = Builder::new(materials());
    let (gf, gw) = (b.group("floor"), b.group("wall"));
    let f = [Vec3::new(-2.0, 0.0, 2.0), Vec3::new(2.0, 0.0, 2.0), Vec3::new(0.0, 0.0, -2.0)].map(|p| b.vertex(p, Vec3::Y));
    b.tri_facing(f, Vec3::Y, 0, gf);
    let w = [Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)].map(|p| b.vertex(p, Vec3::Z));
    b.tri_facing(w, Vec3::Z, 0, gw);
    b.mesh
}

/// Pairs that touch without crossing: two triangles folded at 90° along a
/// shared edge, a third meeting the first only at a shared corner, and a
/// fourth (its own vertices) touching the first's plane in one corner.
pub fn touching_triangles() -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("fold");
    let o = b.vertex(Vec3::ZERO, Vec3::Y);
    let x = b.vertex(Vec3::X, Vec3::Y);
    let z = b.vertex(Vec3::Z, Vec3::Y);
    let up = b.vertex(Vec3::Y, Vec3::NEG_Z);
    b.tri_facing([o, x, z], Vec3::Y, 0, g);
    b.tri_facing([o, x, up], Vec3::NEG_Z, 0, g);
    let far = [Vec3::new(-1.0, 0.5, -1.0), Vec3::new(-1.0, -0.5, -1.0)].map(|p| b.vertex(p, Vec3::X));
    b.tri_facing([o, far[0], far[1]], Vec3::X, 0, g);
    let touch = [Vec3::new(0.2, 0.0, 0.2), Vec3::new(0.2, 1.0, 0.2), Vec3::new(0.4, 1.0, 0.3)].map(|p| b.vertex(p, Vec3::X));
    b.tri_facing(touch, Vec3::X, 0, g);
    b.mesh
}

/// `n` copies of one triangle in the plane y = 0, each slid by 1/100 of its
/// base along the base line: every copy overlaps every other and none covers
/// another (each apex is its own), and every base corner lies on the other
/// copies' bases. The stacked-coplanar case of the clean-up's scaling tests
/// and benches (`n (n − 1) / 2` partial overlaps, nothing to remove or zip).
pub fn stacked_coplanar(n: usize) -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("stack");
    for i in 0..n {
        let d = Vec3::new(0.01 * i as f32, 0.0, 0.0);
        let v = [Vec3::ZERO, Vec3::X, Vec3::new(0.3, 0.0, -1.0)].map(|p| b.vertex(p + d, Vec3::Y));
        b.tri_facing(v, Vec3::Y, 0, g);
    }
    b.mesh
}

/// `n` fins around the y axis (unit radius, turned by 360°/n each), every
/// fin a triangle with one edge on the axis, from y = h to y = h + 1 where
/// h = i / (2n) staggers them: the fins meet only along the axis, where
/// each fin's edge carries the other fins' corners (T-junctions between
/// n surfaces, not a crack).
pub fn fins_on_axis(n: usize) -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("fins");
    for i in 0..n {
        let (a, h) = (2.0 * PI * i as f32 / n as f32, 0.5 * i as f32 / n as f32);
        let out = Vec3::new(a.cos(), h + 0.5, -a.sin());
        let normal = Vec3::new(a.sin(), 0.0, a.cos());
        let v = [Vec3::new(0.0, h, 0.0), Vec3::new(0.0, h + 1.0, 0.0), out].map(|p| b.vertex(p, normal));
        b.tri_facing(v, normal, 0, g);
    }
    b.mesh
}

/// `n` fins sharing the y axis: fin `i` is the triangle (−0.5, 0), (1, 0),
/// (−0.5, 1) of its plane (turned by 180°/n each about the axis), so the
/// axis crosses every fin from y = 0 (its bottom edge) to y = 2/3 (its
/// slanted edge). Every pair of fins crosses along that one segment:
/// `n (n − 1) / 2` crossing pairs, one line to cut.
pub fn fins_through_axis(n: usize) -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("fins");
    for i in 0..n {
        let a = PI * i as f32 / n as f32;
        let (along, normal) = (Vec3::new(a.cos(), 0.0, -a.sin()), Vec3::new(a.sin(), 0.0, a.cos()));
        let v = [(-0.5, 0.0), (1.0, 0.0), (-0.5, 1.0)].map(|(s, y)| b.vertex(along * s + Vec3::Y * y, normal));
        b.tri_facing(v, normal, 0, g);
    }
    b.mesh
}

/// `n` thin triangles (length 2, 0.04 wide at the base) through the origin
/// in pseudo-random directions (a fixed generator): every pair crosses in a
/// short segment through the origin, and every crossing of two segments in
/// a triangle (where three triangles meet) lies there too, so near-coincident
/// points and shallow crossings abound: the degenerate case of cutting.
pub fn thin_crossing(n: usize) -> Mesh {
    let mut b = Builder::new(materials());
    let g = b.group("sticks");
    let mut state = 777u64;
    let mut random = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as f32) / (1u64 << 31) as f32
    };
    for _ in 0..n {
        let d = Vec3::new(random() - 0.5, random() - 0.5, random() - 0.5).normalize();
        let (e, f) = d.any_orthonormal_pair();
        let turn = random() * 2.0 * PI;
        let side = e * turn.cos() + f * turn.sin();
        let normal = d.cross(side);
        let v = [-d - side * 0.02, d, -d + side * 0.02].map(|p| b.vertex(p, normal));
        b.tri_facing(v, normal, 0, g);
    }
    b.mesh
}
