#[test]
#[ignore]
fn rank1_probe() {
    let b = prtbake::bundle::read_bundle(std::path::Path::new("/tmp/chartwork/ferrari.prtb")).unwrap();
    let t = b.transfer.unwrap();
    let data = &t.layers[0].data;
    let n = 9;
    let mut out = Vec::with_capacity(data.len());
    for v in data.chunks_exact(27) {
        let g: Vec<f32> = (0..n).map(|i| (v[i] + v[n + i] + v[2 * n + i]) / 3.0).collect();
        let gg: f32 = g.iter().map(|x| x * x).sum();
        for c in 0..3 {
            let k = if gg > 0.0 { (0..n).map(|i| v[c * n + i] * g[i]).sum::<f32>() / gg } else { 1.0 };
            let k = half::f16::from_f32(k).to_f32();
            out.extend(g.iter().map(|x| k * half::f16::from_f32(*x).to_f32()));
        }
    }
    let lights = prtbake::bundle::budget::reference_lightings(3);
    for l in &lights {
        let e = prtbake::bundle::budget::relative_rms(&prtbake::bundle::budget::shade(data, 3, 3, &l.sh), &prtbake::bundle::budget::shade(&out, 3, 3, &l.sh));
        eprintln!("{}: {e:.4e}", l.name);
    }
}
