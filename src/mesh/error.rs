//! The one error type of the mesh boundary: every message starts with the file path.

use std::path::{Path, PathBuf};

/// Why a mesh could not be loaded or written.
///
/// `Display` always names the file first, then the problem, so a caller can print
/// it as is (`prtbake: car.glb: node cycle at node 3`).
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file (or a file it refers to) could not be opened or read.
    #[error("{}: cannot read: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },

    /// A glTF buffer refers to a separate file that could not be read.
    #[error("{}: buffer {buffer} refers to {}, which cannot be read: {source}", path.display(), file.display())]
    MissingBuffer { path: PathBuf, buffer: usize, file: PathBuf, source: std::io::Error },

    /// The extension is not `.obj`, `.gltf` or `.glb`.
    #[error("{}: unsupported mesh format {extension:?} (expected .obj, .gltf or .glb)", path.display())]
    UnsupportedFormat { path: PathBuf, extension: String },

    /// The file is not a well-formed OBJ (or its structure is inconsistent).
    #[error("{}: malformed OBJ: {message}", path.display())]
    MalformedObj { path: PathBuf, message: String },

    /// The file is not a well-formed glTF/GLB (JSON, schema, buffers, accessors).
    #[error("{}: malformed glTF: {message}", path.display())]
    MalformedGltf { path: PathBuf, message: String },

    /// The glTF lists a required extension that this loader cannot honour.
    #[error("{}: requires extension {extension}, which prtbake does not support; {hint}", path.display())]
    UnsupportedExtension { path: PathBuf, extension: String, hint: &'static str },

    /// The glTF node hierarchy loops back on itself.
    #[error("{}: node cycle at node {node}", path.display())]
    NodeCycle { path: PathBuf, node: usize },

    /// A primitive's index refers past the end of its vertex attributes.
    #[error("{}: mesh {mesh} primitive {primitive}: index {index} (at position {position}) is out of range ({vertex_count} vertices)", path.display())]
    IndexOutOfRange {
        path: PathBuf,
        /// Mesh name and number, e.g. `'Cube' (0)`.
        mesh: String,
        primitive: usize,
        index: u32,
        position: usize,
        vertex_count: usize,
    },

    /// A vertex position is NaN or infinite.
    #[error("{}: {vertex} has a non-finite position {position:?}", path.display())]
    NonFinitePosition {
        path: PathBuf,
        /// Where the vertex is, e.g. `vertex 12 (line 14)` or `mesh 'Box' (0) primitive 0 vertex 3`.
        vertex: String,
        position: [f32; 3],
    },

    /// The file loaded but holds no triangles (only points/lines, or nothing).
    #[error("{}: the mesh has no triangles{}", path.display(), if notes.is_empty() { String::new() } else { format!(" ({})", notes.join("; ")) })]
    Empty {
        path: PathBuf,
        /// Warnings met while loading, which often say why (skipped point/line primitives).
        notes: Vec<String>,
    },

    /// The mesh exceeds a format limit (u32 vertices, u16 materials, size caps).
    #[error("{}: too large: {message}", path.display())]
    TooLarge { path: PathBuf, message: String },

    /// The assembled mesh broke a [`Mesh::validate`](super::Mesh::validate) invariant (a loader bug).
    #[error("{}: internal error, loaded mesh is inconsistent: {message}", path.display())]
    Inconsistent { path: PathBuf, message: String },

    /// The mesh handed to a writer is unusable (e.g. fails `validate`).
    #[error("{}: cannot write this mesh: {message}", path.display())]
    InvalidForWrite { path: PathBuf, message: String },

    /// Writing the output (or its temp file, or the rename) failed.
    #[error("{}: cannot write: {source}", path.display())]
    Write { path: PathBuf, source: std::io::Error },
}

impl MeshError {
    /// Shorthand for a [`MeshError::MalformedGltf`].
    pub(crate) fn gltf(path: &Path, message: impl Into<String>) -> MeshError {
        MeshError::MalformedGltf { path: path.to_path_buf(), message: message.into() }
    }

    /// Shorthand for a [`MeshError::MalformedObj`].
    pub(crate) fn obj(path: &Path, message: impl Into<String>) -> MeshError {
        MeshError::MalformedObj { path: path.to_path_buf(), message: message.into() }
    }
}
