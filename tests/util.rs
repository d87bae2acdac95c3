//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};
use std::process::Output;

/// A fresh scratch folder under the target dir, removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("prtbake-test-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs the prtbake binary with `args`.
pub fn prtbake(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_prtbake")).args(args).output().expect("cannot run prtbake")
}

/// `../shared/data/<rel>` if present; prints a skip notice otherwise.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIP: {} is absent (shared test data not available)", p.display());
        None
    }
}

/// Copies fixtures/scene.obj (a ground quad and a red box floating over it)
/// and its scene.mtl to `path` and beside it.
pub fn write_scene_obj(path: &Path) {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    std::fs::copy(fixtures.join("scene.obj"), path).unwrap();
    std::fs::copy(fixtures.join("scene.mtl"), path.with_file_name("scene.mtl")).unwrap();
}

/// Runs the prtbake binary with `args` and returns its output with its peak
/// resident memory in bytes (`wait4`'s `ru_maxrss` of that child alone), so
/// a test can bound what a run costs without timing it.
#[cfg(unix)]
pub fn prtbake_peak_memory(args: &[&str]) -> (Output, u64) {
    use std::io::Read;
    use std::process::Stdio;
    // Reaped by wait4 below (std's wait would not report the memory).
    #[allow(clippy::zombie_processes)]
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_prtbake"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot run prtbake");
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            let _ = pipe.read_to_end(&mut bytes);
            bytes
        })
    };
    let stdout = drain(Box::new(child.stdout.take().unwrap()));
    let stderr = drain(Box::new(child.stderr.take().unwrap()));
    let (mut status, mut usage) = (0, unsafe { std::mem::zeroed::<libc::rusage>() });
    // SAFETY: waits for our own child, whose pid is valid until reaped here; std's `Child` is not waited on after.
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as libc::pid_t, "wait4 failed");
    use std::os::unix::process::ExitStatusExt;
    let output =
        Output { status: std::process::ExitStatus::from_raw(status), stdout: stdout.join().unwrap(), stderr: stderr.join().unwrap() };
    // ru_maxrss is in KiB on Linux and the BSDs, in bytes on macOS.
    let unit = if cfg!(target_os = "macos") { 1 } else { 1024 };
    (output, usage.ru_maxrss as u64 * unit)
}
