//! Bounded reads of input files. Every loader reads through [`read_limited`],
//! which refuses anything that is not a regular file (after following links)
//! and anything larger than the limit for its kind, before reading a byte.
//! Formats whose header gives the file's size (bundles, GLB, shard files) or
//! bounds it (EXR, Radiance HDR) read that header first ([`read_head`],
//! [`read_tail`], [`HeadReader`]) and refuse a file of another size before
//! reading its body: a valid header on a 3 GB file costs a few bytes.

use std::io::{Read, Seek};
use std::path::Path;

/// The largest input of each kind prtbake reads (docs/safety.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Limit {
    /// A mesh file (.obj, .gltf, .glb) or a glTF external buffer: 8 GiB.
    Mesh,
    /// A `.mtl` material library: 256 MiB.
    Materials,
    /// A bundle (.prtb): 32 GiB.
    Bundle,
    /// An environment map (.exr, .hdr): 4 GiB.
    Image,
    /// A small text input (a CSV of sun directions): 16 MiB.
    Text,
    /// A shard file of a sharded bake (.prtp part, .prth hit records, .prtl layer): 64 GiB.
    Shard,
    /// A measured BRDF (the text table or a MERL `.binary`, 35 MB): 64 MiB.
    Brdf,
}

impl Limit {
    pub fn bytes(self) -> u64 {
        match self {
            Limit::Mesh => 8 << 30,
            Limit::Materials => 256 << 20,
            Limit::Bundle => 32 << 30,
            Limit::Image => 4 << 30,
            Limit::Text => 16 << 20,
            Limit::Shard => 64 << 30,
            Limit::Brdf => 64 << 20,
        }
    }
}

/// What a non-regular file is, for the error message.
pub(super) fn kind_of(file_type: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if file_type.is_fifo() {
            return "a FIFO";
        }
        if file_type.is_char_device() {
            return "a character device";
        }
        if file_type.is_block_device() {
            return "a block device";
        }
        if file_type.is_socket() {
            return "a socket";
        }
    }
    if file_type.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Checks that `path` is a regular file (links followed) of at most `limit`
/// bytes, and returns its size.
pub fn check_regular(path: &Path, limit: Limit) -> std::io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(invalid(format!("is {}, not a regular file", kind_of(meta.file_type()))));
    }
    if meta.len() > limit.bytes() {
        return Err(invalid(format!("is {} bytes, over the {} byte limit for this kind of input", meta.len(), limit.bytes())));
    }
    Ok(meta.len())
}

/// Reads a whole regular file of at most `limit` bytes. Never reads more
/// than the size checked first, even if the file grows meanwhile.
pub fn read_limited(path: &Path, limit: Limit) -> std::io::Result<Vec<u8>> {
    let size = check_regular(path, limit)?;
    read_prefix(path, size)
}

/// Reads at most `max` bytes from the start of `path` (a regular file
/// within `limit`): e.g. a header to check before the body is read.
pub fn read_head(path: &Path, limit: Limit, max: u64) -> std::io::Result<Vec<u8>> {
    let size = check_regular(path, limit)?;
    read_prefix(path, size.min(max))
}

/// Reads the last `n` bytes of `path` (a regular file within `limit`; all of
/// it when shorter), and returns them with the file's size: e.g. a trailer
/// that gives the file's length.
pub fn read_tail(path: &Path, limit: Limit, n: u64) -> std::io::Result<(Vec<u8>, u64)> {
    let size = check_regular(path, limit)?;
    let mut file = std::fs::File::open(path)?;
    let n = n.min(size);
    file.seek(std::io::SeekFrom::Start(size - n))?;
    let mut bytes = Vec::with_capacity(n as usize);
    file.take(n).read_to_end(&mut bytes)?;
    count_read(bytes.len());
    Ok((bytes, size))
}

/// A reader over at most the first `max` bytes of a regular file within a
/// limit, for a decoder that reads a header of its own: what it reads is
/// what is fetched, and [`HeadReader::bytes_read`] says how much that was.
pub struct HeadReader {
    inner: std::io::Take<std::fs::File>,
    read: u64,
    /// The file's size.
    pub size: u64,
}

impl HeadReader {
    pub fn open(path: &Path, limit: Limit, max: u64) -> std::io::Result<HeadReader> {
        let size = check_regular(path, limit)?;
        Ok(HeadReader { inner: std::fs::File::open(path)?.take(max), read: 0, size })
    }

    /// Bytes read so far (the header's length, once a decoder has read it unbuffered).
    pub fn bytes_read(&self) -> u64 {
        self.read
    }
}

impl Read for HeadReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read += n as u64;
        count_read(n);
        Ok(n)
    }
}

fn read_prefix(path: &Path, len: u64) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(len).read_to_end(&mut bytes)?;
    count_read(bytes.len());
    Ok(bytes)
}

#[inline]
fn count_read(_n: usize) {
    #[cfg(test)]
    bytes_read::add(_n);
}

/// Bytes this thread has read from input files, for tests that bound what a
/// refusal costs; release builds count nothing.
#[cfg(test)]
pub(crate) mod bytes_read {
    use std::cell::Cell;

    thread_local!(static READ: Cell<u64> = const { Cell::new(0) });

    pub(crate) fn add(n: usize) {
        READ.with(|read| read.set(read.get() + n as u64));
    }

    /// The bytes read since the last call, on this thread.
    pub(crate) fn take() -> u64 {
        READ.with(|read| read.replace(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_read_whole_and_others_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.obj");
        std::fs::write(&file, "v 0 0 0\n").unwrap();
        assert_eq!(read_limited(&file, Limit::Mesh).unwrap(), b"v 0 0 0\n");
        assert_eq!(read_head(&file, Limit::Mesh, 3).unwrap(), b"v 0");
        let e = read_limited(dir.path(), Limit::Mesh).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        #[cfg(unix)]
        {
            let e = read_limited(Path::new("/dev/zero"), Limit::Mesh).unwrap_err();
            assert!(e.to_string().contains("character device"), "{e}");
        }
    }

    #[test]
    fn files_over_the_limit_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("big.csv");
        // A sparse file: its size costs no disk.
        let f = std::fs::File::create(&file).unwrap();
        f.set_len(Limit::Text.bytes() + 1).unwrap();
        let e = read_limited(&file, Limit::Text).unwrap_err();
        assert!(e.to_string().contains("over the 16777216 byte limit"), "{e}");
    }
}
