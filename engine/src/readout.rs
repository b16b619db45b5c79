//! Per-pixel exposure windows of the detector readout (SPEC §4).
//!
//! Each of the `channels` vertical stripes (`channel_width_px` columns) is reset and read in sequence: along
//! the row (x) from the stripe's left edge, then the next row (up by default). All stripes run in parallel.
//! Pixel (X, Y) has read index `n = row(Y)·W + (X mod W)` and is first read at `t₁ = t_overhead + n·t_pix`.
//! Windows, relative to the exposure start:
//! * `rolling`: `[t₁, t₁ + T]` (CDS: charge between the two reads);
//! * `global-reset`: `[t_overhead, t₁ + T]` — all pixels start together, reads still roll, so later pixels
//!   integrate up to one frame sweep (≈ 1.21 s) longer; the truth catalogue records each star's own length;
//! * `sample-hold`: `[t_overhead, t_overhead + T]` for every pixel.

use crate::config::{Config, ReadoutOrder, RowDirection};

/// Readout timing of one exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadoutTiming {
    pub order: ReadoutOrder,
    pub row_direction: RowDirection,
    pub channel_width_px: usize,
    pub rows: usize,
    pub pixel_time_s: f64,
    pub t_overhead_s: f64,
    pub exposure_s: f64,
    /// One channel's read sweep, the latest window end and the start-to-start time ([`Config`]'s
    /// derived timing, computed there once).
    frame_sweep_s: f64,
    span_s: f64,
    cadence_s: f64,
}

impl ReadoutTiming {
    pub fn new(cfg: &Config) -> Self {
        Self {
            order: cfg.readout.order,
            row_direction: cfg.readout.row_direction,
            channel_width_px: cfg.readout.channel_width_px,
            rows: cfg.instrument.detector_px,
            pixel_time_s: cfg.readout.pixel_time_us * 1e-6,
            t_overhead_s: cfg.readout.t_overhead_s,
            exposure_s: cfg.detector.exposure_s,
            frame_sweep_s: cfg.frame_sweep_s(),
            span_s: cfg.exposure_span_s(),
            cadence_s: cfg.exposure_cadence_s(),
        }
    }

    /// Position of pixel (x, y) in its channel's read sequence.
    pub fn read_index(&self, x: usize, y: usize) -> usize {
        let row = match self.row_direction {
            RowDirection::Up => y,
            RowDirection::Down => self.rows.saturating_sub(1).saturating_sub(y),
        };
        row * self.channel_width_px + x % self.channel_width_px
    }

    /// First (reset-level) read time of pixel (x, y), seconds from the exposure start.
    pub fn first_read_s(&self, x: usize, y: usize) -> f64 {
        self.t_overhead_s + self.read_index(x, y) as f64 * self.pixel_time_s
    }

    /// Integration window `[start, end)` of pixel (x, y), seconds from the exposure start.
    pub fn window_s(&self, x: usize, y: usize) -> (f64, f64) {
        let t1 = self.first_read_s(x, y);
        match self.order {
            ReadoutOrder::Rolling => (t1, t1 + self.exposure_s),
            ReadoutOrder::GlobalReset => (self.t_overhead_s, t1 + self.exposure_s),
            ReadoutOrder::SampleHold => (self.t_overhead_s, self.t_overhead_s + self.exposure_s),
        }
    }

    /// The window every pixel of an `n × n` detector shares, `[max start, min end)` (empty when
    /// `end ≤ start`). Windows are monotonic in the read index, whose extremes lie on the channel's first and
    /// last columns of the first and last rows, so those four pixels decide it.
    pub fn shared_window_s(&self, n: usize) -> (f64, f64) {
        let (w, last) = (self.channel_width_px.min(n).max(1) - 1, n.saturating_sub(1));
        [(0, 0), (w, 0), (0, last), (w, last)]
            .iter()
            .map(|&(x, y)| self.window_s(x, y))
            .fold((f64::NEG_INFINITY, f64::INFINITY), |(a, b), w| {
                (a.max(w.0), b.min(w.1))
            })
    }

    /// Length of pixel (x, y)'s integration window, s: exactly T under the rolling and sample-and-hold
    /// orders, T plus the pixel's read delay under a global reset.
    pub fn window_length_s(&self, x: usize, y: usize) -> f64 {
        match self.order {
            ReadoutOrder::GlobalReset => {
                let (a, b) = self.window_s(x, y);
                b - a
            }
            ReadoutOrder::Rolling | ReadoutOrder::SampleHold => self.exposure_s,
        }
    }

    /// Duration of one read sweep of a channel (W × rows × t_pix).
    pub fn frame_sweep_s(&self) -> f64 {
        self.frame_sweep_s
    }

    /// Latest end of any window, seconds from the exposure start.
    pub fn span_s(&self) -> f64 {
        self.span_s
    }

    /// Start-to-start time of consecutive exposures.
    pub fn cadence_s(&self) -> f64 {
        self.cadence_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timing(order: ReadoutOrder) -> ReadoutTiming {
        let mut cfg = Config::default();
        cfg.readout.order = order;
        ReadoutTiming::new(&cfg)
    }

    #[test]
    fn rolling_offsets_of_known_pixels() {
        let t = timing(ReadoutOrder::Rolling);
        let us = 1e-6;
        // first pixel of every stripe is read first
        for ch in 0..16 {
            assert!((t.first_read_s(ch * 123, 0) - 0.1).abs() < 1e-12);
        }
        // last pixel of the first row of a stripe, then the first pixel of the next row
        assert!((t.first_read_s(122, 0) - (0.1 + 122.0 * 5.0 * us)).abs() < 1e-12);
        assert!((t.first_read_s(0, 1) - (0.1 + 123.0 * 5.0 * us)).abs() < 1e-12);
        assert!((t.first_read_s(123 + 5, 1) - (0.1 + 128.0 * 5.0 * us)).abs() < 1e-12);
        // the last pixel of the frame: 1.21 s after the first
        let last = t.first_read_s(1967, 1967) - 0.1;
        assert!((last - 1.2103).abs() < 1e-4, "last pixel offset {last}");
        assert!((t.frame_sweep_s() - 1.21032).abs() < 1e-9);
        let (a, b) = t.window_s(10, 20);
        assert!((b - a - 12.5).abs() < 1e-12);
    }

    #[test]
    fn shared_window_is_every_pixels_intersection() {
        for order in ReadoutOrder::ALL {
            for dir in [RowDirection::Up, RowDirection::Down] {
                let mut cfg = Config::default();
                cfg.readout.order = order;
                cfg.readout.row_direction = dir;
                cfg.instrument.detector_px = 50;
                cfg.readout.channel_width_px = 7;
                let t = ReadoutTiming::new(&cfg);
                let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
                for y in 0..50 {
                    for x in 0..50 {
                        let w = t.window_s(x, y);
                        a = a.max(w.0);
                        b = b.min(w.1);
                    }
                }
                assert_eq!(t.shared_window_s(50), (a, b), "{order:?} {dir:?}");
            }
        }
    }

    #[test]
    fn orders_and_direction() {
        let g = timing(ReadoutOrder::GlobalReset);
        assert_eq!(g.window_s(5, 1000).0, 0.1);
        assert!(g.window_s(5, 1000).1 > g.window_s(5, 0).1);
        let s = timing(ReadoutOrder::SampleHold);
        assert_eq!(s.window_s(5, 1000), s.window_s(1900, 3));
        let mut cfg = Config::default();
        cfg.readout.row_direction = RowDirection::Down;
        let d = ReadoutTiming::new(&cfg);
        assert!((d.first_read_s(0, 1967) - 0.1).abs() < 1e-12);
        assert!(d.first_read_s(0, 0) > 1.3);
        assert!((timing(ReadoutOrder::Rolling).cadence_s() - (0.1 + 1.21032 + 12.5)).abs() < 1e-9);
    }
}
