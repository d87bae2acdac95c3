use glam::Vec3;
use prtbake::clean::{clean_mesh, CleanParams};
use prtbake::mesh::{Material, Mesh};

fn mesh_of(tris: &[[Vec3; 3]]) -> Mesh {
    let mut m = Mesh { materials: vec![Material::opaque("m", 0.5)], groups: vec!["g".into()], ..Mesh::default() };
    for t in tris {
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        for &p in t {
            m.indices.push(m.positions.len() as u32);
            m.positions.push(p);
            m.normals.push(n);
        }
        m.tri_material.push(0);
        m.tri_group.push(0);
    }
    m
}

fn rot_z(p: Vec3, a: f32) -> Vec3 {
    let (s, c) = a.sin_cos();
    Vec3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = args[1].as_str();
    let n: usize = args[2].parse().unwrap();
    let cut = args.get(3).map(|s| s == "cut").unwrap_or(false);
    let pi = std::f32::consts::PI;
    let tris: Vec<[Vec3; 3]> = match kind {
        // thin triangles in planes through the z axis, crossing along it
        "star" => (0..n)
            .map(|i| {
                let a = pi * i as f32 / n as f32;
                [Vec3::new(-1.0, 0.0, -0.05), Vec3::new(1.0, 0.0, 0.0), Vec3::new(-1.0, 0.0, 0.05)].map(|p| rot_z(p, a))
            })
            .collect(),
        // thin triangles crossing each other at varied heights and angles (a pile of sticks)
        "sticks" => (0..n)
            .map(|i| {
                let a = pi * (i as f32 * 0.618034).fract();
                let z = 0.1 * ((i as f32 * 0.377).fract() - 0.5);
                let tilt = 0.3 * ((i as f32 * 0.7548).fract() - 0.5);
                [Vec3::new(-1.0, -0.02, z - tilt), Vec3::new(1.0, 0.0, z + tilt), Vec3::new(-1.0, 0.02, z - tilt + 0.05)]
                    .map(|p| rot_z(p, a))
            })
            .collect(),
        // fins: triangles with one edge on the z axis
        "fins" => (0..n)
            .map(|i| {
                let a = 2.0 * pi * i as f32 / n as f32;
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0), rot_z(Vec3::new(1.0, 0.0, 0.5), a)]
            })
            .collect(),
        // fins crossing the axis (the axis inside each fin)
        "fins2" => (0..n)
            .map(|i| {
                let a = pi * i as f32 / n as f32;
                [Vec3::new(-0.5, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(-0.5, 0.0, 1.0)].map(|p| rot_z(p, a))
            })
            .collect(),
        // fins with edge on the axis at staggered heights
        "fins3" => (0..n)
            .map(|i| {
                let a = 2.0 * pi * i as f32 / n as f32;
                let z = 0.5 * i as f32 / n as f32;
                [Vec3::new(0.0, 0.0, z), Vec3::new(0.0, 0.0, z + 1.0), rot_z(Vec3::new(1.0, 0.0, z + 0.5), a)]
            })
            .collect(),
        // coplanar triangles rotated about a common centre
        "stack_rot" => (0..n)
            .map(|i| {
                let a = 2.0 * pi * i as f32 / n as f32 / 3.0;
                [Vec3::new(1.0, 0.0, 0.0), Vec3::new(-0.5, 0.866, 0.0), Vec3::new(-0.5, -0.866, 0.0)].map(|p| rot_z(p, a))
            })
            .collect(),
        // coplanar copies shifted in the plane
        "stack_shift" => (0..n)
            .map(|i| {
                let d = Vec3::new(0.01 * i as f32, 0.007 * i as f32, 0.0);
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)].map(|p| p + d)
            })
            .collect(),
        "stack_tiny" => (0..n)
            .map(|i| {
                let d = Vec3::new(1e-4 * i as f32, 0.7e-4 * i as f32, 0.0);
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)].map(|p| p + d)
            })
            .collect(),
        "stack_scale" => (0..n)
            .map(|i| {
                let s = 1.0 + i as f32 / n as f32;
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)].map(|p| p * s)
            })
            .collect(),
        "stack_same" => (0..n).map(|_| [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]).collect(),
        // random thin triangles through the unit ball's centre region
        "random" | "random_thin" => {
            let mut st = 12345u64;
            let mut rnd = move || {
                st = st.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((st >> 33) as f32) / (1u64 << 31) as f32
            };
            let w: f32 = if kind == "random_thin" { 0.01 } else { 0.1 };
            (0..n)
                .map(|_| {
                    let d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
                    let e = d.any_orthonormal_vector();
                    let f = d.cross(e);
                    let (a, b) = ((rnd() * 6.3).cos(), (rnd() * 6.3).sin());
                    let side = e * a + f * b;
                    let c = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 0.2;
                    [c - d, c + d + side * w, c + d - side * w]
                })
                .collect()
        }
        // thin triangles through the origin, random directions (a sea urchin)
        "urchin" | "urchin_off" => {
            let mut st = 777u64;
            let mut rnd = move || {
                st = st.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((st >> 33) as f32) / (1u64 << 31) as f32
            };
            (0..n)
                .map(|_| {
                    let d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
                    let e = d.any_orthonormal_vector();
                    let f = d.cross(e);
                    let (a, b) = ((rnd() * 6.3).cos(), (rnd() * 6.3).sin());
                    let side = e * a + f * b;
                    let c = if kind == "urchin" { Vec3::ZERO } else { Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 0.01 };
                    [c - d - side * 0.02, c + d, c - d + side * 0.02]
                })
                .collect()
        }
        // thin horizontal sticks along x crossing thin sticks along y (a lattice)
        "lattice" => (0..n)
            .map(|i| {
                let k = (i / 2) as f32 / (n / 2) as f32 - 0.5;
                if i % 2 == 0 {
                    [Vec3::new(-1.0, k - 0.01, -0.1), Vec3::new(1.0, k, 0.1), Vec3::new(-1.0, k + 0.01, -0.1)]
                } else {
                    [Vec3::new(k - 0.01, -1.0, 0.1), Vec3::new(k, 1.0, -0.1), Vec3::new(k + 0.01, -1.0, 0.1)]
                }
            })
            .collect(),
        "stack_slide" => (0..n)
            .map(|i| {
                let d = Vec3::new(0.01 * i as f32, 0.0, 0.0);
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.3, 1.0, 0.0)].map(|p| p + d)
            })
            .collect(),
        "stack_base" => {
            (0..n).map(|i| [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.01 * i as f32, 1.0, 0.0)]).collect()
        }
        "stack_diag" => (0..n)
            .map(|i| {
                let d = Vec3::new(0.01 * i as f32, 0.01 * i as f32, 0.0);
                [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)].map(|p| p + d)
            })
            .collect(),
        _ => panic!("kind"),
    };
    let mesh = mesh_of(&tris);
    let t0 = std::time::Instant::now();
    let (out, r) = clean_mesh(&mesh, &CleanParams { cut_intersections: cut, ..CleanParams::default() }).unwrap();
    println!("{kind} n={n} cut={cut}: {:.2} s, {} -> {} tris", t0.elapsed().as_secs_f64(), mesh.triangle_count(), out.triangle_count());
    println!("{}", r.summary());
}
