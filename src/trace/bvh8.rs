//! An 8-wide BVH with exact float child boxes in struct-of-arrays layout,
//! collapsed from the binary BVH obvhs builds, and its traversal.
//!
//! Why not obvhs's CWBVH: its child boxes are quantised to 8 bits of the
//! parent's extent, so every box is a little loose and a ray enters more of
//! them, and its traversal decodes them one child at a time. Exact float
//! boxes, eight tested in one AVX2 pass, took the Ferrari from 1.32 to 2.15
//! Mrays/s closest hit with the same PLOC build (docs/performance.md). One node is
//! one dependent memory access: the walk is bound by memory latency, so
//! depth, not arithmetic, is what counts.
//!
//! A child reference is a `u32`: an inner node index, or (top bit set) a
//! leaf holding `count` consecutive triangles from `first`.

use obvhs::{bvh2::Bvh2, ray::Ray};

/// Children per node.
pub const WIDTH: usize = 8;
const LEAF_BIT: u32 = 1 << 31;
const COUNT_BITS: u32 = 4;
/// Most triangles one leaf can hold (the count field's range).
pub const MAX_LEAF_TRIANGLES: u32 = (1 << COUNT_BITS) - 1;
/// Empty child slot: its box is inverted, so it is never hit.
const EMPTY: u32 = u32::MAX;

/// One node: eight child boxes as rows of eight floats, then eight child references.
/// Rows: min x, max x, min y, max y, min z, max z (so `row = 2·axis + is_max`).
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct Node8 {
    pub bounds: [[f32; WIDTH]; 6],
    pub children: [u32; WIDTH],
}

impl Node8 {
    const EMPTY_NODE: Node8 = Node8 {
        bounds: [
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        children: [EMPTY; WIDTH],
    };
}

/// A leaf reference: triangles `first .. first + count` in leaf order.
#[inline(always)]
pub fn leaf_range(child: u32) -> (u32, u32) {
    ((child & !LEAF_BIT) >> COUNT_BITS, child & MAX_LEAF_TRIANGLES)
}

#[inline(always)]
pub(super) fn is_leaf(child: u32) -> bool {
    child & LEAF_BIT != 0
}

/// The collapsed tree.
#[derive(Default)]
pub struct Bvh8 {
    pub nodes: Vec<Node8>,
    /// Leaf order → index of the primitive in the BVH2's input.
    pub primitive_order: Vec<u32>,
    /// Levels of inner nodes on the longest root-to-leaf path.
    pub depth: u32,
}

impl Bvh8 {
    /// Collapses `bvh2` (leaves of at most [`MAX_LEAF_TRIANGLES`] primitives):
    /// each node starts from a BVH2 inner node's two children and repeatedly
    /// opens the inner child with the largest surface area until it has
    /// eight children (the standard greedy SAH collapse).
    pub fn from_bvh2(bvh2: &Bvh2) -> Bvh8 {
        let mut out = Bvh8::default();
        if bvh2.nodes.is_empty() {
            return out;
        }
        out.nodes.push(Node8::EMPTY_NODE);
        let mut stack: Vec<(u32, u32, u32)> = vec![(0, 0, 1)]; // (bvh2 node, bvh8 node, depth)
        while let Some((source, target, depth)) = stack.pop() {
            out.depth = out.depth.max(depth);
            let root = &bvh2.nodes[source as usize];
            let mut kids: Vec<u32> = if root.is_leaf() {
                vec![source] // a one-leaf tree
            } else {
                vec![root.first_index, root.first_index + 1]
            };
            while kids.len() < WIDTH {
                let widest = kids
                    .iter()
                    .enumerate()
                    .filter(|(_, &k)| !bvh2.nodes[k as usize].is_leaf())
                    .max_by(|a, b| {
                        let area = |k: u32| bvh2.nodes[k as usize].aabb().half_area();
                        area(*a.1).total_cmp(&area(*b.1))
                    })
                    .map(|(slot, _)| slot);
                let Some(slot) = widest else { break };
                let opened = bvh2.nodes[kids[slot] as usize].first_index;
                kids[slot] = opened;
                kids.push(opened + 1);
            }
            // Largest boxes first: the occlusion walk takes children in slot
            // order, and a big box is the likeliest to hold a blocker.
            kids.sort_by(|&a, &b| bvh2.nodes[b as usize].aabb().half_area().total_cmp(&bvh2.nodes[a as usize].aabb().half_area()));
            for (slot, &kid) in kids.iter().enumerate() {
                let node = &bvh2.nodes[kid as usize];
                let aabb = node.aabb();
                let bounds = &mut out.nodes[target as usize].bounds;
                for axis in 0..3 {
                    bounds[2 * axis][slot] = aabb.min[axis];
                    bounds[2 * axis + 1][slot] = aabb.max[axis];
                }
                let child = if node.is_leaf() {
                    let first = out.primitive_order.len() as u32;
                    let count = node.prim_count;
                    assert!(count <= MAX_LEAF_TRIANGLES, "leaf of {count} primitives");
                    assert!(first < (1 << (31 - COUNT_BITS)), "too many triangles for a BVH8 leaf reference");
                    let start = node.first_index as usize;
                    out.primitive_order.extend_from_slice(&bvh2.primitive_indices[start..start + count as usize]);
                    LEAF_BIT | (first << COUNT_BITS) | count
                } else {
                    let index = out.nodes.len() as u32;
                    out.nodes.push(Node8::EMPTY_NODE);
                    stack.push((kid, index, depth + 1));
                    index
                };
                out.nodes[target as usize].children[slot] = child;
            }
        }
        out
    }

    /// Every leaf as `(first, count)`.
    pub fn leaves(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.nodes.iter().flat_map(|node| node.children).filter(|&c| c != EMPTY && is_leaf(c)).map(leaf_range)
    }
}

/// True when every inner child's boxes lie inside the box its parent holds
/// for it: what lets a packet walk test a leaf's box alone for the lone
/// walk's answer ([`super::packets`]). Binary nodes' boxes are unions of
/// their children's, so a collapsed tree always nests; the build checks it.
pub fn boxes_nest(nodes: &[Node8]) -> bool {
    nodes.iter().all(|node| {
        (0..WIDTH).filter(|&slot| node.children[slot] != EMPTY && !is_leaf(node.children[slot])).all(|slot| {
            let child = &nodes[node.children[slot] as usize];
            (0..WIDTH).filter(|&k| child.children[k] != EMPTY).all(|k| {
                (0..3).all(|axis| {
                    node.bounds[2 * axis][slot] <= child.bounds[2 * axis][k]
                        && child.bounds[2 * axis + 1][k] <= node.bounds[2 * axis + 1][slot]
                })
            })
        })
    })
}

/// A ray prepared for box tests.
#[derive(Clone, Copy, Debug)]
pub struct RayBoxes {
    pub origin: [f32; 3],
    pub inverse: [f32; 3],
    /// Row of the near plane per axis (`2·axis`, or `2·axis + 1` when the ray runs toward −axis).
    pub near_row: [usize; 3],
}

impl RayBoxes {
    /// Takes the inverse direction the ray already holds (obvhs keeps it
    /// finite: near-zero components map to ±1/ε, so a box test never
    /// multiplies 0 by infinity).
    #[inline(always)]
    pub fn from_ray(ray: &Ray) -> RayBoxes {
        let inverse = ray.inv_direction.to_array();
        let row = |axis: usize| 2 * axis + usize::from(inverse[axis] < 0.0);
        RayBoxes { origin: ray.origin.to_array(), inverse, near_row: [row(0), row(1), row(2)] }
    }
}

/// Float rounding in the slab test can put a box's exit a little before a
/// triangle hit the triangle test accepts (Ize, "Robust BVH ray traversal",
/// 2013): stretching the exit distance by 1 + 2γ₃ makes the test conservative.
pub(super) const EXIT_STRETCH: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON / 2.0) / (1.0 - 3.0 * f32::EPSILON / 2.0);

/// Tests one node's eight boxes: returns the bit mask of children hit within
/// `[t_min, t_max]` and writes each child's entry distance to `entry`.
pub trait NodeTest {
    fn test(node: &Node8, ray: &RayBoxes, t_min: f32, t_max: f32, entry: &mut [f32; WIDTH]) -> u32;
}

/// Portable path: eight lanes in plain arrays.
pub struct ScalarTest;

impl NodeTest for ScalarTest {
    #[inline(always)]
    fn test(node: &Node8, ray: &RayBoxes, t_min: f32, t_max: f32, entry: &mut [f32; WIDTH]) -> u32 {
        let mut mask = 0;
        for lane in 0..WIDTH {
            let mut near = t_min;
            let mut far = f32::INFINITY;
            for axis in 0..3 {
                let n = node.bounds[ray.near_row[axis]][lane];
                let f = node.bounds[ray.near_row[axis] ^ 1][lane];
                near = ((n - ray.origin[axis]) * ray.inverse[axis]).max(near);
                far = ((f - ray.origin[axis]) * ray.inverse[axis]).min(far);
            }
            let far = (far * EXIT_STRETCH).min(t_max);
            entry[lane] = near;
            mask |= u32::from(near <= far) << lane;
        }
        mask
    }
}

/// AVX2 path: the eight boxes in one register per plane.
#[cfg(target_arch = "x86_64")]
pub struct Avx2Test;

#[cfg(target_arch = "x86_64")]
impl NodeTest for Avx2Test {
    #[inline(always)]
    fn test(node: &Node8, ray: &RayBoxes, t_min: f32, t_max: f32, entry: &mut [f32; WIDTH]) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: only reached through the `#[target_feature(enable = "avx2")]`
        // entry points below, which are only called after runtime detection;
        // every load reads one aligned row of `node`.
        unsafe {
            let rows = node.bounds.as_ptr();
            let plane = |axis: usize, row: usize| {
                let b = _mm256_load_ps((*rows.add(row)).as_ptr());
                _mm256_mul_ps(_mm256_sub_ps(b, _mm256_set1_ps(ray.origin[axis])), _mm256_set1_ps(ray.inverse[axis]))
            };
            let mut near = _mm256_set1_ps(t_min);
            let mut far = _mm256_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                near = _mm256_max_ps(plane(axis, ray.near_row[axis]), near);
                far = _mm256_min_ps(plane(axis, ray.near_row[axis] ^ 1), far);
            }
            far = _mm256_min_ps(_mm256_mul_ps(far, _mm256_set1_ps(EXIT_STRETCH)), _mm256_set1_ps(t_max));
            _mm256_storeu_ps(entry.as_mut_ptr(), near);
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32
        }
    }
}

/// What a leaf visit tells the walk.
pub enum LeafResult {
    /// Keep walking with this (possibly shortened) maximum distance.
    Continue(f32),
    /// Stop: the query is answered (occlusion found).
    Stop,
}

/// Traversal stack: a fixed array for the common case, spilling to the heap
/// only for deep trees (a node pushes at most seven entries).
/// Zero-filled on creation: leaving it uninitialised measured 4–7% slower
/// (1 thread, Ferrari), against expectation; kept as measured. 48 entries
/// rather than 128: zeroing is per ray, and short cabin rays measured up
/// to 10% faster with the smaller array (docs/performance.md).
struct Stack {
    inline: [(u32, f32); 48],
    len: usize,
    spill: Vec<(u32, f32)>,
}

impl Stack {
    #[inline(always)]
    fn new() -> Stack {
        Stack { inline: [(0, 0.0); 48], len: 0, spill: Vec::new() }
    }
    #[inline(always)]
    fn push(&mut self, entry: (u32, f32)) {
        if self.len < self.inline.len() {
            self.inline[self.len] = entry;
            self.len += 1;
        } else {
            self.spill.push(entry);
        }
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.len = 0;
        self.spill.clear();
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, f32)> {
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }
}

/// A walk in progress through the tree: the node or leaf it visits next,
/// the current maximum distance and the children stacked for later.
///
/// With `NEAREST_FIRST` (closest hit) children hit by the ray are visited
/// nearest first, and a stacked child whose entry lies beyond the current
/// maximum distance is skipped. Without it (occlusion) they are visited in
/// slot order, largest box first: measured 17% faster on the Ferrari than
/// nearest-first (its nearest boxes hold the ray's own surface and its
/// twin) and 5% slower on the cabin (docs/performance.md). The walk order
/// depends only on the ray, never on threads or on which other walks run
/// beside it.
pub struct Walk {
    stack: Stack,
    next: u32,
    t_max: f32,
    /// Entry distances of the last node's children.
    entry: [f32; WIDTH],
}

impl Walk {
    /// A walk from the root. The tree must have a root.
    #[inline(always)]
    pub fn new(t_max: f32) -> Walk {
        Walk { stack: Stack::new(), next: 0, t_max, entry: [0.0; WIDTH] }
    }

    /// Starts again from the root, reusing the stack's memory.
    #[inline(always)]
    pub fn restart(&mut self, t_max: f32) {
        self.stack.clear();
        self.next = 0;
        self.t_max = t_max;
    }

    /// The maximum distance the walk has come down to (the query's, or
    /// shortened by the leaves' answers).
    #[inline(always)]
    pub fn t_max(&self) -> f32 {
        self.t_max
    }

    /// Visits the next node or leaf, then picks the one after it, and
    /// returns false once the walk has ended. Every child the ray enters is
    /// prefetched when its parent is tested, so a step rarely waits on memory
    /// when other walks' steps run between two of this one's
    /// ([`super::queries`] interleaves them: `INTERLEAVED`). A lone walk
    /// prefetches by a select instead of a branch, and skips a lone child.
    #[inline(always)]
    pub fn step<T: NodeTest, L: Leaves, const NEAREST_FIRST: bool, const INTERLEAVED: bool>(
        &mut self,
        nodes: &[Node8],
        ray: &RayBoxes,
        t_min: f32,
        leaves: &mut L,
    ) -> bool {
        if is_leaf(self.next) {
            let (first, count) = leaf_range(self.next);
            match leaves.visit(first, count, self.t_max) {
                LeafResult::Continue(t) => self.t_max = t,
                LeafResult::Stop => return false,
            }
        } else {
            let node = &nodes[self.next as usize];
            #[cfg(test)]
            super::queries::work::add_node();
            let entry = &mut self.entry;
            let mut mask = T::test(node, ray, t_min, self.t_max, entry);
            if mask != 0 {
                let rest = mask & (mask - 1);
                if rest == 0 && !INTERLEAVED {
                    // One child: one walk alone gains nothing from a prefetch.
                    self.next = node.children[mask.trailing_zeros() as usize];
                    return true;
                }
                // Fetch every hit child now, in parallel, rather than one
                // dependent miss at a time when the walk reaches it.
                let mut pending = mask;
                while pending != 0 {
                    let child = node.children[pending.trailing_zeros() as usize];
                    pending &= pending - 1;
                    if INTERLEAVED {
                        // Bound by memory: fetch exactly the child's lines.
                        if is_leaf(child) {
                            let (first, count) = leaf_range(child);
                            prefetch_bytes(leaves.block_address(first), count as usize * BLOCK_BYTES_PER_TRIANGLE);
                        } else {
                            prefetch_bytes(nodes.as_ptr().wrapping_add(child as usize), std::mem::size_of::<Node8>());
                        }
                    } else {
                        // Bound by instructions and mispredictions: the same
                        // lines for a node or a leaf, chosen by a select
                        // rather than a branch that mispredicts on mixed nodes.
                        let address = if is_leaf(child) {
                            leaves.block_address(leaf_range(child).0)
                        } else {
                            nodes.as_ptr().wrapping_add(child as usize).cast::<u8>()
                        };
                        prefetch_bytes(address, CHILD_PREFETCH_BYTES);
                    }
                }
                if rest == 0 {
                    self.next = node.children[mask.trailing_zeros() as usize];
                    return true;
                }
                if rest & (rest - 1) == 0 {
                    // Two children, the commonest case: one compare, no sort.
                    // Same order as the keys below (distance, then slot).
                    let (a, b) = (mask.trailing_zeros() as usize, rest.trailing_zeros() as usize);
                    let (near, far) = if NEAREST_FIRST && entry[b] < entry[a] { (b, a) } else { (a, b) };
                    self.stack.push((node.children[far], entry[far]));
                    self.next = node.children[near];
                    return true;
                }
                // Keys: entry distance, then slot (so equal distances order
                // the same way every time).
                let mut keys = [0u64; WIDTH];
                let mut n = 0;
                while mask != 0 {
                    let slot = mask.trailing_zeros();
                    mask &= mask - 1;
                    // Entry distances are ≥ t_min ≥ 0, so their bits sort like the values.
                    keys[n] = (u64::from(entry[slot as usize].to_bits()) << 32) | u64::from(slot);
                    n += 1;
                }
                let keys = &mut keys[..n];
                // Insertion sort: at most eight keys.
                for i in (1..n).filter(|_| NEAREST_FIRST) {
                    let k = keys[i];
                    let mut j = i;
                    while j > 0 && keys[j - 1] > k {
                        keys[j] = keys[j - 1];
                        j -= 1;
                    }
                    keys[j] = k;
                }
                for &k in keys[1..].iter().rev() {
                    self.stack.push((node.children[(k & 0xff) as usize], f32::from_bits((k >> 32) as u32)));
                }
                self.next = node.children[(keys[0] & 0xff) as usize];
                return true;
            }
        }
        // Nothing to descend into: take the nearest stacked child still in range.
        loop {
            match self.stack.pop() {
                None => return false,
                Some((child, t)) if t <= self.t_max => {
                    self.next = child;
                    return true;
                }
                Some(_) => {}
            }
        }
    }
}

/// Bytes a leaf block takes per triangle.
const BLOCK_BYTES_PER_TRIANGLE: usize = super::leaf_blocks::ROWS * std::mem::size_of::<f32>();
/// Bytes prefetched per child a lone walk enters, node or leaf alike: a
/// node's four lines and two more, or a leaf block's first six lines.
const CHILD_PREFETCH_BYTES: usize = 384;

/// What a walk does at its leaves. Implementations mark both methods
/// `#[inline(always)]`: the walk runs inside AVX2 functions, and a leaf test
/// left out of line there loses its SIMD (measured 4× slower).
pub trait Leaves {
    /// Where the block of the leaf whose triangles start at `first` begins (for prefetching).
    fn block_address(&self, first: u32) -> *const u8;
    /// Tests the leaf's triangles within `t_max`.
    fn visit(&mut self, first: u32, count: u32, t_max: f32) -> LeafResult;
}

/// Asks for the cache lines of `bytes` bytes from `start` on (a hint; no
/// effect off x86-64).
#[inline(always)]
pub fn prefetch_bytes<L>(start: *const L, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let base = start.cast::<i8>();
        // SAFETY: prefetch never faults, whatever the address.
        unsafe {
            for offset in (0..bytes).step_by(64) {
                _mm_prefetch::<_MM_HINT_T0>(base.wrapping_add(offset));
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (start, bytes);
}

/// True when this CPU runs the AVX2 node test.
pub fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use obvhs::{bvh2::builder::build_bvh2_from_tris, triangle::Triangle, BvhBuildParams};

    fn grid_triangles(n: usize) -> Vec<Triangle> {
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (x, z) = (i as f32, j as f32);
                let y = ((i * 7 + j * 3) % 5) as f32 * 0.1;
                tris.push(Triangle { v0: glam::vec3a(x, y, z), v1: glam::vec3a(x + 1.0, y, z), v2: glam::vec3a(x, y + 0.5, z + 1.0) });
            }
        }
        tris
    }

    #[test]
    fn collapse_keeps_every_primitive_once_and_boxes_enclose_them() {
        let tris = grid_triangles(40);
        let mut params = BvhBuildParams::medium_build();
        params.max_prims_per_leaf = 4;
        let bvh2 = build_bvh2_from_tris(&tris, params, &mut Default::default());
        let bvh8 = Bvh8::from_bvh2(&bvh2);
        assert_eq!(bvh8.primitive_order.len(), tris.len());
        let mut seen = vec![0u32; tris.len()];
        for &p in &bvh8.primitive_order {
            seen[p as usize] += 1;
        }
        assert!(seen.iter().all(|&c| c == 1), "every triangle in exactly one leaf");
        for node in &bvh8.nodes {
            for slot in 0..WIDTH {
                let child = node.children[slot];
                if child == EMPTY || !is_leaf(child) {
                    continue;
                }
                let (first, count) = leaf_range(child);
                for k in first..first + count {
                    let t = &tris[bvh8.primitive_order[k as usize] as usize];
                    for v in [t.v0, t.v1, t.v2] {
                        for axis in 0..3 {
                            assert!(node.bounds[2 * axis][slot] <= v[axis] && v[axis] <= node.bounds[2 * axis + 1][slot]);
                        }
                    }
                }
            }
        }
        assert!(bvh8.depth >= 2 && bvh8.depth < 20, "depth {}", bvh8.depth);
    }

    /// Past its inline entries the stack spills to the heap and still pops
    /// last-in first-out.
    #[test]
    fn stack_spills_in_order() {
        let mut stack = Stack::new();
        let total = stack.inline.len() as u32 * 3 + 5;
        for k in 0..total {
            stack.push((k, k as f32));
        }
        for k in (0..total).rev() {
            assert_eq!(stack.pop(), Some((k, k as f32)));
        }
        assert_eq!(stack.pop(), None);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_scalar_node_tests_agree() {
        if !avx2_available() {
            eprintln!("skipped: no AVX2 on this CPU");
            return;
        }
        let tris = grid_triangles(12);
        let bvh2 = build_bvh2_from_tris(&tris, BvhBuildParams::medium_build(), &mut Default::default());
        let bvh8 = Bvh8::from_bvh2(&bvh2);
        let mut rand = crate::sampling::test_stream(12345);
        for _ in 0..2000 {
            let o = Vec3::new(rand() * 14.0 - 1.0, rand() * 3.0 - 1.0, rand() * 14.0 - 1.0);
            let mut d = Vec3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5).normalize();
            if rand() < 0.2 {
                d.y = 0.0; // axis-parallel rays exercise the inverse guard
                d = d.normalize();
            }
            let ray = RayBoxes::from_ray(&Ray::new(o.into(), d.into(), 0.0, 50.0));
            for node in &bvh8.nodes {
                let (mut a, mut b) = ([0.0; WIDTH], [0.0; WIDTH]);
                let ma = ScalarTest::test(node, &ray, 0.0, 50.0, &mut a);
                // SAFETY: AVX2 was detected above.
                let mb = unsafe { avx2_node_test(node, &ray, &mut b) };
                assert_eq!(ma, mb);
                for lane in 0..WIDTH {
                    if ma >> lane & 1 == 1 {
                        assert_eq!(a[lane].to_bits(), b[lane].to_bits());
                    }
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn avx2_node_test(node: &Node8, ray: &RayBoxes, entry: &mut [f32; WIDTH]) -> u32 {
        Avx2Test::test(node, ray, 0.0, 50.0, entry)
    }
}
