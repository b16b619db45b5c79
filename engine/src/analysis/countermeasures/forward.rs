//! The `telemetry-model` countermeasure: each star is fitted with a forward model of its own image — the static
//! profile ψ seen through the jitter the telemetry says the star's pixels saw during their own exposure windows —
//! so the model's *shape*, not only its position, follows the attitude (issue: the linear shift response of
//! [`super::telemetry`] misses the shape change of a large drift under the rolling readout).
//!
//! Pixel (X, Y), whose window `[a, b)` (the readout timing, [`crate::readout`]) gives the telemetry's track
//! samples u_j the weights w_j ([`crate::integrate::track`]), holds for a star at (x, y)
//!
//! `μ(X, Y) = f · Σ_j w_j ψ(X − x − u_jx, Y − y − u_jy) / Σ_j w_j + s`
//!
//! the simulator's integral ([`crate::integrate::cpu`]) with the telemetry in place of the true jitter. The
//! samples are deposited cloud-in-cell onto a grid of `1/nodes_per_px` px (one histogram per distinct window among
//! the star's pixels: a row, or a row's part in one readout channel), so a pixel costs one ψ evaluation per
//! occupied node, not one per sample; the deposit smooths ψ by at most the node spacing, a second-order error
//! (the knob [`Forward::nodes_per_px`], benchmarked against the per-sample sum in the tests).

use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::fit::{FitOptions, MAX_RADIUS_GROWTH_PX, Profile};
use crate::integrate::track::{Track, WindowWeights};
use crate::readout::ReadoutTiming;
use std::collections::HashMap;

/// Default nodes per pixel of the jitter histograms: 1/16 px, a second-order, symmetric smoothing of ≈ 5e-4
/// of a star's peak (tested against the per-sample sum; it broadens the profile, it does not move it).
pub const DEFAULT_NODES_PER_PX: usize = 16;

/// Pixels whose windows start and end within this of each other share one histogram, s: the pixels of a
/// row in one readout channel (their windows differ by the pixel time, ≤ 1.3 ms in all). What that ignores is
/// ≤ ½ ms of a 12.5-s window, a weight of ≤ 4e-5: ≤ 4e-5 of the track's excursion, ≪ 0.1 mas.
pub const WINDOW_TOLERANCE_S: f64 = 1e-3;

/// The pixels a fit with options `fit` may reach around its star, px: its disc, grown around a saturated core
/// ([`MAX_RADIUS_GROWTH_PX`]), and a pixel of slack for a step — how far a star's forward profile is made.
pub fn fit_reach_px(fit: &FitOptions) -> f64 {
    fit.radius_px + MAX_RADIUS_GROWTH_PX + 1.0
}

/// The forward model of an exposure: the static profile, the telemetry's track, the readout timing, and the
/// profile already seen through the window every pixel shares (the frame's core, made once per image).
#[derive(Debug, Clone)]
pub struct Forward<'a> {
    /// The static profile ψ (the PSF before the jitter, integrated over the pixel).
    pub profile: &'a Epsf,
    /// The telemetry's track (px, this array's axes, times from the exposure start).
    pub track: &'a Track,
    pub timing: &'a ReadoutTiming,
    /// Nodes per pixel of the jitter histograms (≥ 1).
    pub nodes_per_px: usize,
    core: Option<Core>,
}

/// The part of the exposure every pixel integrates, `[a, b)`: its sample weight and ψ seen through it.
#[derive(Debug, Clone)]
struct Core {
    a_s: f64,
    b_s: f64,
    weight: f64,
    /// `(1/W) Σ_u H(u) ψ(· − u)` on ψ's grid.
    psi: Epsf,
}

/// One star's forward profile: per distinct window among its pixels, the jitter histogram of what that window
/// holds beyond the core.
#[derive(Debug, Clone)]
pub struct StarProfile<'a> {
    forward: &'a Forward<'a>,
    /// Image pixel index → its window's group.
    group_of: HashMap<usize, usize>,
    groups: Vec<Group>,
}

#[derive(Debug, Clone)]
struct Group {
    /// The occupied nodes (ux, uy, weight) of the samples outside the core (all samples without one), raw
    /// weights.
    edge: Vec<(f64, f64, f64)>,
    /// Whether the window holds the core.
    with_core: bool,
    /// 1 / the window's total weight.
    norm: f64,
}

impl<'a> Forward<'a> {
    /// The forward model of an image `detector_px` pixels wide: the core (the window all its pixels share)
    /// deposited and seen through ψ once.
    pub fn new(
        profile: &'a Epsf,
        track: &'a Track,
        timing: &'a ReadoutTiming,
        nodes_per_px: usize,
        detector_px: usize,
    ) -> Self {
        let g = nodes_per_px.max(1) as f64;
        let (a, b) = timing.shared_window_s(detector_px);
        let core = (b > a).then(|| {
            let (psi, weight) = seen_through(profile, track, &[track.window(a, b)], &[], g);
            Core {
                a_s: a,
                b_s: b,
                weight,
                psi,
            }
        });
        Self {
            profile,
            track,
            timing,
            nodes_per_px,
            core,
        }
    }

    /// The forward profile of a star near `(x, y)` for the pixels within `reach_px` of it, in an image of
    /// `nx × ny` pixels (pixel index `Y · nx + X`).
    pub fn star(&self, x: f64, y: f64, reach_px: f64, nx: usize, ny: usize) -> StarProfile<'_> {
        let g = self.nodes_per_px.max(1) as f64;
        let r = reach_px.ceil() as i64 + 1;
        let (cx, cy) = (x.round() as i64, y.round() as i64);
        let mut by_window: HashMap<(i64, i64), usize> = HashMap::new();
        let mut group_of = HashMap::new();
        let mut groups: Vec<Group> = Vec::new();
        let key = |t: f64| (t / WINDOW_TOLERANCE_S).round() as i64;
        for py in (cy - r).max(0)..=(cy + r).min(ny as i64 - 1) {
            for px in (cx - r).max(0)..=(cx + r).min(nx as i64 - 1) {
                let (a, b) = self.timing.window_s(px as usize, py as usize);
                let k = *by_window.entry((key(a), key(b))).or_insert_with(|| {
                    groups.push(self.group(a, b, g));
                    groups.len() - 1
                });
                group_of.insert(py as usize * nx + px as usize, k);
            }
        }
        StarProfile {
            forward: self,
            group_of,
            groups,
        }
    }

    /// The histogram of window `[a, b)` beyond the core (all of it without a core).
    fn group(&self, a: f64, b: f64, g: f64) -> Group {
        match &self.core {
            Some(c) if a <= c.a_s && b >= c.b_s => {
                // the edges hold ≈ the frame sweep's share of the window (≈ 10 %), so a grid twice as coarse
                // costs them no more than the core's grid costs the core, at a quarter of the nodes
                let (edge, w) = deposit(
                    self.track,
                    &[self.track.window(a, c.a_s), self.track.window(c.b_s, b)],
                    &[],
                    (g / 2.0).max(1.0),
                );
                Group {
                    edge,
                    with_core: true,
                    norm: 1.0 / (c.weight + w).max(f64::MIN_POSITIVE),
                }
            }
            _ => {
                let (edge, w) = deposit(self.track, &[self.track.window(a, b)], &[], g);
                Group {
                    edge,
                    with_core: false,
                    norm: 1.0 / w.max(f64::MIN_POSITIVE),
                }
            }
        }
    }
}

/// The profile seen through the jitter of windows, `(1/W) Σ_u H(u) ψ(· − u)` on ψ's grid (the track's samples in
/// the windows deposited on nodes `1/g` px apart; overlapping windows add), and the windows' total weight W.
/// `offsets[k]` (px; missing: 0) is taken from window k's samples, so the windows' profiles can be averaged on
/// their own centres (as an ePSF built from stars at their fitted positions averages them).
pub fn seen_through(
    profile: &Epsf,
    track: &Track,
    windows: &[WindowWeights],
    offsets: &[(f64, f64)],
    g: f64,
) -> (Epsf, f64) {
    let (nodes, weight) = deposit(track, windows, offsets, g);
    let half = (profile.half_nodes / profile.oversampling.max(1)).max(1);
    let w = 1.0 / weight.max(f64::MIN_POSITIVE);
    let scaled: Vec<(f64, f64, f64)> = nodes.iter().map(|&(ux, uy, c)| (ux, uy, c * w)).collect();
    let psi = profile.shifted_sum(half, &scaled);
    (psi, weight)
}

/// The track's samples in the windows `ws` (overlapping windows add), each window's less its offset
/// (`offsets[k]`, px; none: 0), deposited cloud-in-cell onto nodes `1/g` px apart: the occupied nodes with
/// their raw weights, and the total weight.
fn deposit(
    track: &Track,
    ws: &[WindowWeights],
    offsets: &[(f64, f64)],
    g: f64,
) -> (Vec<(f64, f64, f64)>, f64) {
    let n = track.len();
    let samples = || {
        ws.iter()
            .enumerate()
            .filter(move |(_, w)| n > 0 && w.first <= w.last.min(n - 1))
            .flat_map(move |(k, w)| {
                let (ox, oy) = offsets.get(k).copied().unwrap_or((0.0, 0.0));
                (w.first..=w.last.min(n - 1))
                    .map(move |j| (track.dx_px[j] - ox, track.dy_px[j] - oy, w.weight(j)))
            })
            .filter(|&(_, _, wj)| wj > 0.0)
    };
    if samples().next().is_none() {
        return (Vec::new(), 0.0);
    }
    let (mut lo_u, mut hi_u, mut lo_v, mut hi_v) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
    for (x, y, _) in samples() {
        let (u, v) = ((x * g).floor() as i64, (y * g).floor() as i64);
        (lo_u, hi_u, lo_v, hi_v) = (lo_u.min(u), hi_u.max(u), lo_v.min(v), hi_v.max(v));
    }
    // a dense grid over the samples' extent (+1 node for the cloud-in-cell's far corner)
    let (nu, nv) = ((hi_u - lo_u + 2) as usize, (hi_v - lo_v + 2) as usize);
    let mut acc = vec![0.0; nu * nv];
    let mut total = 0.0;
    for (x, y, wj) in samples() {
        let (u, v) = (x * g, y * g);
        let (fu, fv) = (u - u.floor(), v - v.floor());
        let (iu, iv) = (
            (u.floor() as i64 - lo_u) as usize,
            (v.floor() as i64 - lo_v) as usize,
        );
        acc[iv * nu + iu] += wj * (1.0 - fu) * (1.0 - fv);
        acc[iv * nu + iu + 1] += wj * fu * (1.0 - fv);
        acc[(iv + 1) * nu + iu] += wj * (1.0 - fu) * fv;
        acc[(iv + 1) * nu + iu + 1] += wj * fu * fv;
        total += wj;
    }
    let nodes = acc
        .iter()
        .enumerate()
        .filter(|(_, c)| **c > 0.0)
        .map(|(k, c)| {
            (
                ((k % nu) as i64 + lo_u) as f64 / g,
                ((k / nu) as i64 + lo_v) as f64 / g,
                *c,
            )
        })
        .collect();
    (nodes, total)
}

impl StarProfile<'_> {
    /// This star's pixels seen through another static profile's forward model of the same exposure (the same
    /// track and timing: its histograms are this star's, its core and profile `f`'s) — a linear map of
    /// the profile, so a profile's derivative planes cost one star's histograms, not one each.
    pub fn eval_through(
        &self,
        f: &Forward<'_>,
        i: usize,
        px: f64,
        py: f64,
        x: f64,
        y: f64,
    ) -> (f64, f64, f64) {
        let Some(&k) = self.group_of.get(&i) else {
            // a pixel beyond the reach the histograms were made for: the static profile
            return f.profile.eval(px - x, py - y);
        };
        let grp = &self.groups[k];
        let (dx, dy) = (px - x, py - y);
        let (mut v, mut gx, mut gy) = match (&f.core, grp.with_core) {
            (Some(c), true) => {
                let (a, b, d) = c.psi.eval(dx, dy);
                (c.weight * a, c.weight * b, c.weight * d)
            }
            _ => (0.0, 0.0, 0.0),
        };
        for &(ux, uy, w) in &grp.edge {
            let (a, b, c) = f.profile.eval(dx - ux, dy - uy);
            v += w * a;
            gx += w * b;
            gy += w * c;
        }
        (v * grp.norm, gx * grp.norm, gy * grp.norm)
    }
}

impl Profile for StarProfile<'_> {
    fn eval_at(&self, i: usize, px: f64, py: f64, x: f64, y: f64) -> (f64, f64, f64) {
        self.eval_through(self.forward, i, px, py, x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn gaussian(sigma: f64) -> Epsf {
        let mut e = Epsf::from_fn(8, 8, |x, y| {
            (-(x * x + y * y) / (2.0 * sigma * sigma)).exp()
        });
        e.normalise();
        e
    }

    fn timing() -> ReadoutTiming {
        let mut c = Config::default();
        c.instrument.detector_px = 256;
        c.instrument.photosensitive_px = 240;
        c.readout.channels = 2;
        c.readout.channel_width_px = 128;
        ReadoutTiming::new(&c)
    }

    /// A drifting track: 0.6 px along x and 0.4 px along y over the exposure, with a 0.05-px wobble.
    fn drift(span_s: f64) -> Track {
        let dt = 1e-3;
        let n = (span_s / dt) as usize + 2;
        let t = |j: usize| j as f64 * dt / span_s;
        Track::new(
            dt,
            0.0,
            (0..n)
                .map(|j| 0.6 * t(j) + 0.05 * (40.0 * t(j)).sin())
                .collect(),
            (0..n)
                .map(|j| -0.4 * t(j) + 0.05 * (33.0 * t(j)).cos())
                .collect(),
        )
    }

    /// Still telemetry: the forward profile is the static profile (the histogram is one node at 0).
    #[test]
    fn still_telemetry_gives_the_static_profile() {
        let e = gaussian(0.9);
        let tm = timing();
        let still = Track::still(tm.span_s(), 1e-3);
        let f = Forward::new(&e, &still, &tm, DEFAULT_NODES_PER_PX, 256);
        let s = f.star(100.3, 50.7, 6.0, 256, 256);
        for (px, py) in [(100.0, 50.0), (102.0, 49.0), (97.0, 53.0)] {
            let i = py as usize * 256 + px as usize;
            let a = s.eval_at(i, px, py, 100.3, 50.7);
            let b = e.eval(px - 100.3, py - 50.7);
            assert!(
                (a.0 - b.0).abs() < 1e-15 && (a.1 - b.1).abs() < 1e-15,
                "{a:?} {b:?}"
            );
        }
    }

    /// The deposited histogram against the sum over every sample of the window (another way to the same
    /// integral): the deposit's smoothing is second order in the node spacing — within 2e-4 of the peak at
    /// the default 16 nodes per pixel, and four times smaller at 32.
    #[test]
    fn the_deposit_matches_the_per_sample_sum() {
        let e = gaussian(0.9);
        let tm = timing();
        let track = drift(tm.span_s());
        let (x, y) = (120.37, 80.81);
        let peak = e.eval(0.0, 0.0).0;
        let worst = |g: usize| {
            let f = Forward::new(&e, &track, &tm, g, 256);
            let s = f.star(x, y, 5.0, 256, 256);
            let mut worst: f64 = 0.0;
            for py in 77..=85 {
                for px in 116..=124 {
                    let (a, b) = tm.window_s(px, py);
                    let w = track.window(a, b);
                    let (mut sum, mut tot) = (0.0, 0.0);
                    for j in w.first..=w.last {
                        let wj = w.weight(j);
                        sum += wj
                            * e.value(
                                px as f64 - x - track.dx_px[j],
                                py as f64 - y - track.dy_px[j],
                            );
                        tot += wj;
                    }
                    let exact = sum / tot;
                    let i = py * 256 + px;
                    let model = s.eval_at(i, px as f64, py as f64, x, y).0;
                    worst = worst.max((model - exact).abs() / peak);
                }
            }
            worst
        };
        let (w16, w32) = (worst(16), worst(32));
        eprintln!("deposit error: {w16:.2e} (16 nodes/px), {w32:.2e} (32) of the peak");
        assert!(w16 < 1e-3, "{w16}");
        assert!(w32 < 0.35 * w16, "{w32} vs {w16}");
    }

    /// The forward model with the true track equals the simulator's own integration of the star
    /// (`integrate::cpu::fast_stamp`, another implementation of the same integral) under a drifting rolling
    /// exposure, to the two tables' discretisation: the simulator's kernel is bilinear between nodes 1/g px
    /// apart (an O(h²ψ'') error of ≈ 2e-3 of the peak for σ = 0.9 px at g = 8), the profile Keys-cubic on the
    /// same nodes. The difference is within 2.5e-3 of the peak at g = 8 and falls as g⁻² (≤ 0.4× at g = 16):
    /// it is the tables', not the model's.
    #[test]
    fn the_forward_model_of_the_true_track_is_the_simulators_star() {
        use crate::integrate::cpu::{StarSpec, fast_stamp};
        use crate::integrate::kernel::PixelKernel;
        let sigma = 0.9;
        let g2 = |x: f64, y: f64| {
            (-(x * x + y * y) / (2.0 * sigma * sigma)).exp()
                / (2.0 * std::f64::consts::PI * sigma * sigma)
        };
        let tm = timing();
        let track = drift(tm.span_s());
        let (x, y, rate): (f64, f64, f64) = (140.3, 30.6, 5800.0);
        let bounds = (x.round() as i64 - 6, y.round() as i64 - 6, 13, 13);
        let worst = |g: usize| {
            let kernel = PixelKernel::tabulated(g, 7, g2);
            let profile = Epsf::from_fn(g, 7, |x, y| kernel.eval(x, y));
            let star = StarSpec {
                x_px: x,
                y_px: y,
                rate_e_per_s: rate,
            };
            let stamp = fast_stamp(&star, &kernel, &track, &tm, bounds, None);
            let f = Forward::new(&profile, &track, &tm, 2 * g, 256);
            let s = f.star(x, y, 7.0, 256, 256);
            let peak = stamp.data.iter().cloned().fold(0.0, f64::max);
            let mut worst: f64 = 0.0;
            for iy in 0..13 {
                for ix in 0..13 {
                    let (px, py) = (bounds.0 + ix as i64, bounds.1 + iy as i64);
                    let (a, b) = tm.window_s(px as usize, py as usize);
                    let i = py as usize * 256 + px as usize;
                    let model = rate * (b - a) * s.eval_at(i, px as f64, py as f64, x, y).0;
                    worst = worst.max((model - stamp.data[iy * 13 + ix]).abs() / peak);
                }
            }
            worst
        };
        let (w8, w16) = (worst(8), worst(16));
        eprintln!(
            "forward model against the simulator's star: {w8:.2e} (g = 8), {w16:.2e} (16) of the peak"
        );
        assert!(w8 < 2.5e-3, "{w8}");
        assert!(w16 < 0.4 * w8, "{w16} vs {w8}");
    }
}
