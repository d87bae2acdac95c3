//! Meaning ranges of the bundle's float fields.
//!
//! A CRC only says the bytes are the ones written; a forged or buggy file can
//! carry a NaN albedo with a valid CRC, and `export` would then write
//! `"baseColorFactor":[null, …]`. The decoder checks every float field here,
//! the encoder checks the same ranges so it never writes a file the decoder
//! refuses, and glTF export checks them again for bundles built in memory.
//!
//! Ranges (docs/bundle-format.md, reader rule 11): everything finite; normals
//! not the zero vector; albedo, transmittance in [0, 1]; colours ≥ 0; sun
//! directions unit length (± [`UNIT_LENGTH_TOLERANCE`]); sun elevation in
//! [−90, 90] and azimuth in [0, 360] degrees; sun irradiance ≥ 0.

use std::borrow::Cow;

use glam::{Vec2, Vec3};

use super::container::{MATL, MESH, SUND, XFER};
use super::error::BundleError;
pub use super::error::{BadValue, ValueProblem};
use super::types::{Bundle, SunStep};
use crate::mesh::{compute_vertex_normals, Material, Mesh};

/// First minor whose writer guarantees the ranges; in 1.0 files albedo,
/// transmittance, colours and normals are brought into range on read.
pub(crate) const RANGES_CHECKED_SINCE_MINOR: u16 = 1;

/// How far a stored sun direction's length may be from 1. Normalising in f32
/// is good to ~1e-7; anything past 1e-3 is not a direction someone normalised.
pub const UNIT_LENGTH_TOLERANCE: f32 = 1e-3;

/// Attaches a location to a problem: `.map_err(at("material", i, "albedo"))`.
fn at(item: &'static str, index: usize, field: impl Into<Cow<'static, str>>) -> impl FnOnce(ValueProblem) -> BadValue {
    let field = field.into();
    move |problem| BadValue { item, index: index as u64, field, problem }
}

fn finite(x: f64) -> Result<(), ValueProblem> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(ValueProblem::NotFinite { value: x })
    }
}

fn all_finite(xs: &[f32]) -> Result<(), ValueProblem> {
    xs.iter().try_for_each(|&x| finite(x as f64))
}

fn in_range(x: f32, lo: f32, hi: f32, range: &'static str) -> Result<(), ValueProblem> {
    finite(x as f64)?;
    if (lo..=hi).contains(&x) {
        Ok(())
    } else {
        Err(ValueProblem::OutOfRange { value: x as f64, range })
    }
}

fn unit_interval(xs: &[f32]) -> Result<(), ValueProblem> {
    xs.iter().try_for_each(|&x| in_range(x, 0.0, 1.0, "[0, 1]"))
}

fn non_negative(xs: &[f32]) -> Result<(), ValueProblem> {
    xs.iter().try_for_each(|&x| in_range(x, 0.0, f32::MAX, "[0, ∞)"))
}

/// Finite and long enough to normalise (glam's `try_normalize` succeeds).
fn direction(v: Vec3) -> Result<(), ValueProblem> {
    all_finite(&v.to_array())?;
    v.try_normalize().map(|_| ()).ok_or(ValueProblem::ZeroVector)
}

fn unit_direction(v: Vec3) -> Result<(), ValueProblem> {
    direction(v)?;
    let length = v.length();
    if (length - 1.0).abs() <= UNIT_LENGTH_TOLERANCE {
        Ok(())
    } else {
        Err(ValueProblem::NotUnit { length: length as f64 })
    }
}

// ---------------------------------------------------------------- sections

/// MESH: positions, uvs finite; normals finite and not zero; colours finite and ≥ 0.
pub(crate) fn check_mesh(mesh: &Mesh) -> Result<(), BadValue> {
    check_positions(&mesh.positions)?;
    for (v, &n) in mesh.normals.iter().enumerate() {
        direction(n).map_err(at("vertex", v, "normal"))?;
    }
    check_uvs(&mesh.uvs)?;
    check_lightmap_uvs(&mesh.lightmap_uvs)?;
    for (v, c) in mesh.colors.iter().enumerate() {
        non_negative(c).map_err(at("vertex", v, "colour"))?;
    }
    Ok(())
}

pub(crate) fn check_positions(positions: &[Vec3]) -> Result<(), BadValue> {
    positions.iter().enumerate().try_for_each(|(v, p)| all_finite(&p.to_array()).map_err(at("vertex", v, "position")))
}

pub(crate) fn check_uvs(uvs: &[Vec2]) -> Result<(), BadValue> {
    uvs.iter().enumerate().try_for_each(|(v, uv)| all_finite(&uv.to_array()).map_err(at("vertex", v, "uv")))
}

pub(crate) fn check_lightmap_uvs(uvs: &[Vec2]) -> Result<(), BadValue> {
    uvs.iter().enumerate().try_for_each(|(v, uv)| all_finite(&uv.to_array()).map_err(at("vertex", v, "lightmap uv")))
}

/// MATL: albedo and transmittance in [0, 1].
pub(crate) fn check_material(index: usize, m: &Material) -> Result<(), BadValue> {
    unit_interval(&m.albedo).map_err(at("material", index, "albedo"))?;
    unit_interval(&[m.transmittance]).map_err(at("material", index, "transmittance"))
}

/// XFER: one decoded layer's values (SH coefficients) are finite.
pub(crate) fn check_layer(layer: usize, data: &[f32], values_per_vertex: u64) -> Result<(), BadValue> {
    match data.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(j) => {
            let vertex = j as u64 / values_per_vertex.max(1);
            Err(at("layer", layer, format!("value {j} (vertex {vertex})"))(ValueProblem::NotFinite { value: data[j] as f64 }))
        }
    }
}

/// XFER, i16 layers: a vertex's scale is finite and > 0, or 0 with every code 0
/// (the all-zero vertex, the only one the writer gives scale 0).
pub(crate) fn check_i16_scale(layer: usize, vertex: usize, scale: f32, codes: &[u16]) -> Result<(), BadValue> {
    let field = || format!("i16 scale of vertex {vertex}");
    in_range(scale, 0.0, f32::MAX, "[0, ∞)").map_err(at("layer", layer, field()))?;
    if scale == 0.0 && codes.iter().any(|&c| c != 0) {
        return Err(at("layer", layer, field())(ValueProblem::OutOfRange {
            value: 0.0, range: "(0, ∞) for a vertex with non-zero codes"
        }));
    }
    Ok(())
}

/// SUND: one step's time, direction, angles, irradiance and sky SH.
pub(crate) fn check_sun_step(k: usize, s: &SunStep) -> Result<(), BadValue> {
    finite(s.unix_time_utc).map_err(at("step", k, "time"))?;
    unit_direction(Vec3::from(s.direction)).map_err(at("step", k, "sun direction"))?;
    in_range(s.elevation_deg, -90.0, 90.0, "[-90, 90] degrees").map_err(at("step", k, "elevation"))?;
    in_range(s.azimuth_deg, 0.0, 360.0, "[0, 360] degrees").map_err(at("step", k, "azimuth"))?;
    non_negative(&s.sun_rgb).map_err(at("step", k, "sun irradiance"))?;
    s.sky_sh.iter().try_for_each(|c| all_finite(c)).map_err(at("step", k, "sky SH"))
}

/// Every range above, on a whole bundle (for bundles built in memory, which
/// never went through the decoder): the first problem, with its section.
pub(crate) fn check_bundle(b: &Bundle) -> Result<(), BundleError> {
    check_mesh(&b.mesh).map_err(BundleError::bad_value(MESH))?;
    b.mesh.materials.iter().enumerate().try_for_each(|(i, m)| check_material(i, m)).map_err(BundleError::bad_value(MATL))?;
    if let Some(t) = &b.transfer {
        let stride = t.values_per_vertex();
        t.layers.iter().enumerate().try_for_each(|(i, l)| check_layer(i, &l.data, stride)).map_err(BundleError::bad_value(XFER))?;
    }
    if let Some(sun) = &b.sun {
        sun.steps.iter().enumerate().try_for_each(|(k, s)| check_sun_step(k, s)).map_err(BundleError::bad_value(SUND))?;
    }
    Ok(())
}

// ---------------------------------------------------------------- writing

/// What the writer stores for a material: albedo and transmittance clamped into
/// [0, 1], the values the bake itself uses (`bake::surfaces` clamps them the same
/// way) and the range glTF allows. Loaders keep e.g. an OBJ `Kd 1.2`; NaN or
/// infinity is a bug and refused, never clamped.
pub(crate) fn material_for_writing(index: usize, m: &Material) -> Result<Material, BadValue> {
    all_finite(&m.albedo).map_err(at("material", index, "albedo"))?;
    finite(m.transmittance as f64).map_err(at("material", index, "transmittance"))?;
    let clamped = Material { albedo: m.albedo.map(|a| a.clamp(0.0, 1.0)), transmittance: m.transmittance.clamp(0.0, 1.0), ..m.clone() };
    check_material(index, &clamped)?;
    Ok(clamped)
}

/// Vertex colours as the writer stores them: negative channels (meaningless in
/// linear RGB) become 0; non-finite ones are refused.
pub(crate) fn colour_for_writing(vertex: usize, c: [f32; 3]) -> Result<[f32; 3], BadValue> {
    all_finite(&c).map_err(at("vertex", vertex, "colour"))?;
    Ok(c.map(|x| x.max(0.0)))
}

/// Normals as the writer stores them: a zero normal (clean can blend two opposite
/// normals into one) carries no direction, so it is replaced by the vertex's
/// area-and-angle-weighted face normal, as loaders do; non-finite ones are refused.
pub(crate) fn normals_for_writing(mesh: &Mesh) -> Result<Cow<'_, [Vec3]>, BadValue> {
    let mut zero = Vec::new();
    for (v, &n) in mesh.normals.iter().enumerate() {
        match direction(n) {
            Ok(()) => {}
            Err(ValueProblem::ZeroVector) => zero.push(v),
            Err(problem) => return Err(at("vertex", v, "normal")(problem)),
        }
    }
    if zero.is_empty() {
        return Ok(Cow::Borrowed(&mesh.normals));
    }
    let computed = compute_vertex_normals(&mesh.positions, &mesh.indices);
    let mut normals = mesh.normals.clone();
    for v in zero {
        normals[v] = computed[v];
    }
    Ok(Cow::Owned(normals))
}

/// A 1.0 file's mesh as the 1.1 writer would store it: the 1.0 writer neither
/// clamped colours nor replaced zero normals.
pub(crate) fn legacy_mesh_in_range(mut mesh: Mesh) -> Result<Mesh, BadValue> {
    mesh.normals = normals_for_writing(&mesh)?.into_owned();
    mesh.colors = mesh.colors.iter().enumerate().map(|(v, &c)| colour_for_writing(v, c)).collect::<Result<_, _>>()?;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn problems_read_as_sentences() {
        let bad = |field: &'static str, problem| BadValue { item: "material", index: 2, field: field.into(), problem };
        assert_eq!(bad("albedo", ValueProblem::NotFinite { value: f64::NAN }).to_string(), "material 2 albedo is NaN");
        assert_eq!(bad("albedo", ValueProblem::NotFinite { value: f64::NEG_INFINITY }).to_string(), "material 2 albedo is -inf");
        let out = ValueProblem::OutOfRange { value: 1.5, range: "[0, 1]" };
        assert_eq!(bad("transmittance", out).to_string(), "material 2 transmittance is 1.5, outside [0, 1]");
    }

    #[test]
    fn writer_clamps_finite_material_values_and_refuses_nan() {
        let m = Material { albedo: [1.2, -0.1, 0.5], transmittance: 3.0, ..Material::opaque("m", 0.5) };
        let stored = material_for_writing(0, &m).unwrap();
        assert_eq!((stored.albedo, stored.transmittance), ([1.0, 0.0, 0.5], 1.0));
        let nan = Material { albedo: [0.5, f32::NAN, 0.5], ..m.clone() };
        assert_eq!(material_for_writing(4, &nan).unwrap_err().to_string(), "material 4 albedo is NaN");
        let inf = Material { transmittance: f32::INFINITY, ..m };
        assert_eq!(material_for_writing(1, &inf).unwrap_err().to_string(), "material 1 transmittance is inf");
    }

    #[test]
    fn writer_replaces_zero_normals_only() {
        let mut mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z, Vec3::ZERO, Vec3::new(0.0, 0.0, 2.0)],
            indices: vec![0, 1, 2],
            ..Mesh::default()
        };
        assert_eq!(*normals_for_writing(&mesh).unwrap(), [Vec3::Z, Vec3::Z, Vec3::new(0.0, 0.0, 2.0)]);
        mesh.normals[1] = Vec3::new(f32::NAN, 0.0, 0.0);
        assert_eq!(normals_for_writing(&mesh).unwrap_err().to_string(), "vertex 1 normal is NaN");
    }
}
