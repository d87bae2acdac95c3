//! Partial re-bakes: the vertices a refinement changed, the rest kept.

use super::layers::{bake_layers, Kept};
use crate::bake::surfaces::Surfaces;
use crate::bake::{BakeError, BakeParams, TransferResult};
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

/// Re-bakes the vertices not in `kept.vertices` from the triangles flagged
/// in `receivers` (which must hold every triangle around those vertices),
/// and keeps the others' values. Bounces ≥ 1 gather from the merged
/// previous bounce, so a re-baked vertex sees its neighbours' light whether
/// they were re-baked or kept. Returns every bounce's layer (as with
/// `store_bounces`) and the total.
pub(crate) fn bake_transfer_update(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: &[bool],
    kept: &Kept,
) -> Result<TransferResult, BakeError> {
    let params = BakeParams { store_bounces: true, ..*params };
    bake_layers(mesh, scene, surfaces, &params, Some(receivers), Some(kept))
}
