//! The processes one solution runs on: this one alone ([`Single`], the default) or MPI ranks (feature `mpi`,
//! [`super::mpi::MpiRanks`]), and the one way every sum over the sources is taken, so that the solution is
//! the same bit for bit on any number of threads and of ranks.
//!
//! **Leaves.** The sources, in their sky-tile order ([`tile_order`]), are cut into [`LEAVES`] consecutive
//! runs — sky tiles. Every sum over the sources (the exposures' and the calibration's shares of `N v`, their
//! preconditioner blocks, the dot products of the conjugate gradients) is taken leaf by leaf and the leaves'
//! partial sums are added pairwise along one fixed binary tree ([`tree`]): leaves [lo, hi) split at
//! (lo + hi) / 2. A rank owns an aligned subtree of `LEAVES / ranks` leaves (the ranks a power of two), sums
//! it alone, and the ranks finish the tree by recursive doubling ([`across`]): at step k, rank r and rank
//! r ⊕ 2ᵏ swap their subtrees' sums and both add left + right. Every rank ends with the single process's
//! sum, bit for bit. Per iteration each rank sends and receives log₂(ranks) vectors the size of the
//! exposures' and calibration's unknowns (4 E + 2 C doubles) and a few scalars; per-source data never moves
//! until the end, when the ranks' sources are gathered.

use super::{Observation, SolutionError};
use std::ops::Range;

/// Sky tiles the sources are cut into: the leaves of every sum, and the most ranks a solution runs on.
pub const LEAVES: usize = 64;

/// The processes a solution runs on. Only the calling thread talks to the other ranks.
pub trait Ranks {
    /// This process's rank, 0 … size − 1.
    fn rank(&self) -> usize;
    /// The ranks.
    fn size(&self) -> usize;
    /// Send `mine` to rank `partner` and receive its vector, of the same length.
    fn exchange(&self, partner: usize, mine: &[f64]) -> Vec<f64>;
    /// The element-wise maximum over the ranks, in place.
    fn max_in_place(&self, v: &mut [f64]);
    /// Every rank's `mine` (of any length), in rank order.
    fn gather_all(&self, mine: &[f64]) -> Vec<Vec<f64>>;
}

/// This process alone.
#[derive(Debug, Clone, Copy, Default)]
pub struct Single;

impl Ranks for Single {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn exchange(&self, _partner: usize, mine: &[f64]) -> Vec<f64> {
        // never called with one rank (no partner): the identity keeps it total
        mine.to_vec()
    }
    fn max_in_place(&self, _v: &mut [f64]) {}
    fn gather_all(&self, mine: &[f64]) -> Vec<Vec<f64>> {
        vec![mine.to_vec()]
    }
}

thread_local! {
    static WORLD: std::cell::RefCell<Option<std::rc::Rc<dyn Ranks>>> = const { std::cell::RefCell::new(None) };
}

/// Make `ranks` this thread's world: [`super::solve`] called on this thread runs on them from now on (the
/// `jsim-mpi` binary sets MPI's world once, on the thread that initialised MPI).
pub fn set_world(ranks: std::rc::Rc<dyn Ranks>) {
    WORLD.with(|w| *w.borrow_mut() = Some(ranks));
}

/// This thread's world: the ranks [`set_world`] gave it, else this process alone.
pub fn world() -> std::rc::Rc<dyn Ranks> {
    WORLD.with(|w| {
        w.borrow()
            .clone()
            .unwrap_or_else(|| std::rc::Rc::new(Single))
    })
}

/// A number of ranks a solution runs on: a power of two, 1 … [`LEAVES`].
pub fn check(size: usize) -> Result<(), SolutionError> {
    if size == 0 || size > LEAVES || !size.is_power_of_two() {
        return Err(SolutionError::Knob {
            field: "ranks",
            value: size as f64,
            allowed: "a power of two, 1 … 64 (each rank owns an equal share of the 64 sky tiles)",
        });
    }
    Ok(())
}

/// The leaves rank `rank` of `size` owns.
pub fn leaves_of(rank: usize, size: usize) -> Range<usize> {
    rank * LEAVES / size..(rank + 1) * LEAVES / size
}

/// Sources per leaf (the last leaves may hold fewer, or none).
pub fn per_leaf(sources: usize) -> usize {
    sources.div_ceil(LEAVES).max(1)
}

/// Σ over leaves [lo, hi) of `leaf(c)`, pairwise along the fixed tree (split at the middle), the halves in
/// parallel. Each leaf's value is made once; at most a few per thread are alive at a time.
pub fn tree<T: Send>(
    lo: usize,
    hi: usize,
    leaf: &(impl Fn(usize) -> T + Sync),
    add: &(impl Fn(T, T) -> T + Sync),
) -> T {
    if hi - lo <= 1 {
        return leaf(lo);
    }
    let mid = (lo + hi) / 2;
    let (a, b) = rayon::join(|| tree(lo, mid, leaf, add), || tree(mid, hi, leaf, add));
    add(a, b)
}

/// The tree's sum over all ranks from each rank's subtree sum `mine` (same length everywhere): recursive
/// doubling, left + right at every step, so that every rank holds the same bits.
pub fn across(ranks: &dyn Ranks, mut mine: Vec<f64>) -> Vec<f64> {
    let (rank, size) = (ranks.rank(), ranks.size());
    let mut step = 1;
    while step < size {
        let partner = rank ^ step;
        let theirs = ranks.exchange(partner, &mine);
        if rank < partner {
            add_into(&mut mine, &theirs);
        } else {
            let mut left = theirs;
            add_into(&mut left, &mine);
            mine = left;
        }
        step <<= 1;
    }
    mine
}

/// The maximum of `v` over the ranks.
pub fn max_across(ranks: &dyn Ranks, v: f64) -> f64 {
    let mut a = [v];
    ranks.max_in_place(&mut a);
    a[0]
}

/// `a += b`, element by element.
pub fn add_into(a: &mut [f64], b: &[f64]) {
    for (x, y) in a.iter_mut().zip(b) {
        *x += y;
    }
}

/// The sources in sky-tile order: along a Z-order (Morton) curve of their first observed place on a
/// 2¹⁶ × 2¹⁶ grid over the observations' extent, ties by index; unobserved sources last. Consecutive runs of
/// it ([`LEAVES`] of them) are compact patches of sky, so a rank's sources share exposures.
pub fn tile_order(obs: &[Observation], n_sources: usize) -> Vec<usize> {
    let mut first: Vec<Option<[f64; 2]>> = vec![None; n_sources];
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for o in obs {
        if o.source() < n_sources && first[o.source()].is_none() {
            first[o.source()] = Some([o.xi_mas, o.eta_mas]);
        }
        for (k, v) in [o.xi_mas, o.eta_mas].into_iter().enumerate() {
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    let cell = |v: f64, k: usize| -> u32 {
        let span = hi[k] - lo[k];
        if !(span > 0.0) {
            return 0;
        }
        (((v - lo[k]) / span) * 65535.0).clamp(0.0, 65535.0) as u32
    };
    let key =
        |s: usize| -> u64 { first[s].map_or(u64::MAX, |p| morton(cell(p[0], 0), cell(p[1], 1))) };
    let mut order: Vec<usize> = (0..n_sources).collect();
    order.sort_by_key(|&s| (key(s), s));
    order
}

/// The Z-order code of (x, y): their bits interleaved.
fn morton(x: u32, y: u32) -> u64 {
    let spread = |v: u32| -> u64 {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        v = (v | (v << 1)) & 0x5555_5555_5555_5555;
        v
    };
    spread(x) | (spread(y) << 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn ranks_finish_the_single_process_tree_bit_for_bit() {
        // leaf values of wildly different magnitudes: any other order of the additions changes the bits
        let leaf = |c: usize| {
            vec![
                (c as f64 * 0.37).sin() * 10f64.powi((c % 13) as i32 - 6),
                1.0 / (c as f64 + 3.0),
            ]
        };
        let add = |mut a: Vec<f64>, b: Vec<f64>| {
            add_into(&mut a, &b);
            a
        };
        let single = tree(0, LEAVES, &leaf, &add);
        for size in [2, 4, 8] {
            let results = crate::testkit::on_thread_ranks(size, |t| {
                let r = leaves_of(t.rank(), t.size());
                across(t, tree(r.start, r.end, &leaf, &add))
            });
            for r in &results {
                assert_eq!(
                    r.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    single.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    "{size} ranks"
                );
            }
        }
        // and the sequential sum differs in its last bits: the tree is not a no-op
        let sequential: f64 = (0..LEAVES).map(|c| leaf(c)[0]).sum();
        assert_ne!(sequential.to_bits(), single[0].to_bits());
    }

    #[test]
    fn ranks_must_be_a_power_of_two_up_to_the_leaves() {
        for ok in [1, 2, 4, 64] {
            assert!(check(ok).is_ok());
        }
        for bad in [0, 3, 6, 128] {
            let e = check(bad).expect_err("refused").to_string();
            assert!(e.contains("ranks") && e.contains("power of two"), "{e}");
        }
    }

    #[test]
    fn leaves_are_shared_out_whole_and_in_order() {
        for size in [1, 2, 4, 64] {
            let mut next = 0;
            for r in 0..size {
                let l = leaves_of(r, size);
                assert_eq!(l.start, next);
                assert_eq!(l.len(), LEAVES / size);
                next = l.end;
            }
            assert_eq!(next, LEAVES);
        }
    }

    #[test]
    fn the_tile_order_keeps_neighbours_together() {
        // a 16 × 16 grid of sources listed row by row: each run of 4 in tile order spans a 2 × 2 patch
        let obs: Vec<Observation> = (0..256)
            .map(|s| Observation::new(0, s, [(s % 16) as f64, (s / 16) as f64], 1.0, 0, [0.0; 2]))
            .collect();
        let order = tile_order(&obs, 257);
        assert_eq!(order[256], 256, "the unobserved source comes last");
        let spread = |v: &[usize]| {
            v.iter().max().copied().unwrap_or(0) - v.iter().min().copied().unwrap_or(0)
        };
        for run in order[..256].chunks(4) {
            let xs: Vec<usize> = run.iter().map(|s| s % 16).collect();
            let ys: Vec<usize> = run.iter().map(|s| s / 16).collect();
            assert!(spread(&xs) <= 1 && spread(&ys) <= 1, "{run:?}");
        }
    }
}
