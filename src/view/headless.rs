//! Offscreen rendering with no window system: one frame into an `Rgba8Unorm`
//! texture, copied to a buffer, read back as RGBA8 and written as PNG; and
//! frame timing over many frames.

use std::path::Path;
use std::time::Instant;

use super::camera::Camera;
use super::gpu::{Gpu, GpuMemory, Renderer};
use super::scene::PreparedScene;
use super::{FrameSettings, ViewError};
use crate::bundle::SunSeries;

/// Output format of headless frames: gamma is applied by the tone-mapping shader.
pub const HEADLESS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// An 8-bit RGBA image, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// `width · height · 4` bytes.
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel at column `x`, row `y` (must be inside the image).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [self.rgba[i], self.rgba[i + 1], self.rgba[i + 2], self.rgba[i + 3]]
    }

    /// PNG bytes (RGBA, 8 bits, default compression).
    pub fn encode_png(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut out, self.width, self.height);
            encoder.set_color(png::ColorType::Rgba);
            encoder.set_depth(png::BitDepth::Eight);
            let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
            writer.write_image_data(&self.rgba).map_err(|e| e.to_string())?;
        }
        Ok(out)
    }

    /// Decodes an 8-bit RGBA PNG (what [`Image::encode_png`] writes).
    pub fn decode_png(bytes: &[u8]) -> Result<Image, String> {
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().map_err(|e| e.to_string())?;
        let mut rgba = vec![0; reader.output_buffer_size().ok_or("image too large")?];
        let info = reader.next_frame(&mut rgba).map_err(|e| e.to_string())?;
        if (info.color_type, info.bit_depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
            return Err(format!("{:?} {:?}: expected 8-bit RGBA", info.color_type, info.bit_depth));
        }
        rgba.truncate(info.buffer_size());
        Ok(Image { width: info.width, height: info.height, rgba })
    }

    /// Writes the image as PNG at `path` (atomically).
    pub fn write_png(&self, path: &Path) -> Result<(), ViewError> {
        let error = |message: String| ViewError::Write { path: path.to_path_buf(), message };
        let bytes = self.encode_png().map_err(error)?;
        crate::files::write_atomic(path, &bytes).map_err(|e| error(e.to_string()))
    }
}

/// An offscreen output texture and its readback buffer.
struct Offscreen {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row: u32,
}

impl Offscreen {
    fn new(gpu: &Gpu, width: u32, height: u32) -> Offscreen {
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("output"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: HEADLESS_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let padded_row = (width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let readback = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: padded_row as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Offscreen { texture, view, readback, padded_row }
    }

    /// Copies the output to the readback buffer, waits, and returns the pixels.
    fn read(&self, gpu: &Gpu, width: u32, height: u32) -> Result<Image, ViewError> {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_texture_to_buffer(
            self.texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.padded_row), rows_per_image: Some(height) },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        gpu.queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..);
        let (sender, receiver) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |result| {
            let _ = sender.send(result);
        });
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| ViewError::Gpu(e.to_string()))?;
        receiver
            .recv()
            .map_err(|e| ViewError::Gpu(e.to_string()))?
            .map_err(|e| ViewError::Gpu(format!("cannot map the readback buffer: {e}")))?;
        let mut rgba = Vec::with_capacity((width * height * 4) as usize);
        {
            let data = slice.get_mapped_range().map_err(|e| ViewError::Gpu(e.to_string()))?;
            for row in data.chunks_exact(self.padded_row as usize).take(height as usize) {
                rgba.extend_from_slice(&row[..(width * 4) as usize]);
            }
        }
        self.readback.unmap();
        Ok(Image { width, height, rgba })
    }
}

fn check_size(width: u32, height: u32, gpu: &Gpu) -> Result<(), ViewError> {
    let max = gpu.device.limits().max_texture_dimension_2d;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(ViewError::Invalid(format!("image size {width}x{height} is outside 1..={max} per side")));
    }
    Ok(())
}

/// Renders one frame of `scene` offscreen at `width × height` and reads it back.
/// The adaptation of the adaptive operators starts at this frame's luminance.
pub fn render_image(
    gpu: &Gpu,
    scene: &PreparedScene,
    sun: Option<&SunSeries>,
    camera: &Camera,
    settings: &FrameSettings,
    width: u32,
    height: u32,
) -> Result<Image, ViewError> {
    check_size(width, height, gpu)?;
    let renderer = Renderer::new(gpu, scene, HEADLESS_FORMAT, width, height)?;
    let output = Offscreen::new(gpu, width, height);
    renderer.render(gpu, &output.view, camera, settings, sun, 0.0, true);
    output.read(gpu, width, height)
}

/// A linear RGB image (the frame before tone mapping, in the lighting's
/// units), rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    /// `width · height` pixels.
    pub rgb: Vec<[f32; 3]>,
}

impl LinearImage {
    /// The pixel at column `x`, row `y` (must be inside the image).
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[y as usize * self.width as usize + x as usize]
    }

    /// OpenEXR bytes (RGB f32, no compression loss).
    pub fn encode_exr(&self) -> Result<Vec<u8>, String> {
        let w = self.width as usize;
        crate::files::rgb_exr_bytes(w, self.height as usize, |x, y| self.rgb[y * w + x]).map_err(|e| e.to_string())
    }
}

/// Renders one frame like [`render_image`] and reads back its linear
/// radiance before tone mapping (half floats: values past 65,504 read as
/// infinity).
pub fn render_linear(
    gpu: &Gpu,
    scene: &PreparedScene,
    sun: Option<&SunSeries>,
    camera: &Camera,
    settings: &FrameSettings,
    width: u32,
    height: u32,
) -> Result<LinearImage, ViewError> {
    check_size(width, height, gpu)?;
    let renderer = Renderer::new(gpu, scene, HEADLESS_FORMAT, width, height)?;
    let output = Offscreen::new(gpu, width, height);
    renderer.render(gpu, &output.view, camera, settings, sun, 0.0, true);
    let bytes_per_pixel = 8u32;
    let padded_row = (width * bytes_per_pixel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let readback = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("linear readback"),
        size: padded_row as u64 * height as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("linear readback") });
    encoder.copy_texture_to_buffer(
        renderer.hdr_texture().as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &readback,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded_row), rows_per_image: Some(height) },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    gpu.queue.submit([encoder.finish()]);
    let slice = readback.slice(..);
    let (sender, receiver) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |result| {
        let _ = sender.send(result);
    });
    gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| ViewError::Gpu(e.to_string()))?;
    receiver
        .recv()
        .map_err(|e| ViewError::Gpu(e.to_string()))?
        .map_err(|e| ViewError::Gpu(format!("cannot map the readback buffer: {e}")))?;
    let mut rgb = Vec::with_capacity((width * height) as usize);
    {
        let data = slice.get_mapped_range().map_err(|e| ViewError::Gpu(e.to_string()))?;
        for row in data.chunks_exact(padded_row as usize).take(height as usize) {
            for px in row[..(width * bytes_per_pixel) as usize].chunks_exact(8) {
                let h = |i: usize| half::f16::from_le_bytes([px[2 * i], px[2 * i + 1]]).to_f32();
                rgb.push([h(0), h(1), h(2)]);
            }
        }
    }
    readback.unmap();
    Ok(LinearImage { width, height, rgb })
}

/// Frame time and memory of a headless run.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameTiming {
    pub adapter: String,
    pub width: u32,
    pub height: u32,
    /// Frames timed (after one untimed warm-up frame).
    pub frames: u32,
    /// Mean and fastest wall time per frame, submission to completion, milliseconds.
    pub mean_ms: f64,
    pub min_ms: f64,
    /// Triangles drawn and GPU vertices (bundle vertices split by material).
    pub triangles: u64,
    pub gpu_vertices: u64,
    pub memory: GpuMemory,
}

/// Renders `frames` frames (plus a warm-up), waiting for each, and returns the
/// last image and the timing. The lighting is rotated a little every frame so
/// each frame uploads a new SH vector, as in the interactive viewer.
#[allow(clippy::too_many_arguments)]
pub fn time_frames(
    gpu: &Gpu,
    scene: &PreparedScene,
    sun: Option<&SunSeries>,
    camera: &Camera,
    settings: &FrameSettings,
    width: u32,
    height: u32,
    frames: u32,
) -> Result<(Image, FrameTiming), ViewError> {
    check_size(width, height, gpu)?;
    let renderer = Renderer::new(gpu, scene, HEADLESS_FORMAT, width, height)?;
    let output = Offscreen::new(gpu, width, height);
    let order = scene.order as usize;
    let mut times = Vec::with_capacity(frames as usize);
    for frame in 0..=frames {
        let started = Instant::now();
        let rotation = super::lighting::env_rotation(frame as f32 * 0.5, 0.0, 0.0);
        let mut frame_settings = settings.clone();
        frame_settings.lighting = super::lighting::rotate_sh(&settings.lighting, order, rotation);
        renderer.render(gpu, &output.view, camera, &frame_settings, sun, 1.0 / 60.0, frame == 0);
        gpu.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| ViewError::Gpu(e.to_string()))?;
        if frame > 0 {
            times.push(started.elapsed().as_secs_f64() * 1e3);
        }
    }
    let image = output.read(gpu, width, height)?;
    let mean_ms = if times.is_empty() { 0.0 } else { times.iter().sum::<f64>() / times.len() as f64 };
    let min_ms = times.iter().copied().fold(f64::INFINITY, f64::min);
    let timing = FrameTiming {
        adapter: gpu.adapter_name(),
        width,
        height,
        frames,
        mean_ms,
        min_ms: if min_ms.is_finite() { min_ms } else { 0.0 },
        triangles: scene.indices.len() as u64 / 3,
        gpu_vertices: scene.vertices.len() as u64,
        memory: renderer.memory(),
    };
    Ok((image, timing))
}
