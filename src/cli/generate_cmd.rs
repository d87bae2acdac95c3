//! `prtbake generate colonnade -o OUT.glb`: writes a generated scene as a mesh file.

use std::path::Path;

use anyhow::Context;

use crate::fixtures::colonnade::{colonnade, ColonnadeParams};

/// Writes the colonnade at `detail` (`small`, `monument`, `million`) to
/// `output` (.glb, or .obj with its .mtl) and prints its size.
pub fn run_colonnade(output: &Path, detail: &str, force: bool) -> anyhow::Result<()> {
    let is_obj = output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let mtl = crate::mesh::mtl_path_for(output);
    let mut outputs = vec![super::Output::new(output, &["glb", "obj"])];
    if is_obj {
        outputs.push(super::Output { own_marker: Some(crate::mesh::MTL_HEADER.as_bytes()), ..super::Output::new(&mtl, &["mtl"]) });
    }
    super::check_outputs(&[], &outputs, force)?;
    let params = match detail {
        "small" => ColonnadeParams::small(),
        "monument" => ColonnadeParams::monument(),
        "million" => ColonnadeParams::million(),
        other => anyhow::bail!("unknown detail {other:?} (small, monument, million)"),
    };
    let mesh = colonnade(&params);
    if is_obj { crate::mesh::write_obj(output, &mesh) } else { crate::mesh::write_glb(output, &mesh) }
        .with_context(|| format!("cannot write {}", output.display()))?;
    println!("wrote {}: {} vertices, {} triangles", output.display(), mesh.vertex_count(), mesh.triangle_count());
    Ok(())
}
