//! Where prtbake touches the file system, and what it promises there
//! (docs/safety.md):
//!
//! - [`read`]: inputs are read only from regular files (or links to them) and
//!   never past a documented size limit, so `/dev/zero` or a FIFO cannot make a
//!   loader read forever;
//! - [`outputs`]: before any work, every output path is checked: never an input,
//!   never another output, never a directory, device or FIFO, the extension
//!   names what is written, read-only files only with `--force`;
//! - [`atomic`]: outputs are written to short temporary names beside their
//!   targets and renamed together at the end; an interrupt (SIGINT, SIGTERM,
//!   SIGHUP) removes the temporaries, so a run leaves all its outputs or none;
//! - [`exr_bytes`]: linear RGB images as EXR bytes, the same on every run.

pub mod atomic;
pub mod exr_bytes;
pub mod outputs;
pub mod read;

pub use atomic::{install_interrupt_cleanup, write_atomic, write_atomic_with, Staged};
pub use exr_bytes::rgb_exr_bytes;
pub use outputs::{check_outputs, Output, OutputError};
pub use read::{read_limited, Limit};
