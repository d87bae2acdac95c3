//! Sun and sky for a day's time lapse: dates and time zones, the sun's
//! position (NREL SPA), the steps of the day, a clear-sky model (Preetham et
//! al. 1999) with the sun's colour, the CIE overcast sky (`overcast`), and the
//! sky projected to SH.
//!
//! # World frame
//! Right-handed. `up` is the zenith (default +Y; +Z for Z-up scenes) and
//! `north` is the horizontal direction of geographic north in the scene
//! (default −Z for Y-up, +Y for Z-up). East is `north × up`: with up = +Y and
//! north = −Z, east = (−Z) × (+Y) = +X; with up = +Z and north = +Y, east =
//! (+Y) × (+Z) = +X. (In the local East-North-Up frame, E × N = U, so
//! N × U = E.) A `north` that is not horizontal is projected onto the
//! horizontal plane first.
//!
//! # Units
//! Photometric, in linear sRGB (Rec. 709 primaries, D65 white) whose Y is
//! luminous: sky radiance in cd/m² (its SH coefficients `L_i = ∫ L y_i dω`
//! in cd/m²·sr), the sun's irradiance on a plane facing it in lux. So
//! `E = Σ L_i · (irradiance kernel)_i` and the sun's contribution add up
//! directly; the viewer applies an exposure.
//!
//! # Angles
//! Azimuth is measured from north, eastward, in [0, 360); zenith and
//! elevation in degrees, elevation = 90° − zenith.

pub mod day;
pub mod overcast;
pub mod preetham;
pub mod sky_sh;
pub mod solar;
mod spa_tables;
pub mod sun_color;
pub mod time;
pub mod timeline;

pub use day::{day_directions, day_steps, elevation_azimuth, parse_directions, steps_from_directions, DirectionsError, SkyFrame, SunStep};
pub use overcast::{CieOvercast, TYPICAL_OVERCAST_LUX};
pub use preetham::{PreethamSky, DEFAULT_TURBIDITY};
pub use sky_sh::{preetham_sky, SunSky};
pub use solar::{default_north, solar_position, sun_direction, Site, SolarPosition, DEFAULT_DELTA_T_S};
pub use time::{
    athens_utc_offset_minutes, default_date, default_tz_minutes, julian_day, parse_date, parse_hhmm, parse_tz, unix_time, LocalDate,
};
pub use timeline::{default_timeline, timeline, StepSpec, Timeline, MAX_STEPS};

/// Errors from parsing dates, times and time zones, and from building a
/// time line. Messages name the offending text or value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkyError {
    /// A date that is not `YYYY-MM-DD` or names no real day.
    #[error("bad date {text:?}: {reason} (expected YYYY-MM-DD)")]
    BadDate { text: String, reason: &'static str },
    /// A time zone that is not `+HH:MM` / `-HH:MM` within ±14:00.
    #[error("bad time zone {text:?}: {reason} (expected +HH:MM or -HH:MM)")]
    BadTimeZone { text: String, reason: &'static str },
    /// A local time that is not `HH:MM` within 00:00..=24:00.
    #[error("bad time {text:?}: {reason} (expected HH:MM)")]
    BadTime { text: String, reason: &'static str },
    /// A time line whose step count is outside `1..=MAX_STEPS`.
    #[error("time line: {count} steps requested, allowed 1..={max}")]
    BadStepCount { count: u64, max: usize },
    /// A step length that is not a positive finite number of minutes.
    #[error("time line: step of {minutes} minutes, expected a positive finite length")]
    BadStepLength { minutes: f64 },
    /// A span whose bounds are not finite, out of range, or reversed.
    #[error("time line: span {from_min}..{to_min} minutes: {reason}")]
    BadSpan { from_min: f64, to_min: f64, reason: &'static str },
}
