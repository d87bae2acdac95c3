//! Disjoint sets over `u32` ids (union-find on a parent array): the
//! clean-up's point clusters and welds, and an atlas's charts.

/// The root of `i`'s set (path halving).
pub(crate) fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let up = parent[parent[i as usize] as usize];
        parent[i as usize] = up;
        i = up;
    }
    i
}

/// Joins two sets; the smaller root stays the root, so roots are the smallest members.
pub(crate) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // Attach the larger root under the smaller: roots stay deterministic.
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}
