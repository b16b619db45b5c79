//! Observations grouped by source or by exposure: one flat index array, 4 bytes an observation.

/// Observation indices grouped by a key (a source, an exposure) in one flat array: 4 bytes an observation
/// (the count of observations is checked to fit `u32`).
pub(super) struct Groups {
    start: Vec<usize>,
    items: Vec<u32>,
}

impl Groups {
    /// `count` observations grouped by `key(i)` < `n`, each group in rising index.
    pub fn new(n: usize, count: usize, key: impl Fn(usize) -> usize) -> Self {
        let mut start = vec![0usize; n + 1];
        for i in 0..count {
            start[key(i) + 1] += 1;
        }
        for k in 0..n {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; count];
        for i in 0..count {
            let k = key(i);
            items[fill[k]] = i as u32;
            fill[k] += 1;
        }
        Self { start, items }
    }

    /// Group `k`'s observations.
    pub fn get(&self, k: usize) -> &[u32] {
        &self.items[self.start[k]..self.start[k + 1]]
    }

    /// The groups.
    pub fn len(&self) -> usize {
        self.start.len() - 1
    }
}
