//! Per-step lighting: the sun's colour and the sky projected onto SH.

use glam::Vec3;

use super::preetham::PreethamSky;
use super::sun_color::sun_illuminance_rgb;
use crate::sh::{coeff_count, project_function};

/// Quadrature resolution for projecting the sky: 256² directions over the
/// sphere. The sky is smooth but cut at the horizon; at order 3 the DC term
/// moves by < 0.5 % between 128² and 256² (see tests).
pub const SKY_SAMPLES_PER_AXIS: usize = 256;

/// Lighting of one time step.
#[derive(Debug, Clone, PartialEq)]
pub struct SunSky {
    /// Sun illuminance on a plane facing the sun, linear sRGB with Y in lux
    /// (≈ 100 000 at midday). Zero at night.
    pub sun_rgb_irradiance: [f32; 3],
    /// Sky radiance projected onto real SH, `L_i = ∫ L(ω) y_i(ω) dω`
    /// (cd/m²·sr per channel, linear sRGB), `order²` entries, index
    /// `l(l+1)+m`. The sun disc is not included; the ground (below the
    /// horizon) is black. All zero at night.
    pub sky_sh: Vec<[f32; 3]>,
    /// True when the sun's apparent centre is at or below the horizon
    /// (`sun·up ≤ 0`), or the sun direction is unusable (zero, NaN).
    pub night: bool,
}

impl SunSky {
    /// Night lighting: everything zero, `night = true`.
    pub fn night(order: usize) -> SunSky {
        SunSky { sun_rgb_irradiance: [0.0; 3], sky_sh: vec![[0.0; 3]; coeff_count(order)], night: true }
    }
}

/// Sun colour and sky SH for a sun direction, with the Preetham sky.
///
/// `sun_dir_world` points toward the sun (need not be unit), `up` is the
/// zenith, `turbidity` is clamped to 2..=10 (NaN → 3), `order` is the SH
/// order (bands l < order). The sun's strength uses the air mass of the
/// angle between `sun_dir_world` and `up`, i.e. the apparent elevation.
///
/// At night (sun at or below the horizon) everything is zero: the Preetham
/// fits do not cover twilight, and a zero sky keeps the viewer's night
/// honestly black (apply an ambient there if wanted).
pub fn preetham_sky(sun_dir_world: Vec3, up: Vec3, turbidity: f64, order: usize) -> SunSky {
    let Some(sky) = PreethamSky::new(sun_dir_world.as_dvec3(), up.as_dvec3(), turbidity) else {
        return SunSky::night(order);
    };
    let cos_zenith = sun_dir_world.as_dvec3().normalize().dot(up.as_dvec3().normalize());
    let zenith_deg = cos_zenith.clamp(-1.0, 1.0).acos().to_degrees();
    let sun = sun_illuminance_rgb(zenith_deg, super::preetham::clamp_turbidity(turbidity));
    let sky_sh = project_function(order, SKY_SAMPLES_PER_AXIS, |dir| sky.radiance_rgb(dir));
    SunSky { sun_rgb_irradiance: sun.map(|c| c as f32), sky_sh, night: false }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sky::solar::{solar_position, sun_direction, Site, DEFAULT_DELTA_T_S};
    use crate::sky::time::{default_date, default_tz_minutes, unix_time};

    fn sun_at_elevation(elevation_deg: f32) -> Vec3 {
        let e = elevation_deg.to_radians();
        Vec3::new(e.cos(), e.sin(), 0.0)
    }

    /// Irradiance on an upward plane from SH: E = Σ_l Â_l Σ_m L_lm y_lm(up)
    /// with Â_0 = π, Â_1 = 2π/3, Â_2 = π/4 (Ramamoorthi & Hanrahan 2001).
    fn horizontal_illuminance(sh: &[[f32; 3]], channel: usize) -> f64 {
        let mut basis = [0.0f32; 9];
        crate::sh::eval_basis(3, Vec3::Y, &mut basis);
        let kernel = [std::f64::consts::PI, 2.0 * std::f64::consts::PI / 3.0, std::f64::consts::PI / 4.0];
        sh.iter().zip(basis).enumerate().map(|(i, (c, y))| kernel[(i as f64).sqrt() as usize] * f64::from(c[channel]) * f64::from(y)).sum()
    }

    #[test]
    fn sky_dc_is_positive_by_day_and_zero_at_night() {
        let day = preetham_sky(sun_at_elevation(40.0), Vec3::Y, 3.0, 3);
        assert!(!day.night);
        assert_eq!(day.sky_sh.len(), 9);
        assert!(day.sky_sh[0].iter().all(|&c| c > 0.0), "{:?}", day.sky_sh[0]);
        // Blue sky: more blue than red in the DC term.
        assert!(day.sky_sh[0][2] > day.sky_sh[0][0]);
        // Light comes from above: the band-1 coefficient along up (y_1,-1 ∝ y) is positive.
        assert!(day.sky_sh[1][1] > 0.0);
        let night = preetham_sky(sun_at_elevation(-10.0), Vec3::Y, 3.0, 3);
        assert!(night.night);
        assert!(night.sky_sh.iter().flatten().all(|&c| c == 0.0));
        assert_eq!(night.sun_rgb_irradiance, [0.0; 3]);
        assert_eq!(night.sky_sh.len(), 9);
    }

    /// The sky is symmetric about the sun's vertical plane, so turning the
    /// sun about `up` leaves the DC term unchanged (up to quadrature error),
    /// and a coarser quadrature agrees within 0.5 %.
    #[test]
    fn sky_dc_does_not_depend_on_sun_azimuth() {
        let dc = |azimuth: f32| {
            let e = 30f32.to_radians();
            let dir = Vec3::new(e.cos() * azimuth.cos(), e.sin(), e.cos() * azimuth.sin());
            preetham_sky(dir, Vec3::Y, 3.0, 3).sky_sh[0][1]
        };
        let reference = dc(0.0);
        for azimuth in [0.7f32, 2.0, 4.0] {
            assert!((dc(azimuth) - reference).abs() / reference < 5e-3, "{azimuth}");
        }
        let sky = PreethamSky::new(glam::DVec3::new(0.866, 0.5, 0.0), glam::DVec3::Y, 3.0);
        let Some(sky) = sky else { panic!("no sky by day") };
        let coarse = project_function(1, 128, |d| sky.radiance_rgb(d))[0][1];
        assert!((coarse - reference).abs() / reference < 5e-3, "{coarse} vs {reference}");
    }

    /// Measured numbers, printed for the report; asserted only as broad
    /// plausibility bands for clear skies: diffuse horizontal illuminance of
    /// a few to a few tens of klux.
    #[test]
    fn diffuse_horizontal_illuminance_is_plausible() {
        for elevation in [10.0f32, 30.0, 60.0] {
            let s = preetham_sky(sun_at_elevation(elevation), Vec3::Y, 3.0, 3);
            let e_h = horizontal_illuminance(&s.sky_sh, 1);
            eprintln!("elevation {elevation}°: sky E_h (G channel) {e_h:.0} lux, sun {:?}", s.sun_rgb_irradiance);
            assert!((2_000.0..60_000.0).contains(&e_h), "{elevation}: {e_h}");
        }
    }

    #[test]
    fn sun_rgb_reddens_as_elevation_drops_from_60_to_5_degrees() {
        let mut previous_ratio = 0.0;
        for elevation in [60.0f32, 40.0, 20.0, 10.0, 5.0] {
            let rgb = preetham_sky(sun_at_elevation(elevation), Vec3::Y, 3.0, 1).sun_rgb_irradiance;
            let ratio = rgb[0] / rgb[2];
            assert!(ratio > previous_ratio, "{elevation}: {rgb:?}");
            previous_ratio = ratio;
        }
    }

    /// End to end: SPA at local midnight of the default Acropolis day puts
    /// the sun far below the horizon.
    #[test]
    fn midnight_on_the_acropolis_is_night() {
        let t = unix_time(default_date(), 0.0, default_tz_minutes());
        let pos = solar_position(&Site::acropolis(), t, DEFAULT_DELTA_T_S);
        assert!(pos.elevation_deg < -40.0, "{pos:?}");
        let dir = sun_direction(&pos, Vec3::NEG_Z, Vec3::Y);
        let s = preetham_sky(dir, Vec3::Y, 3.0, 3);
        assert!(s.night);
        // And local noon is day.
        let noon = solar_position(&Site::acropolis(), unix_time(default_date(), 720.0, 120), DEFAULT_DELTA_T_S);
        let s = preetham_sky(sun_direction(&noon, Vec3::NEG_Z, Vec3::Y), Vec3::Y, 3.0, 3);
        assert!(!s.night && s.sun_rgb_irradiance[1] > 50_000.0, "{s:?}");
    }
}
