//! Optical PSF: pupil (aperture, central obstruction, Y spiders), Fringe Zernike wavefront error,
//! polychromatic PSF weighted by the star's photon spectrum (SPEC §2).
//!
//! [`PsfBank`] computes each distinct PSF once — keyed by colour and field zone — and shares it.

pub mod airy;
pub mod psf;
pub mod pupil;
pub mod spectrum;
pub mod zernike;

use crate::config::{Band, Config, Instrument, Optics, WfeUnit};
use psf::{PsfRequest, PsfTable};
use pupil::PupilGeometry;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Fringe coefficients at the reference (`optics.fringe`) converted to OPD in µm.
pub fn to_um(optics: &Optics, coeffs: &[f64]) -> Vec<f64> {
    let f = match optics.wfe_unit {
        WfeUnit::Waves => optics.reference_wavelength_um,
        WfeUnit::Um => 1.0,
    };
    let mut v: Vec<f64> = coeffs.iter().map(|c| c * f).collect();
    v.resize(zernike::N_FRINGE, 0.0);
    v
}

/// Fringe coefficients (µm OPD) at a field position: `optics.fringe` when there is no field table, else the
/// inverse-distance-squared weighted mean of the table rows (exact at a table point).
pub fn fringe_um_at(optics: &Optics, x_px: f64, y_px: f64) -> Vec<f64> {
    if optics.field_table.is_empty() {
        return to_um(optics, &optics.fringe);
    }
    let mut acc = vec![0.0; zernike::N_FRINGE];
    let mut wsum = 0.0;
    for row in &optics.field_table {
        let d2 = (row.x_px - x_px).powi(2) + (row.y_px - y_px).powi(2);
        if d2 < 1e-12 {
            return to_um(optics, &row.fringe);
        }
        let w = 1.0 / d2;
        for (a, c) in acc.iter_mut().zip(to_um(optics, &row.fringe)) {
            *a += w * c;
        }
        wsum += w;
    }
    acc.iter().map(|a| a / wsum).collect()
}

/// Key of a cached PSF: colour in milli-magnitudes and field zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct BankKey {
    j_minus_h_milli: i64,
    zone: usize,
    /// 0 for the main PSF; the outer radius (px) for a halo table.
    halo_px: usize,
}

/// Computes each distinct PSF once and shares it between stars and images.
pub struct PsfBank {
    instrument: Instrument,
    optics: Optics,
    band: Band,
    cache: Mutex<HashMap<BankKey, Arc<PsfTable>>>,
}

impl PsfBank {
    pub fn new(cfg: &Config) -> Self {
        Self {
            instrument: cfg.instrument.clone(),
            optics: cfg.optics.clone(),
            band: cfg.band.clone(),
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// Whether this bank's PSFs are valid for `cfg` (same instrument, optics and band).
    pub fn serves(&self, cfg: &Config) -> bool {
        self.instrument == cfg.instrument && self.optics == cfg.optics && self.band == cfg.band
    }

    /// Number of field zones (1 without a field table).
    pub fn zones(&self) -> usize {
        if self.optics.field_table.is_empty() {
            1
        } else {
            self.optics.field_zones * self.optics.field_zones
        }
    }

    /// Zone of a detector position.
    pub fn zone_of(&self, x_px: f64, y_px: f64) -> usize {
        if self.optics.field_table.is_empty() {
            return 0;
        }
        let nz = self.optics.field_zones;
        let size = self.instrument.detector_px as f64 / nz as f64;
        let zx = ((x_px / size).floor().max(0.0) as usize).min(nz - 1);
        let zy = ((y_px / size).floor().max(0.0) as usize).min(nz - 1);
        zy * nz + zx
    }

    /// Centre of a zone (pixels): where its WFE is interpolated.
    pub fn zone_centre(&self, zone: usize) -> (f64, f64) {
        let nz = self.optics.field_zones.max(1);
        let size = self.instrument.detector_px as f64 / nz as f64;
        (
            ((zone % nz) as f64 + 0.5) * size,
            ((zone / nz) as f64 + 0.5) * size,
        )
    }

    /// The PSF for a colour and zone (computed on first use).
    pub fn get(&self, j_minus_h: f64, zone: usize) -> Arc<PsfTable> {
        self.table(j_minus_h, zone, 0)
    }

    /// The PSF halo for a colour and zone: the same PSF at 2 cells per pixel out to
    /// `psf_radius_px + halo_radius_px`, with the square the main table covers set to zero, so the two add
    /// up to the PSF over the larger field (light beyond the main table is no longer dropped).
    pub fn halo(&self, j_minus_h: f64, zone: usize, halo_radius_px: usize) -> Arc<PsfTable> {
        self.table(j_minus_h, zone, halo_radius_px.max(1))
    }

    fn table(&self, j_minus_h: f64, zone: usize, halo_px: usize) -> Arc<PsfTable> {
        let key = BankKey {
            j_minus_h_milli: (j_minus_h * 1000.0).round() as i64,
            zone,
            halo_px,
        };
        if let Some(p) = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return p.clone();
        }
        let (zx, zy) = self.zone_centre(zone);
        let mut optics = self.optics.clone();
        if halo_px > 0 {
            optics.psf_oversampling = 2;
            optics.psf_radius_px = self.optics.psf_radius_px + halo_px;
        }
        let req = PsfRequest {
            geometry: PupilGeometry::from_instrument(&self.instrument),
            optics: &optics,
            band: &self.band,
            pixel_rad: self.instrument.pixel_rad(),
            j_minus_h: key.j_minus_h_milli as f64 / 1000.0,
            fringe_um: fringe_um_at(&self.optics, zx, zy),
        };
        let mut table = psf::polychromatic(&req);
        if halo_px > 0 {
            // cells inside the main table's square (its bilinear ramp ends one main cell beyond its edge)
            let inner = (self.optics.psf_radius_px * 2) as i64;
            let n = table.n();
            let h = table.half_cells as i64;
            for iy in 0..n {
                for ix in 0..n {
                    if (ix as i64 - h).abs() <= inner && (iy as i64 - h).abs() <= inner {
                        table.data[iy * n + ix] = 0.0;
                    }
                }
            }
        }
        let table = Arc::new(table);
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, table.clone());
        table
    }

    /// Number of PSFs computed so far.
    pub fn len(&self) -> usize {
        self.cache.lock().map(|c| c.len()).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Monochromatic PSF of the configured optics at λ (for FWHM and validation), on the configured grid.
pub fn monochromatic(cfg: &Config, lambda_um: f64) -> PsfTable {
    let geom = PupilGeometry::from_instrument(&cfg.instrument);
    let os = cfg.optics.psf_oversampling;
    let half = cfg.optics.psf_radius_px * os;
    let cell = cfg.instrument.pixel_rad() / os as f64;
    let pupil = pupil::Pupil::sample(&geom, cfg.optics.pupil_samples);
    let opd = psf::opd_map_m(
        &pupil,
        geom.radius_m,
        &to_um(&cfg.optics, &cfg.optics.fringe),
    );
    PsfTable {
        oversampling: os,
        half_cells: half,
        data: psf::mft_psf(&pupil, &opd, lambda_um * 1e-6, cell, half),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_table_interpolation_is_exact_at_nodes() {
        let mut o = Optics::default();
        o.wfe_unit = WfeUnit::Um;
        o.field_table = vec![
            crate::config::FieldWfe {
                x_px: 0.0,
                y_px: 0.0,
                fringe: vec![0.0, 0.0, 0.0, 0.1],
            },
            crate::config::FieldWfe {
                x_px: 1000.0,
                y_px: 0.0,
                fringe: vec![0.0, 0.0, 0.0, 0.3],
            },
        ];
        assert!((fringe_um_at(&o, 0.0, 0.0)[3] - 0.1).abs() < 1e-12);
        assert!((fringe_um_at(&o, 1000.0, 0.0)[3] - 0.3).abs() < 1e-12);
        assert!((fringe_um_at(&o, 500.0, 0.0)[3] - 0.2).abs() < 1e-12);
    }

    #[test]
    fn bank_reuses_psfs() {
        let mut cfg = Config::default();
        cfg.optics.psf_oversampling = 4;
        cfg.optics.psf_radius_px = 4;
        cfg.optics.pupil_samples = 64;
        cfg.band.wavelength_step_um = 0.2;
        let bank = PsfBank::new(&cfg);
        let a = bank.get(2.0, 0);
        let b = bank.get(2.0, 0);
        assert!(Arc::ptr_eq(&a, &b));
        let _c = bank.get(1.0, 0);
        assert_eq!(bank.len(), 2);
        assert!(bank.serves(&cfg));
    }
}
