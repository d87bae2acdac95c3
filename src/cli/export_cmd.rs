//! `prtbake export BUNDLE -o OUT.glb`: the bake for other glTF engines, with
//! transfer and sun masks as `_PRT_…` vertex attributes, and a texel bundle's
//! texels as textures on `TEXCOORD_1` (docs/viewer.md).

use std::path::Path;

use anyhow::Context;

use crate::bundle::{self, LayerKind};

/// Parses `--layer`: `total`, `direct` (bounce 0, as `view --layers direct`)
/// or a bounce index.
pub fn parse_layer(text: &str) -> anyhow::Result<Option<LayerKind>> {
    match text {
        "total" => Ok(None),
        "direct" => Ok(Some(LayerKind::Bounce(0))),
        n => n
            .parse::<u32>()
            .map(|b| Some(LayerKind::Bounce(b)))
            .map_err(|_| anyhow::anyhow!("--layer {text:?}: expected total, direct or a bounce index")),
    }
}

/// Exports the bundle at `input` to the GLB `output`.
pub fn run(input: &Path, output: &Path, layer: Option<LayerKind>, as_json: bool, force: bool) -> anyhow::Result<()> {
    super::check_outputs(&[input], &[super::Output::new(output, &["glb"])], force)?;
    let b = bundle::read_bundle(input).with_context(|| format!("cannot export {}", input.display()))?;
    let report =
        bundle::export_glb(output, &b, layer).with_context(|| format!("cannot export {} to {}", input.display(), output.display()))?;
    if as_json {
        return super::print_json(&serde_json::json!({ "output": super::json_path(output), "report": report }));
    }
    println!(
        "wrote {}: {} vertices, {} triangles, {} _PRT_TRANSFER_ attributes ({}), {} _PRT_SUN_ attributes{}",
        output.display(),
        report.vertices,
        report.triangles,
        report.transfer_attributes,
        report.layer,
        report.sun_attributes,
        match (report.texel_textures, report.sun_atlas) {
            (0, _) => String::new(),
            (n, false) => format!(", {n} texel textures on TEXCOORD_1"),
            (n, true) => format!(", {n} texel textures on TEXCOORD_1 (transfer) and TEXCOORD_2 (sun)"),
        }
    );
    Ok(())
}
