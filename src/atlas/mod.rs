//! Lightmap atlas: each triangle's place in a texture whose texels hold light
//! where vertices cannot (a 3 cm slat shadow on a 4 m wall, a big CAD
//! triangle's contact shadow).
//!
//! Why xatlas: measured against the pure-Rust `uvunwrap` on the room, the
//! dining room and the Ferrari (benches/atlas_compare.py,
//! docs/image-accuracy.md), `uvunwrap` cut shorter seams on the two rooms
//! at the same texel use, but had not unwrapped the Ferrari after 12 min
//! where xatlas took 4 s. It is the unwrapper Godot ships. It is
//! vendored (vendor/xatlas, built by build.rs, single-threaded so an atlas
//! is the same on every machine) because the crates.io binding does not
//! link on Linux.
//!
//! The atlas is in texel units: texel `(x, y)` is the square
//! `[x, x+1) × [y, y+1)`, `texel_size` world units on a side. Charts are
//! packed [`PADDING`] texels apart with room for bilinear reads, so a texel
//! is touched by one chart only ([`coverage`]).

pub mod coverage;
pub mod density;
pub mod lightmap;
mod xatlas_ffi;

use crate::disjoint::{find, union};
use crate::mesh::Mesh;
use glam::Vec2;

/// Empty texels between charts: a chart's bilinear reads and its dilation
/// ring stay its own.
pub const PADDING: u32 = 2;
/// Most texels an atlas may have (a 16k × 16k texture); more is refused
/// before unwrapping, with the texel size that would fit.
pub const MAX_TEXELS: f64 = (1u64 << 28) as f64;

/// Why an atlas could not be made.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AtlasError {
    #[error("texel size {0} is not a positive finite length")]
    BadTexelSize(f32),
    #[error("texel size {asked} would need about {texels:.3e} texels, more than {MAX_TEXELS:.3e}: choose {fits:.4} or more")]
    TooManyTexels { asked: f32, texels: f64, fits: f32 },
    #[error("the mesh has no triangle to unwrap")]
    Empty,
    #[error("xatlas refused the mesh: {0}")]
    Refused(String),
    #[error("xatlas returned {got} triangles for {expected}")]
    Incomplete { got: usize, expected: usize },
    #[error("the mesh's lightmap coordinates (TEXCOORD_1) leave the unit square at vertex {vertex}: {uv:?} (give --unwrap to unwrap a new atlas)")]
    LightmapOutside { vertex: u32, uv: [f32; 2] },
    #[error("the mesh's lightmap coordinates (TEXCOORD_1) cover no area (give --unwrap to unwrap a new atlas)")]
    LightmapEmpty,
    #[error("the mesh's lightmap coordinates (TEXCOORD_1) give {triangles} triangles of positive area none in the atlas (first: triangle {first}), so their light would have no texel (give --unwrap to unwrap a new atlas)")]
    LightmapFolded { triangles: usize, first: u32 },
    #[error("the mesh's lightmap coordinates (TEXCOORD_1) at texel size {texel_size}: {shared} texels lie under two charts or overlapping triangles and {beside} beside another chart's texel, so they would hold or blend the light of two places: choose a smaller texel size, or give --unwrap to unwrap a new atlas")]
    LightmapShared { texel_size: f32, shared: usize, beside: usize },
}

/// A mesh's lightmap atlas (struct of arrays, `u32` indices).
#[derive(Clone, Debug, PartialEq)]
pub struct Atlas {
    /// Size in texels.
    pub width: u32,
    pub height: u32,
    /// World units per texel side.
    pub texel_size: f32,
    /// Atlas vertices: position in texels, and the mesh vertex each copies
    /// (a mesh vertex on a chart seam has one atlas vertex per chart).
    pub uv: Vec<Vec2>,
    pub source_vertex: Vec<u32>,
    /// Three atlas vertices per mesh triangle, in the mesh's order.
    pub indices: Vec<u32>,
    /// The chart each triangle lies in; [`NO_CHART`] for a triangle xatlas
    /// left out (zero area), which has no texel.
    pub triangle_chart: Vec<u32>,
    pub chart_count: u32,
}

/// [`Atlas::triangle_chart`] of a triangle in no chart.
pub const NO_CHART: u32 = u32::MAX;

impl Atlas {
    /// The mesh's own lightmap atlas ([`Atlas::from_lightmap_uvs`]) when it
    /// has one and `unwrap` is false, else a new one from xatlas.
    pub fn for_mesh(mesh: &Mesh, texel_size: f32, unwrap: bool) -> Result<Atlas, AtlasError> {
        if mesh.lightmap_uvs.is_empty() || unwrap {
            Atlas::unwrap(mesh, texel_size)
        } else {
            Atlas::from_lightmap_uvs(mesh, texel_size)
        }
    }

    /// The atlas of the mesh's own lightmap coordinates (glTF `TEXCOORD_1`,
    /// in the unit square), at a square resolution whose texels are
    /// `texel_size` on a side on average over the surface (world area over
    /// atlas area). The layout is kept as authored: charts are the groups of
    /// triangles joined by shared vertices; a triangle of zero area has no
    /// chart. Refused when a coordinate leaves the unit square, when a
    /// triangle of positive area has none in the atlas (its light would have
    /// no texel), or
    /// when a texel would mix two places' light: under two charts or
    /// overlapping triangles, or beside another chart's texel (charts less
    /// than a texel apart at this size: bilinear reads blend across).
    pub fn from_lightmap_uvs(mesh: &Mesh, texel_size: f32) -> Result<Atlas, AtlasError> {
        if !(texel_size.is_finite() && texel_size > 0.0) {
            return Err(AtlasError::BadTexelSize(texel_size));
        }
        if mesh.triangle_count() == 0 {
            return Err(AtlasError::Empty);
        }
        if let Some((v, uv)) =
            mesh.lightmap_uvs.iter().enumerate().find(|(_, uv)| !(uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all()))
        {
            return Err(AtlasError::LightmapOutside { vertex: v as u32, uv: uv.to_array() });
        }
        let uv_area = |t: usize| {
            let [a, b, c] = mesh.triangle(t).map(|v| mesh.lightmap_uvs[v as usize].as_dvec2());
            0.5 * (b - a).perp_dot(c - a).abs()
        };
        let world_area = |t: usize| {
            let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
            0.5 * (b - a).cross(c - a).length()
        };
        let triangles = 0..mesh.triangle_count();
        let world: f64 = triangles.clone().map(world_area).sum();
        let atlas_area: f64 = triangles.clone().map(uv_area).sum();
        if atlas_area <= 0.0 {
            return Err(AtlasError::LightmapEmpty);
        }
        // Texels per unit of atlas coordinate, so that the mean texel spans texel_size.
        let side = ((world / atlas_area).sqrt() / texel_size as f64).ceil().max(1.0);
        if side * side > MAX_TEXELS {
            let fits = ((world / atlas_area).sqrt() / MAX_TEXELS.sqrt()) as f32;
            return Err(AtlasError::TooManyTexels { asked: texel_size, texels: side * side, fits });
        }
        let resolution = side as u32;
        let live: Vec<bool> = triangles.clone().map(|t| uv_area(t) > 0.0).collect();
        let lost: Vec<usize> = triangles.clone().filter(|&t| !live[t] && world_area(t) > 0.0).collect();
        if let Some(&first) = lost.first() {
            return Err(AtlasError::LightmapFolded { triangles: lost.len(), first: first as u32 });
        }
        // Charts: triangles joined through a shared vertex (a chart's border is
        // a seam of split vertices, as glTF stores them).
        let mut parent: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
        for t in triangles.clone().filter(|&t| live[t]) {
            let [a, b, c] = mesh.triangle(t);
            union(&mut parent, a, b);
            union(&mut parent, a, c);
        }
        let mut chart_of_root: std::collections::HashMap<u32, u32> = std::collections::HashMap::new();
        let triangle_chart: Vec<u32> = (0..mesh.triangle_count())
            .map(|t| {
                if !live[t] {
                    return NO_CHART;
                }
                let r = find(&mut parent, mesh.triangle(t)[0]);
                let next = chart_of_root.len() as u32;
                *chart_of_root.entry(r).or_insert(next)
            })
            .collect();
        let atlas = Atlas {
            width: resolution,
            height: resolution,
            texel_size,
            uv: mesh.lightmap_uvs.iter().map(|&uv| uv * resolution as f32).collect(),
            source_vertex: (0..mesh.vertex_count() as u32).collect(),
            indices: mesh.indices.clone(),
            triangle_chart,
            chart_count: chart_of_root.len() as u32,
        };
        let (shared, beside) = atlas.texels_mixing_charts();
        if shared + beside > 0 {
            return Err(AtlasError::LightmapShared { texel_size, shared, beside });
        }
        Ok(atlas)
    }

    /// Texels the layout cannot keep to one place: those under triangles of
    /// two charts or under overlapping triangles (overlaps adding up to more
    /// than the texel), and those next to another chart's texel, which a
    /// bilinear read between texel centres would mix with it.
    fn texels_mixing_charts(&self) -> (usize, usize) {
        const MIXED: u32 = u32::MAX - 1;
        let coverage = coverage::Coverage::of(self);
        let mut owner: std::collections::HashMap<u32, u32> = std::collections::HashMap::with_capacity(coverage.len());
        let mut shared = 0;
        for i in 0..coverage.len() {
            let range = coverage.start[i] as usize..coverage.start[i + 1] as usize;
            let first = self.triangle_chart[coverage.triangle[range.start] as usize];
            let two_charts = range.clone().any(|k| self.triangle_chart[coverage.triangle[k] as usize] != first);
            let overfull = coverage.area[range].iter().map(|&a| a as f64).sum::<f64>() > 1.0 + 1e-3;
            if two_charts || overfull {
                shared += 1;
            }
            owner.insert(coverage.texels[i], if two_charts { MIXED } else { first });
        }
        let (w, h) = (self.width as i64, self.height as i64);
        let beside = coverage
            .texels
            .iter()
            .filter(|&&texel| {
                let chart = owner[&texel];
                let (x, y) = ((texel % self.width) as i64, (texel / self.width) as i64);
                chart != MIXED
                    && (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy))).any(|(nx, ny)| {
                        (0..w).contains(&nx) && (0..h).contains(&ny) && owner.get(&((ny * w + nx) as u32)).is_some_and(|&c| c != chart)
                    })
            })
            .count();
        (shared, beside)
    }

    /// Refuses a texel size whose texels, over the mesh's own area (a lower
    /// bound of any atlas's), would be more than [`MAX_TEXELS`], before any
    /// work, naming the size that fits.
    pub fn check_texel_count(mesh: &Mesh, texel_size: f32) -> Result<(), AtlasError> {
        let area: f64 = (0..mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .sum();
        let texels = area / (texel_size as f64).powi(2);
        if texels > MAX_TEXELS {
            let fits = (area / MAX_TEXELS).sqrt() as f32;
            return Err(AtlasError::TooManyTexels { asked: texel_size, texels, fits });
        }
        Ok(())
    }

    /// Unwraps `mesh` with xatlas at `texel_size` world units per texel.
    pub fn unwrap(mesh: &Mesh, texel_size: f32) -> Result<Atlas, AtlasError> {
        if !(texel_size.is_finite() && texel_size > 0.0) {
            return Err(AtlasError::BadTexelSize(texel_size));
        }
        if mesh.triangle_count() == 0 {
            return Err(AtlasError::Empty);
        }
        Self::check_texel_count(mesh, texel_size)?;
        let has_normals = mesh.normals.len() == mesh.positions.len();
        // SAFETY: the declaration points into `mesh`, which outlives the
        // calls (xatlas copies it in AddMesh); the atlas is read before it is
        // destroyed, and every array is read within the counts xatlas gives.
        unsafe {
            use xatlas_ffi as x;
            let mut decl = std::mem::MaybeUninit::<x::MeshDecl>::uninit();
            x::xatlasMeshDeclInit(decl.as_mut_ptr());
            let mut decl = decl.assume_init();
            decl.vertexPositionData = mesh.positions.as_ptr().cast();
            decl.vertexPositionStride = 12;
            decl.vertexCount = mesh.vertex_count() as u32;
            if has_normals {
                decl.vertexNormalData = mesh.normals.as_ptr().cast();
                decl.vertexNormalStride = 12;
            }
            decl.indexData = mesh.indices.as_ptr().cast();
            decl.indexCount = mesh.indices.len() as u32;
            decl.indexFormat = x::INDEX_FORMAT_UINT32;
            let handle = x::xatlasCreate();
            x::check_added(handle, x::xatlasAddMesh(handle, &decl, 1)).map_err(AtlasError::Refused)?;
            // One texture, however large: the bundle holds one atlas.
            x::xatlasGenerate(handle, &x::chart_options(), &x::pack_options(1.0 / texel_size, PADDING));
            let atlas = &*handle;
            let result = Self::read(atlas, mesh.triangle_count(), texel_size);
            x::xatlasDestroy(handle);
            result
        }
    }

    /// Copies xatlas's output out of its memory.
    unsafe fn read(atlas: &xatlas_ffi::Atlas, triangles: usize, texel_size: f32) -> Result<Atlas, AtlasError> {
        if atlas.meshCount != 1 || atlas.atlasCount > 1 {
            return Err(AtlasError::Incomplete { got: 0, expected: triangles });
        }
        let out = &*atlas.meshes;
        let slice = |p: *const u32, n: u32| if n == 0 { &[][..] } else { std::slice::from_raw_parts(p, n as usize) };
        let indices = slice(out.indexArray, out.indexCount).to_vec();
        if indices.len() != 3 * triangles {
            return Err(AtlasError::Incomplete { got: indices.len() / 3, expected: triangles });
        }
        let vertices = if out.vertexCount == 0 { &[][..] } else { std::slice::from_raw_parts(out.vertexArray, out.vertexCount as usize) };
        let uv = vertices.iter().map(|v| Vec2::from(v.uv)).collect();
        let source_vertex = vertices.iter().map(|v| v.xref).collect();
        let mut triangle_chart = vec![NO_CHART; triangles];
        let charts = if out.chartCount == 0 { &[][..] } else { std::slice::from_raw_parts(out.chartArray, out.chartCount as usize) };
        for (k, chart) in charts.iter().enumerate() {
            for &face in slice(chart.faceArray, chart.faceCount) {
                if let Some(c) = triangle_chart.get_mut(face as usize) {
                    *c = k as u32;
                }
            }
        }
        Ok(Atlas {
            width: atlas.width,
            height: atlas.height,
            texel_size,
            uv,
            source_vertex,
            indices,
            triangle_chart,
            chart_count: out.chartCount,
        })
    }

    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Triangle `t`'s corners in texels.
    pub fn triangle_uv(&self, t: usize) -> [Vec2; 3] {
        [0, 1, 2].map(|k| self.uv[self.indices[3 * t + k] as usize])
    }
}

#[cfg(test)]
mod tests;
