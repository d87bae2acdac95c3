//! The triangles of each BVH leaf as one struct-of-arrays block, tested a
//! whole leaf (up to eight triangles) per AVX pass.
//!
//! A leaf of `n` triangles is 12 rows of `n` floats: v0, e1 = v0 − v1,
//! e2 = v2 − v0 and ng = e1 × e2 (obvhs `RtTriangle`'s precomputed form),
//! x, y, z each. Rows are exactly `n` wide, so a leaf of one triangle costs
//! 48 bytes, not a padded eight-lane block (padded 4-wide blocks measured
//! slower: docs/performance.md); a lane past `n` reads the next row and is
//! masked off. Testing a leaf costs the same whatever `n` ≤ 8, which is why
//! the BVH uses leaves of up to eight triangles (`scene::LEAF_TRIANGLES`).
//! The test is obvhs's Möller–Trumbore with the same operations in the same
//! order and no fused multiply-add, so every lane gives the bits
//! `RtTriangle::intersect` gives for that triangle: the SIMD and portable
//! paths, and the brute-force oracle, agree exactly.

use obvhs::{ray::Ray, rt_triangle::RtTriangle};

/// Floats per triangle in a block.
pub const ROWS: usize = 12;
/// Most triangles one block holds (lanes of one AVX register).
pub const MAX_LANES: u32 = 8;
/// Floats past the last block that an eight-lane read of a short row may touch.
const TAIL: usize = MAX_LANES as usize;

/// All leaves' blocks, back to back in leaf order: the block of the leaf
/// whose triangles start at leaf-order position `first` begins at float
/// `ROWS · first`.
pub struct LeafBlocks {
    data: Vec<f32>,
    /// Per triangle in leaf order: `lane << 4 | leaf count`.
    place: Vec<u8>,
}

/// A leaf test's answer: `mask` has bit `k` set when lane `k` is hit within
/// `[t_min, t_max]` (and at a finite distance); `t` holds each lane's distance
/// and `back` has bit `k` set when the ray meets lane `k`'s back face.
#[derive(Clone, Copy, Debug, Default)]
pub struct LeafHits {
    pub mask: u32,
    pub back: u32,
    pub t: [f32; MAX_LANES as usize],
}

impl LeafBlocks {
    /// Packs `triangles` (in leaf order) into blocks; `leaves` lists every
    /// leaf as `(first, count)`, covering `0..triangles.len()` exactly once.
    pub fn new(triangles: &[RtTriangle], leaves: impl IntoIterator<Item = (u32, u32)>) -> LeafBlocks {
        let mut data = vec![0.0f32; ROWS * triangles.len() + TAIL];
        let mut place = vec![u8::MAX; triangles.len()];
        for (first, count) in leaves {
            assert!((1..=MAX_LANES).contains(&count), "leaf of {count} triangles");
            let base = ROWS * first as usize;
            let n = count as usize;
            for lane in 0..n {
                let tri = &triangles[first as usize + lane];
                for (k, v) in [tri.v0, tri.e1, tri.e2, tri.ng].iter().enumerate() {
                    for axis in 0..3 {
                        data[base + (3 * k + axis) * n + lane] = v[axis];
                    }
                }
                place[first as usize + lane] = (lane as u8) << 4 | count as u8;
            }
        }
        assert!(place.iter().all(|&p| p != u8::MAX), "a triangle in no leaf");
        LeafBlocks { data: super::hugepages::copy_to_huge_pages(&data), place }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.place.len()
    }

    pub fn is_empty(&self) -> bool {
        self.place.is_empty()
    }

    /// The triangle at leaf-order position `position`, unpacked.
    #[inline]
    pub fn triangle(&self, position: u32) -> RtTriangle {
        let place = self.place[position as usize];
        let (lane, n) = ((place >> 4) as usize, (place & 0xf) as usize);
        let base = ROWS * (position as usize - lane);
        let value = |row: usize| self.data[base + row * n + lane];
        let vector = |k: usize| glam::Vec3A::new(value(3 * k), value(3 * k + 1), value(3 * k + 2));
        RtTriangle { v0: vector(0), e1: vector(1), e2: vector(2), ng: vector(3) }
    }

    /// Where the block of the leaf starting at `first` begins (a hint for
    /// prefetching: never dereferenced).
    #[inline(always)]
    pub fn block_address(&self, first: u32) -> *const u8 {
        self.data.as_ptr().wrapping_add(ROWS * first as usize).cast()
    }

    /// The block of leaf `(first, count)`, with the tail an eight-lane read
    /// may touch; `None` past the data. The walk reaches leaves through box
    /// tests on floats: should one ever pick an empty child slot (whose
    /// reference decodes far past the end), the leaf is skipped, never read.
    #[inline(always)]
    fn block(&self, first: u32, count: u32) -> Option<&[f32]> {
        let start = ROWS * first as usize;
        self.data.get(start..start + ROWS * count as usize + TAIL)
    }
}

/// Tests every triangle of one leaf against a ray.
pub trait LeafTest {
    fn test_leaf(blocks: &LeafBlocks, first: u32, count: u32, ray: &Ray, t_max: f32) -> LeafHits;
}

/// Portable path: one lane at a time, the same operations as the SIMD path.
pub struct ScalarLeaf;

impl LeafTest for ScalarLeaf {
    #[inline(always)]
    fn test_leaf(blocks: &LeafBlocks, first: u32, count: u32, ray: &Ray, t_max: f32) -> LeafHits {
        let Some(block) = blocks.block(first, count) else { return LeafHits::default() };
        let n = count as usize;
        let (o, d) = (ray.origin, ray.direction);
        let mut hits = LeafHits::default();
        for lane in 0..n {
            let row = |r: usize| block[r * n + lane];
            let (cx, cy, cz) = (row(0) - o.x, row(1) - o.y, row(2) - o.z);
            let (rx, ry, rz) = (d.y * cz - d.z * cy, d.z * cx - d.x * cz, d.x * cy - d.y * cx);
            let (e1, e2, ng) = ([row(3), row(4), row(5)], [row(6), row(7), row(8)], [row(9), row(10), row(11)]);
            let den = ng[0] * d.x + ng[1] * d.y + ng[2] * d.z;
            let inv = 1.0 / den;
            let u = (rx * e2[0] + ry * e2[1] + rz * e2[2]) * inv;
            let v = (rx * e1[0] + ry * e1[1] + rz * e1[2]) * inv;
            let w = 1.0 - u - v;
            let t = (ng[0] * cx + ng[1] * cy + ng[2] * cz) * inv;
            let inside = (u.to_bits() | v.to_bits() | w.to_bits()) & 0x8000_0000 == 0;
            let hit = inv != 0.0 && inside && t >= ray.tmin && t <= t_max && t < f32::INFINITY;
            hits.t[lane] = t;
            hits.mask |= u32::from(hit) << lane;
            hits.back |= u32::from(den < 0.0) << lane;
        }
        hits
    }
}

/// AVX path: up to eight lanes in one register. Only called from the
/// AVX2 walks (`#[target_feature(enable = "avx2")]`, runtime-detected).
#[cfg(target_arch = "x86_64")]
pub struct AvxLeaf;

#[cfg(target_arch = "x86_64")]
impl LeafTest for AvxLeaf {
    #[inline(always)]
    fn test_leaf(blocks: &LeafBlocks, first: u32, count: u32, ray: &Ray, t_max: f32) -> LeafHits {
        use std::arch::x86_64::*;
        let Some(block) = blocks.block(first, count) else { return LeafHits::default() };
        let n = count as usize;
        // SAFETY: reached only from functions compiled with AVX2 after
        // runtime detection; every read is eight floats from row start `r·n`
        // with `r ≤ 11`, which ends at most at `11n + 8 ≤ 12n + TAIL`,
        // inside `block`.
        unsafe {
            let p = block.as_ptr();
            let triangles = std::array::from_fn(|r| _mm256_loadu_ps(p.add(r * n)));
            let splat = _mm256_set1_ps;
            let origin = [splat(ray.origin.x), splat(ray.origin.y), splat(ray.origin.z)];
            let direction = [splat(ray.direction.x), splat(ray.direction.y), splat(ray.direction.z)];
            let (mask, den, t) = moller_trumbore_lanes(&triangles, origin, direction, ray.tmin, splat(t_max));
            let lanes = (1u32 << n) - 1;
            let mut hits = LeafHits {
                mask: mask & lanes,
                back: _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(den, _mm256_setzero_ps())) as u32 & lanes,
                t: [0.0; MAX_LANES as usize],
            };
            _mm256_storeu_ps(hits.t.as_mut_ptr(), t);
            hits
        }
    }
}

/// Möller–Trumbore on eight lanes, each one triangle against one ray
/// (eight triangles against a ray, or a triangle against eight rays):
/// obvhs's operations in its order without fused multiply-add, so each
/// lane gives `RtTriangle::intersect`'s bits. `triangles` holds the rows
/// v0, e1, e2, ng (x, y, z each). Returns the mask of lanes hit within
/// `[t_min, t_max]` (`t_max` per lane) at a finite distance, and each lane's determinant
/// (negative: the back face) and distance. Only called from AVX2 code.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn moller_trumbore_lanes(
    triangles: &[std::arch::x86_64::__m256; ROWS],
    origin: [std::arch::x86_64::__m256; 3],
    direction: [std::arch::x86_64::__m256; 3],
    t_min: f32,
    t_max: std::arch::x86_64::__m256,
) -> (u32, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let row = |r: usize| triangles[r];
    let splat = _mm256_set1_ps;
    let ([ox, oy, oz], [dx, dy, dz]) = (origin, direction);
    let (cx, cy, cz) = (_mm256_sub_ps(row(0), ox), _mm256_sub_ps(row(1), oy), _mm256_sub_ps(row(2), oz));
    let cross = |a: __m256, b: __m256, c: __m256, d: __m256| _mm256_sub_ps(_mm256_mul_ps(a, b), _mm256_mul_ps(c, d));
    let (rx, ry, rz) = (cross(dy, cz, dz, cy), cross(dz, cx, dx, cz), cross(dx, cy, dy, cx));
    let dot = |ax: __m256, ay: __m256, az: __m256, bx: __m256, by: __m256, bz: __m256| {
        _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ax, bx), _mm256_mul_ps(ay, by)), _mm256_mul_ps(az, bz))
    };
    let (ngx, ngy, ngz) = (row(9), row(10), row(11));
    let den = dot(ngx, ngy, ngz, dx, dy, dz);
    let inv = _mm256_div_ps(splat(1.0), den);
    let u = _mm256_mul_ps(dot(rx, ry, rz, row(6), row(7), row(8)), inv);
    let v = _mm256_mul_ps(dot(rx, ry, rz, row(3), row(4), row(5)), inv);
    let w = _mm256_sub_ps(_mm256_sub_ps(splat(1.0), u), v);
    let t = _mm256_mul_ps(dot(ngx, ngy, ngz, cx, cy, cz), inv);
    let outside = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(u, v), w)) as u32;
    // Predicates as Rust's operators: `!=` is true for NaN, the rest false.
    let valid = _mm256_and_ps(
        _mm256_and_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(inv, _mm256_setzero_ps()), _mm256_cmp_ps::<_CMP_GE_OQ>(t, splat(t_min))),
        _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max), _mm256_cmp_ps::<_CMP_LT_OQ>(t, splat(f32::INFINITY))),
    );
    (_mm256_movemask_ps(valid) as u32 & !outside, den, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    fn random_triangles(count: usize) -> Vec<RtTriangle> {
        let mut rand = crate::sampling::test_stream(7);
        (0..count)
            .map(|_| {
                let mut p = || Vec3A::new(rand() * 2.0 - 1.0, rand() * 2.0 - 1.0, rand() * 2.0 - 1.0);
                let a = p();
                RtTriangle::new(a, a + p() * 0.8, a + p() * 0.8)
            })
            .collect()
    }

    /// Leaves of 1–8 triangles; every lane of every path gives
    /// `RtTriangle::intersect`'s answer bit for bit, and unpacking gives the
    /// triangle back.
    #[test]
    fn blocks_agree_with_rt_triangle_bit_for_bit() {
        let triangles = random_triangles(1000);
        let mut leaves = Vec::new();
        let mut first = 0u32;
        while (first as usize) < triangles.len() {
            let count = (1 + first % MAX_LANES).min(triangles.len() as u32 - first);
            leaves.push((first, count));
            first += count;
        }
        let blocks = LeafBlocks::new(&triangles, leaves.iter().copied());
        for (i, tri) in triangles.iter().enumerate() {
            let back = blocks.triangle(i as u32);
            assert_eq!((back.v0, back.e1, back.e2, back.ng), (tri.v0, tri.e1, tri.e2, tri.ng));
        }
        let mut rand = crate::sampling::test_stream(99);
        let mut hit_lanes = 0;
        for k in 0..3000 {
            let o = Vec3A::new(rand() * 4.0 - 2.0, rand() * 4.0 - 2.0, rand() * 4.0 - 2.0);
            let mut d = Vec3A::new(rand() - 0.5, rand() - 0.5, rand() - 0.5);
            if k % 7 == 0 {
                d.x = 0.0;
            }
            let t_max = if k % 3 == 0 { f32::INFINITY } else { rand() * 3.0 };
            let ray = Ray::new(o, d.normalize(), 0.0, t_max);
            for &(first, count) in &leaves {
                let scalar = ScalarLeaf::test_leaf(&blocks, first, count, &ray, t_max);
                #[cfg(target_arch = "x86_64")]
                if crate::trace::bvh8::avx2_available() {
                    // SAFETY: AVX2 was detected.
                    let sse = unsafe { avx_test_leaf(&blocks, first, count, &ray, t_max) };
                    assert_eq!((scalar.mask, scalar.back), (sse.mask, sse.back));
                    for lane in 0..count as usize {
                        if scalar.mask >> lane & 1 == 1 {
                            assert_eq!(scalar.t[lane].to_bits(), sse.t[lane].to_bits());
                        }
                    }
                }
                for lane in 0..count {
                    let tri = &triangles[(first + lane) as usize];
                    let expected = tri.intersect(&Ray { tmax: t_max, ..ray });
                    let hit = scalar.mask >> lane & 1 == 1;
                    assert_eq!(hit, expected.is_finite(), "lane {lane} of leaf {first}");
                    if hit {
                        hit_lanes += 1;
                        assert_eq!(scalar.t[lane as usize].to_bits(), expected.to_bits());
                        assert_eq!(scalar.back >> lane & 1 == 1, tri.ng.dot(ray.direction) < 0.0);
                    }
                }
            }
        }
        assert!(hit_lanes > 1000, "only {hit_lanes} hits");
    }

    /// A leaf reference past the blocks (an empty child slot decodes to
    /// one) reports no hit on either path instead of reading out of range.
    #[test]
    fn a_leaf_past_the_blocks_reports_no_hit() {
        let triangles = random_triangles(5);
        let blocks = LeafBlocks::new(&triangles, [(0, 5)]);
        let ray = Ray::new(Vec3A::ZERO, Vec3A::X, 0.0, f32::INFINITY);
        for (first, count) in [(1u32 << 27, 15u32), (5, 1), (1, 8)] {
            assert_eq!(ScalarLeaf::test_leaf(&blocks, first, count, &ray, f32::INFINITY).mask, 0, "{first}, {count}");
            #[cfg(target_arch = "x86_64")]
            if crate::trace::bvh8::avx2_available() {
                // SAFETY: AVX2 was detected.
                assert_eq!(unsafe { avx_test_leaf(&blocks, first, count, &ray, f32::INFINITY) }.mask, 0);
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn avx_test_leaf(blocks: &LeafBlocks, first: u32, count: u32, ray: &Ray, t_max: f32) -> LeafHits {
        AvxLeaf::test_leaf(blocks, first, count, ray, t_max)
    }
}
