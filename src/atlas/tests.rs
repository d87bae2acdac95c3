use super::coverage::{clip_to_texel, polygon_area, Coverage};
use super::*;
use crate::verify::shapes;

fn uv_area(atlas: &Atlas, t: usize) -> f64 {
    let [a, b, c] = atlas.triangle_uv(t).map(|p| p.as_dvec2());
    0.5 * (b - a).perp_dot(c - a).abs()
}

fn world_area(mesh: &Mesh, t: usize) -> f64 {
    let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

/// A plane (one flat chart) and a sphere (curved charts) side by side.
fn plane_and_sphere() -> Mesh {
    let mut mesh = shapes::plane_grid(6, 2.0);
    let mut sphere = shapes::icosphere(2);
    shapes::transform(&mut sphere, 0.5, glam::Vec3::new(0.0, 0.6, 0.0));
    shapes::append(&mut mesh, &sphere);
    mesh
}

#[test]
fn a_flat_chart_keeps_the_texel_size() {
    // On a plane the unwrap is a rigid map: each triangle's area in texels
    // is its world area over the texel's (xatlas packs at the scale asked).
    let mesh = shapes::plane_grid(6, 2.0);
    let size = 0.05;
    let atlas = Atlas::unwrap(&mesh, size).unwrap();
    assert_eq!(atlas.triangle_count(), mesh.triangle_count());
    for t in 0..mesh.triangle_count() {
        let expected = world_area(&mesh, t) / (size as f64).powi(2);
        assert!((uv_area(&atlas, t) / expected - 1.0).abs() < 1e-3, "triangle {t}: {} texels, expected {expected}", uv_area(&atlas, t));
    }
    // 2 m at 5 cm: 40 texels across, plus the padding.
    assert!(atlas.width >= 40 && atlas.width <= 40 + 4 * PADDING + 2, "{} x {}", atlas.width, atlas.height);
    assert!(atlas.uv.iter().all(|p| p.x >= 0.0 && p.y >= 0.0 && p.x <= atlas.width as f32 && p.y <= atlas.height as f32));
}

#[test]
fn coverage_conserves_each_triangles_area_and_misses_no_texel() {
    let mesh = plane_and_sphere();
    let atlas = Atlas::unwrap(&mesh, 0.04).unwrap();
    let cover = Coverage::of(&atlas);
    let mut summed = vec![0.0f64; atlas.triangle_count()];
    for i in 0..cover.len() {
        for e in cover.start[i] as usize..cover.start[i + 1] as usize {
            summed[cover.triangle[e] as usize] += cover.area[e] as f64;
            assert!(cover.area[e] > 0.0 && cover.area[e] <= 1.0 + 1e-6, "area {}", cover.area[e]);
        }
    }
    for t in 0..atlas.triangle_count() {
        let a = uv_area(&atlas, t);
        assert!((summed[t] - a).abs() <= 1e-5 * a.max(1.0), "triangle {t}: texels sum to {}, triangle {a}", summed[t]);
    }
    // Points inside each triangle fall in a texel listed for it.
    let listed = |texel: u32, t: u32| {
        cover.texels.binary_search(&texel).is_ok_and(|i| cover.triangle[cover.start[i] as usize..cover.start[i + 1] as usize].contains(&t))
    };
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    for t in 0..atlas.triangle_count() {
        let [a, b, c] = atlas.triangle_uv(t);
        for _ in 0..16 {
            let (mut u, mut v) = (next(), next());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let p = a + (b - a) * u + (c - a) * v;
            let texel = p.y.floor() as u32 * atlas.width + p.x.floor() as u32;
            assert!(listed(texel, t as u32), "triangle {t}: point {p} in texel {texel}, not listed");
        }
    }
}

#[test]
fn no_texel_is_shared_by_two_charts() {
    let mesh = plane_and_sphere();
    let atlas = Atlas::unwrap(&mesh, 0.04).unwrap();
    assert!(atlas.chart_count >= 2, "{} charts", atlas.chart_count);
    let cover = Coverage::of(&atlas);
    for i in 0..cover.len() {
        let tris = &cover.triangle[cover.start[i] as usize..cover.start[i + 1] as usize];
        let chart = atlas.triangle_chart[tris[0] as usize];
        assert!(tris.iter().all(|&t| atlas.triangle_chart[t as usize] == chart), "texel {} has charts of {tris:?}", cover.texels[i]);
    }
}

#[test]
fn the_same_mesh_gives_the_same_atlas() {
    let mesh = plane_and_sphere();
    let first = Atlas::unwrap(&mesh, 0.04).unwrap();
    let again = std::thread::spawn(move || Atlas::unwrap(&mesh, 0.04).unwrap()).join().unwrap();
    assert_eq!(first, again);
}

#[test]
fn bad_texel_sizes_and_empty_meshes_are_refused() {
    let mesh = shapes::plane_grid(2, 2.0);
    for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(matches!(Atlas::unwrap(&mesh, bad), Err(AtlasError::BadTexelSize(_))), "{bad}");
    }
    // 4 m² at 0.1 mm: 4e8 texels, refused before unwrapping, naming a size that fits.
    match Atlas::unwrap(&mesh, 1e-4) {
        Err(AtlasError::TooManyTexels { fits, .. }) => {
            assert!(fits > 1e-4 && (4.0 / (fits as f64).powi(2)) <= MAX_TEXELS * 1.001, "{fits}")
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(Atlas::unwrap(&Mesh::default(), 0.1), Err(AtlasError::Empty));
}

#[test]
fn clipping_a_triangle_to_texels_adds_up() {
    // A right triangle with legs of 3 texels: 4.5 texels² over 9 texels.
    let tri = [Vec2::new(0.0, 0.0), Vec2::new(3.0, 0.0), Vec2::new(0.0, 3.0)];
    let total: f64 = (0..3).flat_map(|y| (0..3).map(move |x| (x, y))).map(|(x, y)| polygon_area(&clip_to_texel(tri, x, y))).sum();
    assert!((total - 4.5).abs() < 1e-12, "{total}");
    assert!((polygon_area(&clip_to_texel(tri, 0, 0)) - 1.0).abs() < 1e-12);
    assert!((polygon_area(&clip_to_texel(tri, 1, 1)) - 0.5).abs() < 1e-12);
    assert_eq!(polygon_area(&clip_to_texel(tri, 2, 2)), 0.0);
}

/// Lightmap coordinates of the 2 m planes below: `offset + scale · (position + 1)`.
fn lightmap_of(p: glam::Vec3, offset: Vec2, scale: f32) -> Vec2 {
    offset + scale * (Vec2::new(p.x, p.z) + Vec2::ONE)
}

/// Two 2 m planes 3 m apart, each one chart of its own lightmap at `offsets`, `scale` per metre.
fn two_planes_with_lightmap(offsets: [Vec2; 2], scale: f32) -> Mesh {
    let mut mesh = shapes::plane_grid(2, 2.0);
    let mut other = shapes::plane_grid(2, 2.0);
    shapes::transform(&mut other, 1.0, glam::Vec3::new(3.0, 0.0, 0.0));
    shapes::append(&mut mesh, &other);
    let half = mesh.vertex_count() / 2;
    mesh.lightmap_uvs = (0..mesh.vertex_count())
        .map(|v| {
            let local = mesh.positions[v] - if v < half { glam::Vec3::ZERO } else { glam::Vec3::new(3.0, 0.0, 0.0) };
            lightmap_of(local, offsets[usize::from(v >= half)], scale)
        })
        .collect();
    mesh
}

#[test]
fn a_mesh_with_its_own_lightmap_coordinates_keeps_its_atlas() {
    let mut mesh = shapes::plane_grid(2, 2.0);
    mesh.lightmap_uvs = mesh.positions.iter().map(|&p| lightmap_of(p, Vec2::splat(0.125), 0.25)).collect();
    // 4 m² on a quarter of the atlas at 10 cm: 40 texels across, the layout scaled as authored.
    let atlas = Atlas::for_mesh(&mesh, 0.1, false).unwrap();
    assert_eq!((atlas.width, atlas.height, atlas.chart_count), (40, 40, 1));
    assert_eq!(atlas.indices, mesh.indices);
    assert_eq!(atlas.source_vertex, (0..mesh.vertex_count() as u32).collect::<Vec<_>>());
    for (v, uv) in atlas.uv.iter().enumerate() {
        assert!(uv.abs_diff_eq(mesh.lightmap_uvs[v] * 40.0, 1e-4), "vertex {v}: {uv}");
    }
    for t in 0..mesh.triangle_count() {
        let expected = world_area(&mesh, t) / 0.01;
        assert!((uv_area(&atlas, t) / expected - 1.0).abs() < 1e-4, "triangle {t}");
    }
    // Covered texels: exactly the chart's 20 × 20 (it spans texels 5..25 on each axis).
    assert_eq!(Coverage::of(&atlas).len(), 400);
    // --unwrap: xatlas's atlas instead.
    let unwrapped = Atlas::for_mesh(&mesh, 0.1, true).unwrap();
    assert_eq!(unwrapped, Atlas::unwrap(&mesh, 0.1).unwrap());
    assert_ne!(unwrapped.uv, atlas.uv);
    // Without lightmap coordinates: xatlas.
    mesh.lightmap_uvs.clear();
    assert_eq!(Atlas::for_mesh(&mesh, 0.1, false).unwrap(), unwrapped);
}

#[test]
fn lightmap_coordinates_that_would_mix_two_places_are_refused() {
    // Outside the unit square.
    let mut mesh = shapes::plane_grid(2, 2.0);
    mesh.lightmap_uvs = mesh.positions.iter().map(|&p| lightmap_of(p, Vec2::splat(0.8), 0.25)).collect();
    assert!(matches!(Atlas::from_lightmap_uvs(&mesh, 0.1), Err(AtlasError::LightmapOutside { .. })));
    // All on one point: no area.
    mesh.lightmap_uvs = vec![Vec2::splat(0.5); mesh.vertex_count()];
    assert_eq!(Atlas::from_lightmap_uvs(&mesh, 0.1), Err(AtlasError::LightmapEmpty));
    // One row of the grid folded onto a line: its triangles would have no texel.
    mesh.lightmap_uvs = mesh.positions.iter().map(|&p| lightmap_of(p, Vec2::splat(0.125), 0.25)).collect();
    let row: Vec<usize> = (0..mesh.vertex_count()).filter(|&v| mesh.positions[v].z > 0.5).collect();
    row.iter().for_each(|&v| mesh.lightmap_uvs[v].y = 0.375);
    match Atlas::from_lightmap_uvs(&mesh, 0.1) {
        Err(AtlasError::LightmapFolded { triangles, .. }) => assert_eq!(triangles, 4),
        other => panic!("a folded row: {other:?}"),
    }
    // Two planes on the same spot of the atlas: every covered texel is under both.
    let stacked = two_planes_with_lightmap([Vec2::splat(0.25); 2], 0.125);
    match Atlas::from_lightmap_uvs(&stacked, 0.1) {
        Err(AtlasError::LightmapShared { shared, .. }) => assert!(shared > 0),
        other => panic!("stacked charts: {other:?}"),
    }
    // Charts 1/16 apart (each 1/4 wide; 8 m² on 1/8 of the atlas: 8 / L
    // texels across): at 10 cm 5 texels apart, kept; at 1 m half a texel
    // apart, so their border texels touch and bilinear reads would blend them.
    let apart = two_planes_with_lightmap([Vec2::new(0.0, 0.25), Vec2::new(0.3125, 0.25)], 0.125);
    let kept = Atlas::from_lightmap_uvs(&apart, 0.1).unwrap();
    assert_eq!((kept.width, kept.chart_count), (80, 2));
    match Atlas::from_lightmap_uvs(&apart, 1.0) {
        Err(AtlasError::LightmapShared { shared: 0, beside, .. }) => assert!(beside > 0),
        other => panic!("charts half a texel apart: {other:?}"),
    }
}
