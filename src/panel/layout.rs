//! Which triangles are the panel, and the texel grid laid over them.
//!
//! With texture coordinates (the mesh has UVs and the panel's are not all
//! equal) the texel grid is the unit UV square: texel (col, row) covers
//! `u ∈ [col/W, (col+1)/W)`, `v ∈ [1 − (row+1)/H, 1 − row/H)` (row 0 at the top,
//! as in an image). Without them, the panel's triangles are projected onto
//! their best-fit plane (through the area-weighted centroid, perpendicular to
//! the area-weighted mean normal) and the grid fills their oriented bounding
//! box there (long side along the principal axis of the projected corners).
//! Each texel centre that lands on a panel triangle gets that point, the
//! triangle and its normal; the first triangle (in mesh order) wins on shared edges.

use glam::{DVec2, Vec2, Vec3};
use std::path::Path;

use super::PanelError;
use crate::mesh::{MaterialRole, Mesh};

/// How texels were laid over the panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapping {
    Uv,
    Planar,
}

impl Mapping {
    pub fn name(self) -> &'static str {
        match self {
            Mapping::Uv => "uv",
            Mapping::Planar => "planar",
        }
    }
}

/// Marks a texel that lands on no panel triangle.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// The texels of a panel, struct-of-arrays in row-major order (row 0 at the top).
#[derive(Clone, Debug)]
pub struct PanelLayout {
    pub width: u32,
    pub height: u32,
    pub mapping: Mapping,
    /// Mesh triangle under each texel centre, or [`NO_TRIANGLE`].
    pub triangle: Vec<u32>,
    /// The texel centre's point on the panel.
    pub point: Vec<Vec3>,
    /// The panel's front normal there (the triangle's face normal, turned to the panel's front).
    pub normal: Vec<Vec3>,
    /// Area-weighted centroid and unit mean normal (the front) of the panel; its area.
    pub centre: Vec3,
    pub front: Vec3,
    pub area: f32,
    /// Edge lengths of the planar box (metres along the long and the short axis); UV maps give the bounding box too.
    pub size: [f32; 2],
    /// The planar box (used for the texel coordinates when `mapping` is [`Mapping::Planar`]).
    pub frame: PlanarFrame,
}

/// The panel's best-fit plane and the oriented box of its projected corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarFrame {
    pub centre: Vec3,
    /// Long axis and `front × x_axis`, unit.
    pub x_axis: Vec3,
    pub y_axis: Vec3,
    /// Box corner and extent along the axes, metres (f64: the unit coordinates are computed in it).
    pub lo: DVec2,
    pub span: DVec2,
}

impl PlanarFrame {
    /// Point `p` in box coordinates: [0,1]² over the box (x along the long axis).
    pub fn unit(&self, p: Vec3) -> Vec2 {
        let q = DVec2::new((p - self.centre).dot(self.x_axis) as f64, (p - self.centre).dot(self.y_axis) as f64);
        ((q - self.lo) / self.span).as_vec2()
    }
    pub fn size(&self) -> [f32; 2] {
        [self.span.x as f32, self.span.y as f32]
    }
}

impl PanelLayout {
    pub fn texel_count(&self) -> usize {
        self.triangle.len()
    }
    /// Texels that land on the panel.
    pub fn covered(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count()
    }

    /// Lays a `width × height` grid over `triangles` of `mesh`. `path` names the bundle in errors.
    pub fn new(mesh: &Mesh, triangles: &[u32], width: u32, height: u32, path: &Path) -> Result<PanelLayout, PanelError> {
        if !(1..=4096).contains(&width) || !(1..=4096).contains(&height) {
            return Err(PanelError::BadTexels { width, height });
        }
        let (mut area, mut weighted_normal, mut centroid) = (0.0f64, glam::DVec3::ZERO, glam::DVec3::ZERO);
        for &t in triangles {
            let [a, b, c] = mesh.triangle_positions(t as usize).map(|p| p.as_dvec3());
            let cross = (b - a).cross(c - a);
            let a2 = cross.length() / 2.0;
            area += a2;
            weighted_normal += cross / 2.0;
            centroid += (a + b + c) / 3.0 * a2;
        }
        let pattern_path = || path.to_path_buf();
        if !(area > 1e-12) {
            return Err(PanelError::NoArea { path: pattern_path(), triangles: triangles.len() });
        }
        if weighted_normal.length() < 1e-3 * area {
            return Err(PanelError::NoFacing { path: pattern_path() });
        }
        let front = weighted_normal.normalize().as_vec3();
        let centre = (centroid / area).as_vec3();
        let frame = planar_frame(mesh, triangles, centre, front);
        let mapping = if uv_spans_area(mesh, triangles) { Mapping::Uv } else { Mapping::Planar };
        let count = width as usize * height as usize;
        let mut layout = PanelLayout {
            width,
            height,
            mapping,
            triangle: vec![NO_TRIANGLE; count],
            point: vec![Vec3::ZERO; count],
            normal: vec![Vec3::ZERO; count],
            centre,
            front,
            area: area as f32,
            size: frame.size(),
            frame,
        };
        for &t in triangles {
            let corners = mesh.triangle(t as usize).map(|v| layout.texel_coord(mesh, v));
            layout.rasterize(mesh, t, corners);
        }
        if layout.covered() == 0 {
            return Err(PanelError::NoTexels { path: pattern_path(), width, height, mapping: mapping.name() });
        }
        Ok(layout)
    }

    /// Where mesh vertex `v` of the panel lies on the texel grid, in texel units:
    /// `(x, y)` with texel (col, row) covering `[col, col+1) × [row, row+1)`
    /// (row 0 at the top). The renderer's texture coordinates are this over (W, H).
    pub fn texel_coord(&self, mesh: &Mesh, v: u32) -> Vec2 {
        let unit = match self.mapping {
            Mapping::Uv => mesh.uvs[v as usize],
            Mapping::Planar => self.frame.unit(mesh.positions[v as usize]),
        };
        Vec2::new(unit.x * self.width as f32, (1.0 - unit.y) * self.height as f32)
    }

    /// Gives the texels whose centres fall inside triangle `t` (corners in texel units) their point and normal.
    fn rasterize(&mut self, mesh: &Mesh, t: u32, [a, b, c]: [Vec2; 3]) {
        let (a, b, c) = (a.as_dvec2(), b.as_dvec2(), c.as_dvec2());
        let det = (b - a).perp_dot(c - a);
        if det.abs() < 1e-12 {
            return;
        }
        let lo = a.min(b).min(c);
        let hi = a.max(b).max(c);
        let cols = (lo.x.floor().max(0.0) as u32)..(hi.x.ceil().min(self.width as f64) as u32);
        let rows = (lo.y.floor().max(0.0) as u32)..(hi.y.ceil().min(self.height as f64) as u32);
        let positions = mesh.triangle_positions(t as usize);
        let face = (positions[1] - positions[0]).cross(positions[2] - positions[0]).normalize_or_zero();
        let normal = if face.dot(self.front) < 0.0 { -face } else { face };
        // Inclusive edges, with a tolerance (in barycentric units) for the rounding of f32
        // UVs, so that texel centres on shared edges and vertices are covered.
        let eps = -1e-5;
        for row in rows {
            for col in cols.clone() {
                let index = row as usize * self.width as usize + col as usize;
                if self.triangle[index] != NO_TRIANGLE {
                    continue;
                }
                let p = DVec2::new(col as f64 + 0.5, row as f64 + 0.5);
                let w1 = (p - a).perp_dot(c - a) / det;
                let w2 = (b - a).perp_dot(p - a) / det;
                let w0 = 1.0 - w1 - w2;
                if w0 < eps || w1 < eps || w2 < eps {
                    continue;
                }
                let point = positions[0] * w0 as f32 + positions[1] * w1 as f32 + positions[2] * w2 as f32;
                self.triangle[index] = t;
                self.point[index] = point;
                self.normal[index] = normal;
            }
        }
    }
}

/// Texels for `long_side` along the panel's long edge and as many along the
/// short edge as keep texels square (planar box), at least 1.
pub fn default_texels(mesh: &Mesh, triangles: &[u32], long_side: u32) -> (u32, u32) {
    let (mut weighted_normal, mut centroid, mut area) = (Vec3::ZERO, Vec3::ZERO, 0.0f32);
    for &t in triangles {
        let [a, b, c] = mesh.triangle_positions(t as usize);
        let cross = (b - a).cross(c - a);
        weighted_normal += cross;
        centroid += (a + b + c) / 3.0 * cross.length();
        area += cross.length();
    }
    let (Some(front), true) = (weighted_normal.try_normalize(), area > 0.0) else { return (long_side, long_side) };
    let [long, short] = planar_frame(mesh, triangles, centroid / area, front).size();
    (long_side, ((long_side as f32 * short / long.max(1e-12)).round() as u32).clamp(1, long_side))
}

/// Whether the mesh has UVs and the panel's span an area.
fn uv_spans_area(mesh: &Mesh, triangles: &[u32]) -> bool {
    if mesh.uvs.is_empty() {
        return false;
    }
    let uv_area: f32 = triangles
        .iter()
        .map(|&t| mesh.triangle(t as usize).map(|v| mesh.uvs[v as usize]))
        .map(|c| (c[1] - c[0]).perp_dot(c[2] - c[0]).abs())
        .sum();
    uv_area > 1e-9
}

/// The panel's plane and the oriented box of its corners projected there (x
/// along the long axis, y = front × x).
fn planar_frame(mesh: &Mesh, triangles: &[u32], centre: Vec3, front: Vec3) -> PlanarFrame {
    let (t0, t1) = crate::sampling::tangent_frame(front);
    let in_plane = |p: Vec3| DVec2::new((p - centre).dot(t0) as f64, (p - centre).dot(t1) as f64);
    // Principal axis of the panel's area (second moments of its triangles,
    // ∫ x xᵀ dA = A/12 · (Σ pᵢ pᵢᵀ + s sᵀ), s = Σ pᵢ), in closed form for 2×2.
    let (mut area, mut first, mut sxx, mut sxy, mut syy) = (0.0, DVec2::ZERO, 0.0, 0.0, 0.0);
    for &t in triangles {
        let p = mesh.triangle_positions(t as usize).map(in_plane);
        let a = (p[1] - p[0]).perp_dot(p[2] - p[0]).abs() / 2.0;
        let sum = p[0] + p[1] + p[2];
        area += a;
        first += sum / 3.0 * a;
        sxx += a / 12.0 * (p.iter().map(|q| q.x * q.x).sum::<f64>() + sum.x * sum.x);
        sxy += a / 12.0 * (p.iter().map(|q| q.x * q.y).sum::<f64>() + sum.x * sum.y);
        syy += a / 12.0 * (p.iter().map(|q| q.y * q.y).sum::<f64>() + sum.y * sum.y);
    }
    let mean = first / area.max(f64::MIN_POSITIVE);
    let (sxx, sxy, syy) = (sxx - area * mean.x * mean.x, sxy - area * mean.x * mean.y, syy - area * mean.y * mean.y);
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let mut axis = (t0.as_dvec3() * angle.cos() + t1.as_dvec3() * angle.sin()).normalize();
    // A fixed sign: the axis's largest world component is positive.
    let largest = if axis.x.abs() >= axis.y.abs() && axis.x.abs() >= axis.z.abs() {
        axis.x
    } else if axis.y.abs() >= axis.z.abs() {
        axis.y
    } else {
        axis.z
    };
    if largest < 0.0 {
        axis = -axis;
    }
    let x_axis = axis.as_vec3();
    let y_axis = front.cross(x_axis).normalize();
    let coords: Vec<DVec2> = triangles
        .iter()
        .flat_map(|&t| mesh.triangle_positions(t as usize))
        .map(|p| DVec2::new((p - centre).dot(x_axis) as f64, (p - centre).dot(y_axis) as f64))
        .collect();
    let lo = coords.iter().fold(DVec2::splat(f64::INFINITY), |m, p| m.min(*p));
    let hi = coords.iter().fold(DVec2::splat(f64::NEG_INFINITY), |m, p| m.max(*p));
    let span = (hi - lo).max(DVec2::splat(1e-12));
    PlanarFrame { centre, x_axis, y_axis, lo, span }
}

/// The triangles of the panel: those whose material or group name matches
/// the glob `pattern`, or, when `pattern` is `None`, whose material has the
/// panel role. `path` names the bundle in errors.
pub fn select_panel(mesh: &Mesh, pattern: Option<&str>, path: &Path) -> Result<Vec<u32>, PanelError> {
    let label = pattern.unwrap_or("role panel").to_string();
    let matcher = pattern
        .map(|p| glob::Pattern::new(p).map_err(|e| PanelError::BadPattern { pattern: p.into(), message: e.to_string() }))
        .transpose()?;
    let material_hit: Vec<bool> = mesh
        .materials
        .iter()
        .map(|m| match &matcher {
            Some(p) => p.matches(&m.name),
            None => m.role == MaterialRole::Panel,
        })
        .collect();
    let group_hit: Vec<bool> = mesh.groups.iter().map(|g| matcher.as_ref().is_some_and(|p| p.matches(g))).collect();
    let triangles: Vec<u32> = (0..mesh.triangle_count())
        .filter(|&t| material_hit[mesh.tri_material[t] as usize] || group_hit[mesh.tri_group[t] as usize])
        .map(|t| t as u32)
        .collect();
    if triangles.is_empty() {
        let available = mesh.materials.iter().map(|m| m.name.as_str()).collect::<Vec<_>>().join(", ");
        return Err(PanelError::NoPanel { path: path.to_path_buf(), pattern: label, available });
    }
    Ok(triangles)
}
