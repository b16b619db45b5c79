//! The sources shared out by sky tile: their order, the 64 leaves, the tiles this rank solves, its
//! sources fitted, and every rank's sources gathered to every rank (see [`super::ranks`]).

use super::SolvedSource;
use super::blocks::{Problem, State, fit_source};
use super::ranks::{self, Ranks};
use rayon::prelude::*;

/// The sources in sky-tile order, cut into the [`super::ranks::LEAVES`] leaves, and those of this rank's leaves.
pub(super) struct Tiles {
    pub order: Vec<usize>,
    per_leaf: usize,
    /// This rank's leaves.
    pub mine: std::ops::Range<usize>,
    /// Does this rank solve source s?
    pub owned: Vec<bool>,
    size: usize,
}

impl Tiles {
    pub fn new(p: &Problem, ranks: &dyn Ranks) -> Self {
        let n = p.by_source.len();
        let order = ranks::tile_order(p.obs, n);
        let per_leaf = ranks::per_leaf(n);
        let mine = ranks::leaves_of(ranks.rank(), ranks.size());
        let mut owned = vec![false; n];
        for c in mine.clone() {
            for &s in &order[Self::span(c, per_leaf, n)] {
                owned[s] = true;
            }
        }
        Self {
            order,
            per_leaf,
            mine,
            owned,
            size: ranks.size(),
        }
    }

    /// Leaf c's positions in the tile order.
    pub fn span(c: usize, per_leaf: usize, n: usize) -> std::ops::Range<usize> {
        (c * per_leaf).min(n)..((c + 1) * per_leaf).min(n)
    }

    /// Leaf c's sources.
    pub fn leaf(&self, c: usize) -> &[usize] {
        &self.order[Self::span(c, self.per_leaf, self.order.len())]
    }

    /// The positions in the tile order of leaves `leaves`' sources.
    pub fn run(&self, leaves: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let n = self.order.len();
        Self::span(leaves.start, self.per_leaf, n).start
            ..Self::span(leaves.end - 1, self.per_leaf, n).end
    }

    /// Each of this rank's sources fitted with the attitudes and the calibration held.
    pub fn source_pass(&self, p: &Problem, state: &mut State, active: &[bool]) {
        let fitted: Vec<(usize, SolvedSource)> = self.order[self.run(self.mine.clone())]
            .par_iter()
            .map(|&s| (s, fit_source(p, state, active, s)))
            .collect();
        for (s, fit) in fitted {
            state.sources[s] = fit;
        }
    }

    /// Every rank's sources to every rank.
    pub fn gather(&self, state: &mut State, ranks: &dyn Ranks) {
        if self.size == 1 {
            return;
        }
        let mut mine = Vec::new();
        for &s in &self.order[self.run(self.mine.clone())] {
            let v = &state.sources[s];
            mine.extend_from_slice(&v.params);
            mine.extend_from_slice(&v.sigma);
            mine.extend_from_slice(&[v.observations as f64, v.chi2]);
        }
        for (rank, theirs) in ranks.gather_all(&mine).into_iter().enumerate() {
            let sources = &self.order[self.run(ranks::leaves_of(rank, self.size))];
            for (&s, v) in sources.iter().zip(theirs.chunks_exact(12)) {
                let mut params = [0.0; 5];
                let mut sigma = [0.0; 5];
                params.copy_from_slice(&v[..5]);
                sigma.copy_from_slice(&v[5..10]);
                state.sources[s] = SolvedSource {
                    params,
                    sigma,
                    observations: v[10] as usize,
                    chi2: v[11],
                };
            }
        }
    }
}
