//! The local sky: one estimator for every place the analysis needs the background under a star (the ePSF
//! build and fit, the crowded passes, aperture photometry of a stare).
//!
//! The sky is a robust location of the pixels whose centres lie in an annulus r_in ≤ r ≤ r_out around the star:
//! their median, or, with σ-clipping, the median of those within k·σ of it, σ = 1.4826 × the median absolute
//! deviation (the clipped median of DAOPHOT's and photutils' annulus photometry, Stetson 1987).

use crate::numerics::stats;

/// The statistic taken over the annulus' pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SkyStatistic {
    /// Their median.
    Median,
    /// The median of those within `sigmas` × the MAD σ of their median (a star's wing or a neighbour left out).
    ClippedMedian { sigmas: f64 },
}

/// An annulus' sky: its value (per pixel) and the pixels it was taken from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sky {
    pub value: f64,
    pub pixels: usize,
}

/// The sky around (x, y) over an `nx` × `ny` image: the pixels whose centres lie between `r_in_px` and `r_out_px`
/// of (x, y) (pixel (X, Y) centred at integer X, Y) and for which `value(index)` gives a value (`None`: masked),
/// reduced by `statistic`; `None` with fewer than `min_pixels` of them (and never with none).
#[allow(clippy::too_many_arguments)]
pub fn annulus(
    nx: usize,
    ny: usize,
    x: f64,
    y: f64,
    r_in_px: f64,
    r_out_px: f64,
    value: impl Fn(usize) -> Option<f64>,
    statistic: SkyStatistic,
    min_pixels: usize,
) -> Option<Sky> {
    if nx == 0 || ny == 0 || !(x.is_finite() && y.is_finite() && r_out_px >= 0.0) {
        return None;
    }
    let (x0, x1) = (
        (x - r_out_px).floor().max(0.0) as usize,
        ((x + r_out_px).ceil().max(0.0) as usize).min(nx - 1),
    );
    let (y0, y1) = (
        (y - r_out_px).floor().max(0.0) as usize,
        ((y + r_out_px).ceil().max(0.0) as usize).min(ny - 1),
    );
    let (in2, out2) = (r_in_px * r_in_px, r_out_px * r_out_px);
    let mut v = Vec::new();
    for py in y0..=y1 {
        for px in x0..=x1 {
            let r2 = (px as f64 - x).powi(2) + (py as f64 - y).powi(2);
            if r2 >= in2
                && r2 <= out2
                && let Some(p) = value(py * nx + px)
            {
                v.push(p);
            }
        }
    }
    if v.is_empty() || v.len() < min_pixels {
        return None;
    }
    let pixels = v.len();
    let med = stats::median(&v);
    let value = match statistic {
        SkyStatistic::Median => med,
        SkyStatistic::ClippedMedian { sigmas } => {
            let s = stats::mad_sigma(&v).max(1e-9);
            let kept: Vec<f64> = v
                .into_iter()
                .filter(|p| (p - med).abs() < sigmas * s)
                .collect();
            stats::median(&kept)
        }
    };
    Some(Sky { value, pixels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    const MEDIAN: SkyStatistic = SkyStatistic::Median;
    const CLIPPED: SkyStatistic = SkyStatistic::ClippedMedian { sigmas: 3.0 };

    /// [`annulus`] over a square image of side `n`, no pixel masked.
    fn on(
        img: &[f64],
        n: usize,
        at: (f64, f64),
        radii: (f64, f64),
        st: SkyStatistic,
        min: usize,
    ) -> Option<Sky> {
        annulus(
            n,
            n,
            at.0,
            at.1,
            radii.0,
            radii.1,
            |i| img.get(i).copied(),
            st,
            min,
        )
    }

    /// A flat sky of 100 with unit Gaussian noise, and a bright star's wing at (20, 20).
    fn image(n: usize) -> Vec<f64> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64, (i / n) as f64);
                let g: f64 = StandardNormal.sample(&mut rng);
                let wing = 5.0e4 * (-((x - 20.0).powi(2) + (y - 20.0).powi(2)) / 2.0).exp();
                100.0 + g + wing
            })
            .collect()
    }

    #[test]
    fn the_annulus_holds_exactly_the_pixels_between_its_radii() {
        // pixels with r ∈ [3, 5] around an integer centre, counted by hand (r = 3 and r = 5 kept)
        let n = 21;
        let s = on(&vec![1.0; n * n], n, (10.0, 10.0), (3.0, 5.0), MEDIAN, 1).expect("sky");
        let by_hand = (-5i32..=5)
            .flat_map(|a| (-5i32..=5).map(move |b| a * a + b * b))
            .filter(|r2| (9..=25).contains(r2))
            .count();
        assert_eq!(s.pixels, by_hand);
        assert_eq!(s.value, 1.0);
    }

    #[test]
    fn clipping_removes_a_neighbours_light_that_the_median_keeps() {
        // the annulus around (24, 20) reaches the star at (20, 20): the plain median is pulled up, the clipped
        // median stays within 3 standard errors of the true 100
        let n = 48;
        let img = image(n);
        let plain = on(&img, n, (24.0, 20.0), (3.0, 7.0), MEDIAN, 8).expect("sky");
        let clipped = on(&img, n, (24.0, 20.0), (3.0, 7.0), CLIPPED, 8).expect("sky");
        assert_eq!(plain.pixels, clipped.pixels);
        // the median's standard error: 1.253 σ / √n
        let se = 1.253 / (clipped.pixels as f64).sqrt();
        assert!((clipped.value - 100.0).abs() < 3.0 * se, "{clipped:?}");
        assert!(plain.value > clipped.value, "{plain:?} {clipped:?}");
    }

    #[test]
    fn masked_pixels_edges_and_too_few_pixels() {
        let n = 16;
        let img = vec![5.0; n * n];
        // at a corner about a quarter of the annulus is on the image
        let full = on(&vec![5.0; 1600], 40, (20.0, 20.0), (2.0, 4.0), MEDIAN, 1).expect("sky");
        let corner = on(&img, n, (0.0, 0.0), (2.0, 4.0), MEDIAN, 1).expect("sky");
        assert!(corner.pixels < full.pixels / 2, "{corner:?} {full:?}");
        // every pixel masked, a centre far off the image, fewer pixels than asked, no centre: none
        assert!(annulus(n, n, 8.0, 8.0, 2.0, 4.0, |_| None, MEDIAN, 1).is_none());
        assert!(on(&img, n, (100.0, 8.0), (2.0, 4.0), MEDIAN, 1).is_none());
        assert!(on(&img, n, (0.0, 0.0), (2.0, 4.0), MEDIAN, 1000).is_none());
        assert!(on(&img, n, (f64::NAN, 0.0), (2.0, 4.0), MEDIAN, 1).is_none());
    }
}
