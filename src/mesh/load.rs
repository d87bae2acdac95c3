//! The single entry point for reading a mesh file: picks the loader by extension.

use std::path::Path;

use glam::Vec3;

use super::{gltf_load, obj, Mesh, MeshError};

/// Which axis of the file points up. prtbake's world is right-handed, +Y up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpAxis {
    /// The file is already +Y up (glTF always is).
    #[default]
    Y,
    /// The file is +Z up (common for CAD and scans): rotated by -90° about X,
    /// `(x, y, z) -> (x, z, -y)`, a proper rotation, so handedness and winding are kept.
    Z,
}

impl UpAxis {
    /// Maps a position or normal of a file with this up axis to prtbake's +Y-up frame.
    pub fn to_y_up(self, v: Vec3) -> Vec3 {
        match self {
            UpAxis::Y => v,
            UpAxis::Z => Vec3::new(v.x, v.z, -v.y),
        }
    }
}

/// How to interpret a mesh file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// Up axis of OBJ files (OBJ has no rule). Ignored for glTF, which is +Y up by spec.
    pub up: UpAxis,
}

/// A loaded mesh and the non-fatal problems met on the way (missing `.mtl`,
/// skipped point/line primitives, recomputed normals, ...), one sentence each,
/// for the caller to print.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedMesh {
    pub mesh: Mesh,
    pub warnings: Vec<String>,
    /// Files read besides the mesh file itself (`.mtl` libraries, glTF
    /// buffers), so a command can refuse to overwrite any of them.
    pub sources: Vec<std::path::PathBuf>,
}

/// Loads an `.obj`, `.gltf` or `.glb` file (extension, case-insensitive, decides)
/// into one flat, validated [`Mesh`] in a right-handed +Y-up world.
///
/// - Materials: OBJ `Kd` / glTF `baseColorFactor` RGB as albedo (0.8 grey when
///   absent); glTF materials with `KHR_materials_transmission` factor > 0 become
///   [`MaterialRole::Window`](super::MaterialRole::Window), all else `Opaque`.
///   Parts without a material share an appended `"default"` 0.8 grey material.
/// - Groups: OBJ object/group names, glTF mesh names (`"mesh<N>"` when unnamed).
/// - glTF: the default scene (else scene 0, else every root node) with node
///   transforms and instancing applied; triangle strips and fans converted.
/// - Normals: the file's, unit length; computed (area-and-angle weighted) where
///   absent, zero or non-finite.
///
/// Every failure is a [`MeshError`] naming the file: missing or unreadable
/// file, malformed content, unsupported required glTF extension, node cycle,
/// out-of-range index, NaN/infinite position, no triangles. Never panics.
pub fn load_mesh(path: &Path, options: &LoadOptions) -> Result<LoadedMesh, MeshError> {
    let extension = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !matches!(extension.as_str(), "obj" | "gltf" | "glb") {
        return Err(MeshError::UnsupportedFormat { path: path.to_path_buf(), extension });
    }
    let read_error = |source| MeshError::Read { path: path.to_path_buf(), source };
    let bytes = if extension == "obj" {
        crate::files::read_limited(path, crate::files::Limit::Mesh).map_err(read_error)?
    } else {
        // A GLB's header gives its length: checked against the file's before the rest is read.
        use super::gltf_buffers::{check_glb_head, is_glb, GLB_HEAD_LEN};
        let head = crate::files::read::read_head(path, crate::files::Limit::Mesh, GLB_HEAD_LEN as u64).map_err(read_error)?;
        let size = crate::files::read::check_regular(path, crate::files::Limit::Mesh).map_err(read_error)?;
        if is_glb(&head) {
            check_glb_head(&head, size).map_err(|e| MeshError::gltf(path, e))?;
        }
        crate::files::read::read_head(path, crate::files::Limit::Mesh, size).map_err(read_error)?
    };
    let (mut warnings, mut sources) = (Vec::new(), Vec::new());
    let mesh = match extension.as_str() {
        "obj" => obj::load_obj(path, &bytes, options.up, &mut warnings, &mut sources)?,
        _ => gltf_load::load_gltf(path, &bytes, &mut warnings, &mut sources)?,
    };
    Ok(LoadedMesh { mesh, warnings, sources })
}
