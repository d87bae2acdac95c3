//! `prtbake clean IN -o OUT.(obj|glb) [--report FILE.json]`: repair a mesh
//! for PRT and report every change.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::clean::{clean_mesh, CleanParams, CleanReport};
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
}

/// Cleans `mesh` (loaded from `source`, named in errors).
pub fn clean_loaded(mesh: &Mesh, params: &CleanParams, source: &Path) -> anyhow::Result<(Mesh, CleanReport)> {
    clean_mesh(mesh, params).with_context(|| format!("{}: cannot clean", source.display()))
}

/// Writes `mesh` as OBJ or GLB, chosen by the extension of `path`.
pub fn write_mesh(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    match extension.as_str() {
        "obj" => crate::mesh::write_obj(path, mesh)?,
        "glb" => crate::mesh::write_glb(path, mesh)?,
        _ => anyhow::bail!("{}: unknown output format {extension:?}: use .obj or .glb", path.display()),
    }
    Ok(())
}

pub fn run(config: &CleanConfig) -> anyhow::Result<()> {
    // Check the output format before spending time on the clean-up.
    let extension = config.output.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !matches!(extension.as_deref(), Some("obj" | "glb")) {
        anyhow::bail!("{}: unknown output format: use .obj or .glb", config.output.display());
    }
    let mesh = super::load_mesh(&config.input, config.up, config.quiet)?;
    let (cleaned, report) = clean_loaded(&mesh, &config.params, &config.input)?;
    write_mesh(&config.output, &cleaned)?;
    if let Some(path) = &config.report {
        crate::util::write_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if config.json {
        super::print_json(&serde_json::to_value(&report)?)?;
    } else {
        println!("{}: {}", config.input.display(), report.summary());
        println!("wrote {}", config.output.display());
    }
    Ok(())
}
