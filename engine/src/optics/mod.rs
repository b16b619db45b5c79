//! Optical PSF: pupil (aperture, central obstruction, Y spiders), Fringe Zernike wavefront error,
//! polychromatic PSF weighted by the star's photon spectrum (SPEC §2).
//!
//! [`PsfBank`] computes each distinct PSF once — keyed by colour and field zone — and shares it.

pub mod airy;
pub mod field;
pub mod psf;
pub mod pupil;
pub mod spectrum;
pub mod zernike;

use crate::config::{Band, Config, Instrument, OpdSign, Optics, WfeUnit};
use psf::{PsfRequest, PsfTable};
use pupil::PupilGeometry;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Fringe coefficients at the reference (`optics.fringe`) converted to OPD in µm, in the engine's sign
/// (`optics.opd_sign`: image along +∇W).
pub fn to_um(optics: &Optics, coeffs: &[f64]) -> Vec<f64> {
    let unit = match optics.wfe_unit {
        WfeUnit::Waves => optics.reference_wavelength_um,
        WfeUnit::Um => 1.0,
    };
    let f = match optics.opd_sign {
        OpdSign::ImageAlongGradient => unit,
        OpdSign::ImageAgainstGradient => -unit,
    };
    let mut v: Vec<f64> = coeffs.iter().map(|c| c * f).collect();
    v.resize(zernike::N_FRINGE, 0.0);
    v
}

/// A wavefront of `nm_rms` nanometres rms in Fringe term `j` (1-based) as a coefficient in the configuration's
/// unit and sign ([`to_um`]'s inverse; the term's rms over the unit disk is `√zernike::fringe_norm(j)`).
pub fn coefficient_of_nm_rms(optics: &Optics, j: usize, nm_rms: f64) -> f64 {
    nm_rms / zernike::fringe_norm(j).sqrt() * 1e-3 / to_um(optics, &[1.0])[0]
}

/// Add `value` to Fringe term `j` (1-based) of a coefficient list, lengthening it with zeros as needed.
pub fn add_term(fringe: &mut Vec<f64>, j: usize, value: f64) {
    if fringe.len() < j {
        fringe.resize(j, 0.0);
    }
    fringe[j - 1] += value;
}

/// A PSF's place in the field: its wavefront (Fringe coefficients, µm OPD), exactly (`Exact`, bit
/// patterns) or rounded to the bank's tolerance (`Rounded`, multiples of `optics.field_wfe_step_nm`), so that
/// stars whose interpolated wavefronts round alike share one PSF.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum FieldKey {
    Exact(Vec<u64>),
    Rounded(Vec<i64>),
}

/// Key of a cached PSF: colour in milli-magnitudes and its wavefront.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct BankKey {
    j_minus_h_milli: i64,
    field: FieldKey,
    /// 0 for the main PSF; the outer radius (px) for a halo table.
    halo_px: usize,
}

/// Computes each distinct PSF once and shares it between stars and images.
///
/// A PSF depends on the instrument, the band and the optics, and on the wavefront only through its key
/// ([`FieldKey`]: the coefficients themselves). Banks whose configurations differ in their wavefront alone
/// (`optics.fringe`, `optics.field_table`: the exposures of a sequence under the as-built focus breathing)
/// therefore share one [`PsfStore`] ([`PsfBank::serving`]): an exposure whose wavefront rounds to one already
/// seen takes its PSFs as they are.
pub struct PsfBank {
    instrument: Instrument,
    optics: Optics,
    band: Band,
    /// The field table as a grid (none: one wavefront everywhere).
    grid: Option<field::FieldGrid>,
    store: Arc<PsfStore>,
    /// Memory the kept monochromatic sets may hold ([`PsfBank::MONO_CACHE_BYTES`] unless a test lowers it).
    mono_cache_bytes: usize,
}

/// The PSFs of banks that differ in their wavefront alone, keyed by colour and wavefront.
#[derive(Default)]
struct PsfStore {
    /// Each table with the order it was made in (the oldest unheld go first past [`PsfBank::TABLE_BYTES`]).
    cache: Mutex<HashMap<BankKey, (u64, Arc<PsfTable>)>>,
    made: std::sync::atomic::AtomicU64,
    /// The monochromatic sets most recently used, newest last, at most [`PsfBank::MONO_CACHE_BYTES`]
    /// together (always the newest one): a new colour of a known wavefront costs one weighted sum.
    mono: Mutex<Vec<(MonoKey, Arc<psf::MonochromaticSet>)>>,
    /// Monochromatic sets computed so far (a set is the costly part of a PSF: one MFT per wavelength).
    mono_built: std::sync::atomic::AtomicUsize,
}

/// Key of a monochromatic set: the wavefront and the table's extent (0 for the main PSF, the halo radius).
#[derive(Debug, Clone, PartialEq, Eq)]
struct MonoKey {
    field: FieldKey,
    halo_px: usize,
}

impl PsfBank {
    /// Memory the kept monochromatic sets may hold (one set of the default optics: 61 × 417² cells, 85 MB).
    pub const MONO_CACHE_BYTES: usize = 400 << 20;
    /// Memory a store's PSF tables may hold before the oldest that no one else holds go (one table of the
    /// default optics: 417² cells, 1.4 MB; the as-built bulge's 279 colour × zone PSFs and their halos, ≈ 0.6
    /// GB, are one exposure's).
    pub const TABLE_BYTES: usize = 1 << 30;

    pub fn new(cfg: &Config) -> Self {
        Self::with_store(cfg, Arc::new(PsfStore::default()))
    }

    fn with_store(cfg: &Config, store: Arc<PsfStore>) -> Self {
        Self {
            instrument: cfg.instrument.clone(),
            optics: cfg.optics.clone(),
            band: cfg.band.clone(),
            // a validated configuration's table is a grid; an invalid one falls back to `fringe`
            grid: field::grid_of(&cfg.optics).ok().flatten(),
            store,
            mono_cache_bytes: Self::MONO_CACHE_BYTES,
        }
    }

    /// A bank of `cfg` sharing this bank's PSFs, when `cfg` differs from this bank's configuration in its
    /// wavefront alone (`optics.fringe`, `optics.field_table`); `None` otherwise.
    pub fn sharing(&self, cfg: &Config) -> Option<Self> {
        let rest = |o: &Optics| Optics {
            fringe: Vec::new(),
            field_table: Vec::new(),
            ..o.clone()
        };
        (self.instrument == cfg.instrument
            && self.band == cfg.band
            && rest(&self.optics) == rest(&cfg.optics))
        .then(|| Self {
            mono_cache_bytes: self.mono_cache_bytes,
            ..Self::with_store(cfg, self.store.clone())
        })
    }

    /// Whether two banks share their PSFs.
    pub fn shares_with(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.store, &other.store)
    }

    /// The same bank keeping at most `bytes` of monochromatic sets (the newest always).
    pub fn with_mono_cache_bytes(mut self, bytes: usize) -> Self {
        self.mono_cache_bytes = bytes;
        self
    }

    /// Compute the PSFs of `wanted` (colour, wavefront) not yet in the bank, wavefront by wavefront: each
    /// wavefront's monochromatic set is computed once and serves all its colours, however the stars asking
    /// for them are ordered (asked star by star, a field of more wavefronts than the kept sets recomputed a
    /// set for nearly every new colour). The colours of one wavefront are summed in parallel.
    pub fn prepare(&self, wanted: impl IntoIterator<Item = (f64, FieldKey)>, halo_px: usize) {
        use rayon::prelude::*;
        let mut order: Vec<FieldKey> = Vec::new();
        let mut colours: HashMap<FieldKey, Vec<f64>> = HashMap::new();
        {
            let cache = self.store.cache.lock().unwrap_or_else(|e| e.into_inner());
            for (j_minus_h, field) in wanted {
                let key = BankKey {
                    j_minus_h_milli: (j_minus_h * 1000.0).round() as i64,
                    field,
                    halo_px,
                };
                if cache.contains_key(&key) {
                    continue;
                }
                let list = colours.entry(key.field.clone()).or_insert_with(|| {
                    order.push(key.field.clone());
                    Vec::new()
                });
                let c = key.j_minus_h_milli as f64 / 1000.0;
                if !list.contains(&c) {
                    list.push(c);
                }
            }
        }
        for field in order {
            let list = &colours[&field];
            // the first colour computes the set; the others find it kept
            self.table(list[0], &field, halo_px);
            list[1..].par_iter().for_each(|&c| {
                self.table(c, &field, halo_px);
            });
        }
    }

    /// Monochromatic sets computed so far.
    pub fn monochromatic_sets_built(&self) -> usize {
        self.store
            .mono_built
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    /// `bank` when it serves `cfg`; else a bank of `cfg` sharing its PSFs when only the wavefront differs
    /// ([`PsfBank::sharing`]); else a fresh bank for `cfg`.
    pub fn serving(bank: Arc<Self>, cfg: &Config) -> Arc<Self> {
        if bank.serves(cfg) {
            bank
        } else {
            Arc::new(bank.sharing(cfg).unwrap_or_else(|| Self::new(cfg)))
        }
    }

    /// Whether this bank's PSFs are valid for `cfg` (same instrument, optics and band).
    pub fn serves(&self, cfg: &Config) -> bool {
        self.instrument == cfg.instrument && self.optics == cfg.optics && self.band == cfg.band
    }

    /// The wavefront key of a detector position: `optics.fringe` exactly without a field table, else the
    /// table interpolated to (x, y) and rounded to `optics.field_wfe_step_nm` (exact when it is 0).
    pub fn field_key(&self, x_px: f64, y_px: f64) -> FieldKey {
        // a zone's stars take the wavefront at the zone's centre (`optics.field_zone_px`)
        let zone = self.optics.field_zone_px as f64;
        let (x_px, y_px) = if zone > 0.0 {
            let centre = |v: f64| ((v / zone).floor() + 0.5) * zone;
            (centre(x_px), centre(y_px))
        } else {
            (x_px, y_px)
        };
        let coeffs = match &self.grid {
            None => {
                return FieldKey::Exact(
                    to_um(&self.optics, &self.optics.fringe)
                        .iter()
                        .map(|c| c.to_bits())
                        .collect(),
                );
            }
            Some(g) => g.at(x_px, y_px),
        };
        let step_um = self.optics.field_wfe_step_nm * 1e-3;
        if step_um > 0.0 {
            FieldKey::Rounded(
                coeffs
                    .iter()
                    .map(|c| (c / step_um).round() as i64)
                    .collect(),
            )
        } else {
            FieldKey::Exact(coeffs.iter().map(|c| c.to_bits()).collect())
        }
    }

    /// The wavefront key at the centre of the detector.
    pub fn centre_key(&self) -> FieldKey {
        let c = self.instrument.detector_px as f64 / 2.0;
        self.field_key(c, c)
    }

    /// The wavefront (µm OPD) a key stands for.
    fn coefficients(&self, key: &FieldKey) -> Vec<f64> {
        match key {
            FieldKey::Exact(bits) => bits.iter().map(|b| f64::from_bits(*b)).collect(),
            FieldKey::Rounded(k) => {
                let step_um = self.optics.field_wfe_step_nm * 1e-3;
                k.iter().map(|v| *v as f64 * step_um).collect()
            }
        }
    }

    /// The PSF for a colour and wavefront (computed on first use).
    pub fn get(&self, j_minus_h: f64, field: &FieldKey) -> Arc<PsfTable> {
        self.table(j_minus_h, field, 0)
    }

    /// The PSF halo for a colour and zone: the same PSF at 2 cells per pixel out to
    /// `psf_radius_px + halo_radius_px`, with the square the main table covers set to zero, so the two add
    /// up to the PSF over the larger field (light beyond the main table is no longer dropped).
    pub fn halo(&self, j_minus_h: f64, field: &FieldKey, halo_radius_px: usize) -> Arc<PsfTable> {
        self.table(j_minus_h, field, halo_radius_px.max(1))
    }

    fn table(&self, j_minus_h: f64, field: &FieldKey, halo_px: usize) -> Arc<PsfTable> {
        let key = BankKey {
            j_minus_h_milli: (j_minus_h * 1000.0).round() as i64,
            field: field.clone(),
            halo_px,
        };
        if let Some((_, p)) = self
            .store
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return p.clone();
        }
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
            fringe_um: self.coefficients(&key.field),
        };
        let set = self.monochromatic_set(
            MonoKey {
                field: key.field.clone(),
                halo_px,
            },
            &req,
        );
        let mut table = psf::polychromatic_from(&set, &self.band, req.j_minus_h);
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
        let order = self
            .store
            .made
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut cache = self.store.cache.lock().unwrap_or_else(|e| e.into_inner());
        cache.insert(key, (order, table.clone()));
        // past the budget the oldest tables no one else holds go (a star job, a kernel in the kernel cache
        // or a caller holding one keeps it): made again identically if asked for again
        let mut bytes = table_bytes(&cache);
        if bytes > Self::TABLE_BYTES {
            let mut unheld: Vec<(u64, BankKey)> = cache
                .iter()
                .filter(|(_, (_, t))| Arc::strong_count(t) == 1)
                .map(|(k, (o, _))| (*o, k.clone()))
                .collect();
            unheld.sort_by_key(|(o, _)| *o);
            for (_, k) in unheld {
                if bytes <= Self::TABLE_BYTES {
                    break;
                }
                if let Some((_, t)) = cache.remove(&k) {
                    bytes -= t.data.len() * 8;
                }
            }
        }
        table
    }

    /// The monochromatic set of a wavefront and extent: kept from an earlier colour, or computed (and kept,
    /// dropping the oldest sets beyond [`Self::MONO_CACHE_BYTES`]).
    fn monochromatic_set(&self, key: MonoKey, req: &PsfRequest<'_>) -> Arc<psf::MonochromaticSet> {
        let lock = || self.store.mono.lock().unwrap_or_else(|e| e.into_inner());
        {
            let mut kept = lock();
            if let Some(i) = kept.iter().position(|(k, _)| *k == key) {
                let entry = kept.remove(i);
                let set = entry.1.clone();
                kept.push(entry);
                return set;
            }
        }
        // computed outside the lock (it runs in parallel over wavelengths)
        let set = Arc::new(psf::monochromatic_set(req));
        self.store
            .mono_built
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut kept = lock();
        kept.push((key, set.clone()));
        while kept.len() > 1
            && kept.iter().map(|(_, s)| s.bytes()).sum::<usize>() > self.mono_cache_bytes
        {
            kept.remove(0);
        }
        set
    }

    /// Memory the bank holds, bytes: its PSF tables and its kept monochromatic sets (shared with the banks
    /// it shares its PSFs with).
    pub fn bytes(&self) -> usize {
        let tables: usize = self
            .store
            .cache
            .lock()
            .map(|c| table_bytes(&c))
            .unwrap_or(0);
        let sets: usize = self
            .store
            .mono
            .lock()
            .map(|m| m.iter().map(|(_, s)| s.bytes()).sum())
            .unwrap_or(0);
        tables + sets
    }

    /// Number of PSFs computed so far.
    pub fn len(&self) -> usize {
        self.store.cache.lock().map(|c| c.len()).unwrap_or(0)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Memory the tables of a store's cache hold, bytes.
fn table_bytes(cache: &HashMap<BankKey, (u64, Arc<PsfTable>)>) -> usize {
    cache.values().map(|(_, t)| t.data.len() * 8).sum()
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

    /// Stars share a PSF when their interpolated wavefronts agree within the tolerance, and get their own
    /// otherwise; without a field table every star shares the one PSF of `optics.fringe`.
    #[test]
    fn the_bank_shares_psfs_by_wavefront_within_the_tolerance() {
        let mut cfg = crate::testkit::coarse_psf_config(64, 4, 4);
        cfg.optics.wfe_unit = WfeUnit::Um;
        // Z7 (coma) from 0 to 0.1 µm across 1000 px: 0.1 nm per px
        cfg.optics.field_table = [
            (0.0, 0.0, 0.0),
            (1000.0, 0.0, 0.1),
            (0.0, 1000.0, 0.0),
            (1000.0, 1000.0, 0.1),
        ]
        .into_iter()
        .map(|(x_px, y_px, z7)| crate::config::FieldWfe {
            x_px,
            y_px,
            fringe: vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, z7],
        })
        .collect();
        cfg.optics.field_wfe_step_nm = 1.0;
        cfg.optics.field_zone_px = 0;
        cfg.validate().expect("valid");
        let bank = PsfBank::new(&cfg);
        // 2 px apart: 0.2 nm, the same 1-nm step; 30 px apart: 3 nm, another PSF
        assert_eq!(bank.field_key(500.0, 10.0), bank.field_key(500.4, 900.0));
        assert_ne!(bank.field_key(500.0, 10.0), bank.field_key(530.0, 10.0));
        let a = bank.get(2.0, &bank.field_key(500.0, 10.0));
        let b = bank.get(2.0, &bank.field_key(500.4, 900.0));
        assert!(Arc::ptr_eq(&a, &b));
        let c = bank.get(2.0, &bank.field_key(530.0, 10.0));
        assert!(!Arc::ptr_eq(&a, &c));
        assert_eq!(bank.len(), 2);
        // the shared PSF is the one of the rounded wavefront: 0.050 µm of coma
        let key = bank.field_key(500.0, 10.0);
        assert!((bank.coefficients(&key)[6] - 0.050).abs() < 1e-12);
        // step 0: exact, one PSF per distinct wavefront
        let mut exact = cfg.clone();
        exact.optics.field_wfe_step_nm = 0.0;
        let bank = PsfBank::new(&exact);
        assert_ne!(bank.field_key(500.0, 10.0), bank.field_key(500.4, 10.0));
        // no table: one wavefront everywhere
        let plain = PsfBank::new(&Config::default());
        assert_eq!(plain.field_key(0.0, 0.0), plain.field_key(1900.0, 1500.0));
        // a table that is not a grid is a named configuration error
        let mut bad = cfg.clone();
        bad.optics.field_table.pop();
        let e = bad.validate().expect_err("3 of 4 nodes").to_string();
        assert!(
            e.contains("optics.field_table") && e.contains("rectangular grid"),
            "{e}"
        );
    }

    /// Banks whose configurations differ in their wavefront alone share their PSFs: a focus that rounds to
    /// the same wavefront key takes the PSF as it is (the same table), another focus gets its own, and a
    /// configuration that differs in anything else (the pupil's sampling) gets a bank of its own.
    #[test]
    fn banks_that_differ_in_their_wavefront_alone_share_their_psfs() {
        let mut cfg = crate::testkit::coarse_psf_config(32, 2, 3);
        cfg.optics.wfe_unit = WfeUnit::Um;
        let with_focus = |z4_um: f64| {
            let mut c = cfg.clone();
            c.optics.field_table = [(0.0, 0.0), (1000.0, 0.0), (0.0, 1000.0), (1000.0, 1000.0)]
                .into_iter()
                .map(|(x_px, y_px)| crate::config::FieldWfe {
                    x_px,
                    y_px,
                    fringe: vec![0.0, 0.0, 0.0, z4_um, 0.0, 0.0, 0.02],
                })
                .collect();
            c
        };
        let a = Arc::new(PsfBank::new(&with_focus(0.010)));
        // 0.2 nm more focus: the same 1-nm key; 5 nm more: another
        let near = with_focus(0.0102);
        let far = with_focus(0.015);
        assert!(!a.serves(&near));
        let b = PsfBank::serving(a.clone(), &near);
        let c = PsfBank::serving(a.clone(), &far);
        assert!(b.shares_with(&a) && c.shares_with(&a) && b.serves(&near) && c.serves(&far));
        let pa = a.get(2.0, &a.field_key(500.0, 500.0));
        assert!(Arc::ptr_eq(&pa, &b.get(2.0, &b.field_key(500.0, 500.0))));
        let pc = c.get(2.0, &c.field_key(500.0, 500.0));
        assert!(!Arc::ptr_eq(&pa, &pc));
        // the shared table is the one a bank of its own computes
        let own = PsfBank::new(&far);
        assert_eq!(own.get(2.0, &own.field_key(500.0, 500.0)).data, pc.data);
        assert_eq!(a.len(), 2);
        let mut coarse = near.clone();
        coarse.optics.pupil_samples = 24;
        assert!(!PsfBank::serving(a.clone(), &coarse).shares_with(&a));
    }

    #[test]
    fn bank_reuses_psfs() {
        let cfg = crate::testkit::coarse_psf_config(64, 4, 4);
        let bank = PsfBank::new(&cfg);
        let k = bank.centre_key();
        let a = bank.get(2.0, &k);
        let b = bank.get(2.0, &k);
        assert!(Arc::ptr_eq(&a, &b));
        let _c = bank.get(1.0, &k);
        assert_eq!(bank.len(), 2);
        assert!(bank.serves(&cfg));
    }
}
