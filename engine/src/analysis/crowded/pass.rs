//! One pass of the crowded-field fits: the model image of the stars found so far, and every star fitted
//! in its group with the light of the stars outside it subtracted ([`fit_pass`]).

use super::group_fit::{MAX_GROUP_STARS, Member, Outsiders, fit_group, fit_group_with};
use super::link_radius_px;
use crate::analysis::countermeasures::forward::{Forward, fit_reach_px};
use crate::analysis::epsf::build::build_options;
use crate::analysis::epsf::fit::{PixelData, StarFit, annulus_sky, flags};
use crate::analysis::epsf::varying::EpsfField;
use crate::analysis::image::AnalysisImage;
use crate::config::Analysis as AnalysisCfg;
use crate::numerics::neighbours::{self, Neighbours};
use crate::numerics::stats;
use rayon::prelude::*;

/// Model image `Σₖ fₖ ψ(X − xₖ, Y − yₖ)` of the stars (those with positive flux), over the ePSF table.
pub fn model_image<E: EpsfField + ?Sized>(
    epsf: &E,
    stars: &[Member],
    nx: usize,
    ny: usize,
) -> Vec<f64> {
    let h = epsf.reach_px();
    let mut order: Vec<usize> = (0..stars.len())
        .filter(|&k| stars[k].flux > 0.0 && stars[k].x.is_finite() && stars[k].y.is_finite())
        .collect();
    order.sort_by(|&a, &b| stars[a].y.total_cmp(&stars[b].y));
    let ys: Vec<f64> = order.iter().map(|&k| stars[k].y).collect();
    let mut m = vec![0.0; nx * ny];
    const BAND: usize = 32;
    m.par_chunks_mut(BAND * nx)
        .enumerate()
        .for_each(|(b, band)| {
            let (y0, y1) = (b * BAND, (b * BAND + band.len() / nx) as f64);
            let lo = ys.partition_point(|&y| y < y0 as f64 - h);
            let hi = ys.partition_point(|&y| y < y1 + h);
            for &k in &order[lo..hi] {
                let s = stars[k];
                let (px0, px1) = (
                    (s.x - h).ceil().max(0.0) as usize,
                    ((s.x + h).floor().max(-1.0) + 1.0).min(nx as f64) as usize,
                );
                let (py0, py1) = (
                    ((s.y - h).ceil().max(y0 as f64)) as usize,
                    ((s.y + h).floor() + 1.0).clamp(y0 as f64, y1) as usize,
                );
                for py in py0..py1 {
                    let row = &mut band[(py - y0) * nx..(py - y0 + 1) * nx];
                    for (px, v) in row.iter_mut().enumerate().take(px1).skip(px0) {
                        *v += s.flux * epsf.value_for(s.x, s.y, px as f64 - s.x, py as f64 - s.y);
                    }
                }
            }
        });
    m
}

/// One pass of fits of every star with `epsf`: groups by [`link_radius_px`], each group fitted with the
/// light of the stars outside it (their current values in `stars`) subtracted, on a sky from the annulus of
/// the image minus the model of all stars (the median over the group's members). A [`Member::fixed`] star
/// is only subtracted: its fit is its current values.
pub fn fit_pass<E: EpsfField + ?Sized>(
    img: &AnalysisImage,
    epsf: &E,
    stars: &[Member],
    node_error: f64,
    cfg: &AnalysisCfg,
) -> (Vec<StarFit>, GroupStats) {
    fit_pass_with(img, epsf, stars, node_error, cfg, None)
}

/// [`fit_pass`] with each star fitted through its own profile from the telemetry forward model `forward`
/// (the profile of its pixels' windows at its current position; [`fit_group_with`]); the neighbours'
/// light, subtracted, stays modelled by `epsf`.
pub fn fit_pass_with<E: EpsfField + ?Sized>(
    img: &AnalysisImage,
    epsf: &E,
    stars: &[Member],
    node_error: f64,
    cfg: &AnalysisCfg,
    forward: Option<&Forward<'_>>,
) -> (Vec<StarFit>, GroupStats) {
    let opts = build_options(cfg);
    let profile_reach = fit_reach_px(&opts.fit);
    let group = |members: &[Member], o: &[Member], sky: f64| -> Vec<StarFit> {
        let outsiders = Outsiders { stars: o };
        match forward {
            Some(fw) => {
                let profiles: Vec<_> = members
                    .iter()
                    .map(|m| fw.star(m.x, m.y, profile_reach, img.nx, img.ny))
                    .collect();
                fit_group_with(
                    &img.pixels(),
                    epsf,
                    Some(&profiles),
                    members,
                    &outsiders,
                    sky,
                    node_error,
                    &opts.fit,
                )
            }
            None => fit_group(
                &img.pixels(),
                epsf,
                members,
                &outsiders,
                sky,
                node_error,
                &opts.fit,
            ),
        }
    };
    let pd = img.pixels();
    let model = model_image(epsf, stars, img.nx, img.ny);
    let resid: Vec<f64> = img.e.iter().zip(&model).map(|(e, m)| e - m).collect();
    let rd = PixelData { e: &resid, ..pd };
    let (r_in, r_out) = crate::analysis::detection::sky_annulus(cfg);
    let pos: Vec<(f64, f64)> = stars.iter().map(|s| (s.x, s.y)).collect();
    let nb = Neighbours::new(&pos);
    let free: Vec<usize> = (0..stars.len()).filter(|&k| !stars[k].fixed).collect();
    let free_pos: Vec<(f64, f64)> = free.iter().map(|&k| pos[k]).collect();
    let groups: Vec<Vec<usize>> = neighbours::groups(&free_pos, link_radius_px(cfg))
        .into_iter()
        .map(|g| g.into_iter().map(|i| free[i]).collect())
        .collect();
    let reach = cfg.fit_radius_px + epsf.reach_px() + group_fit_reach_margin();
    let fitted: Vec<Vec<(usize, StarFit)>> = groups
        .par_iter()
        .map(|g| {
            let skies: Vec<f64> = g
                .iter()
                .filter_map(|&k| annulus_sky(&rd, stars[k].x, stars[k].y, r_in, r_out))
                .collect();
            let sky = if skies.is_empty() {
                0.0
            } else {
                stats::median(&skies)
            };
            let outside = |members: &[usize]| -> Vec<Member> {
                let mut o: Vec<usize> = members
                    .iter()
                    .flat_map(|&k| nb.within(stars[k].x, stars[k].y, reach))
                    .filter(|j| !members.contains(j))
                    .collect();
                o.sort_unstable();
                o.dedup();
                o.into_iter().map(|j| stars[j]).collect()
            };
            if g.len() <= MAX_GROUP_STARS {
                let members: Vec<Member> = g.iter().map(|&k| stars[k]).collect();
                let fits = group(&members, &outside(g), sky);
                g.iter().copied().zip(fits).collect()
            } else {
                // a knot too large to fit at once: star by star, everything else subtracted
                g.iter()
                    .map(|&k| {
                        let mut f = group(&[stars[k]], &outside(&[k]), sky)[0];
                        f.flags |= flags::GROUPED;
                        (k, f)
                    })
                    .collect()
            }
        })
        .collect();
    let mut fits: Vec<StarFit> = stars
        .iter()
        .map(|s| StarFit {
            x: s.x,
            y: s.y,
            flux: s.flux,
            crlb_x: f64::INFINITY,
            crlb_y: f64::INFINITY,
            crlb_flux: f64::INFINITY,
            ..Default::default()
        })
        .collect();
    for (k, f) in fitted.into_iter().flatten() {
        fits[k] = f;
    }
    let multi: Vec<usize> = groups.iter().map(Vec::len).filter(|&l| l > 1).collect();
    (
        fits,
        GroupStats {
            groups: multi.len(),
            largest: multi.iter().copied().max().unwrap_or(1),
        },
    )
}

/// How far beyond the fit disc an outsider's model is looked for: one pixel of slack for the step a member
/// may take during its fit.
fn group_fit_reach_margin() -> f64 {
    1.0
}

/// Groups of a pass.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroupStats {
    pub groups: usize,
    pub largest: usize,
}

/// The members of the next pass from fits: their fitted values, unless the fit failed (singular, too few
/// pixels, no flux) or left the image — then the previous values stay, so that a noise peak cannot walk
/// away over the passes. A fit that moved far or did not settle still updates: the next pass starts there.
pub(super) fn members_of(fits: &[StarFit], prev: &[Member], nx: usize, ny: usize) -> Vec<Member> {
    let failed = flags::SINGULAR | flags::FEW_PIXELS | flags::NONPOSITIVE_FLUX;
    fits.iter()
        .zip(prev)
        .map(|(f, p)| {
            let inside = f.x >= 0.0 && f.y >= 0.0 && f.x < nx as f64 && f.y < ny as f64;
            if f.flags & failed == 0 && inside {
                Member {
                    saturated: f.flags & flags::SATURATED != 0,
                    forced: p.forced,
                    flux_prior: p.flux_prior,
                    ..Member::new(f.x, f.y, f.flux)
                }
            } else {
                *p
            }
        })
        .collect()
}
