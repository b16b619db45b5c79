//! The error that a source's observations within one stare share, measured from the residuals between stares
//! and carried into the sources' formal errors.
//!
//! Within a stare a source sits on the same pixels among the same neighbours in every exposure: what its
//! ePSF gets wrong at that pixel phase, its neighbours' share of its fit, a single pointing's calibration — an
//! error common to the stare's exposures, independent between stares a step apart. The observations' σ
//! (each exposure's Cramér–Rao bound ⊕ a floor) leaves it out, so a source's block covariance `N⁻¹`
//! understates its error once it is seen many times in one stare (the pulls 1.15–1.5 of
//! docs/astrometric-solution.md).
//!
//! **The model.** Observation i of stare s: `y_i = a_iᵀ β + δ_s + ε_i`, ε_i ~ N(0, σ_i²), δ_s ~ N(0, τ²)
//! shared by the stare's observations of the source. The solution's estimate, weighted by `w_i = 1/σ_i²`,
//! then has the sandwich covariance (the priors enter N and its middle alike)
//!
//! ```text
//! C = N⁻¹ (N + τ² G) N⁻¹ = N⁻¹ + τ² N⁻¹ G N⁻¹,   G = Σ_s Σ_axis g_s g_sᵀ,   g_s = Σ_{i ∈ s} w_i a_i
//! ```
//!
//! **τ from the data.** Each stare's weighted mean residual r̄_s (per axis, weight W_s = Σ_{i∈s} w_i) has the
//! variance (1/W_s + τ²)(1 − h) with h ≈ p_eff / 2S the share the source's own fit takes; over the sources
//! of a bin of per-observation σ, τ² is where the median of the normalised terms is χ²₁'s (robust: a few
//! blended or mismatched sources do not set everyone's τ)
//!
//! ```text
//! median over sources, stares, axes of  r̄_s² / ((1/W_s + τ²)(1 − p_eff/2S))  =  0.4549,   p_eff = tr(N⁻¹ N_data)
//! ```
//!
//! (S the source's stares, p_eff the parameters its observations pay for: under 2 per axis where a
//! reference prior carries part of the fit); τ = 0 where the left side at τ = 0 is already at or below it.
//! Only sources seen in two stares or more enter the estimate; every source's σ gets the τ of its
//! per-observation σ (interpolated between the bins in log σ, held beyond the ends). The parameters are
//! not changed: with equal stares the weights are the optimal ones either way. Gaia's astrometric excess
//! noise is the per-observation form of this (Lindegren et al. 2012, §5.1.2); with one stare per exposure
//! ([`super::ExposureGeometry::stare`]) this is that form.

use super::blocks::{Problem, State, anchors, corrected_at, design_row};
use rayon::prelude::*;

/// The error beyond each observation's own σ that the sources' formal errors carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExcessNoise {
    /// Each observation's σ alone: the observations taken as independent.
    #[default]
    None,
    /// An error shared by a source's observations within one stare, its τ measured per bin of
    /// per-observation σ from the residuals between stares (the module's equations).
    PerStare,
    /// The same with a visit (a season's stares) in place of a stare: an error that the stares of one
    /// visit share too (their pointings a step apart, one season's calibration and ePSF).
    PerVisit,
}

impl ExcessNoise {
    /// Parse `none` or `per-stare` (a named error otherwise).
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "none" => Ok(Self::None),
            "per-stare" => Ok(Self::PerStare),
            "per-visit" => Ok(Self::PerVisit),
            other => Err(format!(
                "excess noise \"{other}\": allowed none, per-stare or per-visit"
            )),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::PerStare => "per-stare",
            Self::PerVisit => "per-visit",
        }
    }

    /// The group of exposures that share the error: exposure `g`'s visit for `PerVisit`, else its stare.
    fn group(self, g: &super::ExposureGeometry) -> usize {
        match self {
            Self::PerVisit => g.visit,
            Self::None | Self::PerStare => g.stare,
        }
    }
}

/// The shared error measured in one bin of sources.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcessBin {
    /// The bin's median per-observation σ, mas.
    pub sigma_obs_mas: f64,
    /// The error a source's observations share within a stare, mas (0 where the residuals show none).
    pub tau_mas: f64,
    /// Sources that measured it (each seen in two groups — stares or visits — or more).
    pub sources: usize,
}

/// A bin spans at most this factor in per-observation σ (0.1 dex) once it holds [`BIN_SOURCES`].
const BIN_SPAN: f64 = 1.258_925_4;
/// Sources per bin at least (a last bin with fewer joins the one before).
const BIN_SOURCES: usize = 50;
/// Fewer contributing sources than this: no estimate (τ = 0, no bin reported).
const MIN_SOURCES: usize = 20;

/// One source's share: its block, its stares' mean residuals and weights, its design sums.
struct Share {
    /// Parameters fitted (2, 4 or 5).
    n: usize,
    /// N⁻¹ (n × n, row-major in a 5 × 5 array).
    ninv: [f64; 25],
    /// G = Σ_s Σ_axis g gᵀ.
    g: [f64; 25],
    /// Per stare: (W_s, r̄_ξ, r̄_η).
    stares: Vec<(f64, f64, f64)>,
    /// tr(N⁻¹ N_data), both axes.
    p_eff: f64,
    /// Per-observation σ, mas: √(observations / Σ w).
    sigma_obs_mas: f64,
}

/// Source `s`'s share, or None when it has no parameters or no kept observation.
fn share(p: &Problem, state: &State, active: &[bool], s: usize) -> Option<Share> {
    let src = &state.sources[s];
    if !src.params[0].is_finite() {
        return None;
    }
    let n = src.sigma.iter().take_while(|v| v.is_finite()).count();
    if n < 2 {
        return None;
    }
    let mut mine: Vec<(usize, usize)> = p
        .by_source
        .get(s)
        .iter()
        .map(|i| *i as usize)
        .filter(|i| active[*i])
        .map(|i| {
            let g = &p.exposures[p.obs[i].exposure()];
            (p.opt.excess.group(g), i)
        })
        .collect();
    if mine.is_empty() {
        return None;
    }
    mine.sort_unstable();
    let (mut data, mut g) = ([0.0; 25], [0.0; 25]);
    let (mut stares, mut w_total) = (Vec::new(), 0.0);
    let mut k = 0;
    while k < mine.len() {
        let stare = mine[k].0;
        let (mut w_s, mut r_s, mut g_s) = (0.0, [0.0; 2], [[0.0; 5]; 2]);
        while k < mine.len() && mine[k].0 == stare {
            let i = mine[k].1;
            let o = &p.obs[i];
            let (geo, att) = (&p.exposures[o.exposure()], &state.attitudes[o.exposure()]);
            let place = att.invert(
                geo.centre_mas,
                corrected_at(p.obs, p.exposures, &state.cal, i),
            );
            let w = (att.p * att.p + att.q * att.q) / (o.sigma_mas * o.sigma_mas);
            for axis in 0..2 {
                let row = design_row(geo, axis);
                let model: f64 = row.iter().zip(&src.params).map(|(a, b)| a * b).sum();
                r_s[axis] += w * (place[axis] - model);
                for a in 0..n {
                    g_s[axis][a] += w * row[a];
                    for b in 0..n {
                        data[a * n + b] += w * row[a] * row[b];
                    }
                }
            }
            w_s += w;
            k += 1;
        }
        for gs in &g_s {
            for a in 0..n {
                for b in 0..n {
                    g[a * n + b] += gs[a] * gs[b];
                }
            }
        }
        w_total += w_s;
        stares.push((w_s, r_s[0] / w_s, r_s[1] / w_s));
    }
    let mut normal = data;
    if let Some(r) = p.prior[s] {
        for k in 0..n {
            if anchors(r.sigma[k]) {
                normal[k * n + k] += 1.0 / (r.sigma[k] * r.sigma[k]);
            }
        }
    }
    let inv = crate::numerics::linalg::inverse(&normal[..n * n], n)?;
    let mut ninv = [0.0; 25];
    ninv[..n * n].copy_from_slice(&inv);
    let p_eff = (0..n)
        .map(|a| {
            (0..n)
                .map(|b| ninv[a * n + b] * data[b * n + a])
                .sum::<f64>()
        })
        .sum();
    Some(Share {
        n,
        ninv,
        g,
        stares,
        p_eff,
        sigma_obs_mas: (mine.len() as f64 / w_total).sqrt(),
    })
}

/// The median of χ² with one degree of freedom.
const MEDIAN_CHI2_1: f64 = 0.454_936_4;

/// τ² of one bin: where the median over its stares' terms `r̄² / ((1/W_s + τ²)(1 − h))` (per axis, h =
/// p_eff / 2S the share of a term the source's own fit takes) is χ²₁'s, 0.4549 — the median, so that a few
/// mismatched or blended sources, whose residuals are not Gaussian, do not set the τ of all the others; 0
/// where the median at τ = 0 is already at or below it. The bin's sources each keep degrees of freedom
/// (2S − p_eff > 0.5: [`apply`] measures with no others), so 1 − h > 0.
fn tau2_of(bin: &[&Share]) -> f64 {
    // (1/W_s, r̄² / (1 − h)) per stare and axis
    let terms: Vec<(f64, f64)> = bin
        .iter()
        .flat_map(|s| {
            let keep = 1.0 - s.p_eff / (2.0 * s.stares.len() as f64);
            s.stares
                .iter()
                .flat_map(move |(w, rx, ry)| [(1.0 / w, rx * rx / keep), (1.0 / w, ry * ry / keep)])
        })
        .collect();
    if terms.is_empty() {
        return 0.0;
    }
    let mut scratch = vec![0.0; terms.len()];
    let mut median_at = |t2: f64| -> f64 {
        for (z, (v, r2)) in scratch.iter_mut().zip(&terms) {
            *z = r2 / (v + t2);
        }
        let mid = scratch.len() / 2;
        *scratch.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    if median_at(0.0) <= MEDIAN_CHI2_1 {
        return 0.0;
    }
    // the median falls with τ² towards 0: bracket, then bisect (60 halvings of the bracket)
    let mut hi = terms
        .iter()
        .map(|(v, _)| *v)
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let mut steps = 0;
    while median_at(hi) > MEDIAN_CHI2_1 && steps < 200 {
        hi *= 2.0;
        steps += 1;
    }
    let mut lo = 0.0;
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if median_at(mid) > MEDIAN_CHI2_1 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The bins over sources sorted by per-observation σ: each closes once it holds [`BIN_SOURCES`] and the next
/// source lies beyond [`BIN_SPAN`] × its first σ (bins of 0.1 dex where the sources are many, wider where
/// they are few: the bright end keeps its own τ); a last bin short of sources joins the one before.
fn bin_ranges(sorted: &[&Share]) -> Vec<std::ops::Range<usize>> {
    let mut out: Vec<std::ops::Range<usize>> = Vec::new();
    let mut start = 0;
    for k in 1..sorted.len() {
        if k - start >= BIN_SOURCES
            && sorted[k].sigma_obs_mas > BIN_SPAN * sorted[start].sigma_obs_mas
        {
            out.push(start..k);
            start = k;
        }
    }
    match out.last_mut() {
        Some(last) if sorted.len() - start < BIN_SOURCES => last.end = sorted.len(),
        _ => out.push(start..sorted.len()),
    }
    out
}

/// τ at per-observation σ `sigma`: linear in log σ between the bins' medians, held beyond the ends.
fn tau_at(bins: &[ExcessBin], sigma: f64) -> f64 {
    let Some(first) = bins.first() else {
        return 0.0;
    };
    if sigma <= first.sigma_obs_mas || bins.len() == 1 {
        return first.tau_mas;
    }
    for w in bins.windows(2) {
        if sigma <= w[1].sigma_obs_mas {
            let (a, b) = (w[0].sigma_obs_mas.ln(), w[1].sigma_obs_mas.ln());
            let f = if b > a {
                (sigma.ln() - a) / (b - a)
            } else {
                1.0
            };
            return w[0].tau_mas + f * (w[1].tau_mas - w[0].tau_mas);
        }
    }
    bins.last().map_or(0.0, |b| b.tau_mas)
}

/// Measure the shared error and put it into every solved source's σ; returns the bins that measured it
/// (empty where too few sources are seen in two stares).
pub(super) fn apply(p: &Problem, state: &mut State, active: &[bool]) -> Vec<ExcessBin> {
    let shares: Vec<Option<Share>> = (0..state.sources.len())
        .into_par_iter()
        .map(|s| share(p, state, active, s))
        .collect();
    let mut measuring: Vec<&Share> = shares
        .iter()
        .flatten()
        .filter(|s| s.stares.len() >= 2 && 2.0 * s.stares.len() as f64 - s.p_eff > 0.5)
        .collect();
    if measuring.len() < MIN_SOURCES {
        return Vec::new();
    }
    measuring.sort_by(|a, b| a.sigma_obs_mas.total_cmp(&b.sigma_obs_mas));
    let bins: Vec<ExcessBin> = bin_ranges(&measuring)
        .into_iter()
        .map(|r| {
            let chunk = &measuring[r];
            ExcessBin {
                sigma_obs_mas: chunk[chunk.len() / 2].sigma_obs_mas,
                tau_mas: tau2_of(chunk).sqrt(),
                sources: chunk.len(),
            }
        })
        .collect();
    for (src, sh) in state.sources.iter_mut().zip(&shares) {
        let Some(sh) = sh else { continue };
        let t2 = tau_at(&bins, sh.sigma_obs_mas).powi(2);
        if t2 <= 0.0 {
            // nothing shared: the block's own σ stand
            continue;
        }
        let n = sh.n;
        for k in 0..n {
            // (N⁻¹ G N⁻¹)_kk
            let mut extra = 0.0;
            for a in 0..n {
                for b in 0..n {
                    extra += sh.ninv[k * n + a] * sh.g[a * n + b] * sh.ninv[b * n + k];
                }
            }
            src.sigma[k] = (sh.ninv[k * n + k] + t2 * extra).max(0.0).sqrt();
        }
    }
    bins
}
