//! `prtbake inspect BUNDLE`: what a bundle holds.

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use crate::bundle;

/// Describes the bundle at `path` on stdout (JSON with `as_json`).
pub fn run(path: &Path, as_json: bool) -> anyhow::Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let sections = bundle::list_sections(&bytes).with_context(|| format!("{}: not a valid bundle", path.display()))?;
    let b = bundle::decode_bundle(&bytes).with_context(|| format!("{}: not a valid bundle", path.display()))?;
    let transfer = b.transfer.as_ref().map(|t| {
        json!({
            "order": t.order, "channels": t.channels, "quantization": t.quantization.name(),
            "layers": t.layers.iter().map(|l| format!("{:?}", l.kind)).collect::<Vec<_>>(),
        })
    });
    let sun = b.sun.as_ref().map(|s| {
        json!({ "steps": s.step_count(), "sky_order": s.sky_order, "words_per_vertex": s.words_per_vertex })
    });
    let doc = json!({
        "file": path,
        "bytes": bytes.len(),
        "vertices": b.mesh.vertex_count(),
        "triangles": b.mesh.triangle_count(),
        "materials": b.mesh.materials.iter().map(|m| json!({"name": m.name, "role": m.role, "albedo": m.albedo})).collect::<Vec<_>>(),
        "transfer": transfer,
        "sun": sun,
        "sections": sections.iter().map(|s| json!({
            "tag": s.tag_name(), "codec": s.codec_name(), "stored_bytes": s.stored_len, "raw_bytes": s.raw_len,
        })).collect::<Vec<_>>(),
        "meta": b.meta,
    });
    if as_json {
        return super::print_json(&doc);
    }
    println!("{}: {} bytes", path.display(), bytes.len());
    println!("  mesh: {} vertices, {} triangles, {} materials", b.mesh.vertex_count(), b.mesh.triangle_count(), b.mesh.materials.len());
    if let Some(t) = &b.transfer {
        println!(
            "  transfer: order {} ({} coefficients), {} channel(s), {}, layers {:?}",
            t.order,
            t.order * t.order,
            t.channels,
            t.quantization.name(),
            t.layers.iter().map(|l| l.kind).collect::<Vec<_>>()
        );
    }
    if let Some(s) = &b.sun {
        println!("  sun: {} steps, sky order {}", s.step_count(), s.sky_order);
    }
    println!("  sections:");
    for s in &sections {
        println!("    {}  {:<5} {:>10} stored  {:>10} raw", s.tag_name(), s.codec_name(), s.stored_len, s.raw_len);
    }
    if let Some(params) = b.meta.get("params") {
        println!("  params: {params}");
    }
    Ok(())
}
