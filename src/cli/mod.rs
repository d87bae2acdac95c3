//! The command-line glue: each subcommand turns a checked configuration into
//! library calls and a report. Errors carry the path they concern; the binary
//! prints them and exits 2 (a failed check exits 1).

pub mod bake_cmd;
pub mod chart_cmd;
pub mod clean_cmd;
pub mod demo_cmd;
mod demo_panel;
pub mod export_cmd;
pub mod generate_cmd;
pub mod inspect_cmd;
pub mod merge_cmd;
pub mod panel_cmd;
pub mod shard_cmd;
pub mod sun_cmd;
mod sun_rebake;
pub mod verify_cmd;
pub mod view_cmd;

use std::path::{Path, PathBuf};

pub use crate::files::Output;

use anyhow::Context;

/// What a command tells the process to exit with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Exit 0.
    Ok,
    /// Exit 1: the command ran but a check failed.
    CheckFailed,
}

/// The most worker threads a command accepts: four per available core, at
/// least 8. More only costs memory and start-up (each thread has its own
/// stack and per-thread buffers), and 100,000 of them exhausted the machine.
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (4 * cores).max(8)
}

/// Checks `--threads` (0 = every core) against [`max_threads`].
pub fn check_threads(threads: usize) -> anyhow::Result<()> {
    let max = max_threads();
    if threads > max {
        anyhow::bail!("--threads {threads}: at most {max} (4 per available core); 0 uses every core");
    }
    Ok(())
}

/// Runs `f` on a rayon pool of `threads` threads (0 = all cores).
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> anyhow::Result<T> {
    check_threads(threads)?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("cannot start the thread pool")?;
    Ok(pool.install(f))
}

/// `x` with `digits` significant digits (`0.00123`, `45.6`, `1.23e6`), so a
/// small value does not print as 0.0.
pub fn significant(x: f64, digits: usize) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&magnitude) {
        return format!("{:.*e}", digits.saturating_sub(1), x);
    }
    let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
    format!("{x:.decimals$}")
}

/// Prints `value` as pretty JSON on stdout.
pub fn print_json(value: &serde_json::Value) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}

/// Loads a mesh file with the path in every error, prints its warnings, and
/// refuses `outputs` that are any file the loader read (`.mtl` libraries,
/// glTF buffers), as [`check_outputs`] does for the mesh file itself.
pub fn load_mesh(path: &Path, up: crate::mesh::UpAxis, quiet: bool, outputs: &[Output], force: bool) -> anyhow::Result<crate::mesh::Mesh> {
    let loaded = crate::mesh::load_mesh(path, &crate::mesh::LoadOptions { up })?;
    if !quiet {
        for w in &loaded.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
    }
    let mut inputs: Vec<&Path> = vec![path];
    inputs.extend(loaded.sources.iter().map(PathBuf::as_path));
    check_outputs(&inputs, outputs, force)?;
    Ok(loaded.mesh)
}

/// Refuses (exit 2, before any work) outputs that are inputs or each other,
/// not regular files, of the wrong extension, or read-only without `--force`
/// ([`crate::files::outputs`]).
pub fn check_outputs(inputs: &[&Path], outputs: &[Output], force: bool) -> anyhow::Result<()> {
    crate::files::check_outputs(inputs, outputs, force)?;
    Ok(())
}

/// A path for JSON output: lossy where it is not UTF-8 (serde refuses such
/// paths, and a report must not fail on a file name).
pub fn json_path(path: &Path) -> serde_json::Value {
    serde_json::Value::String(path.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    #[test]
    fn significant_digits_keep_small_values() {
        assert_eq!(super::significant(0.0012345, 3), "0.00123");
        assert_eq!(super::significant(45.67, 3), "45.7");
        assert_eq!(super::significant(1234567.0, 3), "1.23e6");
        assert_eq!(super::significant(0.0, 3), "0");
        assert_eq!(super::significant(2.5e-7, 2), "2.5e-7");
    }
}
