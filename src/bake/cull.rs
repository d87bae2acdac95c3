//! View-box culling (seed 001 §5): a viewer confined to a region never sees
//! most of a large scene, so only triangles visible from that region need to
//! be stored. Visibility is found by ray casting: points spread through the
//! box (Owen-scrambled Sobol in 3D) each shoot a uniform sphere of rays, and
//! every triangle a ray reaches first is kept. Rays pass through windows
//! (the viewer sees through glass), up to [`CullParams::window_layers`].
//!
//! Culling decides what is *stored*; occlusion and interreflection still use
//! the whole scene (see [`super::bake_transfer_receivers`]), so the transfer
//! of kept triangles does not change beyond sampling noise. A triangle seen by
//! no sampled ray is dropped even if it is visible through a gap the rays
//! missed: the report gives the ray count so users can raise it.

use glam::Vec3;
use rayon::prelude::*;

use super::surfaces::Surfaces;
use crate::mesh::{MaterialRole, Mesh};
use crate::sampling::{hash_seed, sample_2d, DirectionPattern};
use crate::trace::scene::{RayQuery, Scene};

const TAG_VIEW_POINT: u32 = 0x4355_4c01;
const TAG_VIEW_RAY: u32 = 0x4355_4c02;

/// An axis-aligned box in world coordinates (after the loader's up-axis conversion).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ViewBox {
    #[serde(serialize_with = "vec3")]
    pub min: Vec3,
    #[serde(serialize_with = "vec3")]
    pub max: Vec3,
}

fn vec3<S: serde::Serializer>(v: &Vec3, s: S) -> Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&v.to_array(), s)
}

impl ViewBox {
    /// Parses `MINX,MINY,MINZ,MAXX,MAXY,MAXZ` (a degenerate box, e.g. a point, is allowed).
    pub fn parse(text: &str) -> Result<ViewBox, String> {
        let values: Vec<f32> = text
            .split(',')
            .map(|v| v.trim().parse::<f32>().map_err(|e| format!("view box {text:?}: {v:?} is not a number ({e})")))
            .collect::<Result<_, _>>()?;
        if values.len() != 6 {
            return Err(format!("view box {text:?}: expected 6 numbers MINX,MINY,MINZ,MAXX,MAXY,MAXZ, got {}", values.len()));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(format!("view box {text:?}: every number must be finite"));
        }
        let (min, max) = (Vec3::new(values[0], values[1], values[2]), Vec3::new(values[3], values[4], values[5]));
        if min.cmpgt(max).any() {
            return Err(format!("view box {text:?}: a minimum exceeds its maximum"));
        }
        Ok(ViewBox { min, max })
    }

    /// A box of half-size `half_extent` around the centre of `mesh`'s bounds.
    pub fn around_centre(mesh: &Mesh, half_extent: f32) -> ViewBox {
        let (lo, hi) = mesh.bounds();
        let c = (lo + hi) * 0.5;
        ViewBox { min: c - Vec3::splat(half_extent), max: c + Vec3::splat(half_extent) }
    }
}

/// How hard to look.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CullParams {
    /// Viewpoints sampled in the box.
    pub points: u32,
    /// Rays per viewpoint, uniform over the sphere (≤ 65,536).
    pub rays_per_point: u32,
    pub seed: u32,
    /// Windows a ray may pass through before it stops.
    pub window_layers: u32,
}

impl Default for CullParams {
    fn default() -> Self {
        CullParams { points: 256, rays_per_point: 16_384, seed: 1, window_layers: 4 }
    }
}

/// What culling found.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct CullReport {
    pub view_box: Option<ViewBox>,
    pub params: Option<CullParams>,
    pub triangles_before: u64,
    pub triangles_kept: u64,
    pub triangles_removed: u64,
    pub vertices_before: u64,
    pub vertices_kept: u64,
    pub rays: u64,
    /// Rays that left the scene without a hit (sky seen from the box).
    pub rays_escaped: u64,
}

/// Flags every triangle some ray from `view_box` reaches first (or through windows).
pub fn visible_triangles(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    view_box: &ViewBox,
    params: &CullParams,
) -> (Vec<bool>, CullReport) {
    let see_through = |t: u32| {
        surfaces.window_transmittance[t as usize].is_some()
            || mesh.materials[mesh.tri_material[t as usize] as usize].role == MaterialRole::Window
    };
    let extent = view_box.max - view_box.min;
    let rays = params.rays_per_point.clamp(1, crate::sampling::MAX_RAYS_PER_POINT);
    let per_point: Vec<(Vec<u32>, u64)> = (0..params.points)
        .into_par_iter()
        .map(|p| {
            let box_seed = hash_seed(&[params.seed, TAG_VIEW_POINT]);
            let u =
                Vec3::new(sobol_burley::sample(p, 0, box_seed), sobol_burley::sample(p, 1, box_seed), sobol_burley::sample(p, 2, box_seed));
            let origin = view_box.min + extent * u;
            let ray_seed = hash_seed(&[params.seed, TAG_VIEW_RAY, p]);
            let queries: Vec<RayQuery> = (0..rays)
                .map(|k| {
                    let (u1, u2) = sample_2d(DirectionPattern::Sobol, k, 0, ray_seed);
                    let z = 1.0 - 2.0 * u1;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let phi = std::f32::consts::TAU * u2;
                    RayQuery { origin, direction: Vec3::new(r * phi.cos(), r * phi.sin(), z), t_max: f32::INFINITY }
                })
                .collect();
            // The point's rays in one batch; the few that go on through a window, one at a time.
            let mut first_hits = vec![None; queries.len()];
            scene.closest_hits(&queries, &mut first_hits);
            let mut seen = Vec::new();
            let mut escaped = 0u64;
            for (query, first_hit) in queries.iter().zip(first_hits) {
                let (mut from, mut hit, mut layers) = (origin, first_hit, 0);
                loop {
                    match hit {
                        Some(h) => {
                            seen.push(h.triangle);
                            if layers < params.window_layers && see_through(h.triangle) {
                                layers += 1;
                                from = from + query.direction * (h.t + 2.0 * scene.origin_offset);
                                hit = scene.closest_hit(from, query.direction, f32::INFINITY);
                                continue;
                            }
                        }
                        None => escaped += 1,
                    }
                    break;
                }
            }
            seen.sort_unstable();
            seen.dedup();
            (seen, escaped)
        })
        .collect();
    let mut visible = vec![false; mesh.triangle_count()];
    let mut escaped = 0u64;
    for (seen, e) in &per_point {
        seen.iter().for_each(|&t| visible[t as usize] = true);
        escaped += e;
    }
    let kept = visible.iter().filter(|&&v| v).count() as u64;
    let mut used = vec![false; mesh.vertex_count()];
    for t in (0..mesh.triangle_count()).filter(|&t| visible[t]) {
        mesh.triangle(t).iter().for_each(|&v| used[v as usize] = true);
    }
    let report = CullReport {
        view_box: Some(*view_box),
        params: Some(*params),
        triangles_before: mesh.triangle_count() as u64,
        triangles_kept: kept,
        triangles_removed: mesh.triangle_count() as u64 - kept,
        vertices_before: mesh.vertex_count() as u64,
        vertices_kept: used.iter().filter(|&&u| u).count() as u64,
        rays: params.points as u64 * rays as u64,
        rays_escaped: escaped,
    };
    (visible, report)
}

/// The mesh restricted to the flagged triangles, with unused vertices dropped,
/// and the map old vertex → new vertex (`u32::MAX` for dropped ones).
/// Materials and groups are kept whole (indices stay valid).
pub fn compact(mesh: &Mesh, keep: &[bool]) -> (Mesh, Vec<u32>) {
    let mut map = vec![u32::MAX; mesh.vertex_count()];
    let mut out = Mesh { materials: mesh.materials.clone(), groups: mesh.groups.clone(), ..Mesh::default() };
    for t in (0..mesh.triangle_count()).filter(|&t| keep[t]) {
        for v in mesh.triangle(t) {
            if map[v as usize] == u32::MAX {
                map[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
                out.normals.push(mesh.normals[v as usize]);
                if !mesh.uvs.is_empty() {
                    out.uvs.push(mesh.uvs[v as usize]);
                }
                if !mesh.lightmap_uvs.is_empty() {
                    out.lightmap_uvs.push(mesh.lightmap_uvs[v as usize]);
                }
                if !mesh.colors.is_empty() {
                    out.colors.push(mesh.colors[v as usize]);
                }
            }
            out.indices.push(map[v as usize]);
        }
        out.tri_material.push(mesh.tri_material[t]);
        out.tri_group.push(mesh.tri_group[t]);
    }
    (out, map)
}

/// Per-vertex data (`stride` values per vertex) moved through a vertex map from [`compact`].
pub fn compact_vertex_data(data: &[f32], stride: usize, map: &[u32], kept_vertices: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; kept_vertices * stride];
    for (old, &new) in map.iter().enumerate() {
        if new != u32::MAX {
            out[new as usize * stride..][..stride].copy_from_slice(&data[old * stride..][..stride]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::Surfaces;
    use crate::fixtures::builder::MeshBuilder;
    use crate::mesh::Material;
    use crate::trace::BuildQuality;

    /// A closed room (walls facing in) with a small closed box in the middle
    /// and, inside a second closed box, a hidden object.
    fn room_with_hidden_object() -> (Mesh, std::ops::Range<usize>, std::ops::Range<usize>) {
        let mut b = MeshBuilder::new(vec![Material::opaque("wall", 0.7), Material::opaque("thing", 0.5)]);
        // The room: an inward-facing cuboid (flip an outward cuboid).
        b.cuboid("room", Vec3::splat(-2.0), Vec3::splat(2.0), 2.0, 0);
        b.flip_groups("room");
        let visible_start = b.mesh.triangle_count();
        b.cuboid("crate", Vec3::new(0.8, -2.0, 0.8), Vec3::new(1.6, -1.2, 1.6), 4.0, 1);
        let hidden_start = b.mesh.triangle_count();
        b.cuboid("hidden", Vec3::new(1.0, -1.9, 1.0), Vec3::new(1.4, -1.5, 1.4), 4.0, 1);
        let end = b.mesh.triangle_count();
        (b.mesh, visible_start..hidden_start, hidden_start..end)
    }

    #[test]
    fn view_box_parses_and_rejects() {
        let b = ViewBox::parse("-1,0,-1, 1,2,1").unwrap();
        assert_eq!(b.min, Vec3::new(-1.0, 0.0, -1.0));
        assert!(ViewBox::parse("1,2,3").is_err());
        assert!(ViewBox::parse("0,0,0,1,1,nan").is_err());
        assert!(ViewBox::parse("1,0,0,0,1,1").is_err());
    }

    #[test]
    fn hidden_object_is_culled_and_walls_kept() {
        let (mesh, crate_range, hidden) = room_with_hidden_object();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let view = ViewBox { min: Vec3::new(-1.0, -0.5, -1.0), max: Vec3::new(0.0, 0.5, 0.0) };
        let params = CullParams { points: 32, rays_per_point: 4096, ..CullParams::default() };
        let (visible, report) = visible_triangles(&mesh, &scene, &surfaces, &view, &params);
        eprintln!("cull fixture: {report:?}");
        assert!(hidden.clone().all(|t| !visible[t]), "the object inside the closed crate must be culled");
        // Room triangles away from the crate's corner (where the crate may hide them) are all seen.
        let near_crate = |t: usize| {
            let [a, b, c] = mesh.triangle_positions(t);
            let m = (a + b + c) / 3.0;
            m.y < -1.0 && m.x > 0.5 && m.z > 0.5
        };
        let missed: Vec<usize> = (0..crate_range.start).filter(|&t| !near_crate(t) && !visible[t]).collect();
        assert!(missed.is_empty(), "room triangles not found visible: {missed:?}");
        // The crate's bottom face (on the floor) cannot be seen; its top and sides can.
        let crate_visible = crate_range.clone().filter(|&t| visible[t]).count();
        assert!(crate_visible > 0 && crate_visible < crate_range.len());
        assert_eq!(report.triangles_removed as usize, mesh.triangle_count() - visible.iter().filter(|&&v| v).count());
        assert_eq!(report.rays_escaped, 0, "the room is closed");
        let (kept, map) = compact(&mesh, &visible);
        kept.validate().unwrap();
        assert_eq!(kept.triangle_count() as u64, report.triangles_kept);
        assert_eq!(kept.vertex_count() as u64, report.vertices_kept);
        for (old, &new) in map.iter().enumerate() {
            if new != u32::MAX {
                assert_eq!(kept.positions[new as usize], mesh.positions[old]);
            }
        }
    }
}
