//! A chip's amplifiers: which read it (`CCDAMP`), their values (`READNSE[A-D]`, `ATODGN[A-D]`), and,
//! where the instrument's layout is known, which columns each read.
//!
//! ACS/WFC and WFC3/UVIS read chip 1 (`CCDCHIP = 1`) through amplifiers A (its left half in the calibrated
//! image) and B (its right), chip 2 through C (left) and D (right): the instruments' handbooks, whose
//! one-amplifier subarray apertures are named WFC1A, WFC1B, WFC2C and WFC2D (and UVIS1/UVIS2 alike). The
//! halves meet at the trimmed chip's physical column 2048, which is the image's column 2048 + `LTV1` (a
//! subarray's offset). Elsewhere a chip read through one amplifier takes its value; through several of
//! unknown layout, their rms (the report says so).

use super::Keys;

/// The amplifiers a chip was read through (`CCDAMP`, e.g. `C` or `ABCD`), as letters A–D.
pub(super) fn amplifiers(keys: &dyn Keys) -> Vec<char> {
    keys.text("CCDAMP")
        .map(|s| {
            s.trim()
                .to_ascii_uppercase()
                .chars()
                .filter(|c| ('A'..='D').contains(c))
                .collect()
        })
        .unwrap_or_default()
}

/// The amplifiers of `CCDAMP` and the finite, positive values of `{prefix}{A–D}` for those that have one
/// (`ATODGN`, `READNSE`).
pub(super) fn per_amplifier(keys: &dyn Keys, prefix: &str) -> (Vec<char>, Vec<(char, f64)>) {
    let amps = amplifiers(keys);
    let values = amps
        .iter()
        .filter_map(|a| {
            keys.number(&format!("{prefix}{a}"))
                .filter(|v| *v > 0.0 && v.is_finite())
                .map(|v| (*a, v))
        })
        .collect();
    (amps, values)
}

/// Column spans [x0, x1) of a chip `nx` columns wide from each span's first column (in column order): each
/// ends where the next begins, the last at `nx` (clamped to the chip).
pub(super) fn spans<T: Copy>(first_columns: &[(usize, T)], nx: usize) -> Vec<(usize, usize, T)> {
    first_columns
        .iter()
        .enumerate()
        .map(|(k, &(x0, v))| {
            let x1 = first_columns.get(k + 1).map_or(nx, |c| c.0).min(nx);
            (x0.min(x1), x1, v)
        })
        .collect()
}

/// The trimmed chip's column where ACS/WFC's and WFC3/UVIS's second amplifier begins.
const WFC_UVIS_SPLIT_PX: f64 = 2048.0;

/// Each amplifier reading a chip `nx` columns wide as (first column, letter, value), in column order,
/// from `per_amp` (the values of [`per_amplifier`]); `None` where the layout is not known.
pub(super) fn columns(
    keys: &dyn Keys,
    nx: usize,
    per_amp: &[(char, f64)],
) -> Option<Vec<(usize, char, f64)>> {
    let text = |k: &str| keys.text(k).unwrap_or_default().trim().to_ascii_uppercase();
    let split_layout = matches!(
        (text("INSTRUME").as_str(), text("DETECTOR").as_str()),
        ("ACS", "WFC") | ("WFC3", "UVIS")
    );
    let chip = keys.number("CCDCHIP").map(|c| c.round() as i64);
    let pair = match (split_layout, chip) {
        (true, Some(1)) => Some(['A', 'B']),
        (true, Some(2)) => Some(['C', 'D']),
        _ => None,
    };
    let Some(pair) = pair else {
        // one amplifier: its value, whatever the instrument
        return match per_amp {
            [(a, v)] => Some(vec![(0, *a, *v)]),
            _ => None,
        };
    };
    let value = |a: char| per_amp.iter().find(|p| p.0 == a).map(|p| p.1);
    let split = WFC_UVIS_SPLIT_PX + keys.number("LTV1").unwrap_or(0.0);
    match (value(pair[0]), value(pair[1])) {
        (Some(_), Some(r)) if split <= 0.0 => Some(vec![(0, pair[1], r)]),
        (Some(l), Some(_)) if split >= nx as f64 => Some(vec![(0, pair[0], l)]),
        (Some(l), Some(r)) => Some(vec![(0, pair[0], l), (split.round() as usize, pair[1], r)]),
        (Some(l), None) => Some(vec![(0, pair[0], l)]),
        (None, Some(r)) => Some(vec![(0, pair[1], r)]),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    struct K(HashMap<&'static str, &'static str>);
    impl Keys for K {
        fn number(&self, key: &str) -> Option<f64> {
            self.0.get(key)?.parse().ok()
        }
        fn text(&self, key: &str) -> Option<String> {
            self.0.get(key).map(|s| s.to_string())
        }
    }

    fn wfc(chip: &'static str, ltv1: &'static str) -> K {
        K(HashMap::from([
            ("INSTRUME", "ACS"),
            ("DETECTOR", "WFC"),
            ("CCDAMP", "ABCD"),
            ("CCDCHIP", chip),
            ("LTV1", ltv1),
            ("READNSEA", "4.0"),
            ("READNSEB", "5.0"),
            ("READNSEC", "6.0"),
            ("READNSED", "7.0"),
        ]))
    }

    #[test]
    fn wfc_chips_are_read_by_their_two_amplifiers_half_and_half() {
        let k = wfc("1", "0");
        let (_, per) = per_amplifier(&k, "READNSE");
        assert_eq!(
            columns(&k, 4096, &per),
            Some(vec![(0, 'A', 4.0), (2048, 'B', 5.0)])
        );
        let k = wfc("2", "0");
        assert_eq!(
            columns(&k, 4096, &per),
            Some(vec![(0, 'C', 6.0), (2048, 'D', 7.0)])
        );
        // a subarray 300 columns wide whose first column is physical 1948: the boundary at its 100th
        let k = wfc("2", "-1948");
        assert_eq!(
            columns(&k, 300, &per),
            Some(vec![(0, 'C', 6.0), (100, 'D', 7.0)])
        );
        // one wholly right of the boundary: D alone
        let k = wfc("2", "-2100");
        assert_eq!(columns(&k, 300, &per), Some(vec![(0, 'D', 7.0)]));
    }

    #[test]
    fn one_amplifier_is_its_value_and_several_of_unknown_layout_none() {
        let one = K(HashMap::from([
            ("INSTRUME", "ACS"),
            ("DETECTOR", "HRC"),
            ("CCDAMP", "C"),
            ("CCDCHIP", "1"),
            ("READNSEC", "4.7"),
        ]));
        let (_, per) = per_amplifier(&one, "READNSE");
        assert_eq!(columns(&one, 512, &per), Some(vec![(0, 'C', 4.7)]));
        let four = K(HashMap::from([
            ("INSTRUME", "OTHER"),
            ("CCDAMP", "ABCD"),
            ("READNSEA", "4.0"),
            ("READNSEB", "5.0"),
        ]));
        let (_, per) = per_amplifier(&four, "READNSE");
        assert_eq!(columns(&four, 512, &per), None);
    }
}
