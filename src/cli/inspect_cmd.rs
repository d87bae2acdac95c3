//! `prtbake inspect BUNDLE`: what a bundle holds; `prtbake inspect MESH`:
//! what a mesh is made of before baking (materials and groups with their
//! triangles, areas and likely roles).

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use crate::bundle;

/// Describes the bundle or mesh at `path` on stdout (JSON with `as_json`).
pub fn run(path: &Path, as_json: bool) -> anyhow::Result<()> {
    let head =
        crate::files::read::read_head(path, crate::files::Limit::Bundle, 8).with_context(|| format!("cannot read {}", path.display()))?;
    let is_bundle = head == bundle::MAGIC || path.extension().is_some_and(|e| e.eq_ignore_ascii_case("prtb"));
    if !is_bundle {
        return inspect_mesh(path, as_json);
    }
    let bytes = bundle::read_bundle_bytes(path)?;
    let sections = bundle::list_sections(&bytes).with_context(|| format!("{}: not a valid bundle", path.display()))?;
    let b = bundle::decode_bundle(&bytes).with_context(|| format!("{}: not a valid bundle", path.display()))?;
    let transfer = b.transfer.as_ref().map(|t| {
        json!({
            "order": t.order, "channels": t.channels, "quantization": t.quantization.name(),
            "layers": t.layers.iter().map(|l| l.kind.to_string()).collect::<Vec<_>>(),
            "sides": side_summary(&t.front_share),
        })
    });
    // The sun bits' texels: on the sun's own atlas (TSAT) when it has one.
    let covered = b.sun.as_ref().and_then(|s| s.texel_count(b.texels.as_ref())).unwrap_or(0);
    let lapse = b.sun.as_ref().map(|s| time_lapse(s, b.mesh.vertex_count(), covered, &b.meta));
    let sun = b.sun.as_ref().map(|s| {
        json!({
            "steps": s.step_count(), "sky_order": s.sky_order, "words_per_vertex": s.words_per_vertex,
            "time_lapse": lapse.as_ref().map(|l| l.iter().map(|r| json!({
                "step": r.step, "unix_time_utc": r.unix_time_utc, "local_time": r.local_time,
                "elevation_deg": r.elevation_deg, "azimuth_deg": r.azimuth_deg, "night": r.night,
                "lit_fraction": r.lit_fraction, "texels_lit_fraction": r.texels_lit_fraction, "sun_rgb": r.sun_rgb,
            })).collect::<Vec<_>>()),
        })
    });
    let doc = json!({
        "file": super::json_path(path),
        "bytes": bytes.len(),
        "vertices": b.mesh.vertex_count(),
        "triangles": b.mesh.triangle_count(),
        "materials": b.mesh.materials.iter().map(|m| json!({"name": m.name, "role": m.role, "albedo": m.albedo})).collect::<Vec<_>>(),
        "transfer": transfer,
        "sun": sun,
        "texels": b.texels.as_ref().map(|t| json!({
            "atlas": {"width": t.atlas.width, "height": t.atlas.height, "texel_size": t.atlas.texel_size, "charts": t.atlas.chart_count, "atlas_vertices": t.atlas.uv.len()},
            "covered": t.texels.len(),
            "transfer": t.transfer.as_ref().map(|x| json!({
                "order": x.order, "channels": x.channels, "quantization": x.quantization.name(),
                "layers": x.layers.iter().map(|l| l.kind.to_string()).collect::<Vec<_>>(),
                "sides": side_summary(&x.front_share),
            })),
            "sun_bits": b.sun.as_ref().is_some_and(|s| !s.texel_masks.is_empty()),
            "sun_fractions": b.sun.as_ref().is_some_and(|s| !s.texel_fractions.is_empty()),
            "sun_atlas": b.sun.as_ref().and_then(|s| s.texel_atlas.as_ref()).map(|own| json!({
                "width": own.atlas.width, "height": own.atlas.height, "texel_size": own.atlas.texel_size,
                "charts": own.atlas.chart_count, "atlas_vertices": own.atlas.uv.len(), "covered": own.texels.len(),
            })),
        })),
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
            "  transfer: order {} ({} coefficients), {} channel(s), {}, layers {}",
            t.order,
            t.order * t.order,
            t.channels,
            t.quantization.name(),
            t.layers.iter().map(|l| l.kind.to_string()).collect::<Vec<_>>().join(", ")
        );
        print_sides("vertices", &t.front_share);
    }
    if let Some(x) = b.texels.as_ref().and_then(|t| t.transfer.as_ref()) {
        print_sides("texels", &x.front_share);
    }
    if let Some(t) = &b.texels {
        let a = &t.atlas;
        let transfer = t.transfer.as_ref().map_or("no transfer".to_string(), |x| {
            let layers = x.layers.iter().map(|l| l.kind.to_string()).collect::<Vec<_>>().join(", ");
            format!("order {}, {} channel(s), {}, layers {layers}", x.order, x.channels, x.quantization.name())
        });
        let sun_bits = match &b.sun {
            Some(s) if s.texel_atlas.is_some() => "; sun bits on an atlas of their own (below)",
            Some(s) if !s.texel_fractions.is_empty() => "; sun bits and lit shares per texel",
            Some(s) if !s.texel_masks.is_empty() => "; sun bits per texel",
            _ => "",
        };
        // Where the bake recorded it: whose atlas (the mesh's own TEXCOORD_1 or
        // xatlas's) and its texel size per chart; the sun's, when it made this atlas.
        let own_sun_atlas = b.sun.as_ref().is_some_and(|s| s.texel_atlas.is_some());
        let paths: &[&str] = if own_sun_atlas { &["/texels"] } else { &["/texels", "/sun/texels"] };
        let recorded = |key: &str| paths.iter().find_map(|p| b.meta.pointer(&format!("{p}/{key}")));
        let whose = recorded("atlas").and_then(|v| v.as_str()).map(|s| format!(" of {s}")).unwrap_or_default();
        println!("  texels: {}{whose}; {}, {transfer}{sun_bits}", atlas_summary(a), covered_summary(a, t.texels.len()));
        print_density(recorded("density"));
        if let Some(rays) = b.meta.pointer("/texels/vertex_rays").and_then(|r| r.as_u64()) {
            println!("    vertices baked with {rays} rays a point (--vertex-rays), the texels with the params' rays");
        }
        if let Some(added) = b.meta.pointer("/texels/points_added").and_then(|r| r.as_u64()) {
            let factor = b.meta.pointer("/texels/adaptive").and_then(|f| f.as_f64()).unwrap_or(0.0);
            println!("    {added} texel points added where bounce 0 was noisiest (--texel-adaptive {factor})");
        }
    }
    if let Some((s, own)) = b.sun.as_ref().and_then(|s| s.texel_atlas.as_ref().map(|own| (s, own))) {
        let what = if s.texel_fractions.is_empty() { "sun bits" } else { "sun bits and lit shares" };
        let whose = b.meta.pointer("/sun/texels/atlas").and_then(|v| v.as_str()).map(|s| format!(" of {s}")).unwrap_or_default();
        let covered = covered_summary(&own.atlas, own.texels.len());
        println!("  sun texels (TSAT): {}{whose}; {covered}, {what} per texel", atlas_summary(&own.atlas));
        print_density(b.meta.pointer("/sun/texels/density"));
    }
    if let Some(s) = &b.sun {
        println!("  sun: {} steps, sky order {}", s.step_count(), s.sky_order);
        let texel_column = lapse.iter().flatten().any(|r| r.texels_lit_fraction.is_some());
        println!("    step  time   elevation  azimuth  lit{}", if texel_column { " (vertices, texels)" } else { "" });
        for r in lapse.iter().flatten() {
            println!(
                "    {:>4}  {:>5}  {:>8.2}°  {:>6.2}°  {:>5.1}%{}{}",
                r.step,
                r.local_time.as_deref().unwrap_or("-"),
                r.elevation_deg,
                r.azimuth_deg,
                100.0 * r.lit_fraction,
                r.texels_lit_fraction.map_or(String::new(), |f| format!("  {:>5.1}%", 100.0 * f)),
                if r.night { "  night" } else { "" }
            );
        }
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

/// One row of the time lapse `inspect` shows.
struct LapseRow {
    step: usize,
    unix_time_utc: f64,
    /// `HH:MM` in the zone recorded in META (`sun.source.tz_minutes`), when the steps have times.
    local_time: Option<String>,
    elevation_deg: f32,
    azimuth_deg: f32,
    night: bool,
    /// Fraction of vertices whose bit is set.
    lit_fraction: f64,
    /// Fraction of covered texels whose bit is set, when the sun was baked per texel.
    texels_lit_fraction: Option<f64>,
    sun_rgb: [f32; 3],
}

/// Per step: time, sun angles and the fraction of lit vertices.
/// The materials and groups of the mesh file at `path`.
fn inspect_mesh(path: &Path, as_json: bool) -> anyhow::Result<()> {
    let mesh = super::load_mesh(path, crate::mesh::UpAxis::Y, as_json, &[], false)?;
    let inv = crate::mesh::inventory::inventory(&mesh);
    if as_json {
        return super::print_json(&json!({ "file": super::json_path(path), "mesh": inv }));
    }
    println!("{}: {} vertices, {} triangles, area {}", path.display(), inv.vertices, inv.triangles, super::significant(inv.area, 4));
    if inv.lightmap_atlas {
        println!("  lightmap atlas: its own (TEXCOORD_1), which texel mode keeps (--unwrap: a new one)");
    }
    let role = |e: &crate::mesh::inventory::Entry| match e.role {
        Some(crate::mesh::MaterialRole::Window) => "window",
        Some(crate::mesh::MaterialRole::Panel) => "panel",
        Some(crate::mesh::MaterialRole::Opaque) => "opaque",
        None => "",
    };
    for (title, entries) in [("materials", &inv.materials), ("groups", &inv.groups)] {
        println!("  {title} ({}), largest area first:", entries.len());
        for e in entries.iter() {
            let albedo = e.albedo.map_or(String::new(), |a| format!("  albedo {:.2} {:.2} {:.2}", a[0], a[1], a[2]));
            println!(
                "    {:<28} {:>9} triangles  area {:>10}  {:<7}{albedo}{}",
                e.name,
                e.triangles,
                super::significant(e.area, 4),
                role(e),
                e.likely.map(|l| format!("  likely {l}")).unwrap_or_default()
            );
        }
    }
    let glass: Vec<&str> =
        inv.materials.iter().chain(&inv.groups).filter(|e| e.likely == Some("glass?")).map(|e| e.name.as_str()).collect();
    if !glass.is_empty() {
        println!("  window mode: bake … --window '{}' (if that is the glass light enters through)", glass[0]);
    }
    Ok(())
}

fn time_lapse(sun: &bundle::SunSeries, vertex_count: usize, covered: usize, meta: &serde_json::Value) -> Vec<LapseRow> {
    let source = &meta["sun"]["source"];
    let tz_minutes = (source["kind"] == "spa").then(|| source["tz_minutes"].as_i64()).flatten();
    let words = sun.words_per_vertex as usize;
    let lit_per_step = |masks: &[u32]| {
        let mut lit = vec![0u64; sun.step_count()];
        for receiver_words in masks.chunks_exact(words.max(1)) {
            for (w, &word) in receiver_words.iter().enumerate() {
                let mut word = word;
                while word != 0 {
                    lit[w * 32 + word.trailing_zeros() as usize] += 1;
                    word &= word - 1;
                }
            }
        }
        lit
    };
    let lit = lit_per_step(&sun.masks);
    let texels_lit = (!sun.texel_masks.is_empty() && covered > 0).then(|| lit_per_step(&sun.texel_masks));
    sun.steps
        .iter()
        .enumerate()
        .map(|(k, s)| LapseRow {
            step: k,
            unix_time_utc: s.unix_time_utc,
            local_time: tz_minutes.map(|tz| {
                let minutes = ((s.unix_time_utc / 60.0).round() as i64 + tz).rem_euclid(1440);
                format!("{:02}:{:02}", minutes / 60, minutes % 60)
            }),
            elevation_deg: s.elevation_deg,
            azimuth_deg: s.azimuth_deg,
            night: s.night,
            lit_fraction: if vertex_count == 0 { 0.0 } else { lit[k] as f64 / vertex_count as f64 },
            texels_lit_fraction: texels_lit.as_ref().map(|t| t[k] as f64 / covered as f64),
            sun_rgb: s.sun_rgb,
        })
        .collect()
}

/// How a window-mode bundle's receivers split their light between the two
/// sides of their faces (SIDE, TSID): the fractions lit mostly from behind
/// and lit on both sides (each side at least a tenth); `null` without shares.
fn side_summary(shares: &[f32]) -> serde_json::Value {
    if shares.is_empty() {
        return serde_json::Value::Null;
    }
    let n = shares.len() as f64;
    let back = shares.iter().filter(|&&s| s < 0.5).count() as f64 / n;
    let both = shares.iter().filter(|&&s| (0.1..=0.9).contains(&s)).count() as f64 / n;
    json!({ "receivers": shares.len(), "mostly_back": back, "both_sides": both })
}

/// An atlas's size, texel size and charts, as `inspect` prints them.
fn atlas_summary(a: &crate::atlas::Atlas) -> String {
    format!("atlas {} × {} of {} (world units), {} charts", a.width, a.height, a.texel_size, a.chart_count)
}

fn covered_summary(a: &crate::atlas::Atlas, covered: usize) -> String {
    format!("{covered} covered texels ({:.1}% of the texture)", 100.0 * covered as f64 / (a.width as f64 * a.height as f64))
}

/// A texel size per chart (`--texel-levels`, META `density`): the atlas's size printed is the finest chart's.
fn print_density(density: Option<&serde_json::Value>) {
    let Some(d) = density else { return };
    let levels = d["levels"].as_u64().unwrap_or(0);
    let coarsest = d["pilot_texel_size"].as_f64().unwrap_or(0.0) as f32;
    println!(
        "    texel size per chart, {levels} sizes up to {coarsest} (the pilot's): charts per size, coarsest first {}; estimated resolution error {:.2}% (budget {:.2}%)",
        d["charts_per_level"],
        100.0 * d["estimated_error"].as_f64().unwrap_or(f64::NAN),
        100.0 * d["budget"].as_f64().unwrap_or(f64::NAN)
    );
}

fn print_sides(what: &str, shares: &[f32]) {
    if let Some(s) = side_summary(shares).as_object() {
        let pct = |k: &str| 100.0 * s[k].as_f64().unwrap_or(0.0);
        println!(
            "  sides ({what}): light per side of the face kept; {:.1}% lit mostly from behind, {:.1}% lit on both sides (the viewer draws each side's share)",
            pct("mostly_back"),
            pct("both_sides")
        );
    }
}
