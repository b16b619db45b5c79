//! Display helpers: intensity stretches and colour maps (presentation only, no physics).

use egui::{Color32, ColorImage};
use serde::{Deserialize, Serialize};

/// Intensity stretch of an image display.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stretch {
    Linear,
    Log,
    Asinh,
}

impl Stretch {
    pub const ALL: [Stretch; 3] = [Stretch::Linear, Stretch::Log, Stretch::Asinh];
    pub fn name(self) -> &'static str {
        match self {
            Stretch::Linear => "linear",
            Stretch::Log => "log",
            Stretch::Asinh => "asinh",
        }
    }
}

/// Colour map of an image display.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Colormap {
    Gray,
    Inferno,
}

/// Maps a value to [0, 1] with a stretch between `lo` and `hi`; `soft` sets where log/asinh turn linear.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale {
    pub stretch: Stretch,
    pub lo: f32,
    pub hi: f32,
    pub soft: f32,
}

impl Scale {
    pub fn new(stretch: Stretch, lo: f32, hi: f32, soft: f32) -> Self {
        let hi = if hi > lo { hi } else { lo + 1.0 };
        Self {
            stretch,
            lo,
            hi,
            soft: soft.max(1e-6),
        }
    }

    /// Normalised display value in [0, 1].
    #[inline]
    pub fn apply(&self, v: f32) -> f32 {
        let x = (v - self.lo).max(0.0);
        let range = self.hi - self.lo;
        let t = match self.stretch {
            Stretch::Linear => x / range,
            Stretch::Log => (1.0 + x / self.soft).ln() / (1.0 + range / self.soft).ln(),
            Stretch::Asinh => (x / self.soft).asinh() / (range / self.soft).asinh(),
        };
        if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
}

/// Inferno-like perceptual map (5 stops, linear in between).
const INFERNO: [(f32, [u8; 3]); 6] = [
    (0.0, [0, 0, 4]),
    (0.2, [50, 10, 94]),
    (0.4, [120, 28, 109]),
    (0.6, [187, 55, 84]),
    (0.8, [246, 137, 31]),
    (1.0, [252, 255, 164]),
];

#[inline]
pub fn colour(map: Colormap, t: f32) -> Color32 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    match map {
        Colormap::Gray => {
            let g = (t * 255.0).round() as u8;
            Color32::from_rgb(g, g, g)
        }
        Colormap::Inferno => {
            let mut k = 0;
            while k + 2 < INFERNO.len() && t > INFERNO[k + 1].0 {
                k += 1;
            }
            let (t0, c0) = INFERNO[k];
            let (t1, c1) = INFERNO[k + 1];
            let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
            let mix = |a: u8, b: u8| (a as f32 + f * (b as f32 - a as f32)).round() as u8;
            Color32::from_rgb(mix(c0[0], c1[0]), mix(c0[1], c1[1]), mix(c0[2], c1[2]))
        }
    }
}

/// Blue–white–red for signed values, `t` in [−1, 1].
#[inline]
pub fn diverging(t: f32) -> Color32 {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let w = 1.0 - t.abs();
    let (r, g, b) = if t >= 0.0 { (1.0, w, w) } else { (w, w, 1.0) };
    Color32::from_rgb((r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8)
}

/// An `nx × ny` row-major image (row 0 = Y 0, the bottom) as a texture image, top row first (Y up on screen).
pub fn to_color_image(
    data: &[f32],
    nx: usize,
    ny: usize,
    scale: &Scale,
    map: Colormap,
) -> ColorImage {
    let mut px = Vec::with_capacity(nx * ny);
    for row in (0..ny).rev() {
        let line = &data[row * nx..(row + 1) * nx];
        px.extend(line.iter().map(|v| colour(map, scale.apply(*v))));
    }
    ColorImage::new([nx, ny], px)
}

/// A square cut-out of half-size `r` centred on pixel (cx, cy) of an `n × n` image, zero outside.
pub fn stamp(data: &[f32], n: usize, cx: i64, cy: i64, r: i64) -> Vec<f32> {
    let side = (2 * r + 1) as usize;
    let mut out = vec![0.0; side * side];
    for (j, yy) in (cy - r..=cy + r).enumerate() {
        for (i, xx) in (cx - r..=cx + r).enumerate() {
            if xx >= 0 && yy >= 0 && (xx as usize) < n && (yy as usize) < n {
                out[j * side + i] = data[yy as usize * n + xx as usize];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretches_are_monotone_and_bounded() {
        for s in Stretch::ALL {
            let sc = Scale::new(s, 10.0, 1010.0, 5.0);
            let mut prev = -1.0;
            for k in 0..=100 {
                let t = sc.apply(10.0 + 10.0 * k as f32);
                assert!((0.0..=1.0).contains(&t));
                assert!(t >= prev);
                prev = t;
            }
            assert_eq!(sc.apply(0.0), 0.0);
            assert!((sc.apply(1010.0) - 1.0).abs() < 1e-5);
            assert_eq!(sc.apply(f32::NAN), 0.0);
        }
    }

    #[test]
    fn image_is_flipped_so_y_is_up() {
        let data = [0.0, 0.0, 1.0, 1.0]; // row 0 (bottom) dark, row 1 (top) bright
        let img = to_color_image(
            &data,
            2,
            2,
            &Scale::new(Stretch::Linear, 0.0, 1.0, 1.0),
            Colormap::Gray,
        );
        assert_eq!(img.pixels[0], Color32::WHITE);
        assert_eq!(img.pixels[3], Color32::BLACK);
    }

    #[test]
    fn stamp_pads_outside() {
        let data: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let s = stamp(&data, 4, 0, 0, 1);
        assert_eq!(s, vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 4.0, 5.0]);
    }
}
