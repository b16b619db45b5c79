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
        t.query(&[x, y])
            .within::<SquaredEuclidean<f64>>(radius_px * radius_px)
            .unsorted()
            .execute()
            .into_iter()
            .map(|r| self.index[r.item as usize])
            .collect()
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
