//! Calendar dates, local times and UTC offsets, Unix time and Julian day.
//!
//! Proleptic Gregorian calendar; day counts use Howard Hinnant's
//! `days_from_civil` algorithm (<http://howardhinnant.github.io/date_algorithms.html>).
//! Times are `f64` seconds since 1970-01-01T00:00:00Z (leap seconds ignored,
//! as in POSIX time).

use super::SkyError;

/// A calendar date in the site's local time zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LocalDate {
    /// Gregorian year (e.g. 2026).
    pub year: i32,
    /// Month, 1..=12.
    pub month: u32,
    /// Day of the month, 1..=28/29/30/31.
    pub day: u32,
}

/// Julian day of the Unix epoch, 1970-01-01T00:00Z.
const JD_UNIX_EPOCH: f64 = 2_440_587.5;
const SECONDS_PER_DAY: f64 = 86_400.0;

/// The default day of the Parthenon demo: 2026-03-20, the March equinox.
///
/// Athens is on UTC+2 that day (EU summer time starts 2026-03-29), see
/// [`default_tz_minutes`]. The sun rises at about 06:27 and sets at about
/// 18:37 local time, so every step of the default 06:57..17:34 time line is
/// in daylight, the first one with the sun about 5° high. (The 2006 demo's
/// captured sky saw the sun from 06:52 to 17:44; its date is not published.)
pub fn default_date() -> LocalDate {
    LocalDate { year: 2026, month: 3, day: 20 }
}

/// UTC offset of [`default_date`] in Athens: +120 minutes (EET).
pub fn default_tz_minutes() -> i32 {
    athens_utc_offset_minutes(default_date())
}

/// UTC offset of Athens (EET/EEST) on `date`, in minutes: +180 from the last
/// Sunday of March to the day before the last Sunday of October (EU rule),
/// +120 otherwise.
///
/// The switch happens at 01:00 UTC on the Sunday; this function answers per
/// day, so on the two switch days it gives the offset in force after 04:00
/// local time, which is the whole of any daylight time line.
pub fn athens_utc_offset_minutes(date: LocalDate) -> i32 {
    let last_sunday = |month: u32| -> u32 {
        // Day 31 exists in March and October; step back to a Sunday.
        let weekday_31 = weekday(date.year, month, 31);
        31 - weekday_31
    };
    let summer_start = last_sunday(3);
    let summer_end = last_sunday(10);
    let after_start = date.month > 3 || (date.month == 3 && date.day >= summer_start);
    let before_end = date.month < 10 || (date.month == 10 && date.day < summer_end);
    if after_start && before_end {
        180
    } else {
        120
    }
}

/// Day of the week, 0 = Sunday .. 6 = Saturday.
fn weekday(year: i32, month: u32, day: u32) -> u32 {
    // 1970-01-01 was a Thursday (4).
    (days_from_civil(year, month, day) + 4).rem_euclid(7) as u32
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Hinnant).
fn days_from_civil(year: i32, month: u32, day: u32) -> i64 {
    let y = i64::from(year) - i64::from(month <= 2);
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(month);
    let mp = if m > 2 { m - 3 } else { m + 9 };
    let doy = (153 * mp + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn is_leap_year(year: i32) -> bool {
    (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
}

fn days_in_month(year: i32, month: u32) -> u32 {
    match month {
        2 if is_leap_year(year) => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Parses an ASCII decimal field of exactly `len` digits.
fn parse_digits(text: &str, len: usize) -> Option<u32> {
    if text.len() != len || !text.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    text.parse().ok()
}

/// Parses `YYYY-MM-DD` (four-digit year 1000..=9999, real day of month).
pub fn parse_date(text: &str) -> Result<LocalDate, SkyError> {
    let bad = |reason| SkyError::BadDate { text: text.to_owned(), reason };
    let mut parts = text.trim().split('-');
    let (Some(y), Some(m), Some(d), None) = (parts.next(), parts.next(), parts.next(), parts.next()) else {
        return Err(bad("not three fields separated by '-'"));
    };
    let year = parse_digits(y, 4).ok_or_else(|| bad("year is not four digits"))?;
    let month = parse_digits(m, 2).ok_or_else(|| bad("month is not two digits"))?;
    let day = parse_digits(d, 2).ok_or_else(|| bad("day is not two digits"))?;
    if year < 1000 {
        return Err(bad("year before 1000"));
    }
    // year ≤ 9999 here, so the cast is lossless.
    let year = year as i32;
    if !(1..=12).contains(&month) {
        return Err(bad("month outside 01..12"));
    }
    if day < 1 || day > days_in_month(year, month) {
        return Err(bad("no such day in that month"));
    }
    Ok(LocalDate { year, month, day })
}

/// Splits `HH:MM` into hours and minutes (two digits each).
fn split_hh_mm(text: &str) -> Option<(u32, u32)> {
    let (h, m) = text.split_once(':')?;
    Some((parse_digits(h, 2)?, parse_digits(m, 2)?))
}

/// Parses a UTC offset `+HH:MM` or `-HH:MM` (also `Z` for zero) into signed
/// minutes east of Greenwich, e.g. `"+02:00"` → 120, `"-05:30"` → −330.
/// Offsets beyond ±14:00 are refused.
pub fn parse_tz(text: &str) -> Result<i32, SkyError> {
    let bad = |reason| SkyError::BadTimeZone { text: text.to_owned(), reason };
    let t = text.trim();
    if t == "Z" || t == "z" {
        return Ok(0);
    }
    let (sign, rest) = if let Some(rest) = t.strip_prefix('+') {
        (1, rest)
    } else if let Some(rest) = t.strip_prefix('-') {
        (-1, rest)
    } else {
        return Err(bad("missing leading '+' or '-'"));
    };
    let (h, m) = split_hh_mm(rest).ok_or_else(|| bad("not HH:MM after the sign"))?;
    if m >= 60 {
        return Err(bad("minutes outside 00..59"));
    }
    let minutes = (h * 60 + m) as i32;
    if minutes > 14 * 60 {
        return Err(bad("offset beyond 14:00"));
    }
    Ok(sign * minutes)
}

/// Parses a local time of day `HH:MM` into minutes after midnight,
/// e.g. `"06:57"` → 417. `24:00` is accepted (end of day).
pub fn parse_hhmm(text: &str) -> Result<u32, SkyError> {
    let bad = |reason| SkyError::BadTime { text: text.to_owned(), reason };
    let (h, m) = split_hh_mm(text.trim()).ok_or_else(|| bad("not HH:MM"))?;
    if m >= 60 {
        return Err(bad("minutes outside 00..59"));
    }
    let minutes = h * 60 + m;
    if minutes > 24 * 60 {
        return Err(bad("after 24:00"));
    }
    Ok(minutes)
}

/// Unix time (UTC seconds) of `local_minutes` after local midnight of `date`
/// in a zone `tz_offset_minutes` east of UTC.
///
/// `local_minutes` may leave 0..1440 (it then runs into the neighbouring
/// days). Example: 2026-03-20 12:00 at +02:00 is 10:00 UTC.
pub fn unix_time(date: LocalDate, local_minutes: f64, tz_offset_minutes: i32) -> f64 {
    let days = days_from_civil(date.year, date.month, date.day) as f64;
    days * SECONDS_PER_DAY + (local_minutes - f64::from(tz_offset_minutes)) * 60.0
}

/// Julian day (UT) of a Unix time: `JD = t/86400 + 2440587.5`.
pub fn julian_day(unix_time_utc: f64) -> f64 {
    unix_time_utc / SECONDS_PER_DAY + JD_UNIX_EPOCH
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact reference: the Unix epoch, J2000.0 and a date before 1970.
    #[test]
    fn unix_time_and_julian_day_match_known_epochs() {
        let epoch = LocalDate { year: 1970, month: 1, day: 1 };
        assert_eq!(unix_time(epoch, 0.0, 0), 0.0);
        // J2000.0 = 2000-01-01T12:00 TT; as UT here, JD 2451545.0 exactly.
        let j2000 = LocalDate { year: 2000, month: 1, day: 1 };
        assert_eq!(julian_day(unix_time(j2000, 720.0, 0)), 2_451_545.0);
        // 2000-03-01 is day 11017 (Hinnant's worked numbers: 1970..2000 = 10957
        // days, + 31 (Jan) + 29 (Feb, leap)).
        let march = LocalDate { year: 2000, month: 3, day: 1 };
        assert_eq!(unix_time(march, 0.0, 0), 11_017.0 * 86_400.0);
        let before = LocalDate { year: 1969, month: 12, day: 31 };
        assert_eq!(unix_time(before, 0.0, 0), -86_400.0);
        // Local noon at +02:00 is 10:00 UTC.
        let d = default_date();
        assert_eq!(unix_time(d, 720.0, 120) - unix_time(d, 0.0, 0), 10.0 * 3600.0);
    }

    #[test]
    fn parse_date_accepts_real_days_and_refuses_the_rest() {
        assert_eq!(parse_date("2026-03-20"), Ok(LocalDate { year: 2026, month: 3, day: 20 }));
        assert_eq!(parse_date("2024-02-29").map(|d| d.day), Ok(29));
        for bad in [
            "2026-02-29",
            "2026-13-01",
            "2026-00-10",
            "2026-04-31",
            "26-03-20",
            "2026-3-20",
            "2026-03-20-01",
            "2026/03/20",
            "",
            "２０２６-03-20",
            "0999-01-01",
        ] {
            assert!(parse_date(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn parse_tz_and_hhmm_give_signed_minutes() {
        assert_eq!(parse_tz("+02:00"), Ok(120));
        assert_eq!(parse_tz("-05:30"), Ok(-330));
        assert_eq!(parse_tz("Z"), Ok(0));
        for bad in ["02:00", "+2:00", "+02:60", "+15:00", "+02", "", "+", "±02:00"] {
            assert!(parse_tz(bad).is_err(), "{bad:?} accepted");
        }
        assert_eq!(parse_hhmm("06:57"), Ok(417));
        assert_eq!(parse_hhmm("17:34"), Ok(1054));
        assert_eq!(parse_hhmm("24:00"), Ok(1440));
        for bad in ["6:57", "06:5", "24:01", "06:60", "0657", "", "é6:57"] {
            assert!(parse_hhmm(bad).is_err(), "{bad:?} accepted");
        }
    }

    /// EU summer-time rule; 2026 switch days are 29 March and 25 October
    /// (both Sundays), from the published EU calendar.
    #[test]
    fn athens_offset_follows_eu_summer_time() {
        let d = |month, day| LocalDate { year: 2026, month, day };
        assert_eq!(weekday(2026, 3, 29), 0);
        assert_eq!(weekday(2026, 10, 25), 0);
        assert_eq!(athens_utc_offset_minutes(d(3, 28)), 120);
        assert_eq!(athens_utc_offset_minutes(d(3, 29)), 180);
        assert_eq!(athens_utc_offset_minutes(d(6, 21)), 180);
        assert_eq!(athens_utc_offset_minutes(d(10, 24)), 180);
        assert_eq!(athens_utc_offset_minutes(d(10, 25)), 120);
        assert_eq!(athens_utc_offset_minutes(d(12, 21)), 120);
        assert_eq!(default_tz_minutes(), 120);
    }
}
