//! Pareto fronts and equal-time comparisons over sweep rows.

use super::Row;

/// Marks, per scene, the rows no other row of that scene beats in both
/// seconds and error (ties in both keep both).
pub fn mark_fronts(rows: &mut [Row]) {
    let flags: Vec<bool> = (0..rows.len())
        .map(|i| {
            let r = &rows[i];
            !rows
                .iter()
                .any(|o| o.scene == r.scene && o.seconds <= r.seconds && o.error <= r.error && (o.seconds < r.seconds || o.error < r.error))
        })
        .collect();
    rows.iter_mut().zip(flags).for_each(|(r, f)| r.pareto = f);
}

/// log(error) of a curve at `seconds`, interpolated linearly in log–log
/// between its points; `None` outside the curve's time range.
fn log_error_at(curve: &[(f64, f64)], seconds: f64) -> Option<f64> {
    let t = seconds.ln();
    curve.windows(2).find_map(|w| {
        let ((t0, e0), (t1, e1)) = ((w[0].0.ln(), w[0].1.ln()), (w[1].0.ln(), w[1].1.ln()));
        (t0 <= t && t <= t1).then(|| if t1 > t0 { e0 + (e1 - e0) * (t - t0) / (t1 - t0) } else { e0.min(e1) })
    })
}

/// The points of one curve sorted by time.
fn curve(rows: &[Row], scene: &str, setting: &str) -> Vec<(f64, f64)> {
    let mut c: Vec<(f64, f64)> =
        rows.iter().filter(|r| r.scene == scene && r.setting == setting && r.error > 0.0).map(|r| (r.seconds, r.error)).collect();
    c.sort_by(|a, b| a.0.total_cmp(&b.0));
    c
}

/// Equal-time comparison of two curves of a scene.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Comparison {
    pub scene: String,
    pub a: String,
    pub b: String,
    /// Times (s) of `a`'s points at which `b` has a value: interpolated inside
    /// `b`'s time range, or, past its slowest point, `b`'s best error (it was
    /// not swept further; see `capped`).
    pub seconds: Vec<f64>,
    /// How many of the times used `b`'s best error past its range.
    pub capped: usize,
    /// error(a) / error(b) at those times.
    pub ratios: Vec<f64>,
    /// Geometric mean of the ratios (< 1: `a` is more accurate for the same time).
    pub geometric_mean_ratio: Option<f64>,
}

/// Compares curve `a` against curve `b` of `scene` at `a`'s times.
pub fn compare(rows: &[Row], scene: &str, a: &str, b: &str) -> Comparison {
    let (ca, cb) = (curve(rows, scene, a), curve(rows, scene, b));
    let (mut seconds, mut ratios, mut capped) = (Vec::new(), Vec::new(), 0);
    let slowest = cb.last().map(|p| p.0);
    let best = cb.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    for &(t, e) in &ca {
        if let Some(lb) = log_error_at(&cb, t) {
            seconds.push(t);
            ratios.push(e / lb.exp());
        } else if slowest.is_some_and(|s| t > s) {
            seconds.push(t);
            ratios.push(e / best);
            capped += 1;
        }
    }
    let geometric_mean_ratio = (!ratios.is_empty()).then(|| (ratios.iter().map(|r| r.ln()).sum::<f64>() / ratios.len() as f64).exp());
    Comparison { scene: scene.into(), a: a.into(), b: b.into(), seconds, capped, ratios, geometric_mean_ratio }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(setting: &str, seconds: f64, error: f64) -> Row {
        Row {
            scene: "s".into(),
            setting: setting.into(),
            pattern: String::new(),
            sampling: String::new(),
            order: 1,
            bounces: 0,
            rays: 1,
            seconds,
            error,
            pareto: false,
        }
    }

    #[test]
    fn front_and_equal_time_ratio() {
        let mut rows = vec![row("a", 1.0, 0.1), row("a", 4.0, 0.05), row("b", 1.0, 0.2), row("b", 4.0, 0.1), row("b", 2.0, 0.01)];
        mark_fronts(&mut rows);
        assert_eq!(rows.iter().map(|r| r.pareto).collect::<Vec<_>>(), vec![true, false, false, false, true]);
        let c = compare(&rows[..4], "s", "a", "b");
        assert_eq!((c.ratios.len(), c.capped), (2, 0));
        assert!((c.geometric_mean_ratio.unwrap() - 0.5).abs() < 1e-12);
        // Interpolation in log–log: at t = 2 between (1, 0.2) and (4, 0.1) the error is 0.2·2^(−1/2).
        let e = log_error_at(&[(1.0, 0.2), (4.0, 0.1)], 2.0).unwrap().exp();
        assert!((e - 0.2 / 2f64.sqrt()).abs() < 1e-12);
        assert!(log_error_at(&[(1.0, 0.2), (4.0, 0.1)], 5.0).is_none());
    }
}
