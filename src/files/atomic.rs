//! Atomic outputs: every file is written to a temporary beside its target,
//! synced, and renamed over the target only when all of a command's outputs
//! are complete ([`Staged::commit`]).
//!
//! Temporaries have short fixed-length names (`.prtbake-<pid>-<n>.tmp`), so an
//! output name of up to 255 bytes still fits. They are listed in a process-wide
//! registry: the interrupt handler ([`install_interrupt_cleanup`]) removes them,
//! and takes the registry's lock, so it never runs in the middle of a commit's
//! renames (all of a commit lands, or none of it).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Temporaries of this process not yet renamed or removed.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Distinguishes the temporaries of one process.
static NEXT_TEMPORARY: AtomicU64 = AtomicU64::new(0);

fn registry() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    // A panic while holding the lock leaves the list itself intact.
    TEMPORARIES.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn forget(list: &mut Vec<PathBuf>, tmp: &Path) {
    if let Some(i) = list.iter().position(|p| p == tmp) {
        list.swap_remove(i);
    }
}

/// Outputs written but not yet in place. Dropping it without
/// [`commit`](Staged::commit) removes every temporary: the targets are untouched.
#[derive(Default)]
pub struct Staged {
    /// (temporary, target) in staging order.
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    pub fn new() -> Staged {
        Staged::default()
    }

    /// Writes `path`'s future content into a synced temporary beside the file
    /// it will replace (beside a symbolic link's final target, so the link is
    /// kept and its target replaced).
    pub fn stage(&mut self, path: &Path, fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> std::io::Result<()> {
        let target = super::outputs::final_target(path)?;
        if target.file_name().is_none() {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name"));
        }
        let dir = parent_dir(&target);
        let tmp = dir.join(format!(".prtbake-{}-{}.tmp", std::process::id(), NEXT_TEMPORARY.fetch_add(1, Ordering::Relaxed)));
        registry().push(tmp.clone());
        let written = (|| {
            let mut writer = BufWriter::new(File::create(&tmp)?);
            fill(&mut writer)?;
            writer.into_inner().map_err(|e| e.into_error())?.sync_all()
        })();
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            forget(&mut registry(), &tmp);
            return Err(e);
        }
        self.files.push((tmp, target));
        Ok(())
    }

    /// Stages `bytes` as `path`'s content.
    pub fn stage_bytes(&mut self, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        self.stage(path, |w| w.write_all(bytes))
    }

    /// Renames every temporary over its target, in staging order, with the
    /// interrupt handler held off. On a failed rename the remaining
    /// temporaries are removed and the error names the target.
    pub fn commit(mut self) -> std::io::Result<()> {
        let files = std::mem::take(&mut self.files);
        let mut list = registry();
        let mut result = Ok(());
        for (tmp, target) in &files {
            if result.is_ok() {
                result = std::fs::rename(tmp, target)
                    .map_err(|e| std::io::Error::new(e.kind(), format!("cannot rename into {}: {e}", target.display())));
            }
            if result.is_err() {
                let _ = std::fs::remove_file(tmp);
            }
            forget(&mut list, tmp);
        }
        drop(list);
        // Make the renames durable where the platform can open a directory.
        #[cfg(unix)]
        for (_, target) in &files {
            if let Ok(d) = File::open(parent_dir(target)) {
                let _ = d.sync_all();
            }
        }
        result
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if self.files.is_empty() {
            return;
        }
        let mut list = registry();
        for (tmp, _) in self.files.drain(..) {
            let _ = std::fs::remove_file(&tmp);
            forget(&mut list, &tmp);
        }
    }
}

fn parent_dir(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Writes `bytes` to `path` atomically: an interrupted run never leaves a
/// half-written file, and on failure `path` is untouched.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// [`write_atomic`] with the content written by `fill`.
pub fn write_atomic_with(path: &Path, fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> std::io::Result<()> {
    let mut staged = Staged::new();
    staged.stage(path, fill)?;
    staged.commit()
}

/// Removes this process's temporaries (what an interrupt does before exiting).
/// Returns how many there were. The registry stays locked until the process
/// exits when `hold` is set, so no commit can start afterwards.
fn remove_temporaries(hold: bool) -> usize {
    let mut list = registry();
    let n = list.len();
    for tmp in list.drain(..) {
        let _ = std::fs::remove_file(tmp);
    }
    if hold {
        std::mem::forget(list);
    }
    n
}

/// On SIGINT, SIGTERM or SIGHUP: remove the run's temporaries, say that no
/// output of the interrupted step was written, and exit with 128 + the signal
/// (130 for Ctrl-C, 143 for SIGTERM), so a long bake stops at once and
/// leaves nothing behind. Call once, early in `main`.
pub fn install_interrupt_cleanup() -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
        std::thread::Builder::new().name("interrupt".into()).spawn(move || {
            if let Some(signal) = signals.forever().next() {
                let removed = remove_temporaries(true);
                eprintln!(
                    "\ninterrupted (signal {signal}): stopped; no output of this run was written{}",
                    if removed > 0 { format!(" ({removed} temporary file(s) removed)") } else { String::new() }
                );
                std::process::exit(128 + signal);
            }
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn staged_outputs_land_together_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.obj"), dir.path().join("a.mtl"));
        std::fs::write(&a, "old a").unwrap();
        // A failure while staging the second output leaves the first untouched.
        let mut staged = Staged::new();
        staged.stage_bytes(&a, b"new a").unwrap();
        let failed = staged.stage(&b, |_| Err(std::io::Error::other("disk full")));
        assert!(failed.is_err());
        drop(staged);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert!(!b.exists());
        assert!(leftovers(dir.path()).is_empty(), "{:?}", leftovers(dir.path()));
        // A complete set lands.
        let mut staged = Staged::new();
        staged.stage_bytes(&a, b"new a").unwrap();
        staged.stage_bytes(&b, b"new b").unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a", "nothing lands before the commit");
        staged.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
        assert!(leftovers(dir.path()).is_empty());
    }

    #[test]
    fn a_255_byte_output_name_fits_the_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let name = format!("{}.prtb", "n".repeat(250));
        assert_eq!(name.len(), 255);
        write_atomic(&dir.path().join(&name), b"x").unwrap();
        assert_eq!(std::fs::read(dir.path().join(&name)).unwrap(), b"x");
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_is_followed_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("real.prtb");
        let link = dir.path().join("link.prtb");
        std::fs::write(&target, "old").unwrap();
        std::os::unix::fs::symlink("real.prtb", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
    }

    #[test]
    fn the_registry_lists_exactly_the_pending_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let mut staged = Staged::new();
        staged.stage_bytes(&dir.path().join("x.prtb"), b"x").unwrap();
        let tmp = staged.files[0].0.clone();
        assert!(tmp.exists() && registry().contains(&tmp));
        staged.commit().unwrap();
        assert!(!tmp.exists() && !registry().contains(&tmp));
    }
}
