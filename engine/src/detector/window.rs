//! The windowed readout: only small windows of the array are read, each a reset and a correlated double
//! sampling of its pixels, `n` sub-exposures co-added on board (a transit stare's plates). Each pixel goes
//! the array's way ([`super::chain`]): × the flat, + dark, shot noise, the sum's full well, the node's
//! response over the window, the co-added readout (σ_image √n) and the ADC.

use super::chain;
use crate::config::Detector;

/// Where a window lies on the array: its lower-left pixel and its side, px.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub x0: i64,
    pub y0: i64,
    pub n: usize,
}

impl Window {
    /// `img` (row-major, `detector_px` wide) cut to the window.
    pub fn cut(&self, img: &[f32], detector_px: usize) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.n * self.n);
        for y in 0..self.n {
            let row = (self.y0 + y as i64) as usize * detector_px + self.x0 as usize;
            out.extend_from_slice(&img[row..row + self.n]);
        }
        out
    }
}

/// How a plate's windows are read: the imaging detector for `n` co-added sub-exposures.
#[derive(Debug, Clone)]
pub struct WindowReadout {
    d: Detector,
    /// The plate's dark charge per pixel, e⁻.
    dark_e: f64,
    /// The sum's full well: n sub-exposures' (each kept below its own by the readout's choice).
    full_well_e: f64,
    readout: chain::Readout,
}

impl WindowReadout {
    /// `sub_exposures` co-added over a plate of `plate_s`, a window's read noise `read_noise_e` per plate.
    pub fn new(d: &Detector, plate_s: f64, sub_exposures: usize, read_noise_e: f64) -> Self {
        Self {
            d: d.clone(),
            dark_e: d.dark_e_per_s * plate_s,
            full_well_e: d.full_well_e * sub_exposures as f64,
            readout: chain::Readout::coadded(d, read_noise_e, sub_exposures),
        }
    }

    /// Read window `wdw` of a star whose noise-free electrons at array pixel (x, y) are `star_e(x, y)`,
    /// through the window's cut of the flat: the window as read (ADU) and the clean window (e⁻). Each
    /// pixel's read noise is drawn beside its shot noise from `r`, so the stream's order is the pixels'.
    pub fn read(
        &self,
        wdw: &Window,
        star_e: impl Fn(i64, i64) -> f64,
        flat: &[f32],
        r: &mut impl rand::Rng,
    ) -> (Vec<f32>, Vec<f64>) {
        let n2 = wdw.n * wdw.n;
        let (mut clean, mut charge, mut read_e) =
            (vec![0.0f64; n2], vec![0.0f64; n2], vec![0.0f64; n2]);
        for y in 0..wdw.n {
            for x in 0..wdw.n {
                let e = star_e(wdw.x0 + x as i64, wdw.y0 + y as i64);
                let i = y * wdw.n + x;
                clean[i] = e;
                let mean = e.max(0.0) * flat[i] as f64 + self.dark_e;
                let (q, _) =
                    chain::clip_full_well(chain::shot_e(&self.d, mean, r), self.full_well_e);
                charge[i] = q;
                read_e[i] = self.readout.noise_e(r);
            }
        }
        chain::respond(&mut charge, wdw.n, &self.d);
        let out = charge
            .iter()
            .zip(&read_e)
            .map(|(e, rn)| self.readout.digitised(e + rn).0)
            .collect();
        (out, clean)
    }
}
