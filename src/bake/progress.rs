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
        let reporter = (!quiet).then(|| {
            let (done, finished) = (done.clone(), finished.clone());
            std::thread::spawn(move || report_loop(&label, total, &done, &finished))
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

fn report_loop(label: &str, total: u64, done: &AtomicU64, finished: &AtomicBool) {
    let start = Instant::now();
    let mut stderr = std::io::stderr();
    loop {
        let is_finished = finished.load(Ordering::Relaxed);
        let count = done.load(Ordering::Relaxed).min(total);
        let seconds = start.elapsed().as_secs_f64();
        let fraction = if total == 0 { 1.0 } else { count as f64 / total as f64 };
        let rate = count as f64 / seconds.max(1e-9);
        let eta = if rate > 0.0 { (total - count) as f64 / rate } else { 0.0 };
        let _ = write!(
            stderr,
            "\r{label}: {:5.1}%  {:.1} Mrays  {:.2} Mrays/s  {:.0}s left   ",
            100.0 * fraction,
            count as f64 / 1e6,
            rate / 1e6,
            eta
        );
        if is_finished {
            let _ = writeln!(stderr, "\r{label}: done in {seconds:.2}s ({:.2} Mrays/s){:20}", rate / 1e6, "");
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
