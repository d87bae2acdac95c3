//! A progress line on stderr for long passes: rayon workers add to an atomic
//! counter; a reporter thread redraws the line twice a second.

use std::io::Write;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Shared progress counter of one pass; dropping it ends the line.
pub struct Progress {
    done: Arc<AtomicU64>,
    finished: Arc<AtomicBool>,
    reporter: Option<std::thread::JoinHandle<()>>,
}

impl Progress {
    /// Starts reporting `label` out of `total` units (rays); silent when `quiet`.
    pub fn start(label: String, total: u64, quiet: bool) -> Progress {
        let done = Arc::new(AtomicU64::new(0));
        let finished = Arc::new(AtomicBool::new(false));
        // The clock starts with the pass, not with the reporter thread.
        let start = Instant::now();
        let reporter = (!quiet).then(|| {
            let (done, finished) = (done.clone(), finished.clone());
            std::thread::spawn(move || report_loop(&label, total, start, &done, &finished))
        });
        Progress { done, finished, reporter }
    }

    /// Records `units` more finished.
    #[inline]
    pub fn add(&self, units: u64) {
        self.done.fetch_add(units, Ordering::Relaxed);
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finished.store(true, Ordering::Relaxed);
        if let Some(handle) = self.reporter.take() {
            let _ = handle.join();
        }
    }
}

/// A rate is shown only once this much time has passed: over the first
/// milliseconds one finished task would read as billions of rays a second.
const MIN_SECONDS_FOR_RATE: f64 = 0.25;

/// `" 12.34 Mrays/s"`-style rate text, or a dash while too early to tell.
fn rate_text(count: u64, seconds: f64) -> String {
    if seconds < MIN_SECONDS_FOR_RATE {
        return "– Mrays/s".to_string();
    }
    format!("{:.2} Mrays/s", count as f64 / seconds / 1e6)
}

fn report_loop(label: &str, total: u64, start: Instant, done: &AtomicU64, finished: &AtomicBool) {
    let mut stderr = std::io::stderr();
    loop {
        let is_finished = finished.load(Ordering::Relaxed);
        let count = done.load(Ordering::Relaxed).min(total);
        let seconds = start.elapsed().as_secs_f64();
        let fraction = if total == 0 { 1.0 } else { count as f64 / total as f64 };
        let eta = if seconds >= MIN_SECONDS_FOR_RATE && count > 0 {
            format!("{:.0}s left", (total - count) as f64 * seconds / count as f64)
        } else {
            "–s left".to_string()
        };
        let _ = write!(
            stderr,
            "\r{label}: {:5.1}%  {:.1} Mrays  {}  {eta}   ",
            100.0 * fraction,
            count as f64 / 1e6,
            rate_text(count, seconds)
        );
        if is_finished {
            let _ = writeln!(stderr, "\r{label}: done in {seconds:.2}s ({}){:20}", rate_text(count, seconds), "");
            return;
        }
        let _ = stderr.flush();
        // Sleep in short slices so a finished pass ends its line promptly.
        for _ in 0..10 {
            if finished.load(Ordering::Relaxed) {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_rate_is_claimed_before_there_is_time_to_measure_it() {
        assert_eq!(rate_text(1_000_000, 1e-6), "– Mrays/s");
        assert_eq!(rate_text(5_000_000, 2.0), "2.50 Mrays/s");
    }
}
