//! Broad phases: an AABB tree for box-overlap queries and a hashed grid that
//! clusters points closer than a tolerance.
//!
//! Both are O(n log n) to build and answer a query in O(log n + k), which keeps
//! every clean-up step n log n (the bench cleans up to a million triangles).
//! The tree is a plain median-split BVH: built once, queried many times, and
//! deterministic (ties broken by item index).

pub(crate) use crate::disjoint::{find, union};
use glam::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (union identity).
    pub const EMPTY: Aabb = Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY };

    /// The bounds of `points`, grown by `pad` on every side.
    pub fn of_points(points: &[Vec3], pad: f32) -> Aabb {
        let b = points.iter().fold(Aabb::EMPTY, |b, &p| Aabb { min: b.min.min(p), max: b.max.max(p) });
        Aabb { min: b.min - Vec3::splat(pad), max: b.max + Vec3::splat(pad) }
    }

    pub fn union(self, o: Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }

    fn centroid(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first item in `items`; inner: index of the left child (right is `left + 1`).
    first: u32,
    /// Leaf: number of items; 0 for an inner node.
    count: u32,
}

const LEAF_SIZE: usize = 4;

/// A bounding volume hierarchy over a list of boxes, answering "which boxes overlap this one".
#[derive(Clone, Debug, Default)]
pub(crate) struct AabbTree {
    nodes: Vec<Node>,
    /// Box indices, grouped by leaf.
    items: Vec<u32>,
    boxes: Vec<Aabb>,
}

impl AabbTree {
    /// Builds the tree by recursive median splits along the widest centroid axis.
    pub fn build(boxes: Vec<Aabb>) -> AabbTree {
        let mut tree = AabbTree { nodes: Vec::new(), items: (0..boxes.len() as u32).collect(), boxes };
        if tree.boxes.is_empty() {
            return tree;
        }
        let centroids: Vec<Vec3> = tree.boxes.iter().map(Aabb::centroid).collect();
        tree.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
        // Explicit stack of (node, item range) keeps depth independent of the call stack.
        let mut stack = vec![(0usize, 0usize, tree.items.len())];
        while let Some((node, start, end)) = stack.pop() {
            let slice = &mut tree.items[start..end];
            let bounds = slice.iter().fold(Aabb::EMPTY, |b, &i| b.union(tree.boxes[i as usize]));
            if slice.len() <= LEAF_SIZE {
                tree.nodes[node] = Node { bounds, first: start as u32, count: slice.len() as u32 };
                continue;
            }
            let cb = slice.iter().fold(Aabb::EMPTY, |b, &i| {
                let c = centroids[i as usize];
                b.union(Aabb { min: c, max: c })
            });
            let axis = (cb.max - cb.min).max_position();
            let mid = slice.len() / 2;
            slice.select_nth_unstable_by(mid, |&a, &b| centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis]).then(a.cmp(&b)));
            let left = tree.nodes.len();
            tree.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            tree.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            tree.nodes[node] = Node { bounds, first: left as u32, count: 0 };
            stack.push((left + 1, start + mid, end));
            stack.push((left, start, start + mid));
        }
        tree
    }

    /// Appends to `out` the index of every box overlapping `query` (in tree order).
    pub fn query(&self, query: &Aabb, out: &mut Vec<u32>) {
        self.any(query, |i| {
            out.push(i);
            false
        });
    }

    /// True when `hit` holds for the index of some box overlapping `query`;
    /// stops at the first (in tree order).
    pub fn any(&self, query: &Aabb, mut hit: impl FnMut(u32) -> bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let node = self.nodes[n as usize];
            if !node.bounds.overlaps(query) {
                continue;
            }
            if node.count > 0 {
                let items = &self.items[node.first as usize..(node.first + node.count) as usize];
                if items.iter().any(|&i| self.boxes[i as usize].overlaps(query) && hit(i)) {
                    return true;
                }
            } else {
                stack.push(node.first + 1);
                stack.push(node.first);
            }
        }
        false
    }
}

/// Clusters `ids` (indices into `points`) so that any two points closer than `tol`
/// (distance `<= tol`) end in one cluster (transitively, as union-find does).
///
/// Returns, for each entry of `ids`, the smallest id of its cluster: the
/// deterministic representative. `tol == 0` merges bit-identical positions only.
pub(crate) fn cluster_points(points: &[Vec3], ids: &[u32], tol: f32) -> Vec<u32> {
    cluster_points_limited(points, ids, tol, None)
}

/// [`cluster_points`], except that two entries join only when they are also
/// closer than both their `limit`s (one per entry of `ids`; used when `tol > 0`).
pub(crate) fn cluster_points_limited(points: &[Vec3], ids: &[u32], tol: f32, limit: Option<&[f32]>) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..ids.len() as u32).collect();
    // No pair joins beyond the largest limit: cells that small keep a dense rim's
    // points few per cell.
    let tol = limit.map_or(tol, |l| l.iter().copied().fold(0.0, f32::max).min(tol));
    if tol > 0.0 {
        cluster_grid(points, ids, tol, limit, &mut parent);
    } else {
        cluster_exact(points, ids, &mut parent);
    }
    // The representative of a set is its smallest id: find the minimum per root.
    let mut min_id: Vec<u32> = vec![u32::MAX; ids.len()];
    for (i, &id) in ids.iter().enumerate() {
        let r = find(&mut parent, i as u32) as usize;
        min_id[r] = min_id[r].min(id);
    }
    (0..ids.len()).map(|i| min_id[find(&mut parent, i as u32) as usize]).collect()
}

/// [`cluster_points`] for sets where many points nearly coincide (the ends
/// of the segments thousands of pairs find along one line): points are
/// bucketed in cells of diagonal `tol`, each cell's points are one cluster
/// at once, and two cells join at the first pair of their points within
/// `tol`, so a dense spot costs its size, not its size squared. Same result
/// as [`cluster_points`]; slower than it on spread points (125 cells searched).
pub(crate) fn cluster_points_dense(points: &[Vec3], ids: &[u32], tol: f32) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..ids.len() as u32).collect();
    if tol <= 0.0 {
        cluster_exact(points, ids, &mut parent);
    } else {
        let tol = tol as f64;
        let side = tol / 3f64.sqrt() * (1.0 - 1e-9);
        let pos = |i: usize| points[ids[i] as usize].as_dvec3();
        let cells: Vec<[i64; 3]> = (0..ids.len()).map(|i| (pos(i) / side).floor().as_i64vec3().to_array()).collect();
        let mut sorted: Vec<u32> = (0..ids.len() as u32).collect();
        sorted.sort_unstable_by_key(|&i| (cells[i as usize], i));
        let mut runs: HashMap<[i64; 3], (u32, u32), BuildHasherDefault<CellHasher>> = HashMap::default();
        let mut start = 0u32;
        for run in sorted.chunk_by(|&a, &b| cells[a as usize] == cells[b as usize]) {
            runs.insert(cells[run[0] as usize], (start, run.len() as u32));
            run.iter().for_each(|&i| union(&mut parent, run[0], i));
            start += run.len() as u32;
        }
        let tol2 = tol * tol;
        let mut keys: Vec<[i64; 3]> = runs.keys().copied().collect();
        keys.sort_unstable();
        for c in keys {
            let (s0, n0) = runs[&c];
            let mine = &sorted[s0 as usize..(s0 + n0) as usize];
            for d in (0..125).map(|k| [k % 5 - 2, k / 5 % 5 - 2, k / 25 - 2]).filter(|d| *d > [0, 0, 0]) {
                let Some(&(s1, n1)) = runs.get(&[c[0] + d[0], c[1] + d[1], c[2] + d[2]]) else { continue };
                if find(&mut parent, mine[0]) == find(&mut parent, sorted[s1 as usize]) {
                    continue;
                }
                let theirs = &sorted[s1 as usize..(s1 + n1) as usize];
                let linked = mine
                    .iter()
                    .find_map(|&a| theirs.iter().find(|&&b| pos(a as usize).distance_squared(pos(b as usize)) <= tol2).map(|&b| (a, b)));
                if let Some((a, b)) = linked {
                    union(&mut parent, a, b);
                }
            }
        }
    }
    let mut min_id: Vec<u32> = vec![u32::MAX; ids.len()];
    for (i, &id) in ids.iter().enumerate() {
        let r = find(&mut parent, i as u32) as usize;
        min_id[r] = min_id[r].min(id);
    }
    (0..ids.len()).map(|i| min_id[find(&mut parent, i as u32) as usize]).collect()
}

fn cluster_exact(points: &[Vec3], ids: &[u32], parent: &mut [u32]) {
    let key = |i: usize| points[ids[i] as usize].to_array().map(f32::to_bits);
    let mut order: Vec<usize> = (0..ids.len()).collect();
    order.sort_unstable_by_key(|&i| (key(i), i));
    for w in order.windows(2) {
        if key(w[0]) == key(w[1]) {
            union(parent, w[0] as u32, w[1] as u32);
        }
    }
}

fn cluster_grid(points: &[Vec3], ids: &[u32], tol: f32, limit: Option<&[f32]>, parent: &mut [u32]) {
    // Cells of side 2·tol: a point within `tol` of p lies, per axis, in p's cell or in
    // the one neighbour on the side of p's nearer cell wall, so 8 cells are searched.
    let inv = 0.5 / tol as f64;
    let scaled = |id: u32| points[id as usize].as_dvec3() * inv;
    let cells: Vec<[i64; 3]> = ids.iter().map(|&id| scaled(id).floor().as_i64vec3().to_array()).collect();
    // Entries sorted by cell; each cell maps to its run in `sorted`.
    let mut sorted: Vec<u32> = (0..ids.len() as u32).collect();
    sorted.sort_unstable_by_key(|&i| (cells[i as usize], i));
    let mut runs: HashMap<[i64; 3], (u32, u32), BuildHasherDefault<CellHasher>> = HashMap::default();
    runs.reserve(ids.len());
    let mut start = 0u32;
    for run in sorted.chunk_by(|&a, &b| cells[a as usize] == cells[b as usize]) {
        runs.insert(cells[run[0] as usize], (start, run.len() as u32));
        start += run.len() as u32;
    }
    let tol2 = tol as f64 * tol as f64;
    for (i, &id) in ids.iter().enumerate() {
        let p = points[id as usize].as_dvec3();
        let c = cells[i];
        let f = scaled(id) - scaled(id).floor();
        let side = [f.x, f.y, f.z].map(|x| if x < 0.5 { -1 } else { 1 });
        for k in 0..8 {
            let cell = [0, 1, 2].map(|a| c[a] + if k >> a & 1 == 1 { side[a] } else { 0 });
            let Some(&(start, len)) = runs.get(&cell) else { continue };
            for &j in &sorted[start as usize..(start + len) as usize] {
                if j as usize == i {
                    continue;
                }
                let q = points[ids[j as usize] as usize].as_dvec3();
                let within_limits = || limit.is_none_or(|l| p.distance(q) < l[i].min(l[j as usize]) as f64);
                if p.distance_squared(q) <= tol2 && within_limits() {
                    union(parent, i as u32, j);
                }
            }
        }
    }
}

/// A multiply-rotate hasher for integer cell keys (SipHash is needlessly slow here;
/// keys are not attacker-chosen in a way that matters for an offline tool).
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    fn write_i64(&mut self, x: i64) {
        self.write_u64(x as u64);
    }
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tree_query_matches_brute_force() {
        // Deterministic pseudo-random boxes (LCG), every query compared with a scan.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 33) as f32) / (1u64 << 31) as f32
        };
        let boxes: Vec<Aabb> = (0..500)
            .map(|_| {
                let c = Vec3::new(rnd(), rnd(), rnd()) * 10.0;
                let h = Vec3::new(rnd(), rnd(), rnd()) * 0.5;
                Aabb { min: c - h, max: c + h }
            })
            .collect();
        let tree = AabbTree::build(boxes.clone());
        for q in boxes.iter().take(100) {
            let mut got = Vec::new();
            tree.query(q, &mut got);
            got.sort_unstable();
            let want: Vec<u32> = (0..boxes.len() as u32).filter(|&i| boxes[i as usize].overlaps(q)).collect();
            assert_eq!(got, want);
        }
    }

    #[test]
    fn dense_clustering_matches_the_grid() {
        // Points spread over a box, and a thousand within a hair of two spots.
        let mut s = 99u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 33) as f32) / (1u64 << 31) as f32
        };
        let mut pts: Vec<Vec3> = (0..2000).map(|_| Vec3::new(rnd(), rnd(), rnd())).collect();
        pts.extend((0..1000).map(|i| Vec3::splat((i % 2) as f32 * 0.5) + Vec3::new(rnd(), rnd(), rnd()) * 1e-3));
        let ids: Vec<u32> = (0..pts.len() as u32).rev().collect();
        for tol in [0.0, 1e-3, 0.02, 0.05] {
            assert_eq!(cluster_points_dense(&pts, &ids, tol), cluster_points(&pts, &ids, tol), "tol {tol}");
        }
    }

    #[test]
    fn clusters_within_tolerance_with_smallest_representative() {
        let pts = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.09),
            Vec3::new(5.0, 0.05, 0.0),
            Vec3::new(0.0, 0.0, 0.18), // chains to 0 through 2
        ];
        let ids: Vec<u32> = (0..5).collect();
        assert_eq!(cluster_points(&pts, &ids, 0.1), vec![0, 1, 0, 1, 0]);
        assert_eq!(cluster_points(&pts, &ids, 0.0), vec![0, 1, 2, 3, 4]);
    }
}
