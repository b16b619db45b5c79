//! The `yzones` countermeasures: a position-dependent ePSF, K representative ePSFs for zones along Y,
//! interpolated linearly in Y between zone centres (the paper's proposal). See the module above for why they
//! cannot absorb a displacement.

use crate::analysis::epsf::Epsf;
use crate::analysis::epsf::build::{self, BuildOptions, StarStart};
use crate::analysis::epsf::fit::PixelData;

/// A Y-zoned ePSF: zone centres (px) and their tables, linearly interpolated in Y.
#[derive(Debug, Clone)]
pub struct ZonedEpsf {
    pub centres_y: Vec<f64>,
    pub zones: Vec<Epsf>,
}

impl ZonedEpsf {
    /// The ePSF at detector row y (clamped beyond the outer zone centres).
    pub fn at(&self, y: f64) -> Epsf {
        let c = &self.centres_y;
        if c.len() == 1 || y <= c[0] {
            return self.zones[0].clone();
        }
        if y >= c[c.len() - 1] {
            return self.zones[c.len() - 1].clone();
        }
        let k = c
            .windows(2)
            .position(|w| y >= w[0] && y < w[1])
            .unwrap_or(0);
        Epsf::lerp(
            &self.zones[k],
            &self.zones[k + 1],
            (y - c[k]) / (c[k + 1] - c[k]),
        )
    }
}

/// Build the zoned ePSF from the global one.
pub fn build_zoned(
    pd: &PixelData<'_>,
    ny: usize,
    starts: &[StarStart],
    usable: &[bool],
    bopt: &BuildOptions,
    global: &Epsf,
    global_pos: &[(f64, f64)],
    zones: usize,
    shared: bool,
) -> ZonedEpsf {
    let h = ny as f64 / zones as f64;
    let mut centres = Vec::new();
    let mut tables = Vec::new();
    for z in 0..zones {
        let (lo, hi) = (z as f64 * h, (z + 1) as f64 * h);
        let in_zone: Vec<bool> = starts
            .iter()
            .zip(usable)
            .map(|(s, u)| *u && s.y >= lo && s.y < hi)
            .collect();
        let ys: Vec<f64> = starts
            .iter()
            .zip(&in_zone)
            .filter(|(_, u)| **u)
            .map(|(s, _)| s.y)
            .collect();
        centres.push(if ys.is_empty() {
            0.5 * (lo + hi)
        } else {
            ys.iter().sum::<f64>() / ys.len() as f64
        });
        if ys.len() < 3 {
            tables.push(global.clone());
            continue;
        }
        let mut o = *bopt;
        o.recentre = !shared;
        let b = build::build(
            pd,
            starts,
            &in_zone,
            &o,
            Some(global),
            shared.then_some(global_pos),
        );
        tables.push(b.epsf);
    }
    ZonedEpsf {
        centres_y: centres,
        zones: tables,
    }
}
