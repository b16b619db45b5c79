//! Field-dependent wavefront error: the Zernike table of the optical design, interpolated to each star.
//!
//! The table (`optics.field_table`) gives Fringe coefficients at the nodes of a rectangular grid of field
//! positions (pixels): every combination of its distinct x and y values once (validated with the
//! configuration). A star's coefficients are the bilinear interpolation of the four nodes around it — exact
//! at a node, and exact for any field linear in x and y between nodes — and the edge values beyond the grid
//! (no extrapolation). Inverse-distance weighting over all rows, the earlier scheme, pulled every star towards
//! the field mean.

use crate::config::{FieldWfe, Optics};

/// The field table as a grid: sorted node coordinates and the coefficients (µm OPD) of each node.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldGrid {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// `coeffs[iy * xs.len() + ix]`: the node's Fringe coefficients, µm OPD, 37 terms.
    pub coeffs: Vec<Vec<f64>>,
}

/// Why a field table is not a grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct GridError(pub String);

impl FieldGrid {
    /// The grid of `rows` (coefficients converted to µm OPD by `to_um`), or why they do not form one.
    pub fn new(
        rows: &[FieldWfe],
        to_um: impl Fn(&[f64]) -> Vec<f64>,
    ) -> Result<FieldGrid, GridError> {
        let (xs, ys) = crate::config::field_grid_shape(rows).map_err(GridError)?;
        let mut coeffs: Vec<Option<Vec<f64>>> = vec![None; rows.len()];
        for r in rows {
            let ix = xs.iter().position(|x| *x == r.x_px).unwrap_or(0);
            let iy = ys.iter().position(|y| *y == r.y_px).unwrap_or(0);
            coeffs[iy * xs.len() + ix] = Some(to_um(&r.fringe));
        }
        Ok(FieldGrid {
            xs,
            ys,
            coeffs: coeffs.into_iter().map(Option::unwrap_or_default).collect(),
        })
    }

    /// Bilinear interpolation at (x, y) px, clamped to the grid's extent.
    pub fn at(&self, x_px: f64, y_px: f64) -> Vec<f64> {
        let (ix, fx) = bracket(&self.xs, x_px);
        let (iy, fy) = bracket(&self.ys, y_px);
        let nx = self.xs.len();
        let ix1 = (ix + 1).min(nx - 1);
        let iy1 = (iy + 1).min(self.ys.len() - 1);
        let c = |i: usize, j: usize| &self.coeffs[j * nx + i];
        (0..c(ix, iy).len())
            .map(|k| {
                let bottom = c(ix, iy)[k] * (1.0 - fx) + c(ix1, iy)[k] * fx;
                let top = c(ix, iy1)[k] * (1.0 - fx) + c(ix1, iy1)[k] * fx;
                bottom * (1.0 - fy) + top * fy
            })
            .collect()
    }
}

/// The node below `v` in the sorted `nodes` and the fraction towards the next (0 beyond the ends).
fn bracket(nodes: &[f64], v: f64) -> (usize, f64) {
    if nodes.len() < 2 || v <= nodes[0] {
        return (0, 0.0);
    }
    let last = nodes.len() - 1;
    if v >= nodes[last] {
        return (last, 0.0);
    }
    let i = nodes.partition_point(|n| *n <= v) - 1;
    (i, (v - nodes[i]) / (nodes[i + 1] - nodes[i]))
}

/// The grid of an optics configuration's field table (`None` without one).
pub fn grid_of(optics: &Optics) -> Result<Option<FieldGrid>, GridError> {
    if optics.field_table.is_empty() {
        return Ok(None);
    }
    FieldGrid::new(&optics.field_table, |c| super::to_um(optics, c)).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::WfeUnit;

    fn optics(rows: Vec<(f64, f64, Vec<f64>)>) -> Optics {
        let mut o = Optics::default();
        o.wfe_unit = WfeUnit::Um;
        o.field_table = rows
            .into_iter()
            .map(|(x_px, y_px, fringe)| FieldWfe { x_px, y_px, fringe })
            .collect();
        o
    }

    #[test]
    fn nodes_are_exact_and_a_linear_field_is_reproduced_between_them() {
        // coma Z7 = 0.01 + 2e-5 x − 3e-5 y µm on a 3 × 2 grid, astigmatism only at one node
        let lin = |x: f64, y: f64| 0.01 + 2e-5 * x - 3e-5 * y;
        let mut rows = Vec::new();
        for y in [100.0, 1800.0] {
            for x in [0.0, 900.0, 1968.0] {
                let mut f = vec![0.0; 7];
                f[6] = lin(x, y);
                if (x, y) == (900.0, 1800.0) {
                    f[4] = 0.05;
                }
                rows.push((x, y, f));
            }
        }
        let o = optics(rows);
        let g = grid_of(&o).expect("a grid").expect("a table");
        // a star on a node gets exactly that node's coefficients
        let at = g.at(900.0, 1800.0);
        assert_eq!(at[6], lin(900.0, 1800.0));
        assert_eq!(at[4], 0.05);
        // between nodes the linear term is exact; the single-node term falls off bilinearly
        for (x, y) in [(450.0, 950.0), (1234.5, 333.3), (10.0, 1799.0)] {
            let v = g.at(x, y);
            assert!((v[6] - lin(x, y)).abs() < 1e-15, "({x}, {y}): {}", v[6]);
        }
        let v = g.at(450.0, 1800.0);
        assert!((v[4] - 0.025).abs() < 1e-15, "{}", v[4]);
        // beyond the grid: the edge value, not an extrapolation
        assert_eq!(g.at(-500.0, 100.0)[6], lin(0.0, 100.0));
        assert_eq!(g.at(900.0, 5000.0)[6], lin(900.0, 1800.0));
    }

    #[test]
    fn a_table_that_is_not_a_grid_is_a_named_error() {
        let o = optics(vec![
            (0.0, 0.0, vec![0.1]),
            (1000.0, 0.0, vec![0.2]),
            (0.0, 1000.0, vec![0.3]),
        ]);
        let e = grid_of(&o).expect_err("3 of 4 nodes");
        assert!(e.0.contains("rectangular grid"), "{e}");
        let o = optics(vec![(0.0, 0.0, vec![0.1]), (0.0, 0.0, vec![0.2])]);
        assert!(grid_of(&o).is_err());
    }
}
