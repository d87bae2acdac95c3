//! `clean` end to end: the light leak it cures, the CLI, the demo cabin.

use glam::Vec3;
use prtbake::bake::{bake_mesh, BakeParams, Sampling};
use prtbake::clean::{clean_mesh, fixtures, CleanParams};
use prtbake::fixtures::cabin::generate_cabin;
use prtbake::mesh::Mesh;
use prtbake::verify::shapes;

use crate::util::{prtbake, write_scene_obj, Scratch};

/// A closed unit box under an open-mode sky with a crack of 1e-4 of its size
/// between its lid and its sides, and an upward-facing receiver inside.
/// Before cleaning, rays escape through the crack: the receiver's mean DC is
/// clearly above zero; after cleaning (zipped), none escape.
#[test]
fn cleaning_closes_the_light_leak_of_a_cracked_box() {
    let boxed = fixtures::cracked_box(1e-4).mesh;
    let with_receiver = |m: &Mesh| {
        let mut mesh = m.clone();
        let mut receiver = shapes::plane_grid(8, 0.8);
        shapes::transform(&mut receiver, 1.0, Vec3::new(0.5, 0.6, 0.5));
        shapes::append(&mut mesh, &receiver);
        (mesh, m.vertex_count())
    };
    let params = BakeParams { order: 1, rays: 8192, sampling: Sampling::Vertex, ..BakeParams::default() };
    let receiver_dc = |m: &Mesh| {
        let (mesh, first) = with_receiver(m);
        let (r, _, _) = bake_mesh(&mesh, &params, &[]).unwrap();
        let dc: Vec<f64> = (first..mesh.vertex_count()).map(|v| r.total[v] as f64).collect();
        dc.iter().sum::<f64>() / dc.len() as f64
    };
    let before = receiver_dc(&boxed);
    let (cleaned, report) = clean_mesh(&boxed, &CleanParams::default()).unwrap();
    let after = receiver_dc(&cleaned);
    // One escaping ray of one vertex adds y00·(2/N)… ≈ 3.4e-5/81 to the mean: "clearly above zero" is ≥ 10 such rays.
    let one_ray = 0.282_095 / params.rays as f64 / 81.0;
    eprintln!(
        "cracked box: receiver mean DC before {before:.3e} ({:.0} rays' worth), after {after:.3e}; {} T-junctions fixed",
        before / one_ray,
        report.tjunctions_fixed
    );
    assert!(before >= 10.0 * one_ray, "no leak measured before cleaning: {before}");
    assert!(after <= one_ray, "light still leaks after cleaning: {after}");
    assert_eq!(report.boundary_edges_after, 0);
}

#[test]
fn clean_command_writes_mesh_and_report() {
    let dir = Scratch::new("clean");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    // Append an exact duplicate and a flipped duplicate of the first ground triangle.
    let mut text = std::fs::read_to_string(&obj).unwrap();
    text += "o dupes\nusemtl grey\nf 1 4 3\nf 1 3 4\n";
    std::fs::write(&obj, text).unwrap();
    let out = dir.path("clean.glb");
    let report = dir.path("report.json");
    let o = prtbake(&["clean", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--report", report.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(doc["input_triangles"], 16);
    assert_eq!(doc["duplicates_removed"], 1);
    assert_eq!(doc["flipped_duplicates_removed"], 1);
    assert_eq!(doc["output_triangles"], 14);
    // The cleaned GLB bakes.
    let o = prtbake(&["bake", out.to_str().unwrap(), "-o", dir.path("c.prtb").to_str().unwrap(), "--rays", "8", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A wrong output extension is refused before any work.
    let o = prtbake(&["clean", obj.to_str().unwrap(), "-o", dir.path("x.stl").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("x.stl"));
}

/// The demo cabin's injected defects are repaired, and cleaning again changes nothing.
#[test]
fn demo_cabin_cleans_and_stays_clean() {
    let (mesh, defects) = generate_cabin(24.0);
    let (cleaned, report) = clean_mesh(&mesh, &CleanParams::cad()).unwrap();
    eprintln!("{}", report.summary());
    assert_eq!(report.duplicates_removed, defects.exact_duplicates);
    assert_eq!(report.flipped_duplicates_removed, defects.flipped_duplicates);
    assert!(report.covered_coplanar_removed > 0, "the floor mat overlaps the carpet");
    let (_, again) = clean_mesh(&cleaned, &CleanParams::cad()).unwrap();
    assert_eq!(again.repairs(), 0, "second clean repaired: {}", again.summary());
}

/// One OBJ face of 100k corners (the loader fans it from its first corner):
/// `clean` finishes, and when it stops at the round limit it says on stderr,
/// as in the report, which repairs the last round still made.
#[test]
fn clean_of_a_huge_polygon_face_names_what_kept_retriggering() {
    let dir = Scratch::new("clean-polygon");
    let (obj, out, report) = (dir.path("polygon.obj"), dir.path("out.obj"), dir.path("report.json"));
    let n = 100_000;
    let mut text = String::new();
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        text += &format!("v {} 0 {}\n", a.cos(), -a.sin());
    }
    text += "f";
    (1..=n).for_each(|i| text += &format!(" {i}"));
    text += "\n";
    std::fs::write(&obj, text).unwrap();
    let run = prtbake(&["clean", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--report", report.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(r["input_triangles"], n - 2);
    let retriggered = r["retriggered"].as_array().unwrap();
    if r["converged"] == true {
        assert!(retriggered.is_empty() && !stderr.contains("warning"), "{stderr}");
        return;
    }
    assert!(!retriggered.is_empty(), "{r}");
    assert!(stderr.contains("warning") && stderr.contains("polygon.obj"), "{stderr}");
    for entry in retriggered {
        let (name, count) = (entry[0].as_str().unwrap(), entry[1].as_u64().unwrap());
        assert!(count > 0 && stderr.contains(&format!("{name} {count}")), "{name} {count}: {stderr}");
    }
}
