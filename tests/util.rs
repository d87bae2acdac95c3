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

/// A small OBJ: a ground quad and a floating box over it.
pub fn write_scene_obj(path: &Path) {
    let mut s = String::from("mtllib scene.mtl\n");
    s += "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\n";
    // Box 0.5 on a side, 0.5 above the ground.
    for &(x, y, z) in &[
        (-0.25, 0.5, -0.25), (0.25, 0.5, -0.25), (0.25, 1.0, -0.25), (-0.25, 1.0, -0.25),
        (-0.25, 0.5, 0.25), (0.25, 0.5, 0.25), (0.25, 1.0, 0.25), (-0.25, 1.0, 0.25),
    ] {
        s += &format!("v {x} {y} {z}\n");
    }
    s += "o ground\nusemtl grey\nf 1 4 3\nf 1 3 2\n";
    s += "o box\nusemtl red\n";
    for f in [[5, 7, 6], [5, 8, 7], [9, 10, 11], [9, 11, 12], [5, 6, 10], [5, 10, 9], [8, 12, 11], [8, 11, 7], [5, 9, 12], [5, 12, 8], [6, 7, 11], [6, 11, 10]] {
        s += &format!("f {} {} {}\n", f[0], f[1], f[2]);
    }
    std::fs::write(path, s).unwrap();
    std::fs::write(path.with_file_name("scene.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\nnewmtl red\nKd 0.8 0.2 0.2\n").unwrap();
}
