//! The DC error of bundles against a reference bundle of the same mesh, as
//! docs/speed-accuracy.md reports it for the Ferrari.
//!
//! cargo run --release --example transfer_error -- REFERENCE.prtb[,REFERENCE2.prtb…] BUNDLE.prtb…
//!
//! Several references (comma-separated, e.g. two seeds of a converged bake)
//! are averaged per vertex, which halves the variance two seeds leave.
//!
//! Over the vertices the reference lights (total DC > 0): the relative RMS
//! error of DC, sqrt(Σ (b − r)² / Σ r²) (as `budget::relative_rms`), the mean
//! ratio Σ b / Σ r, how many of them the bundle leaves black (DC = 0), and
//! how concentrated the error is: the share of Σ (b − r)² carried by the 1%
//! of lit vertices with the largest squared error, and by the black ones.

use prtbake::bundle::read_bundle;

fn dc_of(path: &str) -> Vec<f64> {
    let bundle = read_bundle(path.as_ref()).unwrap_or_else(|e| panic!("{path}: {e}"));
    let transfer = bundle.transfer.unwrap_or_else(|| panic!("{path}: no transfer section"));
    let stride = transfer.values_per_vertex() as usize;
    transfer.total().chunks_exact(stride).map(|v| v[0] as f64).collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((reference_path, others)) = args.split_first().filter(|(_, o)| !o.is_empty()) else {
        eprintln!("usage: transfer_error REFERENCE.prtb BUNDLE.prtb…");
        std::process::exit(2);
    };
    let references: Vec<Vec<f64>> = reference_path.split(',').map(dc_of).collect();
    let reference: Vec<f64> =
        (0..references[0].len()).map(|v| references.iter().map(|r| r[v]).sum::<f64>() / references.len() as f64).collect();
    let lit: Vec<usize> = (0..reference.len()).filter(|&v| reference[v] > 0.0).collect();
    println!("reference {reference_path}: {} vertices, {} lit", reference.len(), lit.len());
    println!("| bundle | relative RMS DC | mean ratio | black of lit | error share of the worst 1% | of the black |");
    println!("|---|---:|---:|---:|---:|---:|");
    for path in others {
        let dc = dc_of(path);
        assert_eq!(dc.len(), reference.len(), "{path}: vertex count differs from the reference's");
        let (mut error, mut norm, mut sum, mut reference_sum, mut black, mut black_error) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0usize, 0.0f64);
        for &v in &lit {
            error += (dc[v] - reference[v]).powi(2);
            norm += reference[v].powi(2);
            sum += dc[v];
            reference_sum += reference[v];
            if dc[v] == 0.0 {
                black += 1;
                black_error += reference[v].powi(2);
            }
        }
        let share = 100.0 * black as f64 / lit.len() as f64;
        let mut squared: Vec<f64> = lit.iter().map(|&v| (dc[v] - reference[v]).powi(2)).collect();
        squared.sort_by(|a, b| b.total_cmp(a));
        let worst: f64 = squared[..lit.len().div_ceil(100)].iter().sum();
        let concentration = 100.0 * worst / error.max(f64::MIN_POSITIVE);
        let black_share = 100.0 * black_error / error.max(f64::MIN_POSITIVE);
        println!(
            "| {path} | {:.4} | {:.3} | {black} ({share:.1}%) | {concentration:.0}% | {black_share:.1}% |",
            (error / norm).sqrt(),
            sum / reference_sum
        );
    }
}
