//! `sun BUNDLE --refine`: the sun refines the bundle's mesh, so the transfer
//! the bundle holds no longer fits its vertices. It is baked again on the
//! refined mesh with the parameters the bundle's META records, and stored as
//! it was stored (order, channels, quantization), so one command leaves one
//! mesh with both sections: the bytes of `export`, `bake` with the same
//! parameters, then `sun` (tests/cli.rs).

use std::path::Path;

use anyhow::Context;
use serde_json::Value;

use crate::bake::{self, BakeParams, Surfaces};
use crate::budget;
use crate::bundle::{make_bundle_stored, Bundle, Quantization};
use crate::mesh::Mesh;
use crate::trace::{BuildQuality, Scene};

/// How a bundle's transfer was baked and stored, read from its META.
#[derive(Clone, Debug)]
pub struct TransferRecipe {
    pub params: BakeParams,
    pub window_patterns: Vec<String>,
    pub one_sided_patterns: Vec<String>,
    /// The stored order, channels and quantization, when not as baked (f32).
    pub storage: Option<budget::Storage>,
    /// META entries that describe the mesh, not the bake: `source`, `clean`, `refine`.
    mesh_meta: Value,
}

impl TransferRecipe {
    /// From the META of the bundle at `path`, which holds a transfer
    /// section; refuses what cannot be baked again the same way.
    pub fn from_meta(path: &Path, meta: &Value, quiet: bool) -> anyhow::Result<TransferRecipe> {
        let name = path.display();
        if meta.get("cull").is_some() {
            anyhow::bail!(
                "{name}: its transfer was culled to a view box, so the mesh is only what that box sees: refine the mesh file before culling (`sun MESH --refine`, then `bake --view-box`)"
            );
        }
        let params =
            meta.get("params").cloned().with_context(|| format!("{name}: META has no bake `params` to re-bake the transfer with"))?;
        let mut params: BakeParams =
            serde_json::from_value(params).with_context(|| format!("{name}: META `params` is not a bake's parameters"))?;
        params.quiet = quiet;
        params.hit_cache_bytes = bake::transfer::available_hit_cache_bytes();
        params.check().with_context(|| format!("{name}: META `params`"))?;
        let window_patterns = match meta.get("window_patterns") {
            None | Some(Value::Null) => Vec::new(),
            Some(v) => {
                serde_json::from_value(v.clone()).with_context(|| format!("{name}: META `window_patterns` is not a list of names"))?
            }
        };
        let one_sided_patterns = match meta.get("one_sided_patterns") {
            None | Some(Value::Null) => Vec::new(),
            Some(v) => {
                serde_json::from_value(v.clone()).with_context(|| format!("{name}: META `one_sided_patterns` is not a list of names"))?
            }
        };
        let storage = match meta.get("storage") {
            None | Some(Value::Null) => None,
            Some(s) => Some(stored_as(s).with_context(|| format!("{name}: META `storage` is not a storage choice"))?),
        };
        let mut mesh_meta = serde_json::json!({});
        for key in ["source", "clean", "refine"] {
            if let Some(v) = meta.get(key) {
                mesh_meta[key] = v.clone();
            }
        }
        Ok(TransferRecipe { params, window_patterns, one_sided_patterns, storage, mesh_meta })
    }

    /// Bakes the transfer of `mesh` as the recipe says: a bundle without sun sections.
    pub fn bake(&self, mesh: &Mesh) -> anyhow::Result<Bundle> {
        let surfaces = Surfaces::resolve(mesh, &self.window_patterns)?.with_one_sided(mesh, &self.one_sided_patterns)?;
        let scene = Scene::build(mesh, BuildQuality::Sah)?;
        let result = bake::bake_transfer(mesh, &scene, &surfaces, &self.params)?;
        let choice = self.storage.map(|storage| {
            let lightings = budget::reference_lightings(result.order);
            let mut choice = budget::choose(&result.total, result.order, result.channels, &[storage], f64::INFINITY, &lightings);
            choice.budget = None;
            choice
        });
        let mut meta = crate::bundle::bundle_meta(self.mesh_meta.clone(), &self.window_patterns, &self.one_sided_patterns, &surfaces);
        meta["transfer_rebaked"] =
            Value::String("by `sun --refine`: the transfer baked again on the sun-refined mesh with these params".into());
        Ok(make_bundle_stored(mesh, &result, &self.params, meta, choice.as_ref()))
    }
}

/// The storage META `storage` records (`bundle::storage_meta`).
fn stored_as(storage: &Value) -> anyhow::Result<budget::Storage> {
    let count = |key: &str| -> anyhow::Result<usize> {
        let n = storage.get(key).and_then(Value::as_u64).with_context(|| format!("no `{key}`"))?;
        usize::try_from(n).ok().filter(|&n| n <= 64).with_context(|| format!("`{key}` {n} out of range"))
    };
    let name = storage.get("quantization").and_then(Value::as_str).context("no `quantization`")?;
    let quantization =
        (0..4).filter_map(Quantization::from_code).find(|q| q.name() == name).with_context(|| format!("unknown quantization {name:?}"))?;
    Ok(budget::Storage { order: count("order")?, channels: count("channels")?, quantization })
}
