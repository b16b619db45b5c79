//! One pixel's way through the detector, the same for the array's exposure ([`super::expose`]) and for the
//! windows of a windowed readout ([`super::window`]: a transit stare's plates): the charge collected with its shot
//! noise and clipped at the full well, the node's response over a block of pixels (inter-pixel
//! capacitance, nonlinearity), and the readout (read noise, ÷ gain + bias, the ADC). The callers draw from
//! their own seeded streams in their own order; the physics is here once.

use crate::config::Detector;
use rand_distr::{Distribution, Normal, Poisson};

/// The charge a pixel collects from `mean_e` electrons: a Poisson draw when shot noise is on, the mean
/// itself when it is off or the mean is not positive.
pub fn shot_e(d: &Detector, mean_e: f64, rng: &mut impl rand::Rng) -> f64 {
    if d.shot_noise && mean_e > 0.0 {
        Poisson::new(mean_e)
            .map(|p| p.sample(rng))
            .unwrap_or(mean_e)
    } else {
        mean_e
    }
}

/// `e` clipped at `full_well_e`, and whether it reached it.
pub fn clip_full_well(e: f64, full_well_e: f64) -> (f64, bool) {
    if e >= full_well_e {
        (full_well_e, true)
    } else {
        (e, false)
    }
}

/// The node's response over an n × n block of collected charge: inter-pixel capacitance ([`super::ipc`]),
/// then N − β N² (each off by default, and then nothing is done).
pub fn respond(charge: &mut Vec<f64>, n: usize, d: &Detector) {
    use rayon::prelude::*;
    if d.ipc_alpha > 0.0 || d.ipc_alpha_diagonal > 0.0 {
        *charge = super::ipc::couple(charge, n, d.ipc_alpha, d.ipc_alpha_diagonal);
    }
    if d.nonlinearity_per_e > 0.0 {
        let beta = d.nonlinearity_per_e;
        charge.par_iter_mut().for_each(|e| *e -= beta * *e * *e);
    }
}

/// How an image is read out: Gaussian read noise of σ (when on), ÷ gain + bias, rounded, clipped by the
/// ADC.
#[derive(Debug, Clone)]
pub struct Readout {
    read: Option<Normal<f64>>,
    gain_e_per_adu: f64,
    bias_adu: f64,
    digitise: bool,
    /// The ADC's top, ADU; None: no clipping at all.
    adc_max_adu: Option<f64>,
}

impl Readout {
    /// One exposure, as the detector is configured: the image's read noise
    /// ([`Detector::image_read_noise_e`]), clipped to [0, 2^bits − 1] ADU.
    pub fn image(d: &Detector) -> Self {
        Self {
            read: Normal::new(0.0, d.image_read_noise_e().max(0.0))
                .ok()
                .filter(|_| d.read_noise),
            gain_e_per_adu: d.gain_e_per_adu,
            bias_adu: d.bias_adu,
            digitise: d.digitise,
            adc_max_adu: Some((2f64.powi(d.adc_bits as i32) - 1.0).min(f32::MAX as f64)),
        }
    }

    /// The sum of `n` sub-exposures co-added on board, read as one: read noise `read_sigma_e` (each
    /// sub-exposure's in quadrature), n biases, one rounding of the sum, and no ADC clip (the sum of n
    /// digitised frames has none; each frame's is kept away by choosing its length below the full well).
    pub fn coadded(d: &Detector, read_sigma_e: f64, n: usize) -> Self {
        Self {
            read: Normal::new(0.0, read_sigma_e.max(0.0))
                .ok()
                .filter(|_| d.read_noise),
            gain_e_per_adu: d.gain_e_per_adu,
            bias_adu: d.bias_adu * n as f64,
            digitise: d.digitise,
            adc_max_adu: None,
        }
    }

    /// The ADU of a pixel holding `e` electrons, and the data-quality bits of its ADC clip
    /// ([`super::dq::ADC_HIGH`], [`super::dq::ADC_LOW`]): [`Self::digitised`] of `e` plus
    /// [`Self::noise_e`].
    pub fn adu(&self, e: f64, rng: &mut impl rand::Rng) -> (f32, u8) {
        self.digitised(e + self.noise_e(rng))
    }

    /// One draw of the read noise, e⁻ (none is drawn, and 0 returned, when it is off).
    pub fn noise_e(&self, rng: &mut impl rand::Rng) -> f64 {
        self.read.as_ref().map_or(0.0, |rn| rn.sample(rng))
    }

    /// The ADU of `e` electrons, read noise included: ÷ gain + bias, rounded and clipped.
    pub fn digitised(&self, e: f64) -> (f32, u8) {
        let mut v = e / self.gain_e_per_adu + self.bias_adu;
        let mut flags = 0;
        if self.digitise {
            v = v.round();
            if let Some(top) = self.adc_max_adu {
                if v >= top {
                    v = top;
                    flags |= super::dq::ADC_HIGH;
                }
                if v <= 0.0 {
                    v = 0.0;
                    flags |= super::dq::ADC_LOW;
                }
            }
        }
        (v as f32, flags)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{self, Stream};

    /// A co-added plate of n sub-exposures: the mean and variance of its ADU against the sum's (n biases,
    /// the read noise given, one rounding: + 1/12 ADU²), and no clip at either end of one ADC.
    #[test]
    fn a_coadded_plate_reads_as_the_sum_of_its_sub_exposures() {
        let mut d = crate::config::Config::default().detector;
        d.bias_adu = 100.0;
        let n = 4;
        let sigma_e = 30.0;
        let r = Readout::coadded(&d, sigma_e, n);
        let mut rng = rng::stream(1, Stream::Transit, 0);
        let v: Vec<f64> = (0..100_000)
            .map(|_| f64::from(r.adu(600.0, &mut rng).0))
            .collect();
        let m = crate::numerics::stats::mean(&v);
        let var = crate::numerics::stats::std_dev(&v).powi(2);
        let g = d.gain_e_per_adu;
        let expect = (sigma_e / g).powi(2) + 1.0 / 12.0;
        assert!(
            (m - (600.0 / g + 400.0)).abs() < 4.0 * expect.sqrt() / 316.0,
            "{m}"
        );
        assert!(
            (var / expect - 1.0).abs() < 4.0 * (2.0f64 / 1e5).sqrt(),
            "{var}"
        );
        // far above one ADC's top: summed, not clipped
        let (top, flags) = r.adu(1e6 * g, &mut rng);
        assert!(f64::from(top) > 65_535.0 && flags == 0);
        // one exposure clips and says so
        let one = Readout::image(&d);
        assert_eq!(
            one.adu(1e6 * g, &mut rng),
            (65_535.0, super::super::dq::ADC_HIGH)
        );
        assert_eq!(one.adu(-1e5, &mut rng), (0.0, super::super::dq::ADC_LOW));
    }
}
