//! Meshes: the flat [`Mesh`] type, loading (OBJ via tobj, glTF/GLB via gltf),
//! vertex normals, and writing (OBJ + MTL, GLB).
//!
//! Entry points: [`load_mesh`], [`write_obj`], [`write_glb`].
//! Architecture invariant: no loader panics on any input; every error names the file.

mod builder;
mod error;
mod gltf_accessor;
mod gltf_buffers;
mod gltf_load;
mod gltf_scene;
pub mod inventory;
mod load;
mod normals;
mod obj;
mod types;
mod write;

#[cfg(test)]
mod corpus_tests;
#[cfg(test)]
mod fuzz_tests;
#[cfg(test)]
mod load_tests;

pub use error::MeshError;
pub use load::{load_mesh, LoadOptions, LoadedMesh, UpAxis};
pub use normals::{compute_vertex_normals, repair_normals, FALLBACK_NORMAL};
pub use types::*;
pub use write::{
    mtl_path_for, stage_glb, stage_glb_with, stage_obj, write_glb, write_glb_with, write_obj, AttributeValues, CustomAttribute,
    EmbeddedImage, GlbAdditions, MTL_HEADER,
};

/// Albedo (grey) of materials that state none (OBJ without `Kd`, glTF without
/// `baseColorFactor`) and of the `"default"` material given to parts without one.
pub const DEFAULT_ALBEDO: f32 = 0.8;
