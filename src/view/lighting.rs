//! Lighting as SH vectors: an environment map projected once, a default
//! Preetham sky, or a time-lapse step's sky from the bundle; turned with the
//! car per frame.

use std::path::Path;

use glam::{EulerRot, Mat3, Vec3};

use super::backdrop::SkyBackdrop;
use super::ViewError;
use crate::bundle::SunSeries;
use crate::sh::{coeff_count, load_equirect, project_equirect, EquirectImage, ShRotation};

/// Loads the equirect map at `path` (.exr or .hdr, conventions of
/// [`crate::sh::equirect_direction`]) and projects it onto `order²` RGB
/// coefficients; the image is kept for the backdrop.
pub fn env_map(path: &Path, order: usize) -> Result<(EquirectImage, Vec<[f32; 3]>), ViewError> {
    let image = load_equirect(path)?;
    let sh = project_equirect(&image, order);
    Ok((image, sh))
}

/// The default lighting when neither a map nor a time lapse is given: the
/// Preetham sky (turbidity 3, sun 35° high toward +X−Z) in its own units
/// (cd/m², as a time lapse's sky), without the sun (no masks: the SH has no
/// sun term, so the backdrop draws no disc either). Returns the SH and the backdrop.
pub fn default_sky(order: usize) -> (Vec<[f32; 3]>, SkyBackdrop) {
    let elevation = 35f32.to_radians();
    let sun = Vec3::new(elevation.cos() * 0.6, elevation.sin(), -elevation.cos() * 0.8).normalize();
    let turbidity = crate::sky::DEFAULT_TURBIDITY as f32;
    let sky = crate::sky::preetham_sky(sun, Vec3::Y, f64::from(turbidity), order.max(1)).sky_sh;
    let backdrop = SkyBackdrop { sun, up: Vec3::Y, turbidity, scale: 1.0, sun_irradiance: None, rotation: Mat3::IDENTITY };
    (fit_order(&sky, order), backdrop)
}

/// `coeffs` truncated or zero-padded to `order²` entries.
pub fn fit_order(coeffs: &[[f32; 3]], order: usize) -> Vec<[f32; 3]> {
    let n = coeff_count(order);
    (0..n).map(|i| coeffs.get(i).copied().unwrap_or([0.0; 3])).collect()
}

/// The rotation of the environment for yaw (about +Y, world up), pitch (about
/// +X) and roll (about +Z), degrees, applied in that order of precedence
/// (`R = R_y · R_x · R_z`). A light at direction d moves to R·d.
pub fn env_rotation(yaw_deg: f32, pitch_deg: f32, roll_deg: f32) -> Mat3 {
    Mat3::from_euler(EulerRot::YXZ, yaw_deg.to_radians(), pitch_deg.to_radians(), roll_deg.to_radians())
}

/// The environment's rotation for the car turned by yaw (about +Y, world up),
/// pitch (about +X) and roll (about +Z), degrees, right-handed (positive yaw
/// turns the car counter-clockwise seen from above): the car turning by
/// `C = R_y·R_x·R_z` under a fixed sky is the sky turning by `Cᵀ` around the
/// car, so a light at direction d is seen from the car at `Cᵀ·d`.
pub fn car_to_env_rotation(yaw_deg: f32, pitch_deg: f32, roll_deg: f32) -> Mat3 {
    env_rotation(yaw_deg, pitch_deg, roll_deg).transpose()
}

/// `coeffs` (order `order`) rotated by `rotation` (see [`ShRotation`]).
pub fn rotate_sh(coeffs: &[[f32; 3]], order: usize, rotation: Mat3) -> Vec<[f32; 3]> {
    let input = fit_order(coeffs, order);
    let mut output = vec![[0.0; 3]; input.len()];
    ShRotation::new(order, rotation).apply_rgb(&input, &mut output);
    output
}

/// The sky SH of time-lapse `step`, fitted to `order`. Zeros for an out-of-range step.
pub fn step_sky_sh(sun: &SunSeries, step: usize, order: usize) -> Vec<[f32; 3]> {
    sun.steps.get(step).map_or_else(|| vec![[0.0; 3]; coeff_count(order)], |s| fit_order(&s.sky_sh, order))
}

/// The step whose local time of day (UTC + `tz_offset_minutes`) is nearest to
/// `minutes` after midnight. `None` for an empty series.
pub fn step_nearest_time(sun: &SunSeries, minutes: u32, tz_offset_minutes: i32) -> Option<usize> {
    let day = 1440.0;
    let local = |t: f64| ((t / 60.0 + tz_offset_minutes as f64) % day + day) % day;
    let distance = |t: f64| {
        let d = (local(t) - minutes as f64).abs();
        d.min(day - d)
    };
    (0..sun.steps.len()).min_by(|&a, &b| distance(sun.steps[a].unix_time_utc).total_cmp(&distance(sun.steps[b].unix_time_utc)))
}

/// Local `HH:MM` of a step, for the status line.
pub fn step_local_time(sun: &SunSeries, step: usize, tz_offset_minutes: i32) -> String {
    let Some(s) = sun.steps.get(step) else { return "--:--".into() };
    let minutes = ((s.unix_time_utc / 60.0 + tz_offset_minutes as f64).rem_euclid(1440.0)).round() as u32 % 1440;
    format!("{:02}:{:02}", minutes / 60, minutes % 60)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::SunStep;

    fn series(times: &[f64]) -> SunSeries {
        let steps = times
            .iter()
            .map(|&t| SunStep {
                unix_time_utc: t,
                direction: [0.0, 1.0, 0.0],
                elevation_deg: 90.0,
                azimuth_deg: 0.0,
                sun_rgb: [1.0; 3],
                night: false,
                sky_sh: vec![],
            })
            .collect();
        let (words_per_vertex, masks) = SunSeries::pack(times.len(), 0, |_, _| false);
        SunSeries::per_vertex(0, steps, words_per_vertex, masks)
    }

    #[test]
    fn nearest_step_uses_local_time() {
        // 2026-03-20 05:00 UTC and 10:00 UTC; at UTC+2 they are 07:00 and 12:00.
        let base = 1_773_964_800.0; // 2026-03-20T00:00Z
        let s = series(&[base + 5.0 * 3600.0, base + 10.0 * 3600.0]);
        assert_eq!(step_nearest_time(&s, 7 * 60 + 10, 120), Some(0));
        assert_eq!(step_nearest_time(&s, 11 * 60, 120), Some(1));
        assert_eq!(step_local_time(&s, 1, 120), "12:00");
    }

    #[test]
    fn turning_the_car_left_moves_the_sky_right() {
        // The car's nose points along −Z; after yaw +90° (counter-clockwise from
        // above) it points along −X. The light that was ahead (−Z, world) must now
        // be on the car's right: car-frame +X.
        let rotation = car_to_env_rotation(90.0, 0.0, 0.0);
        let seen = rotation * Vec3::NEG_Z;
        assert!((seen - Vec3::X).length() < 1e-6, "{seen}");
        let nose = env_rotation(90.0, 0.0, 0.0) * Vec3::NEG_Z;
        assert!((nose - Vec3::NEG_X).length() < 1e-6, "{nose}");
    }

    #[test]
    fn rotation_moves_a_light() {
        // A lobe along +Z (y_1,0 ∝ z) turned by yaw 90° points along +X (y_1,1 ∝ x).
        let order = 2;
        let mut lobe = vec![[0.0; 3]; 4];
        lobe[2] = [1.0; 3];
        let rotated = rotate_sh(&lobe, order, env_rotation(90.0, 0.0, 0.0));
        assert!((rotated[3][0] - 1.0).abs() < 1e-5 && rotated[2][0].abs() < 1e-5, "{rotated:?}");
    }
}
