//! Window mode's enclosure rule (docs/conventions.md "Window mode, outside
//! sides"): a side of a point (the half-sphere in front of or behind its
//! face) is outside the enclosure when more of its rays escape to the sky
//! without meeting glass than meet opaque surfaces. Light through glass does
//! not count on such a side: the outer face of a wall would otherwise see a
//! pane in front of its opening from behind and glow, and pass the glow into
//! the room through shared vertices. The transfer bake decides from its own
//! cosine rays; the sun bake, which traces one ray per step, from
//! [`SIDE_PROBE_RAYS`] fixed directions.

use glam::Vec3;

use super::surfaces::Surfaces;
use super::DirectionPattern;
use crate::sampling::{cosine_hemisphere, sample_2d};
use crate::trace::scene::Scene;

/// Per side of a point (0 front, 1 back of its face), how many of its rays
/// escaped to the sky without meeting glass and how many met an opaque
/// surface first. The transfer bake sums them over the sample points of one
/// triangle (or one texel) before it decides: a point's own ~32 rays a side
/// are too few where a side sees a little open sky through a gap.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sides {
    pub escaped: [u32; 2],
    pub opaque: [u32; 2],
}

impl Sides {
    /// Side 0 or 1 of a direction leaving a face.
    #[inline]
    pub fn of(face_normal: Vec3, direction: Vec3) -> usize {
        (face_normal.dot(direction) < 0.0) as usize
    }

    /// Counts one ray of `side` by what it met first (`None`: the sky).
    #[inline]
    pub fn count(&mut self, side: usize, surfaces: &Surfaces, hit: Option<u32>) {
        match hit {
            None => self.escaped[side] += 1,
            Some(t) if surfaces.window_transmittance[t as usize].is_none() => self.opaque[side] += 1,
            Some(_) => {}
        }
    }

    /// Adds another point's counts (the verdict pooled over several points).
    #[inline]
    pub fn add(&mut self, other: &Sides) {
        for side in 0..2 {
            self.escaped[side] += other.escaped[side];
            self.opaque[side] += other.opaque[side];
        }
    }

    /// Inside a cabin or room the sky is seen through windows and, where the
    /// model leaks or a window is open, through gaps that are a small part of
    /// what a side sees; the outer face of a wall, or a car's body, sees open
    /// sky and glass and little else.
    pub fn outside(&self, side: usize) -> bool {
        self.escaped[side] > self.opaque[side]
    }
}

/// Directions the sun bake probes a side with: cosine-distributed over the
/// side's half-sphere, the same Sobol set for every point (a verdict, not an
/// estimate: it need not vary from point to point).
pub(crate) const SIDE_PROBE_RAYS: u32 = 32;

/// Whether `side` of the point at `position` on a face with normal
/// `face_normal` is outside the enclosure, from [`SIDE_PROBE_RAYS`] rays.
pub(crate) fn side_is_outside(scene: &Scene, surfaces: &Surfaces, position: Vec3, face_normal: Vec3, side: usize) -> bool {
    let axis = if side == 0 { face_normal } else { -face_normal };
    let mut sides = Sides::default();
    for k in 0..SIDE_PROBE_RAYS {
        let (u1, u2) = sample_2d(DirectionPattern::Sobol, k, 0, 0);
        let direction = cosine_hemisphere(axis, u1, u2);
        let origin = scene.offset_origin(position, face_normal, direction);
        let hit = scene.closest_hit(origin, direction, f32::INFINITY).map(|h| h.triangle);
        sides.count(side, surfaces, hit);
    }
    sides.outside(side)
}
