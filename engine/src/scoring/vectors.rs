//! The deviation vector map of an image: per used star, fitted − true with the common offset removed, beside
//! the displacement the ACE series predicts for it (SPEC §7), and the figures a reader needs to read it (the
//! per-axis accuracy and a reference arrow). The CLI's `vectors.csv/.png` and the explorer's panel both draw
//! this one reduction.

use super::image::ScoredStar;
use crate::numerics::stats;

/// One arrow: where (fitted position, px) and how much (mas, mean removed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrow {
    pub x_px: f64,
    pub y_px: f64,
    pub dx_mas: f64,
    pub dy_mas: f64,
}

/// A vector map.
#[derive(Debug, Clone, PartialEq)]
pub struct VectorMap {
    /// Measured deviations of the used stars.
    pub measured: Vec<Arrow>,
    /// The predicted displacement of the same stars, in the same order (empty when nothing was predicted):
    /// the fit-response prediction where it was computed, else the mean jitter of the star's window.
    pub predicted: Vec<Arrow>,
    /// Per-axis accuracy of the measured deviations, `√((σx² + σy²)/2)` (the report's definition), mas.
    pub accuracy_mas: f64,
    /// RMS arrow length, `√⟨dx² + dy²⟩` (≈ √2 × the per-axis accuracy), mas.
    pub rms_length_mas: f64,
    /// Length of the reference arrow: the first of 1, 2, 5, 10, 20, 50 mas not shorter than the RMS arrow.
    pub reference_mas: f64,
}

/// Arrows of `stars` (used stars only) with their mean removed.
fn arrows(
    stars: &[&ScoredStar],
    scale_mas: f64,
    d: impl Fn(&ScoredStar) -> (f64, f64),
) -> Vec<Arrow> {
    let n = stars.len().max(1) as f64;
    let (mx, my) = (
        stars.iter().map(|s| d(s).0).sum::<f64>() / n,
        stars.iter().map(|s| d(s).1).sum::<f64>() / n,
    );
    stars
        .iter()
        .map(|s| {
            let (dx, dy) = d(s);
            Arrow {
                x_px: s.x,
                y_px: s.y,
                dx_mas: (dx - mx) * scale_mas,
                dy_mas: (dy - my) * scale_mas,
            }
        })
        .collect()
}

impl VectorMap {
    /// The map of an analysis' stars (`plate_scale_mas` per pixel).
    pub fn new(stars: &[ScoredStar], plate_scale_mas: f64) -> Self {
        let used: Vec<&ScoredStar> = stars.iter().filter(|s| s.is_used()).collect();
        let measured = arrows(&used, plate_scale_mas, |s| (s.dx_px, s.dy_px));
        let fit_pred = used
            .iter()
            .any(|s| s.predicted_fit_dx_px != 0.0 || s.predicted_fit_dy_px != 0.0);
        let mut predicted = if fit_pred {
            arrows(&used, plate_scale_mas, |s| {
                (s.predicted_fit_dx_px, s.predicted_fit_dy_px)
            })
        } else {
            arrows(&used, plate_scale_mas, |s| {
                (s.predicted_dx_px, s.predicted_dy_px)
            })
        };
        if predicted.iter().all(|a| a.dx_mas == 0.0 && a.dy_mas == 0.0) {
            predicted.clear();
        }
        let dx: Vec<f64> = measured.iter().map(|a| a.dx_mas).collect();
        let dy: Vec<f64> = measured.iter().map(|a| a.dy_mas).collect();
        let accuracy_mas = if measured.len() >= 2 {
            ((stats::std_dev(&dx).powi(2) + stats::std_dev(&dy).powi(2)) / 2.0).sqrt()
        } else {
            0.0
        };
        let rms_length_mas = (measured
            .iter()
            .map(|a| a.dx_mas * a.dx_mas + a.dy_mas * a.dy_mas)
            .sum::<f64>()
            / measured.len().max(1) as f64)
            .sqrt();
        let reference_mas = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0]
            .into_iter()
            .find(|r| *r >= rms_length_mas)
            .unwrap_or(100.0);
        Self {
            measured,
            predicted,
            accuracy_mas,
            rms_length_mas,
            reference_mas,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn star(x: f64, dx: f64, dy: f64) -> ScoredStar {
        crate::testkit::scored_star(0, x - dx, 0.0, dx, dy)
    }

    #[test]
    fn mean_is_removed_and_accuracy_is_per_axis() {
        // deviations ±1 px in x around a common offset of 5 px, none in y; scale 10 mas/px
        let stars = vec![star(0.0, 6.0, 2.0), star(1.0, 4.0, 2.0)];
        let m = VectorMap::new(&stars, 10.0);
        assert_eq!(m.measured[0].dx_mas, 10.0);
        assert_eq!(m.measured[1].dx_mas, -10.0);
        assert_eq!(m.measured[0].dy_mas, 0.0);
        // sample std of (10, −10) = 14.14; per-axis combined with 0 in y: 10.0
        assert!((m.accuracy_mas - 10.0).abs() < 1e-12);
        assert!((m.rms_length_mas - 10.0).abs() < 1e-12);
        assert_eq!(m.reference_mas, 10.0);
        assert!(m.predicted.is_empty());
    }
}
