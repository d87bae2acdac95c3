//! Output paths checked before a command does any work: an output is never
//! an input or another output of the same run (compared by canonical path
//! and, where the file exists, by device and inode, so hard links count), never
//! a directory, FIFO, device or socket, and its extension names the format
//! written. Read-only files, and files prtbake did not write where only its
//! own may be replaced (the `.mtl` beside an OBJ), need `--force`.

use std::path::{Path, PathBuf};

/// Links followed at most when resolving an output (as the kernel's ELOOP).
const MAX_LINK_HOPS: usize = 40;

/// One output of a command.
#[derive(Clone, Copy, Debug)]
pub struct Output<'a> {
    pub path: &'a Path,
    /// File extensions (lower case, no dot) of the format written; empty: any.
    pub formats: &'a [&'a str],
    /// The output may be the same file as an input (`sun B.prtb -o B.prtb`,
    /// the one documented in-place update).
    pub may_be_input: bool,
    /// An existing file is replaced only if it starts with these bytes
    /// (prtbake's own header), unless forced.
    pub own_marker: Option<&'a [u8]>,
}

impl<'a> Output<'a> {
    /// An output of one of `formats`, which must not be any input.
    pub fn new(path: &'a Path, formats: &'a [&'a str]) -> Output<'a> {
        Output { path, formats, may_be_input: false, own_marker: None }
    }
}

/// Why an output path is refused.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{}: this output is the input {}: refusing to overwrite an input (choose another output path)", path.display(), input.display())]
    IsInput { path: PathBuf, input: PathBuf },
    #[error("{}: named twice as an output (also as {}): each output needs its own file", path.display(), other.display())]
    Repeated { path: PathBuf, other: PathBuf },
    #[error("{}: unknown output format {extension:?}: expected {}", path.display(), expected.join(" or "))]
    Format { path: PathBuf, extension: String, expected: Vec<String> },
    #[error("{}: is a directory: name a file to write", path.display())]
    Directory { path: PathBuf },
    #[error("{}: exists and is {kind}: refusing to replace it with a regular file", path.display())]
    NotRegular { path: PathBuf, kind: &'static str },
    #[error("{}: cannot write here: {} {problem}", path.display(), dir.display())]
    NoDirectory { path: PathBuf, dir: PathBuf, problem: &'static str },
    #[error("{}: is read-only: refusing to replace it (--force replaces it)", path.display())]
    ReadOnly { path: PathBuf },
    #[error("{}: exists and was not written by prtbake: refusing to replace it (--force replaces it, or choose another output name)", path.display())]
    Foreign { path: PathBuf },
    #[error("{}: the file name is {length} bytes, more than the {max} its folder allows: choose a shorter name", path.display())]
    NameTooLong { path: PathBuf, length: usize, max: usize },
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
}

/// The longest file name the folder `dir` takes (NAME_MAX; 255 where it cannot be asked).
fn name_max(dir: &Path) -> usize {
    #[cfg(unix)]
    {
        if let Ok(c) = std::ffi::CString::new(dir.as_os_str().as_encoded_bytes()) {
            // SAFETY: a valid NUL-terminated path; pathconf only reads it.
            let max = unsafe { libc::pathconf(c.as_ptr(), libc::_PC_NAME_MAX) };
            if max > 0 {
                return max as usize;
            }
        }
    }
    let _ = dir;
    255
}

/// The file a write to `path` replaces: `path` itself, or the end of its chain
/// of symbolic links (which may not exist yet).
pub fn final_target(path: &Path) -> std::io::Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..MAX_LINK_HOPS {
        match std::fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let link = std::fs::read_link(&current)?;
                current = match current.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(current),
        }
    }
    Err(std::io::Error::other(format!("more than {MAX_LINK_HOPS} symbolic links")))
}

/// A file as the file system knows it: canonical path, and device and inode
/// when it exists.
#[derive(Debug, PartialEq)]
struct Identity {
    canonical: PathBuf,
    inode: Option<(u64, u64)>,
}

impl Identity {
    fn same_file(&self, other: &Identity) -> bool {
        self.canonical == other.canonical || (self.inode.is_some() && self.inode == other.inode)
    }
}

#[cfg(unix)]
fn inode(meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn inode(_: &std::fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// The identity of an existing input; `None` if it cannot be resolved (the
/// loader then reports the missing file).
fn input_identity(path: &Path) -> Option<Identity> {
    let canonical = std::fs::canonicalize(path).ok()?;
    let inode = std::fs::metadata(&canonical).ok().and_then(|m| inode(&m));
    Some(Identity { canonical, inode })
}

/// Checks one output's place and kind, and returns its identity.
fn check_one(output: &Output, force: bool) -> Result<Identity, OutputError> {
    let path = output.path;
    let owned = || path.to_path_buf();
    let text = path.as_os_str().as_encoded_bytes();
    if text.is_empty() || text.ends_with(b"/") || path.file_name().is_none() {
        return Err(OutputError::Directory { path: owned() });
    }
    let target = final_target(path).map_err(|source| OutputError::Io { path: owned(), source })?;
    let dir = target.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let no_directory = |problem| OutputError::NoDirectory { path: owned(), dir: dir.to_path_buf(), problem };
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => {}
        Ok(_) => return Err(no_directory("is not a directory")),
        Err(_) => return Err(no_directory("does not exist")),
    }
    // A name the file system refuses would fail only at the final rename,
    // after the work, and after other outputs had landed.
    let name = target.file_name().unwrap_or(path.as_os_str());
    let (length, max) = (name.as_encoded_bytes().len(), name_max(dir));
    if length > max {
        return Err(OutputError::NameTooLong { path: owned(), length, max });
    }
    let canonical_dir = std::fs::canonicalize(dir).map_err(|source| OutputError::Io { path: owned(), source })?;
    let canonical = canonical_dir.join(target.file_name().unwrap_or(path.as_os_str()));
    let meta = match std::fs::metadata(&target) {
        Ok(meta) => meta,
        Err(_) => return Ok(Identity { canonical, inode: None }),
    };
    if meta.is_dir() {
        return Err(OutputError::Directory { path: owned() });
    }
    if !meta.is_file() {
        return Err(OutputError::NotRegular { path: owned(), kind: super::read::kind_of(meta.file_type()) });
    }
    if !force && meta.permissions().readonly() {
        return Err(OutputError::ReadOnly { path: owned() });
    }
    if let Some(marker) = output.own_marker {
        let head = super::read::read_head(&target, super::Limit::Bundle, marker.len() as u64).unwrap_or_default();
        if !force && head != marker {
            return Err(OutputError::Foreign { path: owned() });
        }
    }
    Ok(Identity { canonical, inode: inode(&meta) })
}

/// Refuses an output whose extension does not name the format written.
fn check_format(output: &Output) -> Result<(), OutputError> {
    if output.formats.is_empty() {
        return Ok(());
    }
    let extension = output.path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if output.formats.contains(&extension.as_str()) {
        return Ok(());
    }
    let expected = output.formats.iter().map(|f| format!(".{f}")).collect();
    Err(OutputError::Format { path: output.path.to_path_buf(), extension, expected })
}

/// Checks every output of a command against its inputs and each other
/// (see the module docs). Call before any work, and again once the loader
/// has named the files it read besides the input (`.mtl`, glTF buffers).
pub fn check_outputs(inputs: &[&Path], outputs: &[Output], force: bool) -> Result<(), OutputError> {
    let input_ids: Vec<(PathBuf, Identity)> = inputs.iter().filter_map(|p| input_identity(p).map(|id| (p.to_path_buf(), id))).collect();
    let mut seen: Vec<(PathBuf, Identity)> = Vec::new();
    for output in outputs {
        let id = check_one(output, force)?;
        if !output.may_be_input {
            if let Some((input, _)) = input_ids.iter().find(|(_, i)| i.same_file(&id)) {
                return Err(OutputError::IsInput { path: output.path.to_path_buf(), input: input.clone() });
            }
        }
        if let Some((other, _)) = seen.iter().find(|(_, o)| o.same_file(&id)) {
            return Err(OutputError::Repeated { path: output.path.to_path_buf(), other: other.clone() });
        }
        check_format(output)?;
        seen.push((output.path.to_path_buf(), id));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const PRTB: &[&str] = &["prtb"];

    fn check(inputs: &[&Path], outputs: &[Output]) -> Result<(), OutputError> {
        check_outputs(inputs, outputs, false)
    }

    #[test]
    fn an_output_that_is_an_input_is_refused_by_any_name() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.prtb");
        std::fs::write(&input, "x").unwrap();
        let dotted = dir.path().join(".").join("in.prtb");
        let e = check(&[&input], &[Output::new(&dotted, PRTB)]).unwrap_err();
        assert!(matches!(e, OutputError::IsInput { .. }), "{e}");
        // A hard link is the same file under another name.
        let hard = dir.path().join("hard.prtb");
        std::fs::hard_link(&input, &hard).unwrap();
        assert!(matches!(check(&[&input], &[Output::new(&hard, PRTB)]), Err(OutputError::IsInput { .. })));
        // Unless the command documents the in-place update.
        let in_place = Output { may_be_input: true, ..Output::new(&input, PRTB) };
        check(&[&input], &[in_place]).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_to_an_input_is_the_input() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.prtb");
        std::fs::write(&input, "x").unwrap();
        let link = dir.path().join("link.prtb");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        assert!(matches!(check(&[&input], &[Output::new(&link, PRTB)]), Err(OutputError::IsInput { .. })));
        // A dangling link is written through: its target is the output.
        let dangling = dir.path().join("dangling.prtb");
        std::os::unix::fs::symlink("later.prtb", &dangling).unwrap();
        check(&[&input], &[Output::new(&dangling, PRTB)]).unwrap();
        assert_eq!(final_target(&dangling).unwrap(), dir.path().join("later.prtb"));
    }

    #[test]
    fn two_outputs_naming_one_file_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("c.obj");
        let outputs = [Output::new(&a, &["obj"]), Output::new(&a, &[])];
        assert!(matches!(check(&[], &outputs), Err(OutputError::Repeated { .. })));
    }

    #[test]
    fn extensions_must_name_the_format_written() {
        let dir = tempfile::tempdir().unwrap();
        let txt = dir.path().join("out.txt");
        let e = check(&[], &[Output::new(&txt, PRTB)]).unwrap_err();
        assert_eq!(e.to_string(), format!("{}: unknown output format \"txt\": expected .prtb", txt.display()));
        check(&[], &[Output::new(&dir.path().join("OUT.PRTB"), PRTB)]).unwrap();
    }

    #[test]
    fn directories_and_missing_folders_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("sub.prtb");
        std::fs::create_dir(&sub).unwrap();
        assert!(matches!(check(&[], &[Output::new(&sub, PRTB)]), Err(OutputError::Directory { .. })));
        let slash = PathBuf::from(format!("{}/", sub.display()));
        assert!(matches!(check(&[], &[Output::new(&slash, &[])]), Err(OutputError::Directory { .. })));
        let nowhere = dir.path().join("nodir").join("r.json");
        let e = check(&[], &[Output::new(&nowhere, &["json"])]).unwrap_err();
        assert!(e.to_string().ends_with("nodir does not exist"), "{e}");
        let file = dir.path().join("file");
        std::fs::write(&file, "").unwrap();
        let under_file = file.join("r.json");
        let e = check(&[], &[Output::new(&under_file, &["json"])]).unwrap_err();
        assert!(e.to_string().ends_with("file is not a directory"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_read_only_files_are_not_replaced() {
        let null = Path::new("/dev/null");
        let e = check(&[], &[Output::new(null, &[])]).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe.prtb");
        let name = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
        assert!(matches!(check(&[], &[Output::new(&fifo, PRTB)]), Err(OutputError::NotRegular { kind: "a FIFO", .. })));
        let read_only = dir.path().join("ro.prtb");
        std::fs::write(&read_only, "x").unwrap();
        let mut permissions = std::fs::metadata(&read_only).unwrap().permissions();
        permissions.set_readonly(true);
        std::fs::set_permissions(&read_only, permissions).unwrap();
        assert!(matches!(check(&[], &[Output::new(&read_only, PRTB)]), Err(OutputError::ReadOnly { .. })));
        check_outputs(&[], &[Output::new(&read_only, PRTB)], true).unwrap();
    }

    #[test]
    fn names_too_long_for_the_folder_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join(format!("{}.json", "r".repeat(251)));
        let e = check(&[], &[Output::new(&long, &["json"])]).unwrap_err();
        assert!(matches!(e, OutputError::NameTooLong { length: 256, max: 255, .. }), "{e}");
        check(&[], &[Output::new(&dir.path().join(format!("{}.json", "r".repeat(250))), &["json"])]).unwrap();
    }

    #[test]
    fn only_prtbake_files_are_replaced_where_a_marker_is_asked() {
        let dir = tempfile::tempdir().unwrap();
        let mtl = dir.path().join("c.mtl");
        let output = Output { own_marker: Some(b"# written by prtbake"), ..Output::new(&mtl, &["mtl"]) };
        check(&[], &[output]).unwrap();
        std::fs::write(&mtl, "# written by prtbake\nnewmtl a\n").unwrap();
        check(&[], &[output]).unwrap();
        std::fs::write(&mtl, "newmtl mine\nmap_Kd tex.png\n").unwrap();
        assert!(matches!(check(&[], &[output]), Err(OutputError::Foreign { .. })));
        check_outputs(&[], &[output], true).unwrap();
    }
}
