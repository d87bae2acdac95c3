//! Orientation: consistent winding within each connected component.
//!
//! Components are triangles connected across manifold point edges (edges with
//! exactly two users); a breadth-first walk from the lowest triangle index decides,
//! for each neighbour, whether it must flip to traverse the shared edge in the
//! opposite direction. Then:
//! - a walk that meets a contradiction (a Möbius-like component) leaves the
//!   component as it is and reports it;
//! - a closed component (every edge manifold) is oriented outward: positive
//!   signed volume;
//! - an open component takes the choice that flips fewer triangles (ties: the
//!   seed's winding).
//!
//! A vertex used only by flipped triangles whose normal then points against their
//! faces has its normal negated, so normals keep agreeing with the winding.

use super::work::{edge_runs, sorted_edges, Work};
use super::UnorientableComponent;
use glam::DVec3;
use std::collections::VecDeque;

/// At most this many unorientable components are listed (all are counted).
pub(crate) const MAX_LISTED_COMPONENTS: usize = 64;

/// What [`orient_components`] did.
#[derive(Clone, Debug, Default)]
pub(crate) struct OrientOutcome {
    pub flipped: usize,
    pub unorientable: Vec<UnorientableComponent>,
    pub unorientable_count: usize,
}

/// Makes the winding consistent within each component (see the module doc).
pub(crate) fn orient_components(work: &mut Work) -> OrientOutcome {
    let n = work.tris.len();
    let edges = sorted_edges(work);
    // Manifold links: (other triangle, must differ in flip state, edge midpoint).
    let mut links: Vec<(u32, u32, bool, u32, u32)> = Vec::new();
    let mut open = vec![false; n];
    for run in edge_runs(&edges) {
        if let [e, f] = run {
            links.push((e.tri, f.tri, e.forward == f.forward, e.lo, e.hi));
        } else {
            run.iter().for_each(|e| open[e.tri as usize] = true);
        }
    }
    for (t, open) in open.iter_mut().enumerate() {
        let [a, b, c] = work.tri_points(t);
        if a == b || b == c || c == a {
            *open = true;
        }
    }
    let mut start = vec![0usize; n + 1];
    for l in &links {
        start[l.0 as usize + 1] += 1;
        start[l.1 as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut adj = vec![(0u32, false, 0u32, 0u32); start[n]];
    for &(t1, t2, differ, lo, hi) in &links {
        adj[fill[t1 as usize]] = (t2, differ, lo, hi);
        fill[t1 as usize] += 1;
        adj[fill[t2 as usize]] = (t1, differ, lo, hi);
        fill[t2 as usize] += 1;
    }

    let mut out = OrientOutcome::default();
    let mut visited = vec![false; n];
    let mut flip = vec![false; n];
    let mut component = Vec::new();
    let mut queue = VecDeque::new();
    for seed in 0..n {
        if visited[seed] || !work.tri_alive[seed] {
            continue;
        }
        // Walk the component, recording the first contradiction.
        component.clear();
        visited[seed] = true;
        queue.push_back(seed);
        let mut conflict: Option<(u32, u32)> = None;
        while let Some(t) = queue.pop_front() {
            component.push(t);
            for &(o, differ, lo, hi) in &adj[start[t]..start[t + 1]] {
                let o = o as usize;
                let want = flip[t] ^ differ;
                if !visited[o] {
                    visited[o] = true;
                    flip[o] = want;
                    queue.push_back(o);
                } else if flip[o] != want && conflict.is_none() {
                    conflict = Some((lo, hi));
                }
            }
        }
        if let Some((lo, hi)) = conflict {
            out.unorientable_count += 1;
            if out.unorientable.len() < MAX_LISTED_COMPONENTS {
                let mid = 0.5 * (work.points[lo as usize] + work.points[hi as usize]);
                out.unorientable.push(UnorientableComponent {
                    triangles: component.len(),
                    seed_triangle: work.tri_origin[seed],
                    location: mid.to_array(),
                });
            }
            component.iter().for_each(|&t| flip[t] = false);
            continue;
        }
        let closed = component.iter().all(|&t| !open[t]);
        let invert = if closed {
            let volume: f64 = component
                .iter()
                .map(|&t| {
                    let [a, b, c] = work.tri_positions(t).map(|p| p.as_dvec3());
                    let v = a.dot(b.cross(c));
                    if flip[t] {
                        -v
                    } else {
                        v
                    }
                })
                .sum();
            volume < 0.0
        } else {
            2 * component.iter().filter(|&&t| flip[t]).count() > component.len()
        };
        if invert {
            component.iter().for_each(|&t| flip[t] = !flip[t]);
        }
    }

    // Apply the flips, then fix the normals of vertices that only flipped faces use.
    let mut users = vec![0u32; work.normals.len()];
    let mut flipped_users = vec![0u32; work.normals.len()];
    let mut agreement = vec![0f64; work.normals.len()];
    for (t, &flipped) in flip.iter().enumerate() {
        if !work.tri_alive[t] {
            continue;
        }
        if flipped {
            work.tris[t].swap(1, 2);
            out.flipped += 1;
        }
        let face: DVec3 = work.tri_cross(t);
        for v in work.tris[t] {
            users[v as usize] += 1;
            flipped_users[v as usize] += flipped as u32;
            agreement[v as usize] += work.normals[v as usize].as_dvec3().dot(face);
        }
    }
    for v in 0..work.normals.len() {
        if users[v] > 0 && flipped_users[v] == users[v] && agreement[v] < 0.0 {
            work.normals[v] = -work.normals[v];
        }
    }
    out
}
