//! An optional log of every ray traced through the batch queries, for
//! tracing the very same rays with another tracer
//! (`benches/embree_bake_rays.py`): with `PRTBAKE_LOG_RAYS=FILE` set (a file
//! that does not exist yet: it never replaces one), each batch appends its
//! rays to FILE, 32 bytes a ray: origin, direction and
//! reach as little-endian f32, then the query (0 closest hit, 1 occlusion)
//! as a u32. A batch is written whole, so a point's rays stay together; the
//! order of batches follows the threads. Unset, it costs one load of a
//! once-initialised cell per batch.

use std::fs::File;
use std::io::Write;
use std::sync::{Mutex, OnceLock};

use super::scene::RayQuery;

/// Which query a logged ray was traced with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoggedQuery {
    ClosestHit = 0,
    Occlusion = 1,
}

/// Bytes per logged ray.
pub const RECORD_BYTES: usize = 32;

static LOG: OnceLock<Option<Mutex<File>>> = OnceLock::new();

fn log() -> Option<&'static Mutex<File>> {
    LOG.get_or_init(|| {
        let path = std::env::var_os("PRTBAKE_LOG_RAYS")?;
        // A new file only: the log never replaces one (a mesh named by mistake).
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(file) => Some(Mutex::new(file)),
            Err(e) => {
                eprintln!("warning: PRTBAKE_LOG_RAYS={}: cannot create a new file: {e}; no rays are logged", path.to_string_lossy());
                None
            }
        }
    })
    .as_ref()
}

/// Opens the log now, if one is asked for: a scene does it when it is
/// built, so that a warning about the file comes before any progress line.
pub fn open() {
    let _ = log();
}

/// Appends a batch to the log, when there is one.
#[inline]
pub fn record(queries: &[RayQuery], query: LoggedQuery) {
    if let Some(file) = log() {
        write_batch(file, queries, query);
    }
}

#[cold]
fn write_batch(file: &Mutex<File>, queries: &[RayQuery], query: LoggedQuery) {
    let bytes = encode(queries, query);
    let mut file = file.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Err(e) = file.write_all(&bytes) {
        eprintln!("warning: PRTBAKE_LOG_RAYS: write failed: {e}");
    }
}

/// The batch as log records.
pub fn encode(queries: &[RayQuery], query: LoggedQuery) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(queries.len() * RECORD_BYTES);
    for q in queries {
        for v in [q.origin.x, q.origin.y, q.origin.z, q.direction.x, q.direction.y, q.direction.z, q.t_max] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&(query as u32).to_le_bytes());
    }
    bytes
}

/// Reads log records back: each ray and its query. `None` when the length
/// is not whole records or a query code is unknown.
pub fn decode(bytes: &[u8]) -> Option<Vec<(RayQuery, LoggedQuery)>> {
    if bytes.len() % RECORD_BYTES != 0 {
        return None;
    }
    bytes
        .chunks_exact(RECORD_BYTES)
        .map(|r| {
            let f = |k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap());
            let query = match u32::from_le_bytes(r[28..32].try_into().unwrap()) {
                0 => LoggedQuery::ClosestHit,
                1 => LoggedQuery::Occlusion,
                _ => return None,
            };
            let origin = glam::Vec3::new(f(0), f(1), f(2));
            let direction = glam::Vec3::new(f(3), f(4), f(5));
            Some((RayQuery { origin, direction, t_max: f(6) }, query))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn records_round_trip_and_damage_is_refused() {
        let queries = [
            RayQuery { origin: Vec3::new(1.0, -2.0, 3.5), direction: Vec3::Z, t_max: f32::INFINITY },
            RayQuery { origin: Vec3::new(0.25, 0.0, -1e-7), direction: Vec3::new(0.6, 0.8, 0.0), t_max: 0.125 },
        ];
        let bytes = encode(&queries, LoggedQuery::Occlusion);
        assert_eq!(bytes.len(), 2 * RECORD_BYTES);
        let back = decode(&bytes).unwrap();
        for ((q, kind), original) in back.iter().zip(&queries) {
            assert_eq!((q.origin, q.direction, q.t_max.to_bits()), (original.origin, original.direction, original.t_max.to_bits()));
            assert_eq!(*kind, LoggedQuery::Occlusion);
        }
        assert!(decode(&bytes[..RECORD_BYTES + 5]).is_none(), "a partial record");
        let mut bad = bytes.clone();
        bad[31] = 7;
        assert!(decode(&bad).is_none(), "an unknown query");
    }
}
