//! `prtbake clean IN -o OUT.(obj|glb) [--report FILE.json]`: repair a mesh
//! for PRT and report every change.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;

use super::Output;
use crate::clean::{clean_mesh_timed, CleanParams, CleanReport, StepTimes};
use crate::files::Staged;
use crate::mesh::{Mesh, UpAxis};

/// A checked `clean` configuration.
#[derive(Clone, Debug)]
pub struct CleanConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub report: Option<PathBuf>,
    pub up: UpAxis,
    pub params: CleanParams,
    pub json: bool,
    pub quiet: bool,
    /// Replace read-only outputs, and a `.mtl` prtbake did not write (`--force`).
    pub force: bool,
}

/// Cleans `mesh` (loaded from `source`, named in errors); with the seconds each step took.
pub fn clean_loaded(mesh: &Mesh, params: &CleanParams, source: &Path) -> anyhow::Result<(Mesh, CleanReport, StepTimes)> {
    let (cleaned, report, times) = clean_mesh_timed(mesh, params).with_context(|| format!("{}: cannot clean", source.display()))?;
    if !report.converged {
        // Cleaning the output again would still change it: say which repair keeps coming back.
        eprintln!("warning: {}: clean stopped after {} rounds, {}", source.display(), report.rounds, report.convergence());
    }
    Ok((cleaned, report, times))
}

/// Output formats of a cleaned mesh, by extension.
const MESH_FORMATS: &[&str] = &["obj", "glb"];

/// Every file `clean` writes: the mesh, the `.mtl` beside an OBJ (replaced
/// only if prtbake wrote it, unless forced), and the report.
fn outputs(config: &CleanConfig) -> (Vec<Output<'_>>, Option<PathBuf>) {
    let is_obj = config.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let mtl = is_obj.then(|| crate::mesh::mtl_path_for(&config.output));
    (vec![Output::new(&config.output, MESH_FORMATS)], mtl)
}

pub fn run(config: &CleanConfig) -> anyhow::Result<()> {
    // Check every output before spending time on the clean-up.
    let (mut outputs, mtl) = outputs(config);
    if let Some(mtl) = &mtl {
        // The OBJ names its .mtl inside the file (`mtllib`), as text.
        if mtl.file_name().and_then(|n| n.to_str()).is_none() {
            anyhow::bail!(
                "{}: an OBJ names its material library inside the file as text, so the name must be UTF-8: choose another name or write .glb",
                config.output.display()
            );
        }
    }
    if let Some(mtl) = &mtl {
        outputs.push(Output { own_marker: Some(crate::mesh::MTL_HEADER.as_bytes()), ..Output::new(mtl, &["mtl"]) });
    }
    if let Some(report) = &config.report {
        outputs.push(Output::new(report, &["json"]));
    }
    super::check_outputs(&[&config.input], &outputs, config.force)?;
    let start = Instant::now();
    let mesh = super::load_mesh(&config.input, config.up, config.quiet, &outputs, config.force)?;
    let load_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let (cleaned, report, times) = clean_loaded(&mesh, &config.params, &config.input)?;
    // What the steps do not cover (the input's checks) counts as the clean's own.
    let steps: f64 = times.steps.iter().map(|s| s.1).sum();
    let clean_seconds = (start.elapsed().as_secs_f64() - steps).max(0.0);
    if cleaned.triangle_count() == 0 {
        anyhow::bail!(
            "{}: cleaning left no triangle ({}): nothing to write; the input holds no surface with area",
            config.input.display(),
            report.summary()
        );
    }
    if mtl.is_some() && report.seam_vertices_split > 0 {
        // The OBJ loader welds vertices alike in every attribute: the two sides
        // of a cut line, written as two vertices, would be one again.
        eprintln!(
            "warning: {}: the cut lines' two sides are separate vertices alike in every attribute, which loading an OBJ welds back; write .glb (or bake --clean --cut-intersections) to keep them apart",
            config.output.display()
        );
    }
    if mtl.is_some() && !cleaned.lightmap_uvs.is_empty() {
        eprintln!(
            "warning: {}: OBJ holds one set of texture coordinates, so the mesh's lightmap atlas (TEXCOORD_1) is not written; write .glb to keep it",
            config.output.display()
        );
    }
    // All outputs land together or none does.
    let start = Instant::now();
    let mut staged = Staged::new();
    if mtl.is_some() {
        crate::mesh::stage_obj(&mut staged, &config.output, &cleaned)?;
    } else {
        crate::mesh::stage_glb(&mut staged, &config.output, &cleaned)?;
    }
    if let Some(path) = &config.report {
        staged
            .stage_bytes(path, serde_json::to_string_pretty(&report)?.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    staged.commit().with_context(|| format!("cannot write {}", config.output.display()))?;
    let mut phases = vec![("load".to_string(), load_seconds), ("clean: checks".to_string(), clean_seconds)];
    phases.extend(times.steps.iter().map(|&(name, t)| (format!("clean: {name}"), t)));
    phases.push(("write".to_string(), start.elapsed().as_secs_f64()));
    if config.json {
        // Timings go to stdout only: the --report file stays the same for the same input.
        let mut value = serde_json::to_value(&report)?;
        value["seconds_per_phase"] = phases.iter().map(|(name, t)| (name.clone(), serde_json::json!(t))).collect();
        super::print_json(&value)?;
    } else {
        println!("{}: {}", config.input.display(), report.summary());
        match &mtl {
            Some(mtl) => println!("wrote {} (materials in {})", config.output.display(), mtl.display()),
            None => println!("wrote {}", config.output.display()),
        }
        println!("{}", super::phase_line(&phases));
    }
    Ok(())
}
