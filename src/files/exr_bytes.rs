//! Linear RGB images encoded as OpenEXR bytes, the same bytes on every run.
//!
//! The `exr` crate compresses blocks on several threads and, unless the line
//! order is increasing, writes them in the order they finish: the same
//! pixels then give other bytes from run to run. Increasing order keeps the
//! parallel compression and sorts the blocks.

/// `width × height` pixels, `pixel(x, y)` each (row 0 at the top), as EXR
/// bytes (f32 RGB, the crate's default compression, increasing line order).
pub fn rgb_exr_bytes(width: usize, height: usize, pixel: impl Fn(usize, usize) -> [f32; 3] + Sync) -> Result<Vec<u8>, exr::error::Error> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
        let [r, g, b] = pixel(pos.x(), pos.y());
        (r, g, b)
    });
    let encoding = Encoding { line_order: LineOrder::Increasing, ..Encoding::default() };
    let mut bytes = Vec::new();
    Image::from_encoded_channels((width, height), encoding, channels).write().to_buffered(std::io::Cursor::new(&mut bytes))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same pixels give the same bytes every time, on two threads
    /// compressing at once, and read back as written.
    #[test]
    fn the_same_pixels_give_the_same_bytes() {
        let (w, h) = (400, 300);
        let pixel = |x: usize, y: usize| [x as f32 * 0.37, y as f32 * 1.3, ((x * 31 + y * 17) % 97) as f32];
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let first = rgb_exr_bytes(w, h, pixel).unwrap();
        for _ in 0..16 {
            let again = pool.install(|| rgb_exr_bytes(w, h, pixel)).unwrap();
            assert!(again == first, "the same pixels gave other bytes");
        }
        let read = read_rgb(&first);
        assert_eq!(read.len(), w * h);
        for (x, y) in [(0, 0), (123, 45), (w - 1, h - 1)] {
            assert_eq!(read[y * w + x], pixel(x, y), "pixel ({x}, {y})");
        }
    }

    /// Every pixel of an RGB EXR, row-major.
    fn read_rgb(bytes: &[u8]) -> Vec<[f32; 3]> {
        use exr::prelude::*;
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |resolution, _| (resolution.width(), vec![[0.0f32; 3]; resolution.width() * resolution.height()]),
                |(width, pixels): &mut (usize, Vec<[f32; 3]>), position: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                    pixels[position.y() * *width + position.x()] = [r, g, b];
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .unwrap();
        image.layer_data.channel_data.pixels.1
    }
}
