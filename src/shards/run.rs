//! What one run of a sharded transfer bake is asked to do, where its files
//! are (the shard, the stage, the merged inputs it reads), and how a shard
//! file is read: bounded, its frame checked before its body.

use std::path::{Path, PathBuf};

use anyhow::Context;

use super::{codec, hit_file_name, Shard, ShardError};
use crate::files::read::{read_head, read_tail};
use crate::files::Limit;

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
