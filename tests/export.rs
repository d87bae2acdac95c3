//! `prtbake export`: the GLB read back with the gltf crate matches the bundle.

use glam::Vec3;
use prtbake::bundle::{self, Bundle, LayerKind, Quantization, SunSeries, SunStep, Transfer, TransferLayer};
use prtbake::mesh::Mesh;
use prtbake::verify::shapes;

use crate::util::{prtbake, Scratch};

/// Two groups (plane, sphere), RGB transfer of order 3 (27 values: 7 VEC4s, the
/// last one padded), two layers, and 40 time-lapse steps (2 mask words).
fn sample_bundle() -> Bundle {
    let mut mesh = shapes::plane_grid(6, 2.0);
    let mut sphere = shapes::icosphere(1);
    shapes::transform(&mut sphere, 0.4, Vec3::new(0.0, 0.6, 0.0));
    shapes::append(&mut mesh, &sphere);
    let (order, channels) = (3u32, 3u32);
    let per_vertex = (order * order * channels) as usize;
    let values = |seed: f32| -> Vec<f32> { (0..mesh.vertex_count() * per_vertex).map(|i| (i as f32 * 0.37 + seed).sin() * 0.5).collect() };
    let steps: Vec<SunStep> = (0..40)
        .map(|k| SunStep {
            unix_time_utc: 1.7e9 + 420.0 * k as f64,
            direction: Vec3::new(1.0, 1.0 + k as f32 * 0.1, 0.2).normalize().to_array(),
            elevation_deg: 30.0 + k as f32,
            azimuth_deg: 90.0 + k as f32,
            sun_rgb: [1000.0 + k as f32, 900.0, 800.0],
            night: false,
            sky_sh: vec![[k as f32, 1.0, 2.0]; 4],
        })
        .collect();
    let (words_per_vertex, masks) = SunSeries::pack(steps.len(), mesh.vertex_count(), |v, k| (v * 7 + k * 3) % 5 < 2);
    Bundle {
        meta: serde_json::json!({"conventions": {"sh": "test"}}),
        transfer: Some(Transfer {
            order,
            channels,
            quantization: Quantization::F32,
            layers: vec![
                TransferLayer { kind: LayerKind::Total, data: values(0.0) },
                TransferLayer { kind: LayerKind::Bounce(0), data: values(1.0) },
            ],
            front_share: (0..mesh.vertex_count()).map(|v| ((v * 37) % 256) as f32 / 255.0).collect(),
        }),
        sun: Some(SunSeries::per_vertex(2, steps, words_per_vertex, masks)),
        mesh,
        texels: None,
    }
}

/// The non-empty groups' triangles, each sorted (the GLB writer's documented
/// layout: one glTF mesh per non-empty group, in group order).
fn group_triangles(mesh: &Mesh) -> Vec<Vec<[u32; 3]>> {
    (0..mesh.groups.len() as u32)
        .map(|g| {
            let mut triangles: Vec<[u32; 3]> =
                (0..mesh.triangle_count()).filter(|&t| mesh.tri_group[t] == g).map(|t| mesh.triangle(t)).collect();
            triangles.sort_unstable();
            triangles
        })
        .filter(|t| !t.is_empty())
        .collect()
}

fn read_attribute<T: gltf::accessor::Item + Copy>(primitive: &gltf::Primitive, name: &str, blob: &[u8]) -> Vec<T> {
    let accessor = primitive
        .attributes()
        .find(|(semantic, _)| *semantic == gltf::Semantic::Extras(name.trim_start_matches('_').to_string()))
        .unwrap_or_else(|| panic!("attribute {name} missing"))
        .1;
    gltf::accessor::Iter::<T>::new(accessor, |_| Some(blob)).expect("readable accessor").collect()
}

fn check_glb(path: &std::path::Path, b: &Bundle, expected_transfer: &[f32]) {
    let bytes = std::fs::read(path).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid GLB");
    let blob = gltf.blob.as_deref().expect("a BIN chunk");
    let t = b.transfer.as_ref().unwrap();
    let sun = b.sun.as_ref().unwrap();
    let per_vertex = t.values_per_vertex() as usize;
    let groups = group_triangles(&b.mesh);
    assert_eq!(gltf.meshes().count(), groups.len());
    // Every primitive indexes one pool of all bundle vertices, in bundle order.
    let vertices: Vec<u32> = (0..b.mesh.vertex_count() as u32).collect();
    for (mesh, triangles) in gltf.meshes().zip(&groups) {
        let mut written: Vec<[u32; 3]> = Vec::new();
        for primitive in mesh.primitives() {
            let reader = primitive.reader(|_| Some(blob));
            let indices: Vec<u32> = reader.read_indices().expect("indexed primitives").into_u32().collect();
            written.extend(indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            assert_eq!(positions.len(), vertices.len());
            for (p, &v) in positions.iter().zip(&vertices) {
                assert_eq!(*p, b.mesh.positions[v as usize].to_array());
            }
            for k in 0..per_vertex.div_ceil(4) {
                let values: Vec<[f32; 4]> = read_attribute(&primitive, &format!("_PRT_TRANSFER_{k}"), blob);
                assert_eq!(values.len(), vertices.len());
                for (value, &v) in values.iter().zip(&vertices) {
                    for j in 0..4 {
                        let index = 4 * k + j;
                        let want = if index < per_vertex { expected_transfer[v as usize * per_vertex + index] } else { 0.0 };
                        assert_eq!(value[j].to_bits(), want.to_bits(), "vertex {v}, value {index}");
                    }
                }
            }
            let shares: Vec<f32> = read_attribute(&primitive, "_PRT_FRONT_SHARE", blob);
            assert_eq!(shares, vertices.iter().map(|&v| t.front_share[v as usize]).collect::<Vec<_>>(), "front shares");
            for w in 0..sun.words_per_vertex as usize {
                let words: Vec<[u8; 4]> = read_attribute(&primitive, &format!("_PRT_SUN_{w}"), blob);
                assert_eq!(words.len(), vertices.len());
                for (bytes, &v) in words.iter().zip(&vertices) {
                    // Step 32w + 8j + b is bit b of byte j.
                    for step in 32 * w..(32 * w + 32).min(sun.step_count()) {
                        let (j, bit) = ((step % 32) / 8, step % 8);
                        assert_eq!((bytes[j] >> bit) & 1 == 1, sun.bit(v as usize, step), "vertex {v}, step {step}");
                    }
                }
            }
        }
        written.sort_unstable();
        assert_eq!(&written, triangles, "mesh {:?}: its group's triangles", mesh.name());
    }
    let extras: serde_json::Value = serde_json::from_str(gltf.document.as_json().extras.as_ref().expect("document extras").get()).unwrap();
    let prt = &extras["prtbake"];
    assert_eq!(prt["format"], bundle::GLTF_EXPORT_FORMAT);
    assert_eq!(prt["transfer"]["order"], 3);
    assert_eq!(prt["transfer"]["channels"], 3);
    assert_eq!(prt["transfer"]["attributes"], 7);
    assert_eq!(prt["sun"]["steps"].as_array().unwrap().len(), 40);
    assert_eq!(prt["sun"]["steps"][5]["sun_rgb"][0], 1005.0);
}

#[test]
fn glb_export_reads_back_with_the_gltf_crate() {
    let scratch = Scratch::new("export");
    let b = sample_bundle();
    let total = scratch.path("total.glb");
    let report = bundle::export_glb(&total, &b, None).unwrap();
    assert_eq!((report.transfer_attributes, report.sun_attributes), (7, 2));
    check_glb(&total, &b, &b.transfer.as_ref().unwrap().layers[0].data);
    let direct = scratch.path("direct.glb");
    bundle::export_glb(&direct, &b, Some(LayerKind::Bounce(0))).unwrap();
    check_glb(&direct, &b, &b.transfer.as_ref().unwrap().layers[1].data);
    assert!(bundle::export_glb(&scratch.path("x.glb"), &b, Some(LayerKind::Bounce(3))).is_err());
}

#[test]
fn export_command_writes_a_glb() {
    let scratch = Scratch::new("export-cli");
    let b = sample_bundle();
    let input = scratch.path("scene.prtb");
    bundle::write_bundle(&input, &b).unwrap();
    let output = scratch.path("scene.glb");
    let run = prtbake(&["export", input.to_str().unwrap(), "-o", output.to_str().unwrap(), "--json"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(report["report"]["transfer_attributes"], 7);
    check_glb(&output, &b, &b.transfer.as_ref().unwrap().layers[0].data);
    // A bad layer is an error naming the problem, exit code 2.
    let bad = prtbake(&["export", input.to_str().unwrap(), "-o", output.to_str().unwrap(), "--layer", "9"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("no bounce 9 layer"));
}

/// glTF wants unit normals and no empty primitive: a bundle whose normals are
/// not unit (built in memory) exports them normalised, and one with no
/// triangles is refused; `clean` that leaves no triangle writes nothing.
#[test]
fn exports_are_valid_gltf_and_empty_results_are_errors() {
    let dir = Scratch::new("export-valid");
    let export = |b: &Bundle, name: &str| {
        let path = dir.path(&format!("{name}.prtb"));
        bundle::write_bundle(&path, b).unwrap();
        let out = dir.path(&format!("{name}.glb"));
        (prtbake(&["export", path.to_str().unwrap(), "-o", out.to_str().unwrap()]), out)
    };
    let mut b = sample_bundle();
    for (i, n) in b.mesh.normals.iter_mut().enumerate() {
        *n *= 0.5 + (i % 3) as f32;
    }
    let (o, out) = export(&b, "scaled");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&out).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_deref().unwrap();
    let mut normals = 0;
    for mesh in gltf.meshes() {
        for primitive in mesh.primitives() {
            for n in primitive.reader(|_| Some(blob)).read_normals().unwrap() {
                assert!((Vec3::from(n).length() - 1.0).abs() < 1e-6, "{n:?}");
                normals += 1;
            }
        }
    }
    assert!(normals > 0);
    let mut empty = sample_bundle();
    empty.mesh.indices.clear();
    empty.mesh.tri_material.clear();
    empty.mesh.tri_group.clear();
    let (o, out) = export(&empty, "empty");
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(2) && e.contains("no triangles"), "{e}");
    assert!(!out.exists());
    // Every triangle degenerate: clean removes them all, and says so.
    let obj = dir.path("flat.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 3 4\n").unwrap();
    for out in ["c.obj", "c.glb"] {
        let o = prtbake(&["clean", obj.to_str().unwrap(), "-o", dir.path(out).to_str().unwrap()]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{e}");
        assert!(e.contains("flat.obj") && e.contains("left no triangle"), "{e}");
        assert!(!dir.path(out).exists() && !dir.path("c.mtl").exists());
    }
}

/// Decodes PNG image `index` of a GLB (stored in its BIN chunk) to samples:
/// 16-bit images as u16 (big-endian in the file), 8-bit as u8 widened.
fn png_samples(gltf: &gltf::Gltf, blob: &[u8], index: usize) -> (u32, u32, usize, Vec<u32>) {
    let image = gltf.images().nth(index).expect("image");
    let gltf::image::Source::View { view, mime_type } = image.source() else { panic!("image {index} is not in the BIN chunk") };
    assert_eq!(mime_type, "image/png");
    let bytes = &blob[view.offset()..view.offset() + view.length()];
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().expect("a PNG");
    let mut data = vec![0; reader.output_buffer_size().expect("a size")];
    let info = reader.next_frame(&mut data).expect("PNG data");
    let channels = info.color_type.samples();
    let samples = match info.bit_depth {
        png::BitDepth::Sixteen => data[..info.buffer_size()].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]]) as u32).collect(),
        png::BitDepth::Eight => data[..info.buffer_size()].iter().map(|&b| b as u32).collect(),
        other => panic!("bit depth {other:?}"),
    };
    (info.width, info.height, channels, samples)
}

/// A texel bundle exports its atlas: one vertex per atlas vertex with the
/// atlas position as TEXCOORD_1, every covered texel's transfer in 16-bit
/// textures within the quantization step its extras give, its sun bits
/// exact, a coverage mask, and per-vertex values following their vertices.
#[test]
fn a_texel_bundle_exports_its_texels_as_textures_on_its_lightmap_uvs() {
    let dir = Scratch::new("export-texels");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &shapes::room_with_walls_running_past()).unwrap();
    let (baked, sunned, out) = (dir.path("t.prtb"), dir.path("ts.prtb"), dir.path("t.glb"));
    let bake =
        ["bake", obj.to_str().unwrap(), "-o", baked.to_str().unwrap(), "--rays", "8", "--bounces", "1", "--texel-size", "0.25", "--quiet"];
    let o = prtbake(&bake);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = prtbake(&["sun", baked.to_str().unwrap(), "-o", sunned.to_str().unwrap(), "--steps", "40", "--texel-fractions", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = prtbake(&["export", sunned.to_str().unwrap(), "-o", out.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let b = bundle::read_bundle(&sunned).unwrap();
    let t = b.texels.as_ref().unwrap();
    let (atlas, sun) = (&t.atlas, b.sun.as_ref().unwrap());
    let texel_transfer = t.transfer.as_ref().unwrap().total();
    let per_texel = t.transfer.as_ref().unwrap().values_per_vertex() as usize;
    let words = sun.words_per_vertex as usize;
    assert!(!sun.texel_masks.is_empty() && words == 2);
    // Coverage, ⌈9/4⌉ transfer textures, two sun words, ⌈40/8⌉ fraction words.
    assert!(!sun.texel_fractions.is_empty());
    assert_eq!(report["report"]["texel_textures"], 1 + 3 + 2 + 5);
    assert_eq!(report["report"]["vertices"], atlas.uv.len());

    let bytes = std::fs::read(&out).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid GLB");
    let blob = gltf.blob.as_deref().unwrap();
    let extras: serde_json::Value = serde_json::from_str(gltf.document.as_json().extras.as_ref().unwrap().get()).unwrap();
    let meta = &extras["prtbake"]["texels"];
    assert_eq!((meta["width"].as_u64(), meta["height"].as_u64()), (Some(atlas.width as u64), Some(atlas.height as u64)));
    let (w, h) = (atlas.width, atlas.height);

    // Vertices: the atlas's, positions and TEXCOORD_1 from it; the vertex transfer follows its vertex.
    let vertex_transfer = b.transfer.as_ref().unwrap().total();
    let mut triangles = 0;
    for mesh in gltf.meshes() {
        for primitive in mesh.primitives() {
            let reader = primitive.reader(|_| Some(blob));
            triangles += reader.read_indices().unwrap().into_u32().count() / 3;
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            let uvs: Vec<[f32; 2]> = reader.read_tex_coords(1).expect("TEXCOORD_1").into_f32().collect();
            let dc: Vec<[f32; 4]> = read_attribute(&primitive, "_PRT_TRANSFER_0", blob);
            assert_eq!((positions.len(), uvs.len()), (atlas.uv.len(), atlas.uv.len()));
            for (a, &v) in atlas.source_vertex.iter().enumerate() {
                assert_eq!(positions[a], b.mesh.positions[v as usize].to_array());
                assert!((uvs[a][0] * w as f32 - atlas.uv[a].x).abs() < 1e-3 && (uvs[a][1] * h as f32 - atlas.uv[a].y).abs() < 1e-3);
                assert_eq!(dc[a][0], vertex_transfer[v as usize * per_texel]);
            }
        }
    }
    assert_eq!(triangles, b.mesh.triangle_count());

    // Coverage: exactly the covered texels.
    let (cw, ch, channels, coverage) = png_samples(&gltf, blob, meta["coverage_texture"].as_u64().unwrap() as usize);
    assert_eq!((cw, ch, channels), (w, h, 1));
    let covered: Vec<u32> = (0..w * h).filter(|&i| coverage[i as usize] == 255).collect();
    assert_eq!(covered, t.texels);
    // Transfer: every covered texel's values within half a quantization step.
    for (k, texture) in meta["transfer"]["textures"].as_array().unwrap().iter().enumerate() {
        let (_, _, channels, q) = png_samples(&gltf, blob, texture.as_u64().unwrap() as usize);
        assert_eq!(channels, 4);
        for c in 0..4 {
            let (offset, scale) = (meta["transfer"]["offset"][k][c].as_f64().unwrap(), meta["transfer"]["scale"][k][c].as_f64().unwrap());
            let j = 4 * k + c;
            for (row, &texel) in t.texels.iter().enumerate() {
                let got = offset + scale * q[texel as usize * 4 + c] as f64 / 65535.0;
                let want = if j < per_texel { texel_transfer[row * per_texel + j] as f64 } else { 0.0 };
                assert!((got - want).abs() <= scale / 131_070.0 * 1.001 + 1e-7, "texel {texel} value {j}: {got} against {want}");
            }
        }
    }
    // Sun bits: exact, step 32k + 8j + b in bit b of channel j of texture k.
    for (k, texture) in meta["sun"]["textures"].as_array().unwrap().iter().enumerate() {
        let (_, _, channels, bytes) = png_samples(&gltf, blob, texture.as_u64().unwrap() as usize);
        assert_eq!(channels, 4);
        for (row, &texel) in t.texels.iter().enumerate() {
            for step in 32 * k..(32 * k + 32).min(sun.step_count()) {
                let (j, bit) = ((step % 32) / 8, step % 8);
                assert_eq!((bytes[texel as usize * 4 + j] >> bit) & 1 == 1, sun.texel_bit(row, step), "texel {texel}, step {step}");
            }
        }
    }
    // Sunlit fractions: step 8k + 2j + h in nibble h of channel j of fraction texture k.
    let fractions = meta["sun"]["fraction_textures"].as_array().unwrap();
    assert_eq!(fractions.len(), 5);
    let mut partial = 0;
    for (k, texture) in fractions.iter().enumerate() {
        let (_, _, channels, bytes) = png_samples(&gltf, blob, texture.as_u64().unwrap() as usize);
        assert_eq!(channels, 4);
        for (row, &texel) in t.texels.iter().enumerate() {
            for step in 8 * k..(8 * k + 8).min(sun.step_count()) {
                let (j, h) = ((step % 8) / 2, step % 2);
                let nibble = (bytes[texel as usize * 4 + j] >> (4 * h)) & 0xF;
                assert_eq!(nibble as f32 / 15.0, sun.texel_sun(row, step), "texel {texel}, step {step}");
                partial += usize::from(nibble != 0 && nibble != 15);
            }
        }
    }
    assert!(partial > 0, "no texel was partly sunlit: the fractions were not tested");
}

/// With the sun's bits on an atlas of their own (TSAT), the export splits the
/// vertices along both atlases' seams: every written vertex is a triangle
/// corner of the bundle with its position in each atlas (TEXCOORD_1 and
/// TEXCOORD_2), each corner once; the sun textures are the sun
/// atlas's size, its coverage exact and its bits exact on its texels.
#[test]
fn a_sun_atlas_of_its_own_exports_on_a_second_texture_coordinate() {
    let dir = Scratch::new("export-sun-atlas");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &shapes::room_with_walls_running_past()).unwrap();
    let (baked, sunned, out) = (dir.path("t.prtb"), dir.path("ts.prtb"), dir.path("t.glb"));
    let bake =
        ["bake", obj.to_str().unwrap(), "-o", baked.to_str().unwrap(), "--rays", "8", "--bounces", "0", "--texel-size", "0.25", "--quiet"];
    let o = prtbake(&bake);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sun = ["sun", baked.to_str().unwrap(), "-o", sunned.to_str().unwrap(), "--steps", "12", "--texel-size", "0.1", "--quiet"];
    let o = prtbake(&sun);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = prtbake(&["export", sunned.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let b = bundle::read_bundle(&sunned).unwrap();
    let (t, series) = (b.texels.as_ref().unwrap(), b.sun.as_ref().unwrap());
    let own = series.texel_atlas.as_ref().expect("TSAT");
    let (atlas, sun_atlas) = (&t.atlas, &own.atlas);
    assert!(own.texels.len() > 2 * t.texels.len());
    // Each bundle triangle corner: (position, atlas position, sun atlas position), as bits.
    let key = |p: [f32; 3], a: [f32; 2], s: [f32; 2]| {
        (p.map(f32::to_bits), a.map(|x| (x * 1e3).round() as i64), s.map(|x| (x * 1e3).round() as i64))
    };
    let mut corners = std::collections::HashSet::new();
    for (c, &v) in b.mesh.indices.iter().enumerate() {
        let (a, s) = (atlas.uv[atlas.indices[c] as usize], sun_atlas.uv[sun_atlas.indices[c] as usize]);
        corners.insert(key(b.mesh.positions[v as usize].to_array(), a.to_array(), s.to_array()));
    }
    let bytes = std::fs::read(&out).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid GLB");
    let blob = gltf.blob.as_deref().unwrap();
    let mut written = std::collections::HashSet::new();
    for mesh in gltf.meshes() {
        let primitive = mesh.primitives().next().unwrap();
        let reader = primitive.reader(|_| Some(blob));
        let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        let uvs: Vec<[f32; 2]> = reader.read_tex_coords(1).expect("TEXCOORD_1").into_f32().collect();
        let sun_uvs: Vec<[f32; 2]> = reader.read_tex_coords(2).expect("TEXCOORD_2").into_f32().collect();
        let mut in_this_mesh = std::collections::HashSet::new();
        for i in 0..positions.len() {
            let a = [uvs[i][0] * atlas.width as f32, uvs[i][1] * atlas.height as f32];
            let s = [sun_uvs[i][0] * sun_atlas.width as f32, sun_uvs[i][1] * sun_atlas.height as f32];
            let k = key(positions[i], a, s);
            assert!(corners.contains(&k), "written vertex {i} is no corner of the bundle: {k:?}");
            written.insert(k);
            in_this_mesh.insert(k);
        }
        assert_eq!(in_this_mesh.len(), positions.len(), "a corner written twice in one mesh");
    }
    assert_eq!(written.len(), corners.len(), "every corner written");
    let extras: serde_json::Value = serde_json::from_str(gltf.document.as_json().extras.as_ref().unwrap().get()).unwrap();
    let meta = &extras["prtbake"]["texels"]["sun"];
    assert_eq!(meta["atlas"]["uv"], "TEXCOORD_2");
    let (w, h) = (sun_atlas.width, sun_atlas.height);
    let (cw, ch, _, coverage) = png_samples(&gltf, blob, meta["atlas"]["coverage_texture"].as_u64().unwrap() as usize);
    assert_eq!((cw, ch), (w, h));
    assert_eq!((0..w * h).filter(|&i| coverage[i as usize] == 255).collect::<Vec<_>>(), own.texels);
    let (sw, sh, _, bits) = png_samples(&gltf, blob, meta["textures"][0].as_u64().unwrap() as usize);
    assert_eq!((sw, sh), (w, h));
    let mut lit = 0;
    for (row, &texel) in own.texels.iter().enumerate() {
        for step in 0..series.step_count() {
            let (j, bit) = (step / 8, step % 8);
            assert_eq!((bits[texel as usize * 4 + j] >> bit) & 1 == 1, series.texel_bit(row, step), "texel {texel}, step {step}");
            lit += usize::from(series.texel_bit(row, step));
        }
    }
    assert!(lit > 0, "no sun texel lit: the bits were not tested");
}

/// A second atlas (`TEXCOORD_2`) is refused, naming the file, when the mesh
/// has no first one, when it does not give one position per vertex, or
/// when a position is not finite; nothing is written. With one finite
/// position per vertex beside the first atlas it is written.
#[test]
fn a_second_lightmap_uv_set_is_checked_before_writing() {
    use glam::Vec2;
    use prtbake::mesh::{write_glb_with, GlbAdditions};
    let dir = Scratch::new("export-second-uvs");
    let plain = shapes::plane_grid(2, 1.0);
    let n = plain.vertex_count();
    let mut with_atlas = plain.clone();
    with_atlas.lightmap_uvs = (0..n).map(|v| Vec2::new(v as f32 / n as f32, 0.5)).collect();
    let good: Vec<Vec2> = (0..n).map(|v| Vec2::new(0.25, v as f32 / n as f32)).collect();
    let mut not_finite = good.clone();
    not_finite[3].y = f32::NAN;
    let cases: [(&str, &Mesh, &[Vec2], &str); 3] = [
        ("no-first-atlas", &plain, &good, "TEXCOORD_2 needs TEXCOORD_1 and one per vertex"),
        ("one-short", &with_atlas, &good[..n - 1], "TEXCOORD_2 needs TEXCOORD_1 and one per vertex"),
        ("nan", &with_atlas, &not_finite, "second lightmap UV of vertex 3 is not finite"),
    ];
    for (name, mesh, uvs, expected) in cases {
        let path = dir.path(&format!("{name}.glb"));
        let additions = GlbAdditions { second_lightmap_uvs: uvs, ..GlbAdditions::default() };
        let message = write_glb_with(&path, mesh, additions).expect_err(name).to_string();
        assert!(message.contains(expected) && message.contains(&format!("{name}.glb")), "{name}: {message}");
        assert!(!path.exists(), "{name}: a refused GLB was written");
    }
    let path = dir.path("good.glb");
    write_glb_with(&path, &with_atlas, GlbAdditions { second_lightmap_uvs: &good, ..GlbAdditions::default() }).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = gltf.blob.as_deref().unwrap();
    let mut read = Vec::new();
    for mesh in gltf.meshes() {
        for primitive in mesh.primitives() {
            read.extend(primitive.reader(|_| Some(blob)).read_tex_coords(2).expect("TEXCOORD_2").into_f32().map(Vec2::from));
        }
    }
    assert_eq!(read.len(), n, "the writer may split nothing on a plane");
    for uv in &read {
        assert!(good.contains(uv), "{uv:?} is none of the given positions");
    }
}
