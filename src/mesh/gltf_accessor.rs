//! Bounds-checked glTF accessor decoding, straight from the JSON and the loaded buffers.
//!
//! The gltf crate's reader can panic on short or inconsistent data (`count - 1`
//! underflow, unchecked sparse values, debug asserts on element sizes), so this
//! module decodes accessors itself: every byte range is checked against the buffer
//! view, and every view against its loaded buffer, before a byte is read. Errors
//! are plain strings naming the accessor; the caller adds file and mesh context.

use std::borrow::Cow;

use gltf::json::accessor::{ComponentType, Type};
use gltf::json::validation::Checked;
use gltf::json::{self, Root};

/// Cap on elements of an accessor with no `bufferView` (all zeros, possibly
/// sparse-patched): its size is not bounded by the file, so bound it here.
const MAX_VIEWLESS_ELEMENTS: usize = 1 << 24;

/// Element layout of an accessor.
#[derive(Clone, Copy, Debug)]
struct Layout {
    component_type: ComponentType,
    component_size: usize,
    components: usize,
    normalized: bool,
}

impl Layout {
    fn element_size(&self) -> usize {
        self.component_size * self.components
    }
}

fn component_size(component_type: ComponentType) -> usize {
    match component_type {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

fn layout_of(index: usize, accessor: &json::Accessor) -> Result<Layout, String> {
    let Checked::Valid(component_type) = accessor.component_type else {
        return Err(format!("accessor {index} has an invalid componentType"));
    };
    let components = match accessor.type_ {
        Checked::Valid(Type::Scalar) => 1,
        Checked::Valid(Type::Vec2) => 2,
        Checked::Valid(Type::Vec3) => 3,
        Checked::Valid(Type::Vec4) => 4,
        // Matrices have per-column padding rules and are never mesh attributes.
        _ => return Err(format!("accessor {index} has an unsupported type (matrix or invalid)")),
    };
    let component_type = component_type.0;
    Ok(Layout { component_type, component_size: component_size(component_type), components, normalized: accessor.normalized })
}

/// Decodes one component as `f32`, applying the glTF normalisation rules
/// (`max(c / (2^(b-1) - 1), -1)` for signed, `c / (2^b - 1)` for unsigned).
fn component_as_f32(bytes: &[u8], layout: &Layout) -> Option<f32> {
    let norm = layout.normalized;
    Some(match layout.component_type {
        ComponentType::F32 => f32::from_le_bytes(bytes.try_into().ok()?),
        ComponentType::I8 => {
            let c = i8::from_le_bytes(bytes.try_into().ok()?) as f32;
            if norm {
                (c / 127.0).max(-1.0)
            } else {
                c
            }
        }
        ComponentType::U8 => {
            let c = u8::from_le_bytes(bytes.try_into().ok()?) as f32;
            if norm {
                c / 255.0
            } else {
                c
            }
        }
        ComponentType::I16 => {
            let c = i16::from_le_bytes(bytes.try_into().ok()?) as f32;
            if norm {
                (c / 32767.0).max(-1.0)
            } else {
                c
            }
        }
        ComponentType::U16 => {
            let c = u16::from_le_bytes(bytes.try_into().ok()?) as f32;
            if norm {
                c / 65535.0
            } else {
                c
            }
        }
        ComponentType::U32 => u32::from_le_bytes(bytes.try_into().ok()?) as f32,
    })
}

/// Decodes one unsigned integer component (index data).
fn component_as_u32(bytes: &[u8], layout: &Layout) -> Option<u32> {
    match layout.component_type {
        ComponentType::U8 => Some(u8::from_le_bytes(bytes.try_into().ok()?) as u32),
        ComponentType::U16 => Some(u16::from_le_bytes(bytes.try_into().ok()?) as u32),
        ComponentType::U32 => Some(u32::from_le_bytes(bytes.try_into().ok()?)),
        _ => None,
    }
}

fn to_usize(value: u64, what: &str) -> Result<usize, String> {
    usize::try_from(value).map_err(|_| format!("{what} {value} does not fit in memory"))
}

/// The bytes of buffer view `view_index` and its byte stride (`None` when unset or 0).
fn view_bytes<'b>(root: &Root, view_index: usize, buffers: &'b [Cow<'_, [u8]>]) -> Result<(&'b [u8], Option<usize>), String> {
    let view = root.buffer_views.get(view_index).ok_or_else(|| format!("bufferView {view_index} does not exist"))?;
    let buffer_index = view.buffer.value();
    let buffer = buffers.get(buffer_index).ok_or_else(|| format!("bufferView {view_index} refers to missing buffer {buffer_index}"))?;
    let start = to_usize(view.byte_offset.map_or(0, |o| o.0), "bufferView byteOffset")?;
    let length = to_usize(view.byte_length.0, "bufferView byteLength")?;
    let bytes = start.checked_add(length).and_then(|end| buffer.get(start..end)).ok_or_else(|| {
        format!(
            "bufferView {view_index} (bytes {start}..{}) lies outside buffer {buffer_index} ({} bytes)",
            start.saturating_add(length),
            buffer.len()
        )
    })?;
    Ok((bytes, view.byte_stride.map(|s| s.0).filter(|&s| s != 0)))
}

/// Decodes `count` elements starting at `offset` with `stride` from `bytes`,
/// pushing `components` values per element; checks the whole range first.
fn decode_strided<T>(
    what: &str,
    bytes: &[u8],
    offset: usize,
    stride: usize,
    count: usize,
    layout: &Layout,
    decode: &impl Fn(&[u8], &Layout) -> Option<T>,
) -> Result<Vec<T>, String> {
    if count == 0 {
        return Ok(Vec::new());
    }
    let element_size = layout.element_size();
    if stride < element_size {
        return Err(format!("{what}: byteStride {stride} is smaller than its element size {element_size}"));
    }
    let needed = stride.checked_mul(count - 1).and_then(|n| n.checked_add(element_size)).and_then(|n| n.checked_add(offset));
    match needed {
        Some(needed) if needed <= bytes.len() => {}
        _ => {
            return Err(format!(
                "{what}: {count} elements of {element_size} bytes (stride {stride}, offset {offset}) need more than the {} bytes of its bufferView",
                bytes.len()
            ))
        }
    }
    let mut out = Vec::with_capacity(count * layout.components);
    for element in 0..count {
        let base = offset + element * stride;
        for component in 0..layout.components {
            let at = base + component * layout.component_size;
            let value = bytes
                .get(at..at + layout.component_size)
                .and_then(|b| decode(b, layout))
                .ok_or_else(|| format!("{what}: element {element} cannot be decoded"))?;
            out.push(value);
        }
    }
    Ok(out)
}

/// Reads accessor `index` fully (base data or zeros, then sparse substitution).
fn read_accessor<T: Copy + Default>(
    root: &Root,
    index: usize,
    buffers: &[Cow<'_, [u8]>],
    decode: impl Fn(&[u8], &Layout) -> Option<T>,
) -> Result<(Vec<T>, usize), String> {
    let accessor = root.accessors.get(index).ok_or_else(|| format!("accessor {index} does not exist"))?;
    let layout = layout_of(index, accessor)?;
    let what = format!("accessor {index}");
    let count = to_usize(accessor.count.0, "accessor count")?;
    let offset = to_usize(accessor.byte_offset.map_or(0, |o| o.0), "accessor byteOffset")?;
    let mut values = match accessor.buffer_view {
        Some(view) => {
            let (bytes, stride) = view_bytes(root, view.value(), buffers)?;
            decode_strided(&what, bytes, offset, stride.unwrap_or(layout.element_size()), count, &layout, &decode)?
        }
        None if count <= MAX_VIEWLESS_ELEMENTS => vec![T::default(); count * layout.components],
        None => return Err(format!("{what}: {count} elements without a bufferView exceed the limit of {MAX_VIEWLESS_ELEMENTS}")),
    };
    if let Some(sparse) = &accessor.sparse {
        let sparse_what = format!("{what} sparse");
        let sparse_count = to_usize(sparse.count.0, "sparse count")?;
        let Checked::Valid(index_type) = sparse.indices.component_type else {
            return Err(format!("{sparse_what}: invalid index componentType"));
        };
        let index_layout =
            Layout { component_type: index_type.0, component_size: component_size(index_type.0), components: 1, normalized: false };
        let (index_bytes, _) = view_bytes(root, sparse.indices.buffer_view.value(), buffers)?;
        let index_offset = to_usize(sparse.indices.byte_offset.0, "sparse indices byteOffset")?;
        let targets = decode_strided(
            &format!("{sparse_what} indices"),
            index_bytes,
            index_offset,
            index_layout.element_size(),
            sparse_count,
            &index_layout,
            &component_as_u32,
        )?;
        let (value_bytes, _) = view_bytes(root, sparse.values.buffer_view.value(), buffers)?;
        let value_offset = to_usize(sparse.values.byte_offset.0, "sparse values byteOffset")?;
        let replacements = decode_strided(
            &format!("{sparse_what} values"),
            value_bytes,
            value_offset,
            layout.element_size(),
            sparse_count,
            &layout,
            &decode,
        )?;
        for (&target, replacement) in targets.iter().zip(replacements.chunks_exact(layout.components)) {
            let start = target as usize * layout.components;
            let slot = values
                .get_mut(start..start + layout.components)
                .ok_or_else(|| format!("{sparse_what}: index {target} is out of range ({count} elements)"))?;
            slot.copy_from_slice(replacement);
        }
    }
    Ok((values, layout.components))
}

/// Reads a vertex attribute accessor as `f32` components.
///
/// Returns the flat values and the number of components per element, which must
/// be one of `allowed_components` (e.g. `&[3]` for POSITION, `&[3, 4]` for COLOR_0).
/// Integer components are converted (normalised when the accessor says so).
pub(crate) fn read_floats(
    root: &Root,
    index: usize,
    buffers: &[Cow<'_, [u8]>],
    allowed_components: &[usize],
) -> Result<(Vec<f32>, usize), String> {
    let (values, components) = read_accessor(root, index, buffers, component_as_f32)?;
    if !allowed_components.contains(&components) {
        return Err(format!("accessor {index} has {components} components per element, expected one of {allowed_components:?}"));
    }
    Ok((values, components))
}

/// Reads an index accessor (scalar u8/u16/u32) as `u32`.
pub(crate) fn read_indices(root: &Root, index: usize, buffers: &[Cow<'_, [u8]>]) -> Result<Vec<u32>, String> {
    if let Some(accessor) = root.accessors.get(index) {
        let layout = layout_of(index, accessor)?;
        if layout.components != 1 || component_as_u32(&[0; 4][..layout.component_size], &layout).is_none() {
            return Err(format!("index accessor {index} is not a scalar of unsigned bytes, shorts or ints"));
        }
    }
    Ok(read_accessor(root, index, buffers, component_as_u32)?.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A root with one buffer and whatever accessors/views the JSON text gives.
    fn root(json: &str) -> Root {
        gltf::json::deserialize::from_str(json).unwrap()
    }

    const VIEW_12_BYTES: &str = r#""asset":{"version":"2.0"},"buffers":[{"byteLength":12}],"bufferViews":[{"buffer":0,"byteLength":12}]"#;

    #[test]
    fn reads_normalized_bytes_with_stride() {
        let r = root(&format!(
            r#"{{{VIEW_12_BYTES},"accessors":[{{"bufferView":0,"byteOffset":1,"componentType":5121,"normalized":true,"count":2,"type":"VEC2"}}]}}"#
        ));
        let buffers = [Cow::Owned(vec![0, 255, 0, 51, 0, 0, 0, 0, 0, 0, 0, 0])];
        let (values, components) = read_floats(&r, 0, &buffers, &[2]).unwrap();
        assert_eq!(components, 2);
        assert_eq!(values, vec![1.0, 0.0, 0.2, 0.0]);
    }

    #[test]
    fn refuses_ranges_past_the_view_and_views_past_the_buffer() {
        let r = root(&format!(r#"{{{VIEW_12_BYTES},"accessors":[{{"bufferView":0,"componentType":5126,"count":2,"type":"VEC3"}}]}}"#));
        let buffers = [Cow::Owned(vec![0; 12])];
        assert!(read_floats(&r, 0, &buffers, &[3]).unwrap_err().contains("need more than the 12 bytes"));
        let short = [Cow::Owned(vec![0; 8])];
        assert!(read_floats(&r, 0, &short, &[3]).unwrap_err().contains("lies outside buffer 0"));
    }

    #[test]
    fn applies_sparse_values_and_checks_their_indices() {
        // Base: no view (zeros, 3 scalars); sparse: index 2 -> 7.0.
        let sparse = |target: u8| {
            let r = root(&format!(
                r#"{{{VIEW_12_BYTES},"accessors":[{{"componentType":5126,"count":3,"type":"SCALAR",
                  "sparse":{{"count":1,"indices":{{"bufferView":0,"componentType":5121}},"values":{{"bufferView":0,"byteOffset":4}}}}}}]}}"#
            ));
            let mut bytes = vec![target, 0, 0, 0];
            bytes.extend_from_slice(&7.0f32.to_le_bytes());
            bytes.extend_from_slice(&[0; 4]);
            read_floats(&r, 0, &[Cow::Owned(bytes)], &[1])
        };
        assert_eq!(sparse(2).unwrap().0, vec![0.0, 0.0, 7.0]);
        assert!(sparse(3).unwrap_err().contains("out of range"));
    }

    #[test]
    fn index_accessors_must_be_unsigned_scalars() {
        let r = root(&format!(
            r#"{{{VIEW_12_BYTES},"accessors":[{{"bufferView":0,"componentType":5123,"count":3,"type":"SCALAR"}},
               {{"bufferView":0,"componentType":5126,"count":3,"type":"SCALAR"}}]}}"#
        ));
        let buffers = [Cow::Owned(vec![1, 0, 2, 0, 3, 1, 0, 0, 0, 0, 0, 0])];
        assert_eq!(read_indices(&r, 0, &buffers).unwrap(), vec![1, 2, 259]);
        assert!(read_indices(&r, 1, &buffers).is_err());
        assert!(read_indices(&r, 5, &buffers).unwrap_err().contains("does not exist"));
    }
}
