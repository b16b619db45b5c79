//! The reference catalogue of a sequence's region (`reference.csv`): what a survey of the bulge gives of
//! the field's stars — positions at the field's epoch, proper motions and parallaxes, each with its error —
//! the product that anchors an astrometric solution's frame (`solution`), as Gaia or VIRAC would.
//!
//! Errors per axis scale with magnitude as the single-exposure reference catalogue's do
//! (`io::instrument::SurveyModel`: a floor, ∝ flux^{−1/2} fainter than the knee), from floors of 2 mas,
//! 0.5 mas/yr and 1 mas — chosen: VIRAC v1 gives proper motions better than 1 mas/yr for bright stars and a
//! median parallax error of 1.1 mas (Smith et al. 2018); the bulge's per-magnitude figures were not found.
//! Stars brighter than the survey's limit, each kept with its completeness; every draw seeded per star.

use crate::io::instrument::SurveyModel;
use crate::rng::{self, Stream};
use crate::scene::SkyStar;
pub use crate::solution::feed::SkyReference;
use rand::RngExt;
use rand_distr::{Distribution, StandardNormal};

/// The survey: its position errors, limit and completeness, and the floors of its motions' errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkySurvey {
    pub position: SurveyModel,
    pub pm_floor_mas_per_yr: f64,
    pub parallax_floor_mas: f64,
}

impl Default for SkySurvey {
    fn default() -> Self {
        Self {
            position: SurveyModel::default(),
            pm_floor_mas_per_yr: 0.5,
            parallax_floor_mas: 1.0,
        }
    }
}

/// The survey's catalogue of `stars` (drawn with `seed`; at `epoch_jyear`, the field's).
pub fn survey(
    stars: &[SkyStar],
    survey: &SkySurvey,
    seed: u64,
    epoch_jyear: f64,
) -> Vec<SkyReference> {
    stars
        .iter()
        .enumerate()
        .filter(|(_, s)| s.mag_hw.is_finite() && s.mag_hw <= survey.position.limit_hw)
        .filter_map(|(i, s)| {
            let mut r = rng::stream(seed, Stream::SkyReference, i as u64);
            let z: [f64; 5] = std::array::from_fn(|_| StandardNormal.sample(&mut r));
            let kept = r.random::<f64>() < survey.position.completeness;
            let pos = survey.position.sigma_mas(s.mag_hw);
            let f = pos / survey.position.floor_mas;
            let sigma = [
                pos,
                pos,
                survey.pm_floor_mas_per_yr * f,
                survey.pm_floor_mas_per_yr * f,
                survey.parallax_floor_mas * f,
            ];
            let cos_dec = s.dec_deg.to_radians().cos().max(1e-9);
            kept.then(|| SkyReference {
                ra_deg: s.ra_deg + z[0] * sigma[0] / 3.6e6 / cos_dec,
                dec_deg: s.dec_deg + z[1] * sigma[1] / 3.6e6,
                pmra_mas_per_yr: s.motion.pmra_mas_per_yr + z[2] * sigma[2],
                pmdec_mas_per_yr: s.motion.pmdec_mas_per_yr + z[3] * sigma[3],
                parallax_mas: s.motion.parallax_mas + z[4] * sigma[4],
                sigma,
                hw: s.mag_hw,
                ref_epoch_jyear: epoch_jyear,
            })
        })
        .collect()
}
