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
