//! Builds the vendored xatlas (vendor/xatlas, MIT) for the lightmap atlas.
//! Its C API (`XATLAS_C_API`) is what src/atlas/xatlas_ffi.rs declares; it
//! is built single-threaded (`XA_MULTITHREADED=0`): xatlas's task scheduler
//! sizes its work groups by the machine's core count, and an atlas must come
//! out the same on every machine.

fn main() {
    println!("cargo:rerun-if-changed=vendor/xatlas/xatlas.cpp");
    println!("cargo:rerun-if-changed=vendor/xatlas/xatlas.h");
    println!("cargo:rerun-if-changed=vendor/xatlas/xatlas_c.h");
    cc::Build::new()
        .cpp(true)
        .file("vendor/xatlas/xatlas.cpp")
        .define("XATLAS_C_API", "1")
        .define("XA_MULTITHREADED", "0")
        .define("NDEBUG", None)
        .flag_if_supported("-std=c++14")
        .flag_if_supported("-fno-fast-math")
        .opt_level(2)
        .warnings(false)
        .compile("xatlas");
}
