//! Lookup-table distortions of a FITS header: HST's detector-to-image correction (`D2IMDISj = 'Lookup'`,
//! the `D2IMARR` extensions) and the "Paper IV" residual distortion (`CPDISj = 'Lookup'`, the `WCSDVARR`
//! extensions), as astropy's `all_pix2world` applies them (Calabretta et al., draft FITS WCS Paper IV; astropy
//! `wcs/src/distortion.c` and `pipeline.c`).
//!
//! For a 1-based pixel p, the detector correction first moves it, t = p + D2IM(p); the focal-plane offset
//! from the reference pixel is then u = t − CRPIX + SIP(t − CRPIX) + CPDIS(t), which the linear part and the
//! projection turn into RA/Dec. Each table is its own small image with a WCS of its own: an image
//! coordinate p_i lands at table coordinate (0-based) c_i = (p_i − CRVAL_i)/CDELT_i + CRPIX_i − 1, clamped to
//! the table, where the offset is the bilinear interpolation of the four neighbouring table values.

/// One axis's lookup table (a `WCSDVARR` or `D2IMARR` extension): offsets in pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct LookupTable {
    /// Table size, `[NAXIS1, NAXIS2]` (a 1-D table has `NAXIS2` = 1).
    pub naxis: [usize; 2],
    pub crpix: [f64; 2],
    pub crval: [f64; 2],
    pub cdelt: [f64; 2],
    /// Row-major, `naxis[0]` values per row.
    pub data: Vec<f32>,
}

impl LookupTable {
    /// A table, checked: its size matches its values, and its scale is finite and not zero.
    pub fn new(
        naxis: [usize; 2],
        crpix: [f64; 2],
        crval: [f64; 2],
        cdelt: [f64; 2],
        data: Vec<f32>,
    ) -> Result<Self, String> {
        if naxis.contains(&0) || naxis[0] * naxis[1] != data.len() {
            return Err(format!(
                "a lookup table of {}×{} values holds {}",
                naxis[0],
                naxis[1],
                data.len()
            ));
        }
        let finite = crpix
            .iter()
            .chain(&crval)
            .chain(&cdelt)
            .all(|v| v.is_finite());
        if !finite || cdelt.contains(&0.0) {
            return Err(
                "a lookup table's CRPIX, CRVAL and CDELT must be finite, CDELT not 0".into(),
            );
        }
        if !data.iter().all(|v| v.is_finite()) {
            return Err("a lookup table holds a value that is not finite".into());
        }
        Ok(Self {
            naxis,
            crpix,
            crval,
            cdelt,
            data,
        })
    }

    /// The offset (pixels) at the 1-based image pixel `p`: bilinear between the table's four values around
    /// its coordinate there, the coordinate clamped to the table.
    pub fn offset(&self, p: [f64; 2]) -> f64 {
        let c: [f64; 2] = std::array::from_fn(|i| {
            let t = (p[i] - self.crval[i]) / self.cdelt[i] + self.crpix[i] - 1.0;
            t.clamp(0.0, (self.naxis[i] - 1) as f64)
        });
        let at = |x: f64, y: f64| {
            let xi = (x as usize).min(self.naxis[0] - 1);
            let yi = (y as usize).min(self.naxis[1] - 1);
            self.data[yi * self.naxis[0] + xi] as f64
        };
        let (x0, y0) = (c[0].floor(), c[1].floor());
        let (wx, wy) = (c[0] - x0, c[1] - y0);
        at(x0, y0) * (1.0 - wx) * (1.0 - wy)
            + at(x0, y0 + 1.0) * (1.0 - wx) * wy
            + at(x0 + 1.0, y0) * wx * (1.0 - wy)
            + at(x0 + 1.0, y0 + 1.0) * wx * wy
    }
}

/// A header's lookup-table distortions, each axis's table or none.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LookupDistortion {
    /// `D2IMDIS1`, `D2IMDIS2`: the detector-to-image correction, applied first.
    pub det2im: [Option<LookupTable>; 2],
    /// `CPDIS1`, `CPDIS2`: the residual distortion, added with SIP's at the corrected pixel.
    pub cpdis: [Option<LookupTable>; 2],
}

impl LookupDistortion {
    /// Whether it holds any table.
    pub fn is_empty(&self) -> bool {
        self.det2im.iter().chain(&self.cpdis).all(Option::is_none)
    }

    /// t = p + D2IM(p), 1-based pixels.
    pub fn detector_to_image(&self, p: [f64; 2]) -> [f64; 2] {
        std::array::from_fn(|i| p[i] + self.det2im[i].as_ref().map_or(0.0, |t| t.offset(p)))
    }

    /// CPDIS(t), pixels, at the corrected 1-based pixel t.
    pub fn residual(&self, t: [f64; 2]) -> [f64; 2] {
        std::array::from_fn(|i| self.cpdis[i].as_ref().map_or(0.0, |tab| tab.offset(t)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 × 2 table with unit scale placed so that image pixel (1, 1) is its first value: the values at the
    /// nodes, the bilinear mean between them (worked by hand), and the edge values held beyond the table.
    #[test]
    fn a_table_interpolates_between_its_nodes_and_holds_its_edges() {
        let t = LookupTable::new(
            [3, 2],
            [1.0, 1.0],
            [1.0, 1.0],
            [1.0, 1.0],
            vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0],
        )
        .expect("ok");
        assert_eq!(t.offset([1.0, 1.0]), 0.0);
        assert_eq!(t.offset([3.0, 2.0]), 12.0);
        // halfway between (0, 0), (1, 0), (0, 1), (1, 1): (0 + 1 + 10 + 11) / 4
        assert!((t.offset([1.5, 1.5]) - 5.5).abs() < 1e-12);
        // a quarter along x at the second row: 10 + 0.25
        assert!((t.offset([1.25, 2.0]) - 10.25).abs() < 1e-12);
        // beyond the table the nearest edge's value
        assert_eq!(t.offset([-5.0, 1.0]), 0.0);
        assert_eq!(t.offset([9.0, 9.0]), 12.0);
        // a table 4× coarser than the pixels (CDELT 4): image pixel 5 is table node 2 (1-based)
        let coarse = LookupTable::new(
            [3, 1],
            [1.0, 1.0],
            [1.0, 1.0],
            [4.0, 1.0],
            vec![0.0, 4.0, 8.0],
        )
        .expect("ok");
        assert!((coarse.offset([5.0, 1.0]) - 4.0).abs() < 1e-12);
        assert!((coarse.offset([3.0, 1.0]) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_bad_table_is_named() {
        let e =
            LookupTable::new([2, 2], [1.0; 2], [1.0; 2], [1.0; 2], vec![0.0; 3]).expect_err("e");
        assert!(e.contains("2×2 values holds 3"), "{e}");
        let e = LookupTable::new([1, 1], [1.0; 2], [1.0; 2], [0.0, 1.0], vec![0.0]).expect_err("e");
        assert!(e.contains("CDELT not 0"), "{e}");
        let e =
            LookupTable::new([1, 1], [1.0; 2], [1.0; 2], [1.0; 2], vec![f32::NAN]).expect_err("e");
        assert!(e.contains("not finite"), "{e}");
    }
}
