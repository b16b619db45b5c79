//! The cross-match of a crowded exposure's fits to the truth (`scoring::crowded` uses it for its classes and
//! bins, `scoring::image` for every crowded analysis): the common offset as in
//! [`crate::analysis::detection::match_positions`], then each fit takes the truth star within
//! [`MATCH_RADIUS_PX`] that best agrees in position *and* flux (score `(d/0.5 px)² + (Δm/0.3 mag)²`, one-to-one,
//! best scores first) — in a crowded field the nearest truth star is often a faint one under a bright star's fit.

use crate::analysis::report::StarResult;
use crate::numerics::neighbours::Neighbours;
use crate::truth::TruthRow;

/// Largest distance of a fit from its truth star (after the common offset), px.
pub const MATCH_RADIUS_PX: f64 = 2.0;

/// Cross-match fits to the truth (see the module's documentation): the truth index of each fit, if any.
pub fn match_catalogue(fits: &[StarResult], truth: &[TruthRow]) -> Vec<Option<usize>> {
    let pos: Vec<(f64, f64)> = fits.iter().map(|f| (f.x, f.y)).collect();
    let refs: Vec<(f64, f64)> = truth.iter().map(|t| (t.x_px, t.y_px)).collect();
    // the common offset from the brightest fits' nearest truth stars
    let flux: Vec<f64> = fits.iter().map(|f| f.flux_e).collect();
    let off = crate::analysis::detection::common_offset_of_brightest(&pos, &flux, &refs, 500, 20.0);
    let nb = Neighbours::new(&refs);
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (k, f) in fits.iter().enumerate() {
        let (x, y) = (f.x - off.0, f.y - off.1);
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        for j in nb.within(x, y, MATCH_RADIUS_PX) {
            let d2 = (refs[j].0 - x).powi(2) + (refs[j].1 - y).powi(2);
            let dm = if f.flux_e > 0.0 && truth[j].flux_e > 0.0 {
                2.5 * (f.flux_e / truth[j].flux_e).log10()
            } else {
                3.0
            };
            pairs.push((d2 / 0.25 + (dm / 0.3).powi(2), k, j));
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = vec![None; fits.len()];
    let mut taken = vec![false; truth.len()];
    for (_, k, j) in pairs {
        if out[k].is_none() && !taken[j] {
            out[k] = Some(j);
            taken[j] = true;
        }
    }
    out
}
