//! Atomic outputs: every file is written to a temporary beside its target,
//! synced, and renamed over the target only when all of a command's outputs
//! are complete ([`Staged::commit`]).
//!
//! Temporaries have short names (`.prtbake-<host>-<pid>-<n>.tmp`, the host
//! as 8 hex digits of a hash of its name), so an output name of up to 255
//! bytes still fits. They are listed in a process-wide registry: the
//! interrupt handler ([`install_interrupt_cleanup`]) removes them, and takes
//! the registry's lock, so it never runs in the middle of a commit's renames
//! (all of a commit lands, or none of it). A process killed outright
//! (SIGKILL, a crash) cannot clean up: the first write of a later run into a
//! folder removes the temporaries there of this host's processes that no
//! longer exist ([`remove_stale_temporaries`]); other hosts' (a folder shared
//! by a cluster's nodes) are left alone.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Temporaries of this process not yet renamed or removed.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Distinguishes the temporaries of one process.
static NEXT_TEMPORARY: AtomicU64 = AtomicU64::new(0);
/// Folders this process has already swept for dead processes' temporaries.
static SWEPT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// This host, as 8 hex digits of a CRC-32 of its name (or `0` where the name cannot be read).
fn host_tag() -> String {
    static TAG: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TAG.get_or_init(|| {
        #[cfg(unix)]
        {
            let mut name = [0u8; 256];
            // SAFETY: the buffer is writable for its whole length.
            if unsafe { libc::gethostname(name.as_mut_ptr().cast(), name.len()) } == 0 {
                let end = name.iter().position(|&b| b == 0).unwrap_or(name.len());
                return format!("{:08x}", crc32fast::hash(&name[..end]));
            }
        }
        "0".to_string()
    })
    .clone()
}

/// Whether process `pid` of this host still exists.
fn process_exists(pid: u32) -> bool {
    #[cfg(unix)]
    {
        let Ok(pid) = i32::try_from(pid) else { return false };
        // SAFETY: signal 0 only asks whether the process exists.
        let r = unsafe { libc::kill(pid, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// Removes the temporaries in `dir` that this host's processes no longer
/// running left (killed before they could remove them); returns how many.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    let prefix = format!(".prtbake-{}-", host_tag());
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let own = std::process::id();
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(&prefix)).and_then(|r| r.strip_suffix(".tmp")) else { continue };
        let Some(pid) = rest.split_once('-').and_then(|(pid, n)| n.parse::<u64>().ok().and(pid.parse::<u32>().ok())) else { continue };
        if pid != own && !process_exists(pid) && std::fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Sweeps `dir` once per process (see [`remove_stale_temporaries`]).
fn sweep_once(dir: &Path) {
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut swept = SWEPT.lock().unwrap_or_else(|p| p.into_inner());
        if swept.contains(&key) {
            return;
        }
        swept.push(key);
    }
    let removed = remove_stale_temporaries(dir);
    if removed > 0 {
        eprintln!("note: removed {removed} temporary file(s) an interrupted prtbake left in {}", dir.display());
    }
}

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
        sweep_once(dir);
        let tmp =
            dir.join(format!(".prtbake-{}-{}-{}.tmp", host_tag(), std::process::id(), NEXT_TEMPORARY.fetch_add(1, Ordering::Relaxed)));
        registry().push(tmp.clone());
        // A replaced file keeps its permissions (a 0640 output stays 0640).
        let keep = std::fs::metadata(&target).ok().filter(|m| m.is_file()).map(|m| m.permissions());
        let written = (|| {
            let mut writer = BufWriter::new(File::create(&tmp)?);
            fill(&mut writer)?;
            let file = writer.into_inner().map_err(|e| e.into_error())?;
            if let Some(permissions) = keep {
                file.set_permissions(permissions)?;
            }
            file.sync_all()
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

    #[cfg(unix)]
    #[test]
    fn dead_processes_temporaries_are_removed_and_permissions_kept() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        // A process that has exited: its pid is free (until reused; then its file stays).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let host = host_tag();
        let stale = dir.path().join(format!(".prtbake-{host}-{dead}-0.tmp"));
        let alive = dir.path().join(format!(".prtbake-{host}-{}-99.tmp", std::process::id()));
        let other_host = dir.path().join(format!(".prtbake-ffffffff-{dead}-0.tmp"));
        let not_ours = dir.path().join("notes.tmp");
        for f in [&stale, &alive, &other_host, &not_ours] {
            std::fs::write(f, "x").unwrap();
        }
        assert_eq!(remove_stale_temporaries(dir.path()), if host == "ffffffff" { 2 } else { 1 });
        assert!(!stale.exists() && alive.exists() && not_ours.exists());
        // Replacing keeps the target's mode.
        let out = dir.path().join("out.prtb");
        std::fs::write(&out, "old").unwrap();
        std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_atomic(&out, b"new").unwrap();
        assert_eq!(std::fs::metadata(&out).unwrap().permissions().mode() & 0o777, 0o640);
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
