//! Quality of a cleaned mesh against its input: non-manifold edges (on
//! bit-identical positions) and how many of them the input did not have,
//! boundary edges, and the smallest angle per material, input beside output.
//!
//! Run: `cargo run --release --example cut_quality -- INPUT OUTPUT [MATERIAL…]`
//! (materials: only those; default every material). The docs' dining-room and
//! Ferrari figures for `clean --cut-intersections` come from it.

use prtbake::mesh::{load_mesh, LoadOptions, Mesh};
use std::collections::HashMap;

type Key = [u32; 3];

fn key(p: glam::Vec3) -> Key {
    p.to_array().map(f32::to_bits)
}

/// Users of every edge, on bit-identical positions.
fn edge_users(mesh: &Mesh) -> HashMap<(Key, Key), u32> {
    let mut users = HashMap::new();
    for t in 0..mesh.triangle_count() {
        let p = mesh.triangle_positions(t).map(key);
        for i in 0..3 {
            let (a, b) = (p[i], p[(i + 1) % 3]);
            if a != b {
                *users.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
    }
    users
}

fn min_angle_deg(p: [glam::Vec3; 3]) -> f64 {
    let p = p.map(|x| x.as_dvec3());
    (0..3)
        .map(|i| {
            let (e1, e2) = (p[(i + 1) % 3] - p[i], p[(i + 2) % 3] - p[i]);
            let (l1, l2) = (e1.length(), e2.length());
            if l1 == 0.0 || l2 == 0.0 {
                0.0
            } else {
                (e1.dot(e2) / (l1 * l2)).clamp(-1.0, 1.0).acos().to_degrees()
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// Smallest angle (degrees) and its triangle count per material name.
fn angles_by_material(mesh: &Mesh) -> HashMap<String, (f64, usize)> {
    let mut by: HashMap<String, (f64, usize)> = HashMap::new();
    for t in 0..mesh.triangle_count() {
        let name = mesh.materials[mesh.tri_material[t] as usize].name.clone();
        let e = by.entry(name).or_insert((f64::INFINITY, 0));
        e.0 = e.0.min(min_angle_deg(mesh.triangle_positions(t)));
        e.1 += 1;
    }
    by
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: cut_quality INPUT OUTPUT [MATERIAL…]");
        std::process::exit(2);
    }
    let load = |p: &str| load_mesh(p.as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{p}: {e}")).mesh;
    let (input, output) = (load(&args[0]), load(&args[1]));
    let (before, after) = (edge_users(&input), edge_users(&output));
    let non_manifold = |u: &HashMap<(Key, Key), u32>| u.values().filter(|&&n| n > 2).count();
    let boundary = |u: &HashMap<(Key, Key), u32>| u.values().filter(|&&n| n == 1).count();
    let new_nm = after.iter().filter(|(e, &n)| n > 2 && before.get(e).is_none_or(|&m| m <= 2)).count();
    println!("triangles        {} -> {}", input.triangle_count(), output.triangle_count());
    println!("non-manifold     {} -> {} ({} new)", non_manifold(&before), non_manifold(&after), new_nm);
    println!("boundary edges   {} -> {}", boundary(&before), boundary(&after));
    let (a_in, a_out) = (angles_by_material(&input), angles_by_material(&output));
    let mut names: Vec<&String> = a_in.keys().collect();
    names.sort();
    let pick: Vec<&String> = args[2..].iter().collect();
    println!("smallest angle per material, degrees (input -> output, triangles):");
    for name in names.into_iter().filter(|n| pick.is_empty() || pick.contains(n)) {
        let (i, ni) = a_in[name];
        let (o, no) = a_out.get(name).copied().unwrap_or((f64::NAN, 0));
        println!("  {name:<16} {i:>10.5} -> {o:>10.5}   ({ni} -> {no})");
    }
    let all = |m: &HashMap<String, (f64, usize)>| m.values().map(|v| v.0).fold(f64::INFINITY, f64::min);
    println!("  {:<16} {:>10.5} -> {:>10.5}", "(all)", all(&a_in), all(&a_out));
}
