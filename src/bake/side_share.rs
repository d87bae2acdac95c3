//! Window mode's two sides of a receiver. A window-mode point traces the
//! whole sphere, so its transfer holds the light that reached it through
//! the front of its face and through the back. A single-layer wall between
//! a pane and a room is lit through the pane on its outer face only; drawn
//! from the room with the sum, it glows. The bake keeps, per receiver and
//! bounce, the part of the DC that came through the back (`Moments::wb`,
//! whose sums whole bakes and merged shards make alike), and stores the
//! front side's share of the total DC. A viewer draws the side it sees with
//! the transfer scaled by that side's share (docs/conventions.md "Window
//! mode, one side's light"): exact where one side holds all the light (the
//! common case: a closed solid's back faces its inside), and right in DC
//! where both hold some.

use super::noise::Moments;

/// The part of a receiver's transfer one side of its face shows: its front
/// share from the front, the rest from behind; all of it without a share.
pub fn seen_side_share(front_share: Option<f32>, seen_front: bool) -> f32 {
    match front_share {
        Some(share) if seen_front => share,
        Some(share) => 1.0 - share,
        None => 1.0,
    }
}

/// Adds one bounce's back-side DC per receiver, Σ w·b / Σ w (0 without
/// weight), to `back` (empty: becomes the bounce's).
pub(crate) fn add_back_dc(back: &mut Vec<f32>, weights: &[f32], moments: &[Moments]) {
    if back.is_empty() {
        back.resize(moments.len(), 0.0);
    }
    for ((b, m), &w) in back.iter_mut().zip(moments).zip(weights) {
        if w > 0.0 {
            *b += (m.wb / f64::from(w)) as f32;
        }
    }
}

/// Each receiver's front-side share of its light: 1 − back / DC, the DC the
/// mean over `channels` of coefficient 0 of `total` (`[receiver][channel][coeff]`),
/// clamped to [0, 1]; 1 where the receiver holds no light. None (empty)
/// outside window mode, whose points see one side only.
pub(crate) fn front_shares(mode: super::Mode, back: &[f32], total: &[f32], channels: usize, coeffs: usize) -> Vec<f32> {
    if mode != super::Mode::Window {
        return Vec::new();
    }
    let stride = channels * coeffs;
    back.iter()
        .zip(total.chunks_exact(stride))
        .map(|(&b, row)| {
            let dc = (0..channels).map(|c| f64::from(row[c * coeffs])).sum::<f64>() / channels as f64;
            if dc > 0.0 {
                (1.0 - f64::from(b) / dc).clamp(0.0, 1.0) as f32
            } else {
                1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_share_is_the_front_part_of_the_dc_over_the_bounces() {
        // Two receivers, two bounces, 3 channels of order 1.
        let weights = [2.0f32, 0.0];
        let mut first = Moments::default();
        first.add(2.0, 0.0, 0.25);
        let mut back = Vec::new();
        add_back_dc(&mut back, &weights, &[first, Moments::default()]);
        add_back_dc(&mut back, &weights, &[first, Moments::default()]);
        assert_eq!(back, vec![0.5, 0.0]);
        // Receiver 0's DC is 2 in every channel: a quarter came through the back.
        let total = [2.0f32, 2.0, 2.0, 0.0, 0.0, 0.0];
        assert_eq!(front_shares(Mode::Window, &back, &total, 3, 1), vec![0.75, 1.0]);
        // Rounding past the DC stays a share.
        assert_eq!(front_shares(Mode::Window, &[2.5], &[2.0, 2.0, 2.0], 3, 1), vec![0.0]);
        assert_eq!(front_shares(Mode::Window, &[-0.1], &[2.0, 2.0, 2.0], 3, 1), vec![1.0]);
        assert!(front_shares(Mode::Open, &back, &total, 3, 1).is_empty());
    }

    use crate::bake::{BakeParams, Mode, Surfaces};
    use crate::mesh::{Material, MaterialRole, Mesh};
    use crate::trace::{BuildQuality, Scene};
    use crate::verify::shapes;
    use glam::Vec3;

    /// A closed 2 m box whose top is a pane of transmittance 0.8 and whose
    /// bottom is one of 0.2, with a 1 m single-layer sheet (facing up)
    /// across its middle: each side of the sheet sees one pane, alike.
    fn sheet_between_panes() -> Mesh {
        let mut mesh = shapes::plane_grid(4, 1.0);
        mesh.materials[0].albedo = [0.5; 3];
        let pane = |name: &str, tau: f32| Material { name: name.into(), albedo: [0.0; 3], role: MaterialRole::Window, transmittance: tau };
        mesh.materials.extend([Material::opaque("wall", 0.5), pane("top", 0.8), pane("bottom", 0.2)]);
        let quad = |mesh: &mut Mesh, c: [Vec3; 4], material: u16| shapes::push_quad(mesh, c, material, 0);
        let v = Vec3::new;
        // Every face toward the inside.
        quad(&mut mesh, [v(-1., 1., -1.), v(1., 1., -1.), v(1., 1., 1.), v(-1., 1., 1.)], 2);
        quad(&mut mesh, [v(-1., -1., -1.), v(-1., -1., 1.), v(1., -1., 1.), v(1., -1., -1.)], 3);
        quad(&mut mesh, [v(-1., -1., -1.), v(1., -1., -1.), v(1., 1., -1.), v(-1., 1., -1.)], 1);
        quad(&mut mesh, [v(-1., -1., 1.), v(-1., 1., 1.), v(1., 1., 1.), v(1., -1., 1.)], 1);
        quad(&mut mesh, [v(-1., -1., -1.), v(-1., 1., -1.), v(-1., 1., 1.), v(-1., -1., 1.)], 1);
        quad(&mut mesh, [v(1., -1., -1.), v(1., -1., 1.), v(1., 1., 1.), v(1., 1., -1.)], 1);
        mesh.validate().expect("a valid box");
        mesh
    }

    /// Bounce 0 of the sheet: its two sides see their panes alike, so the
    /// front (upper) side's share is 0.8 / (0.8 + 0.2) at every vertex and
    /// texel, whatever the noise of the two estimates.
    #[test]
    fn a_sheet_between_two_panes_splits_its_light_as_their_transmittances() {
        let mesh = sheet_between_panes();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let params = BakeParams { rays: 256, bounces: 0, mode: Mode::Window, window_sampling: true, ..BakeParams::default() };
        let atlas = crate::atlas::Atlas::unwrap(&mesh, 0.1).unwrap();
        let (vertices, texels) = crate::bake::texels::bake_texels(&mesh, &scene, &surfaces, &params, atlas, 4).unwrap();
        let stride = vertices.channels * crate::sh::coeff_count(params.order);
        assert_eq!(vertices.front_share.len(), mesh.vertex_count());
        for v in 0..25 {
            assert!(vertices.total[v * stride] > 0.0, "vertex {v} holds light");
            assert!((vertices.front_share[v] - 0.8).abs() < 0.03, "vertex {v}: front share {}", vertices.front_share[v]);
        }
        // The sheet's texels: those of its triangles' charts.
        let sheet_triangles = 0..32;
        let coverage = crate::atlas::coverage::Coverage::of(&texels.atlas);
        let mut checked = 0;
        assert_eq!(coverage.texels, texels.texels);
        for i in 0..coverage.texels.len() {
            let on_sheet = sheet_triangles.contains(&(coverage.triangle[coverage.start[i] as usize] as usize));
            if !on_sheet || texels.total[i * stride] <= 0.0 {
                continue;
            }
            assert!((texels.front_share[i] - 0.8).abs() < 0.05, "texel {i}: front share {}", texels.front_share[i]);
            checked += 1;
        }
        assert!(checked > 50, "{checked} sheet texels checked");
        // Open mode keeps no sides.
        let open = crate::bake::bake_transfer(&mesh, &scene, &surfaces, &BakeParams { mode: Mode::Open, ..params }).unwrap();
        assert!(open.front_share.is_empty());
    }

    /// A closed sphere in the box of panes, baked with bounces: a bounce's
    /// ray that leaves a point on the sphere through its back meets the
    /// sphere's inside, a back face, whose side holds no light (the bounce
    /// before lit only the outside). So no light comes through the back in
    /// any bounce: front share 1 at every lit vertex. Gathering the hit
    /// triangle's light of both sides instead, the inside returns the
    /// outside's light: vertices then took up to 26% of theirs through the back.
    #[test]
    fn a_closed_solid_takes_no_light_through_its_inside_in_any_bounce() {
        let mut mesh = sheet_between_panes();
        // The sheet's 32 triangles out, a closed sphere (outward faces) in.
        let sheet_vertices = 25;
        mesh.indices.drain(..32 * 3);
        mesh.tri_material.drain(..32);
        mesh.tri_group.drain(..32);
        mesh.indices.iter_mut().for_each(|i| *i -= sheet_vertices);
        mesh.positions.drain(..sheet_vertices as usize);
        mesh.normals.drain(..sheet_vertices as usize);
        let mut sphere = shapes::icosphere(2);
        shapes::transform(&mut sphere, 0.4, Vec3::ZERO);
        sphere.materials[0].albedo = [0.8; 3];
        let first = mesh.vertex_count();
        shapes::append(&mut mesh, &sphere);
        let sphere_vertices = first..mesh.vertex_count();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let params = BakeParams { rays: 64, bounces: 2, mode: Mode::Window, store_bounces: true, ..BakeParams::default() };
        let result = crate::bake::bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
        let stride = result.channels * crate::sh::coeff_count(params.order);
        let mut checked = 0;
        for v in sphere_vertices {
            assert!(result.bounces[1][v * stride] > 0.0, "vertex {v} takes bounce light");
            assert!(result.front_share[v] > 1.0 - 1e-5, "sphere vertex {v}: front share {}", result.front_share[v]);
            checked += 1;
        }
        assert!(checked > 100);
    }

    /// The window-halo room with the outer sides kept: the front wall's
    /// outer face, between the wall and the pane outside its opening, is
    /// lit through the pane; its inner face sees only the room. In bounce 0
    /// every lit wall vertex's light came through its back: front share 0.
    #[test]
    fn a_wall_lit_from_outside_holds_its_light_on_the_outer_side() {
        let (mesh, wall) = shapes::room_with_pane_outside_opening();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let params = BakeParams { rays: 64, bounces: 0, mode: Mode::Window, keep_outside_sides: true, ..BakeParams::default() };
        let result = crate::bake::bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
        let stride = result.channels * crate::sh::coeff_count(params.order);
        let dc = |v: usize| result.total[v * stride];
        let lit: Vec<usize> = wall.filter(|&v| dc(v) > 1e-4).collect();
        assert!(lit.len() >= 8, "{} wall vertices lit through the pane", lit.len());
        for v in lit {
            // 0 but for the rounding of the sums the two are made of.
            assert!(result.front_share[v] < 1e-5, "wall vertex {v} (DC {}): front share {}", dc(v), result.front_share[v]);
        }
        // The floor, lit through the opening from above: by its front.
        let floor_lit: Vec<usize> = (0..289).filter(|&v| dc(v) > 1e-3).collect();
        assert!(!floor_lit.is_empty());
        assert!(floor_lit.iter().all(|&v| result.front_share[v] > 1.0 - 1e-5));
    }
}
