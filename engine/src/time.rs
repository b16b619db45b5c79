//! Time scales of an observation: UTC (the headers' `DATE-OBS`, `MJD-OBS`), TT (uniform: exposures are
//! laid out in it) and TDB (the ephemeris and the stars' motion), by the IAU SOFA routines (`sofars`,
//! a pure-Rust port of SOFA).
//!
//! UTC → TAI by SOFA's leap-second table (TAI − UTC = 37 s since 2017-01-01; later leap seconds are not
//! known, so a mission-era date is taken with 37 s — a choice, stated in the headers' documentation);
//! TT = TAI + 32.184 s; TDB = TT + `dtdb` (the Fairhead & Bretagnon 1990 series, ≤ 1.7 ms, evaluated
//! geocentrically: a 600-km orbit changes it by < 2 µs).

use sofars::{cal, ts};

/// Modified Julian Date zero point (JD 2 400 000.5).
pub const MJD_ZERO_JD: f64 = 2_400_000.5;
/// The years a date may take: SOFA's leap-second table starts in 1972 (UTC with whole leap seconds) and
/// the Earth ephemeris (`epv00`) is valid 1900–2100.
pub const YEAR_RANGE: (i32, i32) = (1972, 2100);

/// An instant, kept as a two-part Julian Date in TT (the uniform scale exposures are laid out in).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Epoch {
    tt1: f64,
    tt2: f64,
}

impl Epoch {
    /// From an ISO 8601 UTC date, `YYYY-MM-DD[Thh:mm:ss[.fff]]` (a trailing `Z` is accepted).
    pub fn from_utc_iso(text: &str) -> Result<Epoch, String> {
        let bad = |why: &str| {
            format!(
                "{text:?}: {why}; expected YYYY-MM-DDThh:mm:ss[.fff] (UTC), years {} … {}",
                YEAR_RANGE.0, YEAR_RANGE.1
            )
        };
        let t = text.trim().trim_end_matches('Z');
        let (date, clock) = t.split_once('T').unwrap_or((t, "00:00:00"));
        let d: Vec<&str> = date.split('-').collect();
        let c: Vec<&str> = clock.split(':').collect();
        if d.len() != 3 || c.len() != 3 {
            return Err(bad("not a date and time"));
        }
        let int = |s: &str| s.parse::<i32>().map_err(|_| bad("a field is not a number"));
        let (y, m, day) = (int(d[0])?, int(d[1])?, int(d[2])?);
        let (h, mi) = (int(c[0])?, int(c[1])?);
        let sec: f64 = c[2].parse().map_err(|_| bad("seconds are not a number"))?;
        if !(YEAR_RANGE.0..=YEAR_RANGE.1).contains(&y) {
            return Err(bad("year out of range"));
        }
        if !(0..24).contains(&h) || !(0..60).contains(&mi) || !(0.0..61.0).contains(&sec) {
            return Err(bad("time of day out of range"));
        }
        let (u1, u2) = ts::dtf2d("UTC", y, m, day, h, mi, sec).map_err(|_| bad("no such day"))?;
        let (a1, a2) = ts::utctai(u1, u2).map_err(|_| bad("no UTC → TAI"))?;
        let (tt1, tt2) = ts::taitt(a1, a2).map_err(|_| bad("no TAI → TT"))?;
        Ok(Epoch { tt1, tt2 })
    }

    /// From a two-part Julian Date in TT.
    pub fn from_tt_jd(tt1: f64, tt2: f64) -> Epoch {
        Epoch { tt1, tt2 }
    }

    /// This instant plus `s` seconds (of TT).
    pub fn plus_s(&self, s: f64) -> Epoch {
        Epoch {
            tt1: self.tt1,
            tt2: self.tt2 + s / 86_400.0,
        }
    }

    /// Two-part Julian Date, TT.
    pub fn tt_jd(&self) -> (f64, f64) {
        (self.tt1, self.tt2)
    }

    /// Two-part quasi Julian Date, UTC (SOFA's convention on a leap-second day).
    pub fn utc_jd(&self) -> (f64, f64) {
        // both conversions fail only for dates outside SOFA's table, which from_utc_iso refuses
        let (a1, a2) = ts::tttai(self.tt1, self.tt2).unwrap_or((self.tt1, self.tt2));
        ts::taiutc(a1, a2).unwrap_or((a1, a2 - 37.0 / 86_400.0))
    }

    /// Modified Julian Date, UTC (the headers' `MJD-OBS`).
    pub fn utc_mjd(&self) -> f64 {
        let (u1, u2) = self.utc_jd();
        (u1 - MJD_ZERO_JD) + u2
    }

    /// `YYYY-MM-DDThh:mm:ss.sss` in UTC (the headers' `DATE-OBS`), rounded to the millisecond.
    pub fn utc_iso(&self) -> String {
        let (u1, u2) = self.utc_jd();
        match ts::d2dtf("UTC", 3, u1, u2) {
            Ok((y, m, d, [h, mi, s, ms])) => {
                format!("{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{ms:03}")
            }
            Err(_) => String::from("1970-01-01T00:00:00.000"),
        }
    }

    /// Two-part Julian Date, TDB: TT + TDB − TT (SOFA `dtdb`, geocentric).
    pub fn tdb_jd(&self) -> (f64, f64) {
        let (u1, u2) = self.utc_jd();
        let ut_fraction = (u1.fract() + u2.fract() + 0.5).rem_euclid(1.0);
        let dt_s = ts::dtdb(self.tt1, self.tt2, ut_fraction, 0.0, 0.0, 0.0);
        (self.tt1, self.tt2 + dt_s / 86_400.0)
    }

    /// Modified Julian Date, TDB.
    pub fn tdb_mjd(&self) -> f64 {
        let (t1, t2) = self.tdb_jd();
        (t1 - MJD_ZERO_JD) + t2
    }

    /// Julian epoch (TDB), years: 2000.0 + (JD − 2 451 545.0)/365.25.
    pub fn julian_year_tdb(&self) -> f64 {
        let (t1, t2) = self.tdb_jd();
        cal::epj(t1, t2)
    }

    /// Seconds from `other` to this instant (TT).
    pub fn seconds_since(&self, other: &Epoch) -> f64 {
        ((self.tt1 - other.tt1) + (self.tt2 - other.tt2)) * 86_400.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_tt_tdb_of_known_instants() {
        // J2000.0 is 2000-01-01T12:00:00 TT = 11:58:55.816 UTC (TAI − UTC = 32 s then; TT − TAI = 32.184 s)
        let e = Epoch::from_utc_iso("2000-01-01T11:58:55.816").expect("date");
        let (t1, t2) = e.tt_jd();
        assert!(
            ((t1 - 2_451_545.0) + t2).abs() * 86_400.0 < 1e-6,
            "{t1} {t2}"
        );
        assert_eq!(e.utc_iso(), "2000-01-01T11:58:55.816");
        // after 2017-01-01 TAI − UTC = 37 s: TT − UTC = 69.184 s
        let e = Epoch::from_utc_iso("2031-03-21T00:00:00").expect("date");
        let (t1, t2) = e.tt_jd();
        let (u1, u2) = e.utc_jd();
        assert!((((t1 - u1) + (t2 - u2)) * 86_400.0 - 69.184).abs() < 1e-6);
        assert_eq!(e.utc_iso(), "2031-03-21T00:00:00.000");
        // MJD 2031-03-21 = 62 946 (MJD 51 544 = 2000-01-01, + 31 years of 365/366 days)
        assert!((e.utc_mjd() - 62_946.0).abs() < 1e-9, "{}", e.utc_mjd());
        // TDB − TT is periodic, ≤ 1.7 ms (Fairhead & Bretagnon 1990)
        let (d1, d2) = e.tdb_jd();
        let dt = ((d1 - t1) + (d2 - t2)) * 86_400.0;
        assert!(dt.abs() < 1.7e-3 && dt != 0.0, "{dt}");
        // the Julian epoch: 2031.0 + (2031-03-21 − J2031.0)
        let jy = e.julian_year_tdb();
        assert!((jy - (2000.0 + (62_946.0 + 69.184 / 86_400.0 - 51_544.5) / 365.25)).abs() < 1e-9);
        // a leap second's day: 2016-12-31T23:59:60 exists
        let leap = Epoch::from_utc_iso("2016-12-31T23:59:60.5").expect("leap second");
        let after = Epoch::from_utc_iso("2017-01-01T00:00:00.5").expect("date");
        assert!((after.seconds_since(&leap) - 1.0).abs() < 1e-6);
        assert!((e.plus_s(12.5).seconds_since(&e) - 12.5).abs() < 1e-6);
    }

    #[test]
    fn bad_dates_are_named() {
        for (text, needle) in [
            ("2031/03/21", "not a date"),
            ("2031-13-01T00:00:00", "no such day"),
            ("2031-02-30T00:00:00", "no such day"),
            ("1950-01-01T00:00:00", "year out of range"),
            ("2031-03-21T25:00:00", "time of day"),
            ("2031-03-21Tab:00:00", "not a number"),
        ] {
            let e = Epoch::from_utc_iso(text).expect_err(text);
            assert!(e.contains(needle) && e.contains("YYYY-MM-DD"), "{e}");
        }
        assert!(Epoch::from_utc_iso("2031-03-21").is_ok());
        assert!(Epoch::from_utc_iso("2031-03-21T06:30:00.25Z").is_ok());
    }
}
