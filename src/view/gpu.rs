//! The GPU side: device, the scene's buffers, five pipelines and one frame's
//! passes.
//!
//! A frame is: (1) the scene pass into an `Rgba16Float` HDR target with a
//! `Depth32Float` depth buffer: the opaque draws with per-vertex PRT shading
//! (shading.wgsl), drawn two-sided (industrial meshes have inconsistent
//! winding); then the backdrop, a full-screen triangle at the far plane that
//! fills what no geometry covers with the env map or the sky (backdrop.wgsl);
//! then the window glass, which lowers the pixel's alpha to its transmittance
//! (min blend, no depth write); (2) for the adaptive operators, a
//! one-workgroup compute pass over a 128×128 grid of the HDR target that
//! updates the adapted luminance in a small storage buffer (luminance.wgsl);
//! (3) a full-screen pass that tone-maps `rgb · alpha` into the output
//! (tonemap.wgsl). Per frame the CPU writes only the frame uniform (camera,
//! lighting SH, sun), the backdrop uniform and two tiny parameter blocks.

use wgpu::util::DeviceExt;

use super::backdrop;
use super::camera::Camera;
use super::panel::PanelTexture;
use super::scene::{DrawKind, MaterialDraw, PreparedScene, GPU_VERTEX_BYTES};
use super::tonemap::{ADAPT_TAU_BRIGHTEN_S, ADAPT_TAU_DARKEN_S};
use super::{FrameSettings, ViewError};
use crate::bundle::SunSeries;

/// Format of the HDR target.
pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// Format of the depth buffer.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Lighting coefficients the frame uniform holds (order 16).
const MAX_COEFFS: usize = 256;
/// Frame uniform: mat4 + 3 vec4 + 256 vec4.
const FRAME_BYTES: usize = 64 + 4 * 16 + MAX_COEFFS * 16;

/// An adapter, its device and queue.
pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// Any adapter, no window system: a hardware one if present, else a
    /// software one (Mesa's lavapipe). [`ViewError::NoAdapter`] when there is none.
    pub fn headless() -> Result<Gpu, ViewError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
        let adapter = [false, true]
            .into_iter()
            .find_map(|force_fallback_adapter| {
                let options = wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter,
                    compatible_surface: None,
                    ..Default::default()
                };
                pollster::block_on(instance.request_adapter(&options)).ok()
            })
            .ok_or(ViewError::NoAdapter)?;
        Gpu::with_adapter(instance, adapter)
    }

    /// Opens the device of `adapter` with every limit the adapter supports
    /// (large meshes need big storage buffers).
    pub fn with_adapter(instance: wgpu::Instance, adapter: wgpu::Adapter) -> Result<Gpu, ViewError> {
        let descriptor = wgpu::DeviceDescriptor { label: Some("prtbake"), required_limits: adapter.limits(), ..Default::default() };
        let (device, queue) = pollster::block_on(adapter.request_device(&descriptor)).map_err(|e| ViewError::Device(e.to_string()))?;
        Ok(Gpu { instance, adapter, device, queue })
    }

    /// "name (backend, device type)" of the adapter.
    pub fn adapter_name(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }
}

/// GPU memory the renderer allocated, in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct GpuMemory {
    /// Vertex, index, transfer, mask and uniform buffers (and the panel's texture coordinates).
    pub buffers: u64,
    /// The environment map texture drawn as the backdrop (16 B per texel).
    pub environment: u64,
    /// Of which the transfer storage buffer.
    pub transfer: u64,
    /// HDR colour target and depth buffer (not the output image).
    pub targets: u64,
}

/// Size-dependent targets and the bind groups that read them.
struct Targets {
    width: u32,
    height: u32,
    /// Linear radiance of the frame before tone mapping (read back for linear screenshots).
    hdr: wgpu::Texture,
    hdr_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    luminance_bind: wgpu::BindGroup,
    tonemap_bind: wgpu::BindGroup,
}

/// The panel's pipeline, texture coordinates and texture (scenes with a panel).
struct PanelGpu {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    texcoords: wgpu::Buffer,
    /// The texture and its bind group; `None` draws the panel PRT-shaded only.
    texture: Option<(wgpu::Texture, wgpu::BindGroup)>,
}

/// Texel mode's pipeline, atlas coordinates and irradiance texture, and the
/// texels the texture is recomputed from each frame's lighting.
struct LightmapGpu {
    pipeline: wgpu::RenderPipeline,
    texcoords: wgpu::Buffer,
    texture: wgpu::Texture,
    /// The sunlit shares on the sun's own atlas (R32Float; 1 × 1 without one).
    sun_texture: wgpu::Texture,
    /// The step whose shares `sun_texture` holds (outer `None`: not written
    /// yet): the texture, millions of texels, changes with the step only.
    sun_texture_step: std::cell::Cell<Option<Option<usize>>>,
    bind: wgpu::BindGroup,
    scene: super::scene::LightmapScene,
}

/// Draws a prepared scene: pipelines, buffers and targets.
pub struct Renderer {
    panel: Option<PanelGpu>,
    lightmap: Option<LightmapGpu>,
    scene_pipeline: wgpu::RenderPipeline,
    glass_pipeline: wgpu::RenderPipeline,
    backdrop_pipeline: wgpu::RenderPipeline,
    backdrop_bind: wgpu::BindGroup,
    backdrop_buffer: wgpu::Buffer,
    /// Size of the uploaded environment map (1×1 placeholder without one).
    env_size: (u32, u32),
    draws: Vec<MaterialDraw>,
    luminance_pipeline: wgpu::ComputePipeline,
    tonemap_pipeline: wgpu::RenderPipeline,
    luminance_layout: wgpu::BindGroupLayout,
    tonemap_layout: wgpu::BindGroupLayout,
    scene_bind: wgpu::BindGroup,
    frame_buffer: wgpu::Buffer,
    vertex_buffer: wgpu::Buffer,
    index_buffer: wgpu::Buffer,
    transfer_buffer: wgpu::Buffer,
    mask_buffer: wgpu::Buffer,
    /// Per bundle vertex its front-side share (a 16-byte placeholder without).
    share_buffer: wgpu::Buffer,
    /// Whether the bundle has side shares (frame `eye.w`).
    has_shares: bool,
    adapt_state: wgpu::Buffer,
    adapt_params: wgpu::Buffer,
    tone_buffer: wgpu::Buffer,
    targets: Targets,
    order: u32,
    channels: u32,
    words_per_vertex: u32,
    srgb_output: bool,
}

fn buffer_entry(binding: u32, visibility: wgpu::ShaderStages, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    }
}

fn hdr_texture_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// Little-endian bytes of 32-bit words (f32 as bits).
fn words_to_bytes(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

impl Renderer {
    /// Uploads `scene` and builds the pipelines for an output of `output_format`
    /// at `width × height` (each ≥ 1).
    ///
    /// Errors when a buffer exceeds the device's limits (the message says
    /// which), when the device runs out of memory, or on a validation error.
    pub fn new(
        gpu: &Gpu,
        scene: &PreparedScene,
        output_format: wgpu::TextureFormat,
        width: u32,
        height: u32,
    ) -> Result<Renderer, ViewError> {
        // Capture errors instead of letting wgpu's default handler panic.
        let out_of_memory = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let renderer = Self::build(gpu, scene, output_format, width, height);
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(out_of_memory.pop())];
        match errors.into_iter().flatten().next() {
            Some(error) => Err(ViewError::Gpu(error.to_string())),
            None => renderer,
        }
    }

    fn build(gpu: &Gpu, scene: &PreparedScene, output_format: wgpu::TextureFormat, width: u32, height: u32) -> Result<Renderer, ViewError> {
        let device = &gpu.device;
        let limits = device.limits();
        let transfer_bytes = scene.transfer.len() as u64 * 4;
        if transfer_bytes > limits.max_storage_buffer_binding_size || transfer_bytes > limits.max_buffer_size {
            return Err(ViewError::Gpu(format!(
                "the transfer needs a {transfer_bytes}-byte storage buffer; this device allows {} (choose a lower order or fewer channels)",
                limits.max_storage_buffer_binding_size
            )));
        }
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            // Zero-sized bindings are invalid: keep at least 16 bytes.
            let mut bytes = contents.to_vec();
            bytes.resize(bytes.len().max(16), 0);
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents: &bytes, usage })
        };
        let mut vertex_bytes = Vec::with_capacity(scene.vertices.len() * GPU_VERTEX_BYTES);
        scene.vertices.iter().for_each(|v| v.write_to(&mut vertex_bytes));
        let vertex_buffer = init("vertices", &vertex_bytes, wgpu::BufferUsages::VERTEX);
        let index_buffer = init("indices", &words_to_bytes(&scene.indices), wgpu::BufferUsages::INDEX);
        let transfer_words: Vec<u32> = scene.transfer.iter().map(|x| x.to_bits()).collect();
        let transfer_buffer =
            init("transfer", &words_to_bytes(&transfer_words), wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        let mask_buffer = init("sun masks", &words_to_bytes(&scene.masks), wgpu::BufferUsages::STORAGE);
        let share_words: Vec<u32> = scene.front_share.iter().map(|x| x.to_bits()).collect();
        let share_buffer = init("side shares", &words_to_bytes(&share_words), wgpu::BufferUsages::STORAGE);
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame"),
            size: FRAME_BYTES as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let small = |label: &str, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 48,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let adapt_state = small("adaptation", wgpu::BufferUsages::STORAGE);
        let adapt_params = small("adaptation parameters", wgpu::BufferUsages::UNIFORM);
        let tone_buffer = small("tone", wgpu::BufferUsages::UNIFORM);

        // Scene pipeline.
        let vs_fs = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let scene_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("scene"),
            entries: &[
                buffer_entry(0, vs_fs, wgpu::BufferBindingType::Uniform),
                buffer_entry(1, wgpu::ShaderStages::VERTEX, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer_entry(2, wgpu::ShaderStages::VERTEX, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer_entry(3, wgpu::ShaderStages::VERTEX, wgpu::BufferBindingType::Storage { read_only: true }),
            ],
        });
        let scene_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("scene"),
            layout: &scene_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: frame_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: transfer_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: mask_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: share_buffer.as_entire_binding() },
            ],
        });
        let shading = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("shading.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shading.wgsl").into()),
        });
        let scene_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("scene"),
            bind_group_layouts: &[Some(&scene_layout)],
            immediate_size: 0,
        });
        let vertex_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3, 3 => Uint32];
        let vertex_layout = [Some(wgpu::VertexBufferLayout {
            array_stride: GPU_VERTEX_BYTES as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &vertex_attributes,
        })];
        // Every pass of the scene: same targets, its own shaders, depth rule and blend.
        let hdr_pipeline = |label: &str,
                            layout: &wgpu::PipelineLayout,
                            module: &wgpu::ShaderModule,
                            entry_points: (&str, &str),
                            buffers: &[Option<wgpu::VertexBufferLayout>],
                            depth: (bool, wgpu::CompareFunction),
                            target: wgpu::ColorTargetState| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                vertex: wgpu::VertexState { module, entry_point: Some(entry_points.0), compilation_options: Default::default(), buffers },
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(depth.0),
                    depth_compare: Some(depth.1),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some(entry_points.1),
                    compilation_options: Default::default(),
                    targets: &[Some(target)],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let opaque = (true, wgpu::CompareFunction::Less);
        let scene_pipeline =
            hdr_pipeline("scene", &scene_pipeline_layout, &shading, ("vs_main", "fs_main"), &vertex_layout, opaque, HDR_FORMAT.into());
        // A textured variant of the scene's shading (same bindings in group 0): a texture
        // in group 1 and texture coordinates in vertex buffer 1 (the panel, texel mode).
        // `texcoord_floats`: 2 (one atlas position) or 4 (the lightmap's two).
        let textured = |label: &str, source: String, entry_points: (&str, &str), textures: u32, texcoord_floats: u64| {
            let entries: Vec<_> = (0..textures).map(|b| hdr_texture_entry(b, wgpu::ShaderStages::FRAGMENT)).collect();
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
            let module = device
                .create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(source.into()) });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(&scene_layout), Some(&layout)],
                immediate_size: 0,
            });
            let texcoord_attributes =
                if texcoord_floats == 4 { wgpu::vertex_attr_array![4 => Float32x4] } else { wgpu::vertex_attr_array![4 => Float32x2] };
            let buffers = [
                vertex_layout[0].clone(),
                Some(wgpu::VertexBufferLayout {
                    array_stride: 4 * texcoord_floats,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &texcoord_attributes,
                }),
            ];
            (hdr_pipeline(label, &pipeline_layout, &module, entry_points, &buffers, opaque, HDR_FORMAT.into()), layout)
        };
        let panel = scene.panel.as_ref().map(|draws| {
            let source = concat!(include_str!("shading.wgsl"), include_str!("panel.wgsl")).to_string();
            let (pipeline, layout) = textured("panel", source, ("vs_panel", "fs_panel"), 1, 2);
            let texcoord_words: Vec<u32> = draws.texcoords.iter().flatten().map(|x| x.to_bits()).collect();
            let texcoords = init("panel texture coordinates", &words_to_bytes(&texcoord_words), wgpu::BufferUsages::VERTEX);
            let mut panel = PanelGpu { pipeline, layout, texcoords, texture: None };
            if let Some(texture) = &draws.texture {
                panel.set_texture(gpu, texture);
            }
            panel
        });
        // Texel mode: the opaque draws read a texture of the texels' irradiance (group 1) at atlas coordinates (buffer 1).
        let lightmap = match &scene.lightmap {
            None => None,
            Some(lm) => {
                if lm.width > limits.max_texture_dimension_2d || lm.height > limits.max_texture_dimension_2d {
                    return Err(ViewError::Gpu(format!(
                        "the atlas is {} × {} texels; this device's textures reach {} (bake with a larger --texel-size)",
                        lm.width, lm.height, limits.max_texture_dimension_2d
                    )));
                }
                // Whether the texels carry their own sun bits and sky light, as constants of the shader.
                let source = format!(
                    "{}{}const TEXEL_SUN: bool = {};\nconst TEXEL_SKY: bool = {};\nconst TEXEL_SIDES: bool = {};\nconst SUN_ATLAS: bool = {};\n",
                    include_str!("shading.wgsl"),
                    include_str!("lightmap.wgsl"),
                    lm.has_sun_bits(),
                    lm.has_sky(),
                    lm.has_side_shares(),
                    lm.sun_atlas.is_some()
                );
                if let Some(own) = &lm.sun_atlas {
                    if own.width > limits.max_texture_dimension_2d || own.height > limits.max_texture_dimension_2d {
                        return Err(ViewError::Gpu(format!(
                            "the sun's atlas is {} × {} texels; this device's textures reach {} (bake the sun with a larger --texel-size)",
                            own.width, own.height, limits.max_texture_dimension_2d
                        )));
                    }
                }
                let (pipeline, layout) = textured("lightmap", source, ("vs_lightmap", "fs_lightmap"), 3, 4);
                let texcoord_words: Vec<u32> = lm.texcoords.iter().flatten().map(|x| x.to_bits()).collect();
                let texcoords = init("lightmap texture coordinates", &words_to_bytes(&texcoord_words), wgpu::BufferUsages::VERTEX);
                let size = wgpu::Extent3d { width: lm.width, height: lm.height, depth_or_array_layers: 1 };
                // The texels' front shares do not change with the lighting: written once.
                let share_size = if lm.has_side_shares() { size } else { wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 } };
                let shares = read_texture(device, "texel side shares", share_size, wgpu::TextureFormat::R32Float);
                let share_image = if lm.has_side_shares() { lm.side_share_image() } else { vec![1.0] };
                let share_words: Vec<u32> = share_image.iter().map(|x| x.to_bits()).collect();
                gpu.queue.write_texture(
                    shares.as_image_copy(),
                    &words_to_bytes(&share_words),
                    wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(4 * share_size.width),
                        rows_per_image: Some(share_size.height),
                    },
                    share_size,
                );
                let share_view = shares.create_view(&Default::default());
                let sun_size = lm.sun_atlas.as_ref().map_or(wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 }, |own| {
                    wgpu::Extent3d { width: own.width, height: own.height, depth_or_array_layers: 1 }
                });
                let sun_texture = read_texture(device, "sun texels", sun_size, wgpu::TextureFormat::R32Float);
                let sun_view = sun_texture.create_view(&Default::default());
                let (texture, bind) = rgba32f_texture(device, &layout, "lightmap", size, &[&share_view, &sun_view]);
                let sun_texture_step = std::cell::Cell::new(None);
                Some(LightmapGpu { pipeline, texcoords, texture, sun_texture, sun_texture_step, bind, scene: lm.clone() })
            }
        };
        // Glass: alpha ← min(alpha, τ); colour untouched.
        let min = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::One,
            operation: wgpu::BlendOperation::Min,
        };
        let glass_target = wgpu::ColorTargetState {
            format: HDR_FORMAT,
            blend: Some(wgpu::BlendState { color: min, alpha: min }),
            write_mask: wgpu::ColorWrites::ALPHA,
        };
        let behind_nothing = (false, wgpu::CompareFunction::Less);
        let glass_pipeline =
            hdr_pipeline("glass", &scene_pipeline_layout, &shading, ("vs_glass", "fs_glass"), &vertex_layout, behind_nothing, glass_target);

        // Backdrop: its uniform and the environment map (full resolution, f32, loaded texel by texel).
        let backdrop_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("backdrop"),
            entries: &[buffer_entry(0, vs_fs, wgpu::BufferBindingType::Uniform), hdr_texture_entry(1, wgpu::ShaderStages::FRAGMENT)],
        });
        let backdrop_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("backdrop"),
            size: backdrop::UNIFORM_BYTES,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let placeholder = crate::sh::EquirectImage { width: 1, height: 1, rgb: vec![[0.0; 3]] };
        let environment = match &scene.environment {
            Some(image) => backdrop::fit_to_texture(image, limits.max_texture_dimension_2d),
            None => std::borrow::Cow::Borrowed(&placeholder),
        };
        let env_size = (environment.width, environment.height);
        let env_texels: Vec<u32> = environment.rgb.iter().flat_map(|p| [p[0], p[1], p[2], 1.0]).map(f32::to_bits).collect();
        let env_texture = device.create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("environment"),
                size: wgpu::Extent3d { width: env_size.0, height: env_size.1, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            &words_to_bytes(&env_texels),
        );
        let env_view = env_texture.create_view(&Default::default());
        let backdrop_bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("backdrop"),
            layout: &backdrop_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: backdrop_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&env_view) },
            ],
        });
        let backdrop_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("backdrop.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("backdrop.wgsl").into()),
        });
        let backdrop_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("backdrop"),
            bind_group_layouts: &[Some(&backdrop_layout)],
            immediate_size: 0,
        });
        // At the far plane, where the depth buffer is still clear: only what no geometry covers.
        let at_far_plane = (false, wgpu::CompareFunction::LessEqual);
        let backdrop_pipeline = hdr_pipeline(
            "backdrop",
            &backdrop_pipeline_layout,
            &backdrop_module,
            ("vs_backdrop", "fs_backdrop"),
            &[],
            at_far_plane,
            HDR_FORMAT.into(),
        );

        // Luminance (compute) pipeline.
        let luminance_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("luminance"),
            entries: &[
                hdr_texture_entry(0, wgpu::ShaderStages::COMPUTE),
                buffer_entry(1, wgpu::ShaderStages::COMPUTE, wgpu::BufferBindingType::Storage { read_only: false }),
                buffer_entry(2, wgpu::ShaderStages::COMPUTE, wgpu::BufferBindingType::Uniform),
            ],
        });
        let luminance_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("luminance.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("luminance.wgsl").into()),
        });
        let luminance_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("luminance"),
            layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("luminance"),
                bind_group_layouts: &[Some(&luminance_layout)],
                immediate_size: 0,
            })),
            module: &luminance_module,
            entry_point: Some("cs_luminance"),
            compilation_options: Default::default(),
            cache: None,
        });

        // Tone-mapping pipeline.
        let tonemap_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("tonemap"),
            entries: &[
                hdr_texture_entry(0, wgpu::ShaderStages::FRAGMENT),
                buffer_entry(1, wgpu::ShaderStages::FRAGMENT, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer_entry(2, wgpu::ShaderStages::FRAGMENT, wgpu::BufferBindingType::Uniform),
            ],
        });
        let tonemap_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("tonemap.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("tonemap.wgsl").into()),
        });
        let tonemap_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("tonemap"),
            layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("tonemap"),
                bind_group_layouts: &[Some(&tonemap_layout)],
                immediate_size: 0,
            })),
            vertex: wgpu::VertexState {
                module: &tonemap_module,
                entry_point: Some("vs_fullscreen"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &tonemap_module,
                entry_point: Some("fs_tonemap"),
                compilation_options: Default::default(),
                targets: &[Some(output_format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });

        let targets =
            Self::create_targets(device, &luminance_layout, &tonemap_layout, &adapt_state, &adapt_params, &tone_buffer, width, height);
        Ok(Renderer {
            panel,
            lightmap,
            scene_pipeline,
            luminance_pipeline,
            tonemap_pipeline,
            luminance_layout,
            tonemap_layout,
            scene_bind,
            frame_buffer,
            vertex_buffer,
            index_buffer,
            transfer_buffer,
            mask_buffer,
            share_buffer,
            has_shares: !scene.front_share.is_empty(),
            adapt_state,
            adapt_params,
            tone_buffer,
            targets,
            glass_pipeline,
            backdrop_pipeline,
            backdrop_bind,
            backdrop_buffer,
            env_size,
            draws: scene.draws.clone(),
            order: scene.order,
            channels: scene.channels,
            words_per_vertex: scene.words_per_vertex,
            srgb_output: output_format.is_srgb(),
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn create_targets(
        device: &wgpu::Device,
        luminance_layout: &wgpu::BindGroupLayout,
        tonemap_layout: &wgpu::BindGroupLayout,
        adapt_state: &wgpu::Buffer,
        adapt_params: &wgpu::Buffer,
        tone_buffer: &wgpu::Buffer,
        width: u32,
        height: u32,
    ) -> Targets {
        let (width, height) = (width.max(1), height.max(1));
        let texture = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let hdr = texture(
            "hdr",
            HDR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        let hdr_view = hdr.create_view(&Default::default());
        let depth_view = texture("depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT).create_view(&Default::default());
        let bind = |label: &str, layout: &wgpu::BindGroupLayout, second: &wgpu::Buffer, third: &wgpu::Buffer| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&hdr_view) },
                    wgpu::BindGroupEntry { binding: 1, resource: second.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: third.as_entire_binding() },
                ],
            })
        };
        let luminance_bind = bind("luminance", luminance_layout, adapt_state, adapt_params);
        let tonemap_bind = bind("tonemap", tonemap_layout, adapt_state, tone_buffer);
        Targets { width, height, hdr, hdr_view, depth_view, luminance_bind, tonemap_bind }
    }

    /// The linear (pre-tone-mapping) frame target, `HDR_FORMAT`.
    pub fn hdr_texture(&self) -> &wgpu::Texture {
        &self.targets.hdr
    }

    /// Recreates the HDR and depth targets for a new output size.
    pub fn resize(&mut self, gpu: &Gpu, width: u32, height: u32) {
        if (width.max(1), height.max(1)) != (self.targets.width, self.targets.height) {
            self.targets = Self::create_targets(
                &gpu.device,
                &self.luminance_layout,
                &self.tonemap_layout,
                &self.adapt_state,
                &self.adapt_params,
                &self.tone_buffer,
                width,
                height,
            );
        }
    }

    /// Replaces the shaded transfer (after a layer toggle); `values` must have
    /// the length of the uploaded one.
    pub fn set_transfer(&self, gpu: &Gpu, values: &[f32]) -> Result<(), ViewError> {
        let bytes = words_to_bytes(&values.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        if bytes.len() as u64 > self.transfer_buffer.size() {
            return Err(ViewError::Invalid(format!("{} transfer bytes for a {}-byte buffer", bytes.len(), self.transfer_buffer.size())));
        }
        gpu.queue.write_buffer(&self.transfer_buffer, 0, &bytes);
        Ok(())
    }

    /// Draws the panel with `texture` (same size: written in place), or PRT-shaded only with `None`.
    /// Does nothing for a scene without a panel.
    pub fn set_panel_texture(&mut self, gpu: &Gpu, texture: Option<&PanelTexture>) {
        if let Some(panel) = &mut self.panel {
            match texture {
                Some(texture) => panel.set_texture(gpu, texture),
                None => panel.texture = None,
            }
        }
    }

    /// Memory held by the renderer's buffers and targets.
    pub fn memory(&self) -> GpuMemory {
        let buffers = [
            &self.vertex_buffer,
            &self.index_buffer,
            &self.transfer_buffer,
            &self.mask_buffer,
            &self.share_buffer,
            &self.frame_buffer,
            &self.adapt_state,
            &self.adapt_params,
            &self.tone_buffer,
            &self.backdrop_buffer,
        ]
        .iter()
        .map(|b| b.size())
        .sum::<u64>()
            + self.panel.as_ref().map_or(0, |p| p.texcoords.size())
            + self.lightmap.as_ref().map_or(0, |l| {
                let texels = l.scene.width as u64 * l.scene.height as u64;
                let sun_texels = l.scene.sun_atlas.as_ref().map_or(1, |own| own.width as u64 * own.height as u64);
                l.texcoords.size() + 16 * texels + if l.scene.has_side_shares() { 4 * texels } else { 4 } + 4 * sun_texels
            });
        let pixels = self.targets.width as u64 * self.targets.height as u64;
        let environment = self.env_size.0 as u64 * self.env_size.1 as u64 * 16;
        GpuMemory { buffers, environment, transfer: self.transfer_buffer.size(), targets: pixels * (8 + 4) }
    }

    /// The frame uniform's bytes for `camera`, `settings` and the sun series.
    fn frame_bytes(&self, camera: &Camera, settings: &FrameSettings, sun: Option<&SunSeries>) -> Vec<u8> {
        let aspect = self.targets.width as f32 / self.targets.height as f32;
        let mut words: Vec<u32> = camera.view_proj(aspect).to_cols_array().iter().map(|x| x.to_bits()).collect();
        let step = settings.sun_step.and_then(|k| sun.and_then(|s| s.steps.get(k)).map(|s| (k, s)));
        let (direction, rgb, on, k) = match step {
            Some((k, s)) if self.words_per_vertex > 0 => (s.direction, s.sun_rgb, 1.0, k as u32),
            _ => ([0.0; 3], [0.0; 3], 0.0, 0),
        };
        words.extend([direction[0], direction[1], direction[2], 0.0].map(f32::to_bits));
        words.extend([rgb[0], rgb[1], rgb[2], on].map(f32::to_bits));
        words.extend([self.order * self.order, self.channels, self.words_per_vertex, k]);
        words.extend([camera.eye.x, camera.eye.y, camera.eye.z, if self.has_shares { 1.0 } else { 0.0 }].map(f32::to_bits));
        let n2 = (self.order * self.order) as usize;
        for i in 0..MAX_COEFFS {
            let c = if i < n2 { settings.lighting.get(i).copied().unwrap_or([0.0; 3]) } else { [0.0; 3] };
            words.extend([c[0], c[1], c[2], 0.0].map(f32::to_bits));
        }
        words_to_bytes(&words)
    }

    /// Renders one frame into `target` (a view of a texture of the renderer's
    /// size and output format) and submits it.
    ///
    /// `dt` is the time since the previous frame (seconds) for the temporal
    /// adaptation; `reset_adaptation` jumps straight to the current frame's
    /// luminance (first frame, screenshots).
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        &self,
        gpu: &Gpu,
        target: &wgpu::TextureView,
        camera: &Camera,
        settings: &FrameSettings,
        sun: Option<&SunSeries>,
        dt: f32,
        reset_adaptation: bool,
    ) -> wgpu::SubmissionIndex {
        let queue = &gpu.queue;
        queue.write_buffer(&self.frame_buffer, 0, &self.frame_bytes(camera, settings, sun));
        let aspect = self.targets.width as f32 / self.targets.height as f32;
        let backdrop_words = backdrop::uniform_words(&settings.backdrop, self.env_size, camera.ray_basis(aspect));
        queue.write_buffer(&self.backdrop_buffer, 0, &words_to_bytes(&backdrop_words));
        let t = &settings.tonemap;
        let mode = match t.operator {
            super::ToneOperator::Linear => 0u32,
            super::ToneOperator::Drago => 1,
            super::ToneOperator::Photographic => 2,
        };
        let mut tone = vec![t.exposure_stops.exp2().to_bits(), t.gamma.to_bits(), mode, self.srgb_output as u32];
        tone.extend([t.bias, t.display_max, 0.0, 0.0].map(f32::to_bits));
        queue.write_buffer(&self.tone_buffer, 0, &words_to_bytes(&tone));
        let adapt = [dt.max(0.0).to_bits(), ADAPT_TAU_BRIGHTEN_S.to_bits(), ADAPT_TAU_DARKEN_S.to_bits(), reset_adaptation as u32];
        queue.write_buffer(&self.adapt_params, 0, &words_to_bytes(&adapt));

        if let Some(lm) = &self.lightmap {
            let step = settings.sun_step.filter(|&k| sun.is_some_and(|s| k < s.steps.len()) && self.words_per_vertex > 0);
            let image = lm.scene.irradiance(self.order, self.channels, &settings.lighting, step);
            let words: Vec<u32> = image.iter().flatten().map(|x| x.to_bits()).collect();
            write_rgba32f(queue, &lm.texture, &words);
            if lm.scene.sun_atlas.is_some() && lm.sun_texture_step.get() != Some(step) {
                lm.sun_texture_step.set(Some(step));
                let shares: Vec<u32> = lm.scene.own_atlas_sun(step).iter().map(|x| x.to_bits()).collect();
                let size = lm.sun_texture.size();
                queue.write_texture(
                    lm.sun_texture.as_image_copy(),
                    &words_to_bytes(&shares),
                    wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * size.width), rows_per_image: Some(size.height) },
                    size,
                );
            }
        }
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("scene"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.targets.hdr_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.targets.depth_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &self.scene_bind, &[]);
            pass.set_vertex_buffer(0, self.vertex_buffer.slice(..));
            pass.set_index_buffer(self.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
            match &self.lightmap {
                Some(lm) => {
                    pass.set_pipeline(&lm.pipeline);
                    pass.set_bind_group(1, &lm.bind, &[]);
                    pass.set_vertex_buffer(1, lm.texcoords.slice(..));
                }
                None => pass.set_pipeline(&self.scene_pipeline),
            }
            for draw in self.draws.iter().filter(|d| d.kind == DrawKind::Opaque) {
                pass.draw_indexed(draw.indices.clone(), 0, 0..1);
            }
            pass.set_pipeline(&self.scene_pipeline);
            let panel_draws = self.draws.iter().filter(|d| d.kind == DrawKind::Panel);
            match &self.panel {
                Some(PanelGpu { pipeline, texcoords, texture: Some((_, bind)), .. }) => {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(1, bind, &[]);
                    pass.set_vertex_buffer(1, texcoords.slice(..));
                    for draw in panel_draws {
                        pass.draw_indexed(draw.indices.clone(), 0, 0..1);
                    }
                }
                _ => panel_draws.for_each(|draw| pass.draw_indexed(draw.indices.clone(), 0, 0..1)),
            }
            pass.set_pipeline(&self.backdrop_pipeline);
            pass.set_bind_group(0, &self.backdrop_bind, &[]);
            pass.draw(0..3, 0..1);
            pass.set_pipeline(&self.glass_pipeline);
            pass.set_bind_group(0, &self.scene_bind, &[]);
            for draw in self.draws.iter().filter(|d| matches!(d.kind, DrawKind::Glass { .. })) {
                pass.draw_indexed(draw.indices.clone(), 0, 0..1);
            }
        }
        if t.operator.adapts() {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("luminance"), timestamp_writes: None });
            pass.set_pipeline(&self.luminance_pipeline);
            pass.set_bind_group(0, &self.targets.luminance_bind, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("tonemap"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.tonemap_pipeline);
            pass.set_bind_group(0, &self.targets.tonemap_bind, &[]);
            pass.draw(0..3, 0..1);
        }
        queue.submit([encoder.finish()])
    }
}

impl PanelGpu {
    /// Writes `texture` into the GPU texture, recreating it (and its bind group) when the size changed.
    fn set_texture(&mut self, gpu: &Gpu, texture: &PanelTexture) {
        let size = wgpu::Extent3d { width: texture.width.max(1), height: texture.height.max(1), depth_or_array_layers: 1 };
        if self.texture.as_ref().is_none_or(|(t, _)| t.size() != size) {
            self.texture = Some(rgba32f_texture(&gpu.device, &self.layout, "panel", size, &[]));
        }
        let Some((gpu_texture, _)) = &self.texture else { return };
        let texels: Vec<u32> = texture.rgb.iter().flat_map(|p| [p[0], p[1], p[2], 1.0]).map(f32::to_bits).collect();
        write_rgba32f(&gpu.queue, gpu_texture, &texels);
    }
}

/// A 2D texture the CPU writes and a shader reads (`textureLoad`).
fn read_texture(device: &wgpu::Device, label: &str, size: wgpu::Extent3d, format: wgpu::TextureFormat) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

/// An RGBA32F texture the fragment stage reads (`textureLoad`), bound alone
/// in a group of `layout` (the panel's and texel mode's group 1).
/// An RGBA32F texture and its bind group (binding 0; `more`, at bindings 1, 2, …).
fn rgba32f_texture(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    size: wgpu::Extent3d,
    more: &[&wgpu::TextureView],
) -> (wgpu::Texture, wgpu::BindGroup) {
    let texture = read_texture(device, label, size, wgpu::TextureFormat::Rgba32Float);
    let view = texture.create_view(&Default::default());
    let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) }];
    for (binding, view) in (1..).zip(more) {
        entries.push(wgpu::BindGroupEntry { binding, resource: wgpu::BindingResource::TextureView(view) });
    }
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries });
    (texture, bind)
}

/// Writes a whole RGBA32F texture from its texels' f32 bits (4 words a texel, rows in order).
fn write_rgba32f(queue: &wgpu::Queue, texture: &wgpu::Texture, words: &[u32]) {
    let size = texture.size();
    queue.write_texture(
        texture.as_image_copy(),
        &words_to_bytes(words),
        wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(16 * size.width), rows_per_image: Some(size.height) },
        size,
    );
}
