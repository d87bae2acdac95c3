//! The steps of the day: a list of UTC instants between two local times.
//!
//! The default is the Parthenon demo's: 92 steps from 06:57 to 17:34, every
//! 7 minutes (91 × 7 = 637 min = 10 h 37 min), on [`default_date`] in Athens.

use super::time::{default_date, default_tz_minutes, unix_time, LocalDate};
use super::SkyError;

/// Largest number of steps a time line may hold (sun masks pack one bit
/// per step; 1024 steps is 32 u32 words per vertex).
pub const MAX_STEPS: usize = 1024;

/// Latest local time, in minutes after midnight of the date, that a span may
/// reach (the end of the next day), so spans can cross one midnight.
const MAX_LOCAL_MINUTES: f64 = 2.0 * 1440.0;

/// Tolerance (minutes) for a fixed step landing on the span's end.
const STEP_END_TOLERANCE_MIN: f64 = 1e-6;

/// Local start and end of the Parthenon demo's day, minutes after midnight.
pub const PARTHENON_FROM_MIN: f64 = 6.0 * 60.0 + 57.0;
/// See [`PARTHENON_FROM_MIN`]: 17:34.
pub const PARTHENON_TO_MIN: f64 = 17.0 * 60.0 + 34.0;
/// Step count of the Parthenon demo (4 floats × 23 mantissa bits in 2006).
pub const PARTHENON_STEPS: u32 = 92;

/// How to divide a span into steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepSpec {
    /// A step every `minutes`, from the start up to and including the end
    /// when it falls on a step (within 1e-6 min).
    Step(f64),
    /// `n` instants evenly spaced from start to end, both included
    /// (`n = 1`: the start alone).
    Count(u32),
}

/// The instants of a time lapse, in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeline {
    /// Unix times (UTC seconds), one per step, non-decreasing, 1..=MAX_STEPS long.
    pub steps: Vec<f64>,
}

/// Builds the time line of `date` in a zone `tz_offset_minutes` east of UTC,
/// from `from_min` to `to_min` local minutes after midnight of `date`.
///
/// Preconditions, each refused with a [`SkyError`]: bounds finite, within
/// 0..=2880 (the span may run into the next day), `to_min ≥ from_min`, and a
/// non-empty span when more than one step is asked for; step count in
/// `1..=MAX_STEPS`; a step length positive and finite.
pub fn timeline(date: LocalDate, tz_offset_minutes: i32, from_min: f64, to_min: f64, spec: StepSpec) -> Result<Timeline, SkyError> {
    let bad_span = |reason| SkyError::BadSpan { from_min, to_min, reason };
    if !from_min.is_finite() || !to_min.is_finite() {
        return Err(bad_span("bounds must be finite"));
    }
    if from_min < 0.0 || to_min > MAX_LOCAL_MINUTES {
        return Err(bad_span("bounds must lie within 0..=2880 minutes of the date"));
    }
    if to_min < from_min {
        return Err(bad_span("end before start"));
    }
    let span = to_min - from_min;
    let local_minutes: Vec<f64> = match spec {
        StepSpec::Count(n) => {
            let count = n as usize;
            if count == 0 || count > MAX_STEPS {
                return Err(SkyError::BadStepCount { count: u64::from(n), max: MAX_STEPS });
            }
            if count > 1 && span == 0.0 {
                return Err(bad_span("several steps asked for an empty span"));
            }
            let stride = if count > 1 { span / (count - 1) as f64 } else { 0.0 };
            (0..count).map(|k| from_min + stride * k as f64).collect()
        }
        StepSpec::Step(minutes) => {
            if !(minutes.is_finite() && minutes > 0.0) {
                return Err(SkyError::BadStepLength { minutes });
            }
            // Count steps without building a huge list first.
            let whole = ((span + STEP_END_TOLERANCE_MIN) / minutes).floor();
            if whole >= MAX_STEPS as f64 {
                return Err(SkyError::BadStepCount { count: whole as u64 + 1, max: MAX_STEPS });
            }
            let count = whole as usize + 1;
            (0..count).map(|k| from_min + minutes * k as f64).collect()
        }
    };
    let steps = local_minutes.into_iter().map(|m| unix_time(date, m, tz_offset_minutes)).collect();
    Ok(Timeline { steps })
}

/// The Parthenon demo's time line: 92 steps, 06:57..17:34 every 7 minutes,
/// on [`default_date`] at [`default_tz_minutes`] (Athens, UTC+2).
pub fn default_timeline() -> Timeline {
    let steps =
        (0..PARTHENON_STEPS).map(|k| unix_time(default_date(), PARTHENON_FROM_MIN + 7.0 * f64::from(k), default_tz_minutes())).collect();
    Timeline { steps }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Local minutes after midnight of the default date for a Unix time.
    fn local_minutes(t: f64) -> f64 {
        (t - unix_time(default_date(), 0.0, default_tz_minutes())) / 60.0
    }

    /// The 2006 demo (seed 001 §5.1): 92 samples, 6:57 to 17:34, 7 min apart.
    #[test]
    fn default_timeline_has_92_steps_from_0657_to_1734() {
        let tl = default_timeline();
        assert_eq!(tl.steps.len(), 92);
        assert_eq!(local_minutes(tl.steps[0]), 417.0);
        assert_eq!(local_minutes(tl.steps[91]), 1054.0);
        assert!(tl.steps.windows(2).all(|w| w[1] - w[0] == 420.0));
        // Same result through the general builder, both ways of asking.
        let (d, tz) = (default_date(), default_tz_minutes());
        let by_count = timeline(d, tz, PARTHENON_FROM_MIN, PARTHENON_TO_MIN, StepSpec::Count(92));
        let by_step = timeline(d, tz, PARTHENON_FROM_MIN, PARTHENON_TO_MIN, StepSpec::Step(7.0));
        assert_eq!(by_count.as_ref(), Ok(&tl));
        assert_eq!(by_step.as_ref(), Ok(&tl));
    }

    #[test]
    fn counts_1_and_1024_work_and_0_and_1025_are_refused() {
        let (d, tz) = (default_date(), default_tz_minutes());
        let one = timeline(d, tz, 600.0, 700.0, StepSpec::Count(1)).map(|t| t.steps);
        assert_eq!(one, Ok(vec![unix_time(d, 600.0, tz)]));
        let many = timeline(d, tz, 0.0, 1023.0, StepSpec::Count(1024)).map(|t| t.steps.len());
        assert_eq!(many, Ok(1024));
        for n in [0, 1025] {
            let r = timeline(d, tz, 0.0, 1023.0, StepSpec::Count(n));
            assert!(matches!(r, Err(SkyError::BadStepCount { .. })), "{n}: {r:?}");
        }
        // A 1-minute step over 1024 minutes would need 1025 steps.
        assert!(timeline(d, tz, 0.0, 1023.0, StepSpec::Step(1.0)).is_ok());
        assert!(matches!(timeline(d, tz, 0.0, 1024.0, StepSpec::Step(1.0)), Err(SkyError::BadStepCount { .. })));
    }

    #[test]
    fn bad_spans_and_steps_are_refused() {
        let (d, tz) = (default_date(), default_tz_minutes());
        let refused = |from: f64, to: f64, spec| timeline(d, tz, from, to, spec).is_err();
        assert!(refused(700.0, 600.0, StepSpec::Count(10)), "to < from");
        assert!(refused(700.0, 600.0, StepSpec::Step(7.0)), "to < from");
        assert!(refused(600.0, 600.0, StepSpec::Count(2)), "empty span, 2 steps");
        assert!(refused(f64::NAN, 600.0, StepSpec::Count(2)));
        assert!(refused(-1.0, 600.0, StepSpec::Count(2)));
        assert!(refused(0.0, 3000.0, StepSpec::Count(2)));
        for step in [0.0, -7.0, f64::NAN, f64::INFINITY] {
            assert!(refused(600.0, 700.0, StepSpec::Step(step)), "step {step}");
        }
        // A step that does not divide the span stops before the end.
        let t = timeline(d, tz, 600.0, 620.0, StepSpec::Step(7.0)).map(|t| t.steps.len());
        assert_eq!(t, Ok(3));
        // An empty span with one step is fine.
        assert!(!refused(600.0, 600.0, StepSpec::Count(1)));
    }
}
