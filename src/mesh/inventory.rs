//! What a mesh is made of, before baking: per material and per group the
//! triangles, the area and the role the bake would give it, and a guess of
//! what the name means (glass, an emitter), so a user can choose `--window`
//! patterns without reading the file.

use super::{MaterialRole, Mesh};

/// One material or group of a mesh.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Entry {
    pub name: String,
    pub triangles: u64,
    /// Summed triangle area, in the file's units squared.
    pub area: f64,
    /// Materials only: the albedo and the role the loader read (window from
    /// KHR_materials_transmission or an MTL `prtbake_role`, panel).
    pub albedo: Option<[f32; 3]>,
    pub role: Option<MaterialRole>,
    /// What the name or the file suggests, for `--window` and the like:
    /// `window` (a window already), `glass?` (named like glass), `emitter?`
    /// (named like a light), or `None`.
    pub likely: Option<&'static str>,
}

/// A mesh's materials and groups, each sorted by area, largest first.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Inventory {
    pub vertices: u64,
    pub triangles: u64,
    pub area: f64,
    /// The mesh has its own lightmap atlas (glTF `TEXCOORD_1`), which texel mode keeps.
    pub lightmap_atlas: bool,
    pub materials: Vec<Entry>,
    pub groups: Vec<Entry>,
}

/// Words that name glass in the names CAD and scene files use.
const GLASS_WORDS: &[&str] = &["glass", "glazing", "window", "pane", "windscreen", "windshield", "vidro", "verre", "glas", "fenster"];
/// Words that name light sources ("light" alone is too often a colour: `Interior_light`).
const EMITTER_WORDS: &[&str] = &["emit", "lamp", "bulb", "luminaire", "arealight", "area_light", "lightsource", "light_source"];

/// What `name` suggests (case-insensitive word parts).
fn guess(name: &str) -> Option<&'static str> {
    let lower = name.to_lowercase();
    if GLASS_WORDS.iter().any(|w| lower.contains(w)) {
        Some("glass?")
    } else if EMITTER_WORDS.iter().any(|w| lower.contains(w)) {
        Some("emitter?")
    } else {
        None
    }
}

/// The inventory of `mesh`.
pub fn inventory(mesh: &Mesh) -> Inventory {
    let mut material_sums = vec![(0u64, 0f64); mesh.materials.len()];
    let mut group_sums = vec![(0u64, 0f64); mesh.groups.len()];
    let mut total = 0.0;
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
        let area = 0.5 * (b - a).cross(c - a).length();
        total += area;
        for (sums, index) in [(&mut material_sums, mesh.tri_material[t] as usize), (&mut group_sums, mesh.tri_group[t] as usize)] {
            sums[index].0 += 1;
            sums[index].1 += area;
        }
    }
    let mut materials: Vec<Entry> = mesh
        .materials
        .iter()
        .zip(&material_sums)
        .map(|(m, &(triangles, area))| Entry {
            name: m.name.clone(),
            triangles,
            area,
            albedo: Some(m.albedo),
            role: Some(m.role),
            likely: if m.role == MaterialRole::Window { Some("window") } else { guess(&m.name) },
        })
        .collect();
    let mut groups: Vec<Entry> = mesh
        .groups
        .iter()
        .zip(&group_sums)
        .filter(|(_, &(triangles, _))| triangles > 0)
        .map(|(g, &(triangles, area))| Entry { name: g.clone(), triangles, area, albedo: None, role: None, likely: guess(g) })
        .collect();
    let by_area = |a: &Entry, b: &Entry| b.area.total_cmp(&a.area).then_with(|| a.name.cmp(&b.name));
    materials.sort_by(by_area);
    groups.sort_by(by_area);
    Inventory {
        vertices: mesh.vertex_count() as u64,
        triangles: mesh.triangle_count() as u64,
        area: total,
        lightmap_atlas: !mesh.lightmap_uvs.is_empty(),
        materials,
        groups,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Material;

    #[test]
    fn counts_areas_and_guesses() {
        // A unit square: two triangles of area 0.5.
        let mut mesh = crate::verify::shapes::plane_grid(1, 1.0);
        mesh.materials = vec![Material::opaque("Wall", 0.7), Material::opaque("Glass_Gray", 0.1), Material::opaque("emitter_ceiling", 0.9)];
        mesh.tri_material = vec![0, 1];
        mesh.groups = vec!["room".into(), "unused".into()];
        mesh.tri_group = vec![0, 0];
        let inv = inventory(&mesh);
        assert_eq!((inv.vertices, inv.triangles), (4, 2));
        assert!((inv.area - 1.0).abs() < 1e-12);
        let names: Vec<(&str, u64, Option<&str>)> = inv.materials.iter().map(|e| (e.name.as_str(), e.triangles, e.likely)).collect();
        assert_eq!(names, [("Glass_Gray", 1, Some("glass?")), ("Wall", 1, None), ("emitter_ceiling", 0, Some("emitter?"))]);
        assert!(inv.materials.iter().take(2).all(|e| (e.area - 0.5).abs() < 1e-12));
        assert_eq!(inv.groups.len(), 1, "groups without triangles are left out");
        mesh.materials[1].role = MaterialRole::Window;
        assert_eq!(inventory(&mesh).materials[0].likely, Some("window"));
    }
}
