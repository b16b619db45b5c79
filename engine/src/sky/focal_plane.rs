//! The focal plane of four arrays in a 2 × 2 layout: where each array sits, how it is turned, and which array
//! (or gap) a focal-plane position falls on.
//!
//! Focal-plane coordinates (f_x, f_y) are pixels from the optical axis in the frame of [`super::Pointing`]
//! (+y at the position angle, sky parity). Array k (0 lower left, 1 lower right, 2 upper left, 3 upper right)
//! is centred at (±c, ±c), c = (N + gap) / 2 for N-pixel arrays, and turned by r_k (a multiple of 90°,
//! counter-clockwise in the focal-plane frame): a point at offset d from the array's centre is at array pixel
//! R(−r_k)·d + (N − 1)/2 — so its rows, channels and rolling readout run along a different direction on the
//! sky on each array — and its WCS has position angle PA + r_k ([`FocalPlane::array_wcs`]).
//!
//! As assembled, each array also sits `offsets_px[k]` from its nominal centre and is turned a further
//! `rotation_errors_deg[k]` (a small angle): where stars land and the WCS follow the array as built; the
//! jitter and the PSF are turned into the array by its nominal quarter turn (a ≤ 0.1° error turns them by
//! ≤ 0.2 % of their size), and a display turns the image by that quarter turn too.

use super::Pointing;
use super::wcs::{ArrayWcs, Sip};

/// Where a focal-plane position falls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Placement {
    /// On the photosensitive pixels of `array`, at the array's pixel (x, y) (0-based, integer = centre).
    Photosensitive { array: usize, x: f64, y: f64 },
    /// On `array` but in its border, which sees no light.
    Border { array: usize, x: f64, y: f64 },
    /// Between the arrays.
    Gap,
    /// Outside the focal plane.
    Off,
}

/// The 2 × 2 focal plane.
#[derive(Debug, Clone, PartialEq)]
pub struct FocalPlane {
    /// Pixels per array side (full format).
    pub array_px: usize,
    /// Photosensitive pixels per side (centred; the rest is border).
    pub photosensitive_px: usize,
    /// Gap between neighbouring arrays' full formats, pixels.
    pub gap_px: f64,
    /// Each array's rotation, degrees: 0, 90, 180 or 270.
    pub rotations_deg: [f64; 4],
    /// Each array's displacement from its nominal centre as assembled, focal-plane pixels.
    pub offsets_px: [[f64; 2]; 4],
    /// Each array's further turn as assembled, degrees (small).
    pub rotation_errors_deg: [f64; 4],
}

/// Quadrant signs of array k: (−,−), (+,−), (−,+), (+,+).
const SIGNS: [(f64, f64); 4] = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)];

impl FocalPlane {
    /// Check the layout, naming the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.array_px == 0 || self.photosensitive_px > self.array_px {
            return Err(format!(
                "photosensitive_px = {}: must be 1 … array_px ({})",
                self.photosensitive_px, self.array_px
            ));
        }
        if !(self.gap_px >= 0.0 && self.gap_px.is_finite()) {
            return Err(format!("gap_px = {}: must be ≥ 0", self.gap_px));
        }
        for (k, r) in self.rotations_deg.iter().enumerate() {
            if ![0.0, 90.0, 180.0, 270.0].contains(r) {
                return Err(format!(
                    "rotations_deg[{k}] = {r}: must be 0, 90, 180 or 270"
                ));
            }
        }
        let limit = self.gap_px / 2.0;
        for (k, o) in self.offsets_px.iter().enumerate() {
            if !o.iter().all(|v| v.is_finite() && v.abs() <= limit.max(0.0)) {
                return Err(format!(
                    "array_offsets_px[{k}] = {o:?}: each must be within ±gap_px/2 ({limit} px): arrays may not overlap"
                ));
            }
        }
        for (k, e) in self.rotation_errors_deg.iter().enumerate() {
            if !(e.is_finite() && e.abs() <= 1.0) {
                return Err(format!(
                    "array_rotation_errors_deg[{k}] = {e}: must be within ±1°"
                ));
            }
        }
        Ok(())
    }

    /// The centre of array k in focal-plane pixels, as assembled.
    pub fn centre(&self, k: usize) -> (f64, f64) {
        let c = (self.array_px as f64 + self.gap_px) / 2.0;
        (
            SIGNS[k].0 * c + self.offsets_px[k][0],
            SIGNS[k].1 * c + self.offsets_px[k][1],
        )
    }

    /// Array k's turn as assembled: its quarter turn plus its rotation error, degrees.
    pub fn rotation_deg(&self, k: usize) -> f64 {
        self.rotations_deg[k] + self.rotation_errors_deg[k]
    }

    /// The same focal plane as designed: no offsets, no rotation errors.
    pub fn nominal(&self) -> FocalPlane {
        FocalPlane {
            offsets_px: [[0.0; 2]; 4],
            rotation_errors_deg: [0.0; 4],
            ..self.clone()
        }
    }

    fn half(&self) -> f64 {
        (self.array_px as f64 - 1.0) / 2.0
    }

    /// Array k's pixel (x, y) of a focal-plane position (which may lie off the array).
    pub fn to_array(&self, k: usize, fx: f64, fy: f64) -> (f64, f64) {
        let (cx, cy) = self.centre(k);
        let (dx, dy) = (fx - cx, fy - cy);
        let (s, c) = (-self.rotation_deg(k)).to_radians().sin_cos();
        (c * dx - s * dy + self.half(), s * dx + c * dy + self.half())
    }

    /// The focal-plane position of array k's pixel (x, y).
    pub fn to_focal_plane(&self, k: usize, x: f64, y: f64) -> (f64, f64) {
        let (cx, cy) = self.centre(k);
        let (dx, dy) = (x - self.half(), y - self.half());
        let (s, c) = self.rotation_deg(k).to_radians().sin_cos();
        (cx + c * dx - s * dy, cy + s * dx + c * dy)
    }

    /// Array k's image (row-major, `array_px` square) turned into focal-plane axes: element `v·N + u` is the
    /// array pixel at focal-plane position `(c_x − h + u, c_y − h + v)` (c the array's centre, h = (N − 1)/2),
    /// an exact permutation for turns of 90°. What a display of the focal plane draws: the nominal layout
    /// (an assembly's offsets and small turns are not drawn).
    pub fn in_focal_plane_axes<T: Copy>(&self, k: usize, image: &[T]) -> Vec<T> {
        if self.offsets_px != [[0.0; 2]; 4] || self.rotation_errors_deg != [0.0; 4] {
            return self.nominal().in_focal_plane_axes(k, image);
        }
        let n = self.array_px;
        let (cx, cy) = self.centre(k);
        let h = self.half();
        (0..n * n)
            .map(|i| {
                let (u, v) = ((i % n) as f64, (i / n) as f64);
                let (x, y) = self.to_array(k, cx - h + u, cy - h + v);
                let (x, y) = (x.round() as usize, y.round() as usize);
                image[y.min(n - 1) * n + x.min(n - 1)]
            })
            .collect()
    }

    /// Which array, border, gap or outside a focal-plane position falls on.
    pub fn locate(&self, fx: f64, fy: f64) -> Placement {
        let n = self.array_px as f64;
        let border = (self.array_px - self.photosensitive_px) as f64 / 2.0;
        for k in 0..4 {
            let (x, y) = self.to_array(k, fx, fy);
            let on = |v: f64, lo: f64| v >= lo - 0.5 && v < n - lo - 0.5;
            if on(x, 0.0) && on(y, 0.0) {
                return if on(x, border) && on(y, border) {
                    Placement::Photosensitive { array: k, x, y }
                } else {
                    Placement::Border { array: k, x, y }
                };
            }
        }
        let extent = n + self.gap_px / 2.0;
        if fx.abs() < extent && fy.abs() < extent {
            Placement::Gap
        } else {
            Placement::Off
        }
    }

    /// The WCS of array k at `pointing`, `scale_mas` per pixel, with the forward distortion `sip` expressed
    /// in that array's pixel axes.
    pub fn array_wcs(
        &self,
        k: usize,
        pointing: &Pointing,
        scale_mas: f64,
        sip: Option<Sip>,
    ) -> Result<ArrayWcs, String> {
        self.validate()?;
        let (ax, ay) = self.to_array(k, 0.0, 0.0);
        ArrayWcs::new(
            pointing,
            self.rotation_deg(k),
            scale_mas,
            [ax, ay],
            [self.array_px, self.array_px],
            sip,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_turned_into_focal_plane_axes_puts_each_pixel_where_to_focal_plane_says() {
        let plane = FocalPlane {
            array_px: 6,
            photosensitive_px: 6,
            gap_px: 2.0,
            rotations_deg: [0.0, 90.0, 180.0, 270.0],
            offsets_px: [[0.0; 2]; 4],
            rotation_errors_deg: [0.0; 4],
        };
        let image: Vec<usize> = (0..36).collect();
        for k in 0..4 {
            let turned = plane.in_focal_plane_axes(k, &image);
            let (cx, cy) = plane.centre(k);
            for (i, &v) in turned.iter().enumerate() {
                // the array pixel shown at display position (u, v) sits there on the focal plane
                let (x, y) = (v % 6, v / 6);
                let (fx, fy) = plane.to_focal_plane(k, x as f64, y as f64);
                let (u, w) = (fx - (cx - 2.5), fy - (cy - 2.5));
                assert!((u - (i % 6) as f64).abs() < 1e-9 && (w - (i / 6) as f64).abs() < 1e-9);
            }
            let mut sorted = turned.clone();
            sorted.sort();
            assert_eq!(sorted, image, "array {k}: a permutation");
        }
    }

    fn jasmine() -> FocalPlane {
        // 1968-px arrays of 10-µm pixels, 3 mm apart, turned so that no two read along the same direction
        FocalPlane {
            array_px: 1968,
            photosensitive_px: 1952,
            gap_px: 300.0,
            rotations_deg: [0.0, 90.0, 180.0, 270.0],
            offsets_px: [[0.0; 2]; 4],
            rotation_errors_deg: [0.0; 4],
        }
    }

    #[test]
    fn array_pixels_and_focal_plane_round_trip_and_rotate_as_stated() {
        let fp = jasmine();
        for k in 0..4 {
            for (x, y) in [(0.0, 0.0), (1967.0, 3.0), (983.5, 983.5), (100.25, 1500.75)] {
                let (fx, fy) = fp.to_focal_plane(k, x, y);
                let (x2, y2) = fp.to_array(k, fx, fy);
                assert!((x2 - x).abs() < 1e-9 && (y2 - y).abs() < 1e-9);
            }
            // the array's centre pixel is the array's centre
            let (cx, cy) = fp.to_focal_plane(k, 983.5, 983.5);
            assert_eq!((cx, cy), fp.centre(k));
        }
        // array 1 is turned by 90°: its +x runs along the focal plane's +y
        let (a, b) = (
            fp.to_focal_plane(1, 10.0, 0.0),
            fp.to_focal_plane(1, 11.0, 0.0),
        );
        assert!((b.0 - a.0).abs() < 1e-12 && (b.1 - a.1 - 1.0).abs() < 1e-12);
        // array 2 by 180°: its +x runs along −x
        let (a, b) = (
            fp.to_focal_plane(2, 10.0, 0.0),
            fp.to_focal_plane(2, 11.0, 0.0),
        );
        assert!((b.0 - a.0 + 1.0).abs() < 1e-12 && (b.1 - a.1).abs() < 1e-12);
    }

    #[test]
    fn positions_fall_on_arrays_borders_gaps_or_nowhere() {
        let fp = jasmine();
        // the optical axis is in the cross-shaped gap
        assert_eq!(fp.locate(0.0, 0.0), Placement::Gap);
        assert_eq!(fp.locate(1100.0, 149.0), Placement::Gap);
        assert_eq!(fp.locate(5000.0, 0.0), Placement::Off);
        let (cx, cy) = fp.centre(3);
        match fp.locate(cx, cy) {
            Placement::Photosensitive { array, x, y } => {
                assert_eq!(array, 3);
                assert!((x - 983.5).abs() < 1e-9 && (y - 983.5).abs() < 1e-9);
            }
            p => panic!("{p:?}"),
        }
        // 3 px inside the edge of array 0 is border (the 8-px border sees no light)
        let (fx, fy) = fp.to_focal_plane(0, 3.0, 900.0);
        assert!(matches!(
            fp.locate(fx, fy),
            Placement::Border { array: 0, .. }
        ));
        // the first photosensitive pixel is pixel 8
        let (fx, fy) = fp.to_focal_plane(0, 8.0, 900.0);
        assert!(matches!(
            fp.locate(fx, fy),
            Placement::Photosensitive { array: 0, .. }
        ));
    }

    #[test]
    fn each_array_wcs_agrees_with_the_focal_plane_geometry() {
        // a star's focal-plane position from one WCS of the whole plane, then its array and pixel: the same
        // as the array's own WCS says (rotation conventions of the geometry and the WCS agree)
        let fp = jasmine();
        let p = Pointing {
            ra_deg: 266.4168,
            dec_deg: -29.0078,
            pa_deg: 25.0,
        };
        let scale = 472.1;
        let plane = ArrayWcs::new(&p, 0.0, scale, [0.0, 0.0], [1, 1], None).expect("plane");
        let arrays: Vec<ArrayWcs> = (0..4)
            .map(|k| fp.array_wcs(k, &p, scale, None).expect("array"))
            .collect();
        let mut seen = [0usize; 4];
        for i in 0..15 {
            for j in 0..15 {
                let (ra, dec) = (
                    p.ra_deg + (i as f64 - 7.0) * 0.06,
                    p.dec_deg + (j as f64 - 7.0) * 0.05,
                );
                let (fx, fy) = plane.sky_to_pixel(ra, dec).expect("on the plane");
                if let Placement::Photosensitive { array, x, y } = fp.locate(fx, fy) {
                    seen[array] += 1;
                    let (xa, ya) = arrays[array].sky_to_pixel(ra, dec).expect("a pixel");
                    assert!(
                        (xa - x).abs() < 1e-6 && (ya - y).abs() < 1e-6,
                        "array {array}: geometry ({x}, {y}), WCS ({xa}, {ya})"
                    );
                }
            }
        }
        assert!(
            seen.iter().all(|&n| n > 5),
            "every array sees stars: {seen:?}"
        );
    }

    #[test]
    fn a_distortion_turned_into_each_array_agrees_with_the_plane() {
        // a distortion given in focal-plane axes (Sip::rotated into each array's axes): the array's WCS puts
        // a sky position on the same focal-plane point as one distorted WCS of the whole plane
        let fp = jasmine();
        let p = Pointing::GALACTIC_CENTRE;
        let scale = 472.1;
        let k3 = 3.7e-11; // 1 px of radial distortion at 3000 px from the axis
        let sip = Sip {
            a: crate::sky::wcs::SipPolynomial {
                terms: vec![(3, 0, k3), (1, 2, k3), (2, 0, 2e-8), (0, 2, -1e-8)],
            },
            b: crate::sky::wcs::SipPolynomial {
                terms: vec![(2, 1, k3), (0, 3, k3), (1, 1, 3e-8)],
            },
        };
        let plane = ArrayWcs::new(&p, 0.0, scale, [0.0, 0.0], [4236, 4236], Some(sip.clone()))
            .expect("plane");
        let mut seen = [0usize; 4];
        for k in 0..4 {
            let w = fp
                .array_wcs(k, &p, scale, Some(sip.rotated(fp.rotations_deg[k])))
                .expect("array");
            for (x, y) in [
                (10.0, 20.0),
                (1900.0, 40.0),
                (983.5, 983.5),
                (30.0, 1950.0),
                (1960.0, 1960.0),
            ] {
                let (fx, fy) = fp.to_focal_plane(k, x, y);
                let a = w.pixel_to_sky(x, y).expect("sky");
                let b = plane.pixel_to_sky(fx, fy).expect("sky");
                let d_mas = ((a.0 - b.0) * p.dec_deg.to_radians().cos()).hypot(a.1 - b.1) * 3.6e6;
                assert!(d_mas < 1e-3, "array {k} ({x}, {y}): {d_mas} mas apart");
                seen[k] += 1;
            }
        }
        assert_eq!(seen, [5; 4]);
        // the identity turn changes nothing; four quarter turns come back
        assert_eq!(sip.rotated(0.0), sip);
        let back = sip.rotated(90.0).rotated(90.0).rotated(90.0).rotated(90.0);
        for (x, y) in [(100.0, -300.0), (-2000.0, 1500.0)] {
            assert!((back.a.eval(x, y) - sip.a.eval(x, y)).abs() < 1e-12);
            assert!((back.b.eval(x, y) - sip.b.eval(x, y)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_bad_layout_is_named() {
        let mut fp = jasmine();
        fp.rotations_deg[2] = 45.0;
        assert!(
            fp.validate()
                .expect_err("rotation")
                .contains("rotations_deg[2]")
        );
        let mut fp = jasmine();
        fp.gap_px = -1.0;
        assert!(fp.validate().expect_err("gap").contains("gap_px"));
    }
}
