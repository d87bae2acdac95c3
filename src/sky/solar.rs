//! Solar position: the NREL Solar Position Algorithm (SPA).
//!
//! I. Reda and A. Andreas, "Solar position algorithm for solar radiation
//! applications", Solar Energy 76(5):577–589, 2004; NREL/TP-560-34302,
//! revised January 2008. Uncertainty ±0.0003° for years −2000..6000.
//! Equation numbers below are the report's (section 3.x). The periodic-term
//! tables are in `spa_tables.rs`.

use glam::{DVec3, Vec3};

use super::spa_tables::{
    EARTH_LATITUDE_TERMS, EARTH_LONGITUDE_TERMS, EARTH_RADIUS_TERMS, NUTATION_ARGUMENT_MULTIPLIERS, NUTATION_COEFFICIENTS,
};
use super::time::julian_day;

/// ΔT = TT − UT1 to use for 2024–2027, in seconds (IERS: 69.1 s in 2024).
/// One second of error in ΔT moves the sun by ~1e-5°.
pub const DEFAULT_DELTA_T_S: f64 = 69.0;

/// Sun's apparent radius (degrees) and the refraction at sunrise (degrees)
/// that SPA uses to decide whether to apply the refraction correction.
const SUN_RADIUS_DEG: f64 = 0.26667;
const REFRACTION_AT_HORIZON_DEG: f64 = 0.5667;

/// An observer on the Earth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    /// Geodetic latitude in degrees, north positive, −90..=90.
    pub latitude_deg: f64,
    /// Longitude in degrees, east positive, −180..=180.
    pub longitude_deg: f64,
    /// Elevation above sea level in metres.
    pub elevation_m: f64,
    /// Mean annual local pressure in millibars (for refraction).
    pub pressure_mbar: f64,
    /// Mean annual local temperature in °C (for refraction).
    pub temperature_c: f64,
}

impl Site {
    /// A site at sea-level-referenced `elevation_m`, with the standard
    /// atmosphere's pressure `1013.25·(1 − 2.25577e-5·h)^5.25588` mbar and 20 °C.
    pub fn new(latitude_deg: f64, longitude_deg: f64, elevation_m: f64) -> Site {
        Site { latitude_deg, longitude_deg, elevation_m, pressure_mbar: standard_pressure_mbar(elevation_m), temperature_c: 20.0 }
    }

    /// The Parthenon, Athens: 37.9715° N, 23.7267° E, 150 m.
    pub fn acropolis() -> Site {
        Site::new(37.9715, 23.7267, 150.0)
    }
}

/// Standard-atmosphere pressure at `elevation_m` (ISO 2533 troposphere).
pub fn standard_pressure_mbar(elevation_m: f64) -> f64 {
    1013.25 * (1.0 - 2.25577e-5 * elevation_m).max(0.0).powf(5.25588)
}

/// Where the sun is seen from a [`Site`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolarPosition {
    /// Topocentric zenith angle in degrees, corrected for refraction, 0..=180.
    pub zenith_deg: f64,
    /// Topocentric azimuth in degrees from north, eastward, in [0, 360).
    pub azimuth_deg: f64,
    /// Apparent elevation above the horizon, `90 − zenith_deg`.
    pub elevation_deg: f64,
}

/// Evaluates one of the L, B, R series: Σ_i (Σ_j A cos(B + C·JME)) · JME^i / 1e8.
fn earth_periodic_sum(terms: &[&[[f64; 3]]], jme: f64) -> f64 {
    let mut sum = 0.0;
    let mut power = 1.0;
    for series in terms {
        let partial: f64 = series.iter().map(|[a, b, c]| a * (b + c * jme).cos()).sum();
        sum += partial * power;
        power *= jme;
    }
    sum / 1e8
}

/// `a + b·x + c·x² + x³/d` (the form of the nutation arguments, eq. 15–19).
fn cubic(x: f64, a: f64, b: f64, c: f64, d: f64) -> f64 {
    a + x * (b + x * (c + x / d))
}

/// Computes the sun's topocentric position (NREL SPA).
///
/// `unix_time_utc` is UT1 ≈ UTC seconds since 1970 (the ≤ 0.9 s difference
/// moves the sun by ≤ 0.004°); `delta_t_s` is ΔT = TT − UT1 (use
/// [`DEFAULT_DELTA_T_S`] for current dates). Non-finite input gives NaN fields.
///
/// Refraction (eq. 42) uses the site's pressure and temperature and is
/// applied only while the sun's centre is above −(0.26667° + 0.5667°), as in
/// NREL's reference code.
pub fn solar_position(site: &Site, unix_time_utc: f64, delta_t_s: f64) -> SolarPosition {
    // 3.1 Julian day, ephemeris day, centuries and millennium.
    let jd = julian_day(unix_time_utc);
    let jde = jd + delta_t_s / 86_400.0;
    let jc = (jd - 2_451_545.0) / 36_525.0;
    let jce = (jde - 2_451_545.0) / 36_525.0;
    let jme = jce / 10.0;

    // 3.2 Earth heliocentric longitude, latitude (degrees) and radius (AU).
    let earth_longitude = earth_periodic_sum(&EARTH_LONGITUDE_TERMS, jme).to_degrees().rem_euclid(360.0);
    let earth_latitude = earth_periodic_sum(&EARTH_LATITUDE_TERMS, jme).to_degrees();
    let earth_radius = earth_periodic_sum(&EARTH_RADIUS_TERMS, jme);

    // 3.3 Geocentric longitude and latitude.
    let theta = (earth_longitude + 180.0).rem_euclid(360.0);
    let beta = -earth_latitude;

    // 3.4 Nutation in longitude and obliquity (degrees).
    let x = [
        cubic(jce, 297.85036, 445_267.111_480, -0.001_914_2, 189_474.0),
        cubic(jce, 357.52772, 35_999.050_340, -0.000_160_3, -300_000.0),
        cubic(jce, 134.96298, 477_198.867_398, 0.008_697_2, 56_250.0),
        cubic(jce, 93.27191, 483_202.017_538, -0.003_682_5, 327_270.0),
        cubic(jce, 125.04452, -1_934.136_261, 0.002_070_8, 450_000.0),
    ];
    let mut delta_psi = 0.0;
    let mut delta_epsilon = 0.0;
    for (multipliers, [a, b, c, d]) in NUTATION_ARGUMENT_MULTIPLIERS.iter().zip(NUTATION_COEFFICIENTS.iter()) {
        let argument: f64 = multipliers.iter().zip(x.iter()).map(|(&y, &xj)| f64::from(y) * xj).sum();
        let argument = argument.to_radians();
        delta_psi += (a + b * jce) * argument.sin();
        delta_epsilon += (c + d * jce) * argument.cos();
    }
    let delta_psi = delta_psi / 36_000_000.0;
    let delta_epsilon = delta_epsilon / 36_000_000.0;

    // 3.5 True obliquity of the ecliptic (eq. 24, arcseconds; U = JME/10).
    let u = jme / 10.0;
    const OBLIQUITY: [f64; 11] = [84_381.448, -4_680.93, -1.55, 1_999.25, -51.38, -249.67, -39.05, 7.12, 27.87, 5.79, 2.45];
    let epsilon0 = OBLIQUITY.iter().rev().fold(0.0, |acc, &k| acc * u + k);
    let epsilon = epsilon0 / 3600.0 + delta_epsilon;

    // 3.6–3.8 Aberration, apparent sun longitude, sidereal time at Greenwich.
    let delta_tau = -20.4898 / (3600.0 * earth_radius);
    let lambda = theta + delta_psi + delta_tau;
    let nu0 = (280.460_618_37 + 360.985_647_366_29 * (jd - 2_451_545.0) + 0.000_387_933 * jc * jc - jc * jc * jc / 38_710_000.0)
        .rem_euclid(360.0);
    let nu = nu0 + delta_psi * epsilon.to_radians().cos();

    // 3.9–3.10 Geocentric right ascension and declination.
    let (lambda_r, epsilon_r, beta_r) = (lambda.to_radians(), epsilon.to_radians(), beta.to_radians());
    let alpha = (lambda_r.sin() * epsilon_r.cos() - beta_r.tan() * epsilon_r.sin()).atan2(lambda_r.cos()).to_degrees().rem_euclid(360.0);
    let delta = (beta_r.sin() * epsilon_r.cos() + beta_r.cos() * epsilon_r.sin() * lambda_r.sin()).asin();

    // 3.11 Observer local hour angle.
    let hour_angle = (nu + site.longitude_deg - alpha).rem_euclid(360.0).to_radians();

    // 3.12 Topocentric right ascension parallax and declination.
    let xi = (8.794 / (3600.0 * earth_radius)).to_radians();
    let phi = site.latitude_deg.to_radians();
    let u_lat = (0.996_647_19 * phi.tan()).atan();
    let x_term = u_lat.cos() + site.elevation_m / 6_378_140.0 * phi.cos();
    let y_term = 0.996_647_19 * u_lat.sin() + site.elevation_m / 6_378_140.0 * phi.sin();
    let delta_alpha = (-x_term * xi.sin() * hour_angle.sin()).atan2(delta.cos() - x_term * xi.sin() * hour_angle.cos());
    let delta_prime = ((delta.sin() - y_term * xi.sin()) * delta_alpha.cos()).atan2(delta.cos() - x_term * xi.sin() * hour_angle.cos());
    // 3.13 Topocentric local hour angle.
    let hour_angle_prime = hour_angle - delta_alpha;

    // 3.14 Topocentric elevation without, then with, refraction.
    let e0 = (phi.sin() * delta_prime.sin() + phi.cos() * delta_prime.cos() * hour_angle_prime.cos()).asin().to_degrees();
    let refraction = if e0 >= -(SUN_RADIUS_DEG + REFRACTION_AT_HORIZON_DEG) {
        (site.pressure_mbar / 1010.0) * (283.0 / (273.0 + site.temperature_c)) * 1.02
            / (60.0 * (e0 + 10.3 / (e0 + 5.11)).to_radians().tan())
    } else {
        0.0
    };
    let elevation = e0 + refraction;

    // 3.15 Topocentric azimuth, measured from north eastward.
    let gamma = hour_angle_prime.sin().atan2(hour_angle_prime.cos() * phi.sin() - delta_prime.tan() * phi.cos()).to_degrees();
    let azimuth = (gamma + 180.0).rem_euclid(360.0);

    SolarPosition { zenith_deg: 90.0 - elevation, azimuth_deg: azimuth, elevation_deg: elevation }
}

/// The default scene direction of north for an up axis: −Z when up is +Y
/// (glTF), +Y when up is +Z; for any other up, a horizontal vector
/// derived from −Z (or +Y when up is ±Z).
pub fn default_north(up: Vec3) -> Vec3 {
    let up = up.normalize_or(Vec3::Y);
    let candidate = if up.dot(Vec3::Z).abs() > 0.9 { Vec3::Y } else { Vec3::NEG_Z };
    (candidate - up * candidate.dot(up)).normalize_or(Vec3::NEG_Z)
}

/// East in the world frame: `north × up`, with `north` made horizontal.
///
/// Returns `(north_h, east, up)` as an orthonormal right-handed basis. A
/// `north` parallel to `up` (or zero) falls back to any horizontal direction.
fn horizon_basis(north: Vec3, up: Vec3) -> (DVec3, DVec3, DVec3) {
    let up = up.as_dvec3().try_normalize().unwrap_or(DVec3::Y);
    let north = north.as_dvec3();
    let north_h = (north - up * north.dot(up)).try_normalize().unwrap_or_else(|| up.any_orthonormal_vector());
    (north_h, north_h.cross(up), up)
}

/// Unit vector toward the sun in the world frame.
///
/// `north` is the scene's direction of geographic north (made horizontal),
/// `up` its zenith; east is `north × up` (see the module docs of `sky`). The
/// elevation used is the apparent (refracted) one. Example: with
/// north = −Z and up = +Y, azimuth 90° at elevation 0° gives +X.
pub fn sun_direction(pos: &SolarPosition, north: Vec3, up: Vec3) -> Vec3 {
    let (north_h, east, up) = horizon_basis(north, up);
    let azimuth = pos.azimuth_deg.to_radians();
    let elevation = pos.elevation_deg.to_radians();
    let horizontal = north_h * azimuth.cos() + east * azimuth.sin();
    (horizontal * elevation.cos() + up * elevation.sin()).as_vec3()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sky::time::{unix_time, LocalDate};

    /// Tolerance for SPA against its published worked example (degrees).
    const SPA_EXAMPLE_TOL_DEG: f64 = 1e-4;
    /// Tolerance against pvlib's SPA (degrees), as the brief requires.
    const PVLIB_TOL_DEG: f64 = 0.01;

    /// Reda & Andreas (2004/2008), NREL/TP-560-34302, Table A5.1 worked
    /// example: 2003-10-17 12:30:30 local, TZ −7, ΔT 67 s, 39.742476 N,
    /// 105.1786 W, 1830.14 m, 820 mbar, 11 °C ⇒ topocentric zenith 50.11162°,
    /// azimuth 194.34024°.
    #[test]
    fn spa_matches_reda_andreas_worked_example() {
        let site =
            Site { latitude_deg: 39.742476, longitude_deg: -105.1786, elevation_m: 1830.14, pressure_mbar: 820.0, temperature_c: 11.0 };
        let date = LocalDate { year: 2003, month: 10, day: 17 };
        let t = unix_time(date, 12.0 * 60.0 + 30.0 + 30.0 / 60.0, -7 * 60);
        let pos = solar_position(&site, t, 67.0);
        assert!((pos.zenith_deg - 50.11162).abs() < SPA_EXAMPLE_TOL_DEG, "zenith {}", pos.zenith_deg);
        assert!((pos.azimuth_deg - 194.34024).abs() < SPA_EXAMPLE_TOL_DEG, "azimuth {}", pos.azimuth_deg);
        assert!((pos.elevation_deg + pos.zenith_deg - 90.0).abs() < 1e-12);
    }

    /// Reference: pvlib 0.16.1 (PyPI), `pvlib.solarposition.spa_python(times,
    /// 37.9715, 23.7267, altitude=150, pressure=99535.95 Pa (standard
    /// atmosphere at 150 m), temperature=20, delta_t=69, how='numpy')`, an
    /// independent Python implementation of NREL SPA. Values are its
    /// `apparent_zenith` and `azimuth` at every 13th step of the default
    /// Acropolis day (2026-03-20, UTC+2, 06:57 + 7 min · k).
    #[test]
    fn acropolis_default_day_matches_pvlib_spa() {
        // (local minutes, apparent zenith, azimuth) from pvlib.
        let reference: [(f64, f64, f64); 8] = [
            (417.0, 85.139387, 93.887020),   // 06:57
            (508.0, 67.696857, 108.834570),  // 08:28
            (599.0, 51.909951, 127.914878),  // 09:59
            (690.0, 40.682186, 155.576936),  // 11:30
            (781.0, 38.582763, 191.452041),  // 13:01
            (872.0, 46.889872, 223.001041),  // 14:32
            (963.0, 61.390652, 244.816881),  // 16:03
            (1054.0, 78.440297, 260.891727), // 17:34
        ];
        let site = Site::acropolis();
        let date = LocalDate { year: 2026, month: 3, day: 20 };
        for (minutes, zenith, azimuth) in reference {
            let pos = solar_position(&site, unix_time(date, minutes, 120), DEFAULT_DELTA_T_S);
            assert!((pos.zenith_deg - zenith).abs() < PVLIB_TOL_DEG, "{minutes}: zenith {} vs {zenith}", pos.zenith_deg);
            assert!((pos.azimuth_deg - azimuth).abs() < PVLIB_TOL_DEG, "{minutes}: azimuth {} vs {azimuth}", pos.azimuth_deg);
        }
    }

    #[test]
    fn sun_direction_points_up_at_zenith_and_east_at_azimuth_90() {
        let overhead = SolarPosition { zenith_deg: 0.0, azimuth_deg: 123.0, elevation_deg: 90.0 };
        let d = sun_direction(&overhead, Vec3::NEG_Z, Vec3::Y);
        assert!((d - Vec3::Y).length() < 1e-6, "{d}");
        let east = SolarPosition { zenith_deg: 90.0, azimuth_deg: 90.0, elevation_deg: 0.0 };
        assert!((sun_direction(&east, Vec3::NEG_Z, Vec3::Y) - Vec3::X).length() < 1e-6);
        // Z-up with north = +Y: east is still +X, south is −Y.
        assert!((sun_direction(&east, Vec3::Y, Vec3::Z) - Vec3::X).length() < 1e-6);
        let south = SolarPosition { zenith_deg: 90.0, azimuth_deg: 180.0, elevation_deg: 0.0 };
        assert!((sun_direction(&south, Vec3::Y, Vec3::Z) + Vec3::Y).length() < 1e-6);
        // A tilted north is projected onto the horizon; 30° elevation.
        let tilted = SolarPosition { zenith_deg: 60.0, azimuth_deg: 0.0, elevation_deg: 30.0 };
        let d = sun_direction(&tilted, Vec3::new(0.0, 0.5, -1.0), Vec3::Y);
        let expected = Vec3::new(0.0, 0.5, -(0.75f32).sqrt());
        assert!((d - expected).length() < 1e-6, "{d}");
        assert_eq!(default_north(Vec3::Y), Vec3::NEG_Z);
        assert_eq!(default_north(Vec3::Z), Vec3::Y);
        // Degenerate north (parallel to up) still yields a unit vector.
        let d = sun_direction(&tilted, Vec3::Y, Vec3::Y);
        assert!((d.length() - 1.0).abs() < 1e-6 && (d.y - 0.5).abs() < 1e-6);
    }

    #[test]
    fn standard_pressure_is_1013_at_sea_level() {
        assert!((standard_pressure_mbar(0.0) - 1013.25).abs() < 1e-9);
        // ISA at 1000 m: 898.76 hPa.
        assert!((standard_pressure_mbar(1000.0) - 898.76).abs() < 0.05);
        assert!(standard_pressure_mbar(1e9).is_finite());
    }
}
