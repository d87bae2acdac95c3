//! What one run of a sharded transfer bake is asked to do, where its files
//! are (the shard, the stage, the merged inputs it reads), and how a shard
//! file is read: bounded, its frame checked before its body.

use std::path::{Path, PathBuf};

use anyhow::Context;

use super::{
    codec, hit_file_name, HitFile, LayerFile, PilotFile, PilotInput, RoundInput, RoundOutput, Shard, ShardError, Stage, TransferKey,
};
use crate::bake::Surfaces;
use crate::files::read::{read_head, read_tail};
use crate::files::{Limit, Staged};
use crate::mesh::Mesh;
use crate::trace::{BuildQuality, Scene, SceneError};

/// A round's merged inputs, read and checked before any ray: the layer of
/// the round before with this shard's hit records (rounds ≥ 1), and the
/// pilot (every round of an adaptive bake), each with its CRC.
pub struct RoundFiles {
    layer: Option<(LayerFile, u32, HitFile)>,
    pilot: Option<(PilotFile, u32)>,
}

impl RoundFiles {
    /// A later round's (`None` in round 0 and the pilot stage): the chart
    /// levels round 0's `--texel-levels` pilot chose, as this shard's hit records keep them.
    pub fn chart_levels(&self) -> Option<Option<&super::files::ChartLevels>> {
        self.layer.as_ref().map(|(_, _, hits)| hits.texels.as_ref().and_then(|t| t.density.as_ref()))
    }
}

/// What `bake --shard` asks of one run.
#[derive(Clone, Debug)]
pub struct ShardRun {
    pub shard: Shard,
    /// The bounce this run bakes (0..=bounces).
    pub round: u32,
    /// `--round pilot`: adaptive allocation's pilot instead of a round.
    pub pilot_stage: bool,
    /// Rounds ≥ 1: the merged layer of the round before.
    pub layer: Option<PathBuf>,
    /// Every round of an adaptive bake: the merged pilot (`--pilot`).
    pub pilot: Option<PathBuf>,
    /// The folder of this shard's hit records (default: the part's).
    pub shard_dir: Option<PathBuf>,
}

impl ShardRun {
    /// Where shard `shard`'s hit records are written (round 0) and read (later rounds).
    pub fn hits_path(&self, part: &Path) -> PathBuf {
        let dir = match &self.shard_dir {
            Some(dir) => dir.clone(),
            None => part.parent().map(Path::to_path_buf).unwrap_or_default(),
        };
        dir.join(hit_file_name(self.shard))
    }

    /// The stage this run bakes.
    pub fn stage(&self) -> Stage {
        if self.pilot_stage {
            Stage::Pilot
        } else {
            Stage::Round(self.round)
        }
    }

    /// Refuses a run whose stage, inputs and parameters do not go together
    /// (`bounces`, and whether the bake has adaptive allocation), with the
    /// command-line words a user fixes them with.
    pub fn check(&self, bounces: u32, adaptive: bool) -> anyhow::Result<()> {
        match (self.stage(), adaptive, &self.pilot) {
            (Stage::Pilot, false, _) => anyhow::bail!("--round pilot is adaptive allocation's stage; this bake has --adaptive 0"),
            (Stage::Pilot, true, Some(p)) => anyhow::bail!("--pilot {}: the pilot stage makes the pilot; rounds 0 and later read it", p.display()),
            (Stage::Round(r), true, None) => anyhow::bail!(
                "--round {r} of an adaptive bake needs --pilot, the merged pilot (run --round pilot on every shard, then prtbake merge … -o PILOT.prta; docs/scale.md)"
            ),
            (Stage::Round(_), false, Some(p)) => anyhow::bail!("--pilot {}: this bake has --adaptive 0 and no pilot stage", p.display()),
            _ => {}
        }
        if self.round > bounces {
            anyhow::bail!("--round {}: a bake of {bounces} bounce(s) has rounds 0..={bounces}", self.round);
        }
        match (self.round, &self.layer) {
            (0, Some(layer)) => anyhow::bail!("--layer {}: round 0 traces from scratch and takes no layer", layer.display()),
            (r, None) if r > 0 => {
                anyhow::bail!("--round {r} needs --layer, the merged layer of round {} (prtbake merge … -o LAYER.prtl)", r - 1)
            }
            _ => {}
        }
        Ok(())
    }

    /// Whether this run writes hit records beside its part (round 0 of a bake with bounces).
    pub fn writes_hits(&self, bounces: u32) -> bool {
        self.stage() == Stage::Round(0) && bounces > 0
    }

    /// The files this run reads besides the mesh (for the output checks).
    pub fn inputs(&self, part: &Path) -> Vec<PathBuf> {
        let mut inputs = Vec::new();
        if let Some(layer) = &self.layer {
            inputs.extend([layer.clone(), self.hits_path(part)]);
        }
        inputs.extend(self.pilot.clone());
        inputs
    }

    /// Reads and checks the round's merged inputs (`part`: where the part
    /// goes, beside which the hit records are by default).
    pub fn read_inputs(&self, part: &Path) -> anyhow::Result<RoundFiles> {
        let layer = match &self.layer {
            None => None,
            Some(layer_path) => {
                let bytes = read_shard_file(layer_path)?;
                let (layer, crc): (LayerFile, u32) = decode(layer_path, &bytes, LayerFile::decode)?;
                drop(bytes);
                let hits_path = self.hits_path(part);
                let bytes = read_shard_file(&hits_path).with_context(|| {
                    format!("shard {}'s hit records from round 0 (--shard-dir names their folder; round 0 writes them)", self.shard)
                })?;
                Some((layer, crc, decode(&hits_path, &bytes, HitFile::decode)?))
            }
        };
        let pilot = match &self.pilot {
            None => None,
            Some(path) => {
                let bytes = read_shard_file(path)?;
                Some(decode(path, &bytes, PilotFile::decode)?)
            }
        };
        Ok(RoundFiles { layer, pilot })
    }

    /// The scene this run traces: without a BVH in rounds ≥ 1, which gather
    /// from round 0's hit records and trace nothing (building it would be
    /// most of their time).
    pub fn scene(&self, mesh: &Mesh) -> Result<Scene, SceneError> {
        match self.stage() {
            Stage::Round(r) if r > 0 => Scene::without_bvh(mesh),
            _ => Scene::build(mesh, BuildQuality::Sah),
        }
    }

    /// Bakes this shard's part of its stage: the estimator over the shard's
    /// items (and in texel mode its texels), from the round's merged inputs.
    #[allow(clippy::too_many_arguments)]
    pub fn bake(
        &self,
        mesh: &Mesh,
        scene: &Scene,
        surfaces: &Surfaces,
        key: &TransferKey,
        texels: Option<&mut crate::bake::texels::TexelTransferPlan>,
        quiet: bool,
        files: RoundFiles,
        part: &Path,
    ) -> Result<RoundOutput, ShardError> {
        let stage = self.stage();
        let hits_path = self.hits_path(part);
        let (layer_path, pilot_path) = (self.layer.clone().unwrap_or_default(), self.pilot.clone().unwrap_or_default());
        let input = files.layer.map(|(layer, layer_crc, hits)| RoundInput {
            hits_path: &hits_path,
            hits,
            layer_path: &layer_path,
            layer,
            layer_crc,
        });
        let pilot = files.pilot.map(|(pilot, crc)| PilotInput { path: &pilot_path, pilot, crc });
        super::bake_transfer_shard(mesh, scene, surfaces, key, texels, quiet, self.shard, stage, input, pilot)
    }

    /// Writes the part and its hit records, together or not at all.
    pub fn write(&self, output: &RoundOutput, part: &Path) -> anyhow::Result<()> {
        let hits_path = self.hits_path(part);
        let mut staged = Staged::new();
        staged.stage(part, |w| output.part.write_to(w).map(drop)).with_context(|| format!("cannot write {}", part.display()))?;
        if let Some(hits) = &output.hits {
            staged.stage(&hits_path, |w| hits.write_to(w).map(drop)).with_context(|| format!("cannot write {}", hits_path.display()))?;
        }
        staged.commit().with_context(|| format!("cannot write {}", part.display()))?;
        Ok(())
    }
}

/// Reads a shard file whole (bounded), with the path in every error; its
/// header and trailer are read and checked against the file's size first
/// ([`codec::check_frame`]), so a file of another size than its
/// trailer gives is refused before its body is read.
pub fn read_shard_file(path: &Path) -> anyhow::Result<Vec<u8>> {
    let cannot_read = || format!("cannot read {}", path.display());
    let head = read_head(path, Limit::Shard, codec::HEADER_LEN as u64).with_context(cannot_read)?;
    let (tail, size) = read_tail(path, Limit::Shard, codec::TRAILER_LEN as u64).with_context(cannot_read)?;
    codec::check_frame(&head, &tail, size).map_err(|problem| ShardError::malformed(path, problem))?;
    read_head(path, Limit::Shard, size).with_context(cannot_read)
}

/// Decodes with the file named in the error.
pub fn decode<T>(path: &Path, bytes: &[u8], decode: impl FnOnce(&[u8]) -> Result<T, String>) -> Result<T, ShardError> {
    decode(bytes).map_err(|problem| ShardError::Malformed { path: path.to_path_buf(), problem })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::read::bytes_read;
    use crate::shards::codec::FileKind;

    /// A shard file of another size than its trailer gives (a layer
    /// extended to a sparse 3 GiB, or cut short) is refused after its header
    /// and trailer, naming the file and both sizes; the file itself reads whole.
    #[test]
    fn shard_files_are_checked_against_their_trailer_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("grown.prtl");
        let bytes = codec::to_vec(FileKind::Layer, |w| w.f32s(&[1.0; 1000]));
        std::fs::write(&path, &bytes).unwrap();
        bytes_read::take();
        assert_eq!(read_shard_file(&path).unwrap(), bytes);
        let frame = (codec::HEADER_LEN + codec::TRAILER_LEN) as u64;
        assert_eq!(bytes_read::take(), frame + bytes.len() as u64);
        let big = 3u64 << 30;
        for len in [big, bytes.len() as u64 - 4] {
            std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(len).unwrap();
            let message = format!("{:#}", read_shard_file(&path).unwrap_err());
            assert_eq!(bytes_read::take(), frame);
            // Extended with zeros or cut short, the last 12 bytes are not a trailer.
            let says = format!("is {len} bytes and does not end in its own length and CRC-32");
            assert!(message.contains("grown.prtl") && message.contains(&says) && message.contains("truncated or extended"), "{message}");
        }
    }
}
