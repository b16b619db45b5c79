//! Neighbours of stars in an image: a k-d tree ([`kiddo`]) over their positions, the radius queries of
//! the crowded-field fits, and the groups of stars whose models overlap (connected components of the
//! "closer than the link radius" graph, by union–find over the tree's pairs: O(N log N)).

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// A k-d tree over a set of positions (pixels); non-finite positions are kept out.
pub struct Neighbours {
    tree: Option<ImmutableKdTree<f64, 2>>,
    /// Tree item → index into the positions given.
    index: Vec<usize>,
}

impl Neighbours {
    pub fn new(pos: &[(f64, f64)]) -> Self {
        let (pts, index): (Vec<[f64; 2]>, Vec<usize>) = pos
            .iter()
            .enumerate()
            .filter(|(_, p)| p.0.is_finite() && p.1.is_finite())
            .map(|(k, p)| ([p.0, p.1], k))
            .unzip();
        let tree = if pts.is_empty() {
            None
        } else {
            ImmutableKdTree::new_from_slice(&pts).ok()
        };
        Self { tree, index }
    }

    /// Indices of the positions within `radius_px` of (x, y) (inclusive, unordered).
    pub fn within(&self, x: f64, y: f64, radius_px: f64) -> Vec<usize> {
        let Some(t) = &self.tree else {
            return Vec::new();
        };
        if !(x.is_finite() && y.is_finite()) {
            // a position off the plane has no neighbour
            return Vec::new();
        }
        t.query(&[x, y])
            .within::<SquaredEuclidean<f64>>(radius_px * radius_px)
            .unsorted()
            .execute()
            .into_iter()
            .map(|r| self.index[r.item as usize])
            .collect()
    }
}

impl Neighbours {
    /// Indices of the positions within `radius_px` of (x, y), and perhaps a hair beyond (10⁻⁹ of the
    /// radius): for a caller that tests each distance itself, so that the tree's squared distances, rounded
    /// otherwise than the caller's, never leave one out.
    pub fn near(&self, x: f64, y: f64, radius_px: f64) -> Vec<usize> {
        self.within(x, y, radius_px * (1.0 + 1e-9) + 1e-12)
    }
}

/// Of `candidates` (a tree's [`Neighbours::near`]), the nearest to `p` within `radius_px` (squared
/// distance ≤ radius², ties to the lowest index), with its squared distance; `at(k)` is position k.
pub fn nearest_of(
    candidates: impl IntoIterator<Item = usize>,
    at: impl Fn(usize) -> (f64, f64),
    p: (f64, f64),
    radius_px: f64,
) -> Option<(usize, f64)> {
    let mut best: Option<(usize, f64)> = None;
    for k in candidates {
        let q = at(k);
        let d2 = (q.0 - p.0).powi(2) + (q.1 - p.1).powi(2);
        if d2 <= radius_px * radius_px && best.is_none_or(|(bk, b)| d2 < b || (d2 == b && k < bk)) {
            best = Some((k, d2));
        }
    }
    best
}

/// A k-d tree that grows: positions pushed since it was built are searched one by one, and the first query
/// that finds more than [`GROW_LINEAR_MAX`] of them rebuilds the tree over them all. A caller that pushes a
/// batch and then queries (the solution's feed: an exposure's new sources, then the next exposure's
/// detections) rebuilds once per batch; a query never scans more than [`GROW_LINEAR_MAX`] positions one by one.
pub struct GrowingNeighbours {
    pos: Vec<(f64, f64)>,
    tree: Neighbours,
    /// Positions `0..in_tree` are in the tree; the rest are searched one by one.
    in_tree: usize,
}

/// The most positions pushed since the last build that a [`GrowingNeighbours`] query scans one by one.
const GROW_LINEAR_MAX: usize = 32;

impl GrowingNeighbours {
    pub fn new(pos: Vec<(f64, f64)>) -> Self {
        let tree = Neighbours::new(&pos);
        let in_tree = pos.len();
        Self { pos, tree, in_tree }
    }

    /// Add a position; its index is the number of positions before it.
    pub fn push(&mut self, p: (f64, f64)) -> usize {
        self.pos.push(p);
        self.pos.len() - 1
    }

    /// Position `k` (its index as [`GrowingNeighbours::push`] returned it).
    pub fn position(&self, k: usize) -> (f64, f64) {
        self.pos[k]
    }

    /// Every position, in the order they were given.
    pub fn into_positions(self) -> Vec<(f64, f64)> {
        self.pos
    }

    /// As [`Neighbours::near`]: every position within `radius_px`, perhaps a hair beyond.
    pub fn near(&mut self, x: f64, y: f64, radius_px: f64) -> Vec<usize> {
        if self.pos.len() - self.in_tree > GROW_LINEAR_MAX {
            self.tree = Neighbours::new(&self.pos);
            self.in_tree = self.pos.len();
        }
        let mut out = self.tree.near(x, y, radius_px);
        let r = radius_px * (1.0 + 1e-9) + 1e-12;
        out.extend(
            (self.in_tree..self.pos.len())
                .filter(|&k| (self.pos[k].0 - x).powi(2) + (self.pos[k].1 - y).powi(2) <= r * r),
        );
        out
    }
}

/// Union–find with path halving.
struct Disjoint(Vec<usize>);

impl Disjoint {
    fn find(&mut self, mut a: usize) -> usize {
        while self.0[a] != a {
            self.0[a] = self.0[self.0[a]];
            a = self.0[a];
        }
        a
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
}

/// Groups of positions linked by distances below `link_px` (transitively): each group's members in
/// ascending order, groups ordered by their first member. A non-finite position is a group of its own.
pub fn groups(pos: &[(f64, f64)], link_px: f64) -> Vec<Vec<usize>> {
    let nb = Neighbours::new(pos);
    let mut d = Disjoint((0..pos.len()).collect());
    for (k, &(x, y)) in pos.iter().enumerate() {
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        for j in nb.within(x, y, link_px) {
            if j > k {
                d.union(k, j);
            }
        }
    }
    let mut by_root: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for k in 0..pos.len() {
        let r = d.find(k);
        by_root.entry(r).or_default().push(k);
    }
    by_root.into_values().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tree grown by 3 000 pushes, queried after every 97 (a rebuild) and 5 more (those five searched one by
    /// one; every fifth push on one shared x, as pixel positions are), finds what brute force finds, and
    /// nothing beyond the radius's hair.
    #[test]
    fn a_grown_tree_finds_what_brute_force_finds() {
        let mut s = 11u64;
        let mut u = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 * 200.0
        };
        let mut g = GrowingNeighbours::new((0..50).map(|_| (u(), u())).collect());
        let mut all: Vec<(f64, f64)> = g.pos.clone();
        for k in 0..3000 {
            let p = if k % 5 == 0 { (17.0, u()) } else { (u(), u()) };
            assert_eq!(g.push(p), all.len());
            all.push(p);
            if k % 97 == 0 || k % 97 == 5 {
                if k % 97 == 5 && k > 97 {
                    // five pushed since the last query's rebuild: searched one by one
                    assert_eq!(g.pos.len() - g.in_tree, 5);
                }
                let (x, y, r) = (u(), u(), 1.0 + u() / 20.0);
                let mut got = g.near(x, y, r);
                got.sort_unstable();
                let want: Vec<usize> = (0..all.len())
                    .filter(|&j| (all[j].0 - x).hypot(all[j].1 - y) <= r)
                    .collect();
                let beyond: Vec<usize> =
                    got.iter().copied().filter(|j| !want.contains(j)).collect();
                assert!(want.iter().all(|j| got.contains(j)), "missed at push {k}");
                assert!(
                    beyond
                        .iter()
                        .all(|&j| (all[j].0 - x).hypot(all[j].1 - y) <= r * (1.0 + 1e-8)),
                    "{beyond:?}"
                );
            }
        }
    }

    /// Groups against the brute-force connected components of the same graph.
    #[test]
    fn groups_equal_brute_force_components() {
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pos: Vec<(f64, f64)> = (0..600).map(|_| (rnd() * 200.0, rnd() * 200.0)).collect();
        let link = 6.0;
        let g = groups(&pos, link);
        // brute force: flood fill over all pairs
        let mut label = vec![usize::MAX; pos.len()];
        let mut want: Vec<Vec<usize>> = Vec::new();
        for k in 0..pos.len() {
            if label[k] != usize::MAX {
                continue;
            }
            let id = want.len();
            let mut stack = vec![k];
            let mut members = Vec::new();
            label[k] = id;
            while let Some(a) = stack.pop() {
                members.push(a);
                for b in 0..pos.len() {
                    let d = (pos[a].0 - pos[b].0).hypot(pos[a].1 - pos[b].1);
                    if label[b] == usize::MAX && d <= link {
                        label[b] = id;
                        stack.push(b);
                    }
                }
            }
            members.sort_unstable();
            want.push(members);
        }
        assert_eq!(g, want);
        assert!(g.iter().any(|m| m.len() > 2) && g.iter().any(|m| m.len() == 1));
        // radius query against brute force
        let nb = Neighbours::new(&pos);
        let mut got = nb.within(100.0, 100.0, 15.0);
        got.sort_unstable();
        let want: Vec<usize> = (0..pos.len())
            .filter(|&k| (pos[k].0 - 100.0).hypot(pos[k].1 - 100.0) <= 15.0)
            .collect();
        assert_eq!(got, want);
        assert!(groups(&[], 3.0).is_empty());
        assert_eq!(groups(&[(f64::NAN, 1.0), (1.0, 1.0)], 3.0).len(), 2);
    }
}
