//! Greyscale image previews (a linear stretch, nearest-neighbour zoom).

use super::{PlotError, draw_error, write_png};
use plotters::prelude::*;
use std::path::Path;

/// Largest image `image_png` writes (pixels), keeping the bitmap allocation sane.
const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// Greyscale PNG of a row-major `nx × ny` array (row 0 at the bottom, astronomical convention), stretched
/// linearly from `low` (black) to `high` (white) with clipping, each pixel repeated `zoom × zoom` times
/// (nearest neighbour). NaN is drawn black. Empty images, `zoom == 0` and a data length other than
/// `nx * ny` are errors.
pub fn image_png(
    path: &Path,
    data: &[f32],
    nx: usize,
    ny: usize,
    low: f32,
    high: f32,
    zoom: usize,
) -> Result<(), PlotError> {
    if nx == 0 || ny == 0 || zoom == 0 {
        return Err(draw_error(
            path,
            format!("empty image ({nx} × {ny}, zoom {zoom})"),
        ));
    }
    if nx.checked_mul(ny) != Some(data.len()) {
        return Err(draw_error(
            path,
            format!("{} values for a {nx} × {ny} image", data.len()),
        ));
    }
    let size = nx
        .checked_mul(zoom)
        .zip(ny.checked_mul(zoom))
        .and_then(|(w, h)| Some((u32::try_from(w).ok()?, u32::try_from(h).ok()?)));
    let (w, h) = match size {
        Some((w, h)) if u64::from(w) * u64::from(h) <= MAX_IMAGE_PIXELS => (w, h),
        _ => {
            return Err(draw_error(
                path,
                format!("image too large ({nx} × {ny} at zoom {zoom})"),
            ));
        }
    };

    let span = high - low;
    let grey = |v: f32| -> u8 {
        if v.is_nan() {
            0
        } else if span > 0.0 && span.is_finite() {
            (((v - low) / span).clamp(0.0, 1.0) * 255.0).round() as u8
        } else if v >= low {
            255
        } else {
            0
        }
    };

    write_png(path, |tmp| {
        let mut backend = BitMapBackend::new(tmp, (w, h));
        let mut row = vec![0u8; 3 * w as usize];
        for r in 0..ny {
            // Output rows run top-down; data row 0 is the bottom of the picture.
            let src = &data[(ny - 1 - r) * nx..(ny - r) * nx];
            for (i, &v) in src.iter().enumerate() {
                let g = grey(v);
                row[3 * i * zoom..3 * (i + 1) * zoom].fill(g);
            }
            for z in 0..zoom {
                let y = i32::try_from(r * zoom + z)?;
                backend.blit_bitmap((0, y), (w, 1), &row)?;
            }
        }
        backend.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::super::tests::{assert_png, test_dir};
    use super::*;

    #[test]
    fn image_png_writes_and_rejects_empty() {
        let dir = test_dir("image");
        let (nx, ny) = (64, 48);
        let data: Vec<f32> = (0..nx * ny)
            .map(|i| {
                let (x, y) = ((i % nx) as f32 - 20.0, (i / nx) as f32 - 10.0);
                1000.0 * (-(x * x + y * y) / 30.0).exp() + (i % 7) as f32
            })
            .collect();
        let path = dir.join("stamp.png");
        image_png(&path, &data, nx, ny, 0.0, 300.0, 4).expect("image");
        assert_png(&path, 1000);

        assert!(image_png(&dir.join("empty.png"), &[], 0, 0, 0.0, 1.0, 1).is_err());
        assert!(image_png(&dir.join("zoom0.png"), &data, nx, ny, 0.0, 1.0, 0).is_err());
        assert!(image_png(&dir.join("short.png"), &data[1..], nx, ny, 0.0, 1.0, 1).is_err());
        assert!(
            image_png(
                &dir.join("huge.png"),
                &data,
                nx,
                ny,
                0.0,
                1.0,
                usize::MAX / 2
            )
            .is_err()
        );
        assert!(!dir.join("empty.png").exists());
        // Degenerate stretch and NaN pixels still produce a picture.
        let odd = vec![f32::NAN, 1.0, f32::INFINITY, -1.0];
        image_png(&dir.join("odd.png"), &odd, 2, 2, 1.0, 1.0, 1).expect("odd image");
        assert_png(&dir.join("odd.png"), 10);
    }
}
