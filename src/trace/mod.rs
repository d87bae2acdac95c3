//! The ray tracer: a BVH over a mesh's triangles (a top-down binned SAH
//! build collapsed into 8-wide nodes, leaf triangles in struct-of-arrays
//! blocks, fans around points of high valence) and its queries — closest
//! hit with barycentrics, facing and a deterministic tie-break, occlusion,
//! one ray or a batch, and occlusion of parallel rays in packets (the
//! sun's). It knows triangles and rays, nothing of light: the estimators in
//! `bake`, `panel` and `sun` ask it where rays go.

pub mod build;
pub mod bvh8;
pub mod fans;
pub mod hugepages;
pub mod leaf_blocks;
pub mod packets;
pub mod queries;
pub mod ray_log;
pub mod sah;
pub mod scene;

pub use scene::{check_extent, BatchMode, Batching, BuildQuality, Hit, RayQuery, Scene, SceneError, Traversal, MAX_SCENE_EXTENT};
