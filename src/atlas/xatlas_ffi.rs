//! The C API of the vendored xatlas (vendor/xatlas/xatlas_c.h), as much of
//! it as [`super::Atlas::unwrap`] and [`super::Atlas::with_chart_scales`] use. Layouts follow the header field by
//! field; the `*Init` functions fill the defaults.

#![allow(non_snake_case)]

use std::ffi::c_void;

#[repr(C)]
pub struct Chart {
    pub faceArray: *mut u32,
    pub atlasIndex: u32,
    pub faceCount: u32,
    pub chart_type: i32,
    pub material: u32,
}

#[repr(C)]
pub struct Vertex {
    /// −1 when the vertex is in no atlas (a face xatlas ignored).
    pub atlasIndex: i32,
    pub chartIndex: i32,
    pub uv: [f32; 2],
    pub xref: u32,
}

#[repr(C)]
pub struct Mesh {
    pub chartArray: *mut Chart,
    pub indexArray: *mut u32,
    pub vertexArray: *mut Vertex,
    pub chartCount: u32,
    pub indexCount: u32,
    pub vertexCount: u32,
}

#[repr(C)]
pub struct Atlas {
    pub image: *mut u32,
    pub meshes: *mut Mesh,
    pub utilization: *mut f32,
    pub width: u32,
    pub height: u32,
    pub atlasCount: u32,
    pub chartCount: u32,
    pub meshCount: u32,
    pub texelsPerUnit: f32,
}

pub const INDEX_FORMAT_UINT32: i32 = 1;

#[repr(C)]
pub struct MeshDecl {
    pub vertexPositionData: *const c_void,
    pub vertexNormalData: *const c_void,
    pub vertexUvData: *const c_void,
    pub indexData: *const c_void,
    pub faceIgnoreData: *const bool,
    pub faceMaterialData: *const u32,
    pub faceVertexCount: *const u8,
    pub vertexCount: u32,
    pub vertexPositionStride: u32,
    pub vertexNormalStride: u32,
    pub vertexUvStride: u32,
    pub indexCount: u32,
    pub indexOffset: i32,
    pub faceCount: u32,
    pub indexFormat: i32,
    pub epsilon: f32,
}

#[repr(C)]
pub struct UvMeshDecl {
    pub vertexUvData: *const c_void,
    pub indexData: *const c_void,
    /// Faces of different materials never share a chart.
    pub faceMaterialData: *const u32,
    pub vertexCount: u32,
    pub vertexStride: u32,
    pub indexCount: u32,
    pub indexOffset: i32,
    pub indexFormat: i32,
}

#[repr(C)]
pub struct ChartOptions {
    pub paramFunc: Option<unsafe extern "C" fn(*const f32, *mut f32, u32, *const u32, u32)>,
    pub maxChartArea: f32,
    pub maxBoundaryLength: f32,
    pub normalDeviationWeight: f32,
    pub roundnessWeight: f32,
    pub straightnessWeight: f32,
    pub normalSeamWeight: f32,
    pub textureSeamWeight: f32,
    pub maxCost: f32,
    pub maxIterations: u32,
    pub useInputMeshUvs: bool,
    pub fixWinding: bool,
}

#[repr(C)]
pub struct PackOptions {
    pub maxChartSize: u32,
    pub padding: u32,
    pub texelsPerUnit: f32,
    pub resolution: u32,
    pub bilinear: bool,
    pub blockAlign: bool,
    pub bruteForce: bool,
    pub createImage: bool,
    pub rotateChartsToAxis: bool,
    pub rotateCharts: bool,
}

pub const ADD_MESH_SUCCESS: i32 = 0;

extern "C" {
    pub fn xatlasCreate() -> *mut Atlas;
    pub fn xatlasDestroy(atlas: *mut Atlas);
    pub fn xatlasAddMesh(atlas: *mut Atlas, decl: *const MeshDecl, mesh_count_hint: u32) -> i32;
    pub fn xatlasAddUvMesh(atlas: *mut Atlas, decl: *const UvMeshDecl) -> i32;
    pub fn xatlasComputeCharts(atlas: *mut Atlas, chart_options: *const ChartOptions);
    pub fn xatlasPackCharts(atlas: *mut Atlas, pack_options: *const PackOptions);
    pub fn xatlasUvMeshDeclInit(decl: *mut UvMeshDecl);
    pub fn xatlasGenerate(atlas: *mut Atlas, chart_options: *const ChartOptions, pack_options: *const PackOptions);
    pub fn xatlasMeshDeclInit(decl: *mut MeshDecl);
    pub fn xatlasChartOptionsInit(options: *mut ChartOptions);
    pub fn xatlasPackOptionsInit(options: *mut PackOptions);
    pub fn xatlasAddMeshErrorString(error: i32) -> *const std::ffi::c_char;
}

/// xatlas's default chart options.
pub fn chart_options() -> ChartOptions {
    let mut options = std::mem::MaybeUninit::<ChartOptions>::uninit();
    // SAFETY: the Init function writes every field.
    unsafe {
        xatlasChartOptionsInit(options.as_mut_ptr());
        options.assume_init()
    }
}

/// Packing into one texture however large, `texels_per_unit`, charts
/// `padding` texels apart with room for bilinear reads.
pub fn pack_options(texels_per_unit: f32, padding: u32) -> PackOptions {
    let mut options = std::mem::MaybeUninit::<PackOptions>::uninit();
    // SAFETY: the Init function writes every field.
    let mut options = unsafe {
        xatlasPackOptionsInit(options.as_mut_ptr());
        options.assume_init()
    };
    options.texelsPerUnit = texels_per_unit;
    options.padding = padding;
    options.bilinear = true;
    options.resolution = 0;
    options.maxChartSize = 0;
    options
}

/// xatlas's words for an AddMesh or AddUvMesh `error`; the atlas is
/// destroyed when it is one.
///
/// # Safety
/// `handle` is a live atlas from [`xatlasCreate`].
pub unsafe fn check_added(handle: *mut Atlas, error: i32) -> Result<(), String> {
    if error == ADD_MESH_SUCCESS {
        return Ok(());
    }
    let text = std::ffi::CStr::from_ptr(xatlasAddMeshErrorString(error)).to_string_lossy().into_owned();
    xatlasDestroy(handle);
    Err(text)
}
