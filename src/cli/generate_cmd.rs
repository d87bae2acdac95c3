//! `prtbake generate colonnade|cabin -o OUT.glb [--detail D] [--copies N]`:
//! writes a generated scene as a mesh file.

use std::path::Path;

use anyhow::Context;

use crate::fixtures::cabin::generate_cabin;
use crate::fixtures::colonnade::{street, ColonnadeParams};
use crate::mesh::Mesh;

/// Cells per metre of the small cabin: the one tests/shards.rs bakes
/// (11,738 triangles once cleaned).
const SMALL_CABIN_DETAIL: f32 = 10.0;

/// Writes `scene` at `detail` to `output` (.glb, or .obj with its .mtl) and
/// prints its size. The colonnade: `small`, `monument` (default), `million`,
/// or a street of `copies` of it; the demo cabin with its injected defects:
/// `small`, `demo` (default, what `prtbake demo` bakes).
pub fn run(scene: &str, output: &Path, detail: Option<&str>, copies: u32, force: bool) -> anyhow::Result<()> {
    let is_obj = output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let mtl = crate::mesh::mtl_path_for(output);
    let mut outputs = vec![super::Output::new(output, &["glb", "obj"])];
    if is_obj {
        outputs.push(super::Output { own_marker: Some(crate::mesh::MTL_HEADER.as_bytes()), ..super::Output::new(&mtl, &["mtl"]) });
    }
    super::check_outputs(&[], &outputs, force)?;
    let mesh = generate(scene, detail, copies)?;
    if is_obj { crate::mesh::write_obj(output, &mesh) } else { crate::mesh::write_glb(output, &mesh) }
        .with_context(|| format!("cannot write {}", output.display()))?;
    println!("wrote {}: {} vertices, {} triangles", output.display(), mesh.vertex_count(), mesh.triangle_count());
    Ok(())
}

fn generate(scene: &str, detail: Option<&str>, copies: u32) -> anyhow::Result<Mesh> {
    match (scene, detail) {
        ("colonnade", detail) => {
            let params = match detail.unwrap_or("monument") {
                "small" => ColonnadeParams::small(),
                "monument" => ColonnadeParams::monument(),
                "million" => ColonnadeParams::million(),
                other => anyhow::bail!("unknown colonnade detail {other:?} (small, monument, million)"),
            };
            Ok(street(&params, copies))
        }
        ("cabin", _) if copies != 1 => anyhow::bail!("--copies applies to the colonnade only"),
        ("cabin", Some("small")) => Ok(generate_cabin(SMALL_CABIN_DETAIL).0),
        ("cabin", None | Some("demo")) => Ok(generate_cabin(super::demo_cmd::DEMO_DETAIL).0),
        ("cabin", Some(other)) => anyhow::bail!("unknown cabin detail {other:?} (small, demo)"),
        (other, _) => anyhow::bail!("unknown scene {other:?} (colonnade, cabin)"),
    }
}
