//! The one error type of the BRDF loaders: every message starts with the file
//! (and the line, for the text table), so the CLI can print it as is.

use std::path::PathBuf;

/// Why a BRDF could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum BrdfError {
    /// The file could not be opened or read (missing, not a regular file, over the size limit).
    #[error("{}: cannot read: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },

    /// A line of a text table is malformed (`table.brdf:12: …`).
    #[error("{}:{line}: {message}", path.display())]
    Line { path: PathBuf, line: usize, message: String },

    /// The file as a whole is malformed (wrong size, missing samples, a bad value at a byte offset).
    #[error("{}: {message}", path.display())]
    Malformed { path: PathBuf, message: String },

    /// A parameter of an analytic BRDF is out of its range.
    #[error("invalid BRDF parameter: {message}")]
    Parameter { message: String },
}
