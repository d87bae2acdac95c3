//! A day's sun and sky, step by step, ready for a bundle's SUND section:
//! the sun's direction (NREL SPA, or a list of directions), its RGB
//! irradiance and the Preetham sky's SH per step.
//!
//! Night rule, shared with the mask baker: a step is night when the stored
//! (f32) sun direction has `s · up ≤ 0`. Night steps store zero irradiance
//! and a zero sky, and every mask bit of the step is 0.

use glam::Vec3;
use rayon::prelude::*;

use super::sky_sh::{preetham_sky, SunSky};
use super::solar::{solar_position, sun_direction, Site};
use super::timeline::Timeline;

/// The sun and sky at one time step.
#[derive(Clone, Debug, PartialEq)]
pub struct SunStep {
    /// Seconds since 1970-01-01T00:00:00Z.
    pub unix_time_utc: f64,
    /// Unit vector in the world frame pointing toward the sun.
    pub direction: [f32; 3],
    /// Sun elevation above the horizon, degrees (negative below).
    pub elevation_deg: f32,
    /// Sun azimuth, degrees, as the sky module defines it (clockwise from north).
    pub azimuth_deg: f32,
    /// Sun irradiance on a surface facing it, linear RGB.
    pub sun_rgb: [f32; 3],
    /// The sun is below the horizon.
    pub night: bool,
    /// Sky radiance SH, `sky_order²` RGB coefficients, index `l(l+1)+m`.
    pub sky_sh: Vec<[f32; 3]>,
}

/// How the frame and sky of a day are set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkyFrame {
    /// World direction of geographic north (made horizontal).
    pub north: Vec3,
    /// World zenith.
    pub up: Vec3,
    /// Preetham turbidity (clamped to 2..=10).
    pub turbidity: f64,
    /// SH order of the sky (bands l < order); 0 stores no sky coefficients.
    pub sky_order: usize,
}

/// The steps of `timeline` at `site`: SPA sun position (apparent elevation,
/// `delta_t_s` = TT − UT1), direction in the world frame of `frame`, sun
/// colour and sky SH. Steps are independent and computed in parallel;
/// the result does not depend on the thread count.
pub fn day_steps(site: &Site, timeline: &Timeline, delta_t_s: f64, frame: &SkyFrame) -> Vec<SunStep> {
    timeline
        .steps
        .par_iter()
        .map(|&t| {
            let pos = solar_position(site, t, delta_t_s);
            let direction = sun_direction(&pos, frame.north, frame.up);
            let mut step = lit_step(direction, frame);
            step.unix_time_utc = t;
            step.elevation_deg = pos.elevation_deg as f32;
            step.azimuth_deg = pos.azimuth_deg as f32;
            step
        })
        .collect()
}

/// Steps for given sun directions (world frame, toward the sun; need not be
/// unit): elevation and azimuth measured in `frame`, time 0 (unknown).
///
/// Precondition: directions finite and non-zero (see [`parse_directions`]).
pub fn steps_from_directions(directions: &[Vec3], frame: &SkyFrame) -> Vec<SunStep> {
    directions
        .par_iter()
        .map(|&d| {
            let direction = d.normalize();
            let mut step = lit_step(direction, frame);
            let (elevation, azimuth) = elevation_azimuth(direction, frame.north, frame.up);
            step.elevation_deg = elevation;
            step.azimuth_deg = azimuth;
            step
        })
        .collect()
}

/// The sun's direction per step, or `None` at night: what the mask baker takes.
pub fn day_directions(steps: &[SunStep]) -> Vec<Option<Vec3>> {
    steps.iter().map(|s| (!s.night).then(|| Vec3::from(s.direction))).collect()
}

/// Elevation (degrees above the horizon) and azimuth (degrees from north,
/// eastward, in [0, 360)) of unit `direction` in the frame `north`, `up`.
pub fn elevation_azimuth(direction: Vec3, north: Vec3, up: Vec3) -> (f32, f32) {
    let up = up.normalize_or(Vec3::Y);
    let north = (north - up * north.dot(up)).normalize_or(up.any_orthonormal_vector());
    let east = north.cross(up);
    let elevation = direction.dot(up).clamp(-1.0, 1.0).asin().to_degrees();
    let azimuth = direction.dot(east).atan2(direction.dot(north)).to_degrees().rem_euclid(360.0);
    // rem_euclid can round −0.0…-tiny up to exactly 360.
    (elevation, if azimuth >= 360.0 { 0.0 } else { azimuth })
}

/// A step for unit `direction` with sun colour and sky, time and angles zero.
fn lit_step(direction: Vec3, frame: &SkyFrame) -> SunStep {
    // Written as !(x > 0) so a NaN direction counts as night.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let night = !(direction.dot(frame.up.normalize_or(Vec3::Y)) > 0.0);
    let sky = if night { SunSky::night(frame.sky_order) } else { preetham_sky(direction, frame.up, frame.turbidity, frame.sky_order) };
    SunStep {
        unix_time_utc: 0.0,
        direction: direction.to_array(),
        elevation_deg: 0.0,
        azimuth_deg: 0.0,
        sun_rgb: if night { [0.0; 3] } else { sky.sun_rgb_irradiance },
        night,
        sky_sh: if night { vec![[0.0; 3]; frame.sky_order * frame.sky_order] } else { sky.sky_sh },
    }
}

/// A bad row of a directions file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct DirectionsError {
    /// 1-based line number.
    pub line: usize,
    pub message: String,
}

/// Parses a directions file: one `x,y,z` per line (world frame, toward the
/// sun), spaces allowed around numbers; blank lines and text after `#` are
/// ignored. Each direction is normalised. Refuses rows that are not three
/// finite numbers or whose length is zero, files with no direction, and
/// more than `max_steps` directions.
pub fn parse_directions(text: &str, max_steps: usize) -> Result<Vec<Vec3>, DirectionsError> {
    let mut out = Vec::new();
    // Spreadsheets often start a UTF-8 CSV with a byte-order mark.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let fields: Vec<&str> = content.split(',').map(str::trim).collect();
        if fields.len() != 3 {
            return Err(DirectionsError { line, message: format!("expected x,y,z, found {} field(s) in {content:?}", fields.len()) });
        }
        let mut v = [0.0f32; 3];
        for (slot, field) in v.iter_mut().zip(&fields) {
            *slot = field
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| DirectionsError { line, message: format!("{field:?} is not a finite number") })?;
        }
        // Normalised in f64: 1e30² overflows f32, and a long vector is still a direction.
        let d = glam::DVec3::from(v.map(f64::from))
            .try_normalize()
            .map(|d| d.as_vec3())
            .ok_or_else(|| DirectionsError { line, message: format!("direction {content:?} has no length") })?;
        if out.len() == max_steps {
            return Err(DirectionsError { line, message: format!("more than {max_steps} directions") });
        }
        out.push(d);
    }
    if out.is_empty() {
        return Err(DirectionsError { line: text.lines().count().max(1), message: "no direction in the file".into() });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sky::{default_north, default_timeline, DEFAULT_DELTA_T_S, DEFAULT_TURBIDITY};

    fn frame(order: usize) -> SkyFrame {
        SkyFrame { north: default_north(Vec3::Y), up: Vec3::Y, turbidity: DEFAULT_TURBIDITY, sky_order: order }
    }

    #[test]
    fn csv_rows_parse_and_bad_rows_name_their_line() {
        let d = parse_directions("# sun\n0, 2, 0\n\n1,1,0 # east-ish\n", 1024).unwrap();
        // A byte-order mark and huge finite components are fine.
        let bom = parse_directions("\u{feff}0,1,0\n1e30,1e30,1e30\n", 1024).unwrap();
        assert_eq!(bom[0], Vec3::Y);
        assert!((bom[1] - Vec3::splat(1.0 / 3f32.sqrt())).length() < 1e-6, "{:?}", bom[1]);
        assert!(parse_directions("0,0,0\n", 1024).unwrap_err().message.contains("no length"));
        assert_eq!(d.len(), 2);
        assert!((d[0] - Vec3::Y).length() < 1e-7);
        assert!((d[1].length() - 1.0).abs() < 1e-6);
        for (text, line) in [("0,1,0\n1,2\n", 2), ("0,1,0\n\n0,nan,1\n", 3), ("0,0,0\n", 1), ("x,1,0", 1), ("# only\n", 1)] {
            let e = parse_directions(text, 1024).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e}");
        }
        assert!(parse_directions("0,1,0\n0,1,0\n", 1).is_err());
    }

    /// Directions, angles and the night flag agree: the default day is all daylight, with
    /// the sun rising in the east and the stored angles those of SPA.
    #[test]
    fn default_day_steps_are_consistent() {
        let tl = default_timeline();
        let steps = day_steps(&crate::sky::Site::acropolis(), &tl, DEFAULT_DELTA_T_S, &frame(2));
        assert_eq!(steps.len(), 92);
        for s in &steps {
            assert!(!s.night && s.elevation_deg > 0.0 && s.sun_rgb[1] > 0.0 && s.sky_sh.len() == 4);
            let (e, a) = elevation_azimuth(Vec3::from(s.direction), default_north(Vec3::Y), Vec3::Y);
            assert!((e - s.elevation_deg).abs() < 1e-3 && (a - s.azimuth_deg).abs() < 1e-3, "{e} {a} vs {s:?}");
        }
        // Morning sun in the east (+X with north −Z), evening in the west.
        assert!(steps[0].direction[0] > 0.5 && steps[91].direction[0] < -0.5);
    }

    #[test]
    fn below_horizon_directions_are_night() {
        let steps = steps_from_directions(&[Vec3::new(1.0, -0.1, 0.0), Vec3::X, Vec3::new(0.0, 1.0, -1.0)], &frame(3));
        assert!(steps[0].night && steps[1].night && !steps[2].night);
        assert!(steps[0].sun_rgb == [0.0; 3] && steps[0].sky_sh.iter().all(|c| *c == [0.0; 3]));
        assert!((steps[2].elevation_deg - 45.0).abs() < 1e-4 && steps[2].azimuth_deg.abs() < 1e-4);
        assert_eq!(day_directions(&steps).iter().filter(|d| d.is_some()).count(), 1);
    }
}
