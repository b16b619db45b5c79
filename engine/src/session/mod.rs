//! The engine session: the long-lived object every front end holds (the CLI, the explorer's worker, the
//! experiment, the benchmarks, the sweeps, the Python module). It owns what is expensive and shareable —
//! PSF banks, pixel kernels, the integrator (CPU or GPU, chosen once per backend with its message) and the
//! last few datasets' simulators — and hands out [`Simulator`]s built from them.
//!
//! Every stage is bit-identical whatever is cached: a simulator from a session gives the same image as one
//! built alone ([`Simulator::new`]).

pub mod source;

pub use source::{Source, SourceError, SourceProducts, analysis_image};

use crate::analysis::countermeasures::{Countermeasure, Plan};
use crate::analysis::crowding;
use crate::analysis::pipeline::{Supplied, analyse_crowded_image};
use crate::analysis::{AnalysisError, analyse_image};
use crate::config::{Backend, Config};
use crate::integrate::Integrator;
use crate::integrate::kernel::KernelCache;
use crate::io::analysis_input::AnalysisInput;
use crate::optics::PsfBank;
use crate::scoring::image::{Scored, score};
use crate::simulate::{FocalPlaneSimulator, SimError, Simulator};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

/// At most this many PSF banks (distinct instrument/optics/band) are kept; the oldest goes first.
pub const MAX_BANKS: usize = 8;
/// The banks kept hold at most this much memory together, bytes ([`PsfBank::bytes`]; the newest is always
/// kept). A sequence under the as-built focus breathing has a new wavefront, so a new bank, at every exposure
/// (≈ 1 GB each on the bulge): eight of them filled this machine's 24 GB.
pub const MAX_BANK_BYTES: usize = 2 << 30;
/// At most this many simulators (distinct datasets) are kept; the oldest goes first.
pub const MAX_SIMULATORS: usize = 4;

/// The engine session.
#[derive(Default)]
pub struct Session {
    integrators: Mutex<HashMap<Backend, Integrator>>,
    notes: Mutex<Vec<String>>,
    banks: Mutex<Vec<Arc<PsfBank>>>,
    /// The PSF banks' byte budget: [`MAX_BANK_BYTES`] unless set ([`Session::with_bank_bytes`]).
    bank_bytes: Option<usize>,
    kernels: Arc<KernelCache>,
    simulators: Mutex<Vec<(String, Arc<Simulator>)>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The key of a dataset's simulation: its configuration without the analysis knobs (which no simulated
/// image depends on).
pub fn simulation_key(cfg: &Config) -> String {
    let mut c = cfg.clone();
    c.analysis = Default::default();
    c.hash_hex()
}

impl Session {
    pub fn new() -> Self {
        Self::default()
    }

    /// The integrator of a backend, chosen on first use ([`Integrator::choose`]); when the CPU stands in
    /// for a GPU the reason is queued once for [`Session::take_notes`].
    pub fn integrator(&self, backend: Backend) -> Integrator {
        let mut m = lock(&self.integrators);
        if let Some(i) = m.get(&backend) {
            return i.clone();
        }
        let (i, note) = Integrator::choose(backend);
        if let Some(n) = note {
            lock(&self.notes).push(n);
        }
        m.insert(backend, i.clone());
        i
    }

    /// Messages about the backend not yet shown (each is returned once).
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut *lock(&self.notes))
    }

    /// The PSF bank that serves `cfg` (shared by every configuration with the same instrument, optics and
    /// band).
    pub fn bank(&self, cfg: &Config) -> Arc<PsfBank> {
        let mut v = lock(&self.banks);
        if let Some(b) = v.iter().find(|b| b.serves(cfg)) {
            return b.clone();
        }
        // a configuration that differs in its wavefront alone shares the PSFs (the focus breathing)
        let b = Arc::new(
            v.iter()
                .rev()
                .find_map(|b| b.sharing(cfg))
                .unwrap_or_else(|| PsfBank::new(cfg)),
        );
        if v.len() >= MAX_BANKS {
            v.remove(0);
        }
        // the older banks go first while all of them, the new one's future tables aside, pass the budget
        let budget = self.bank_bytes.unwrap_or(MAX_BANK_BYTES);
        // (banks sharing their PSFs counted once; the new bank's shared PSFs count)
        let held = |v: &[Arc<PsfBank>]| -> usize {
            let mut distinct: Vec<&Arc<PsfBank>> = Vec::new();
            for x in v.iter().chain([&b]) {
                if !distinct.iter().any(|d| d.shares_with(x)) {
                    distinct.push(x);
                }
            }
            distinct.iter().map(|d| d.bytes()).sum()
        };
        while !v.is_empty() && held(&v) > budget {
            v.remove(0);
        }
        v.push(b.clone());
        b
    }

    /// The same session keeping at most `bytes` of PSF banks (the newest always).
    pub fn with_bank_bytes(mut self, bytes: usize) -> Self {
        self.bank_bytes = Some(bytes);
        self
    }

    /// PSF banks kept.
    pub fn banks_kept(&self) -> usize {
        lock(&self.banks).len()
    }

    /// A new simulator of `cfg` (validated) on the session's bank, kernels and integrator: the one array of
    /// a single-array focal plane ([`Session::new_focal_plane`]).
    pub fn new_simulator(&self, cfg: &Config) -> Result<Simulator, SimError> {
        crate::simulate::check_single_array(cfg)?;
        self.new_focal_plane(cfg)?.into_single()
    }

    /// New simulators of every array of `cfg`'s focal plane (validated), on the session's bank, kernels and
    /// integrator.
    pub fn new_focal_plane(&self, cfg: &Config) -> Result<FocalPlaneSimulator, SimError> {
        cfg.validate()?;
        // the bank of the instrument as built, which takes the images
        let bank = self.bank(&crate::instrument::realise(cfg)?);
        FocalPlaneSimulator::build(
            cfg,
            bank,
            self.kernels.clone(),
            self.integrator(cfg.fidelity.backend),
        )
    }

    /// The simulator of `cfg`, reused while only the analysis knobs change (the last
    /// [`MAX_SIMULATORS`] datasets are kept). Its `cfg.analysis` is the one it was built with: pass the
    /// analysis configuration to the pipeline explicitly.
    pub fn simulator(&self, cfg: &Config) -> Result<Arc<Simulator>, SimError> {
        let key = simulation_key(cfg);
        if let Some((_, s)) = lock(&self.simulators).iter().find(|(k, _)| *k == key) {
            return Ok(s.clone());
        }
        let s = Arc::new(self.new_simulator(cfg)?);
        let mut v = lock(&self.simulators);
        if v.len() >= MAX_SIMULATORS {
            v.remove(0);
        }
        v.push((key, s.clone()));
        Ok(s)
    }

    /// Whether the simulator of `cfg` is cached (no PSF, ACE series or scene to compute).
    pub fn has_simulator(&self, cfg: &Config) -> bool {
        let key = simulation_key(cfg);
        lock(&self.simulators).iter().any(|(k, _)| *k == key)
    }

    /// Whether the PSFs of `cfg` are at hand.
    pub fn has_bank(&self, cfg: &Config) -> bool {
        lock(&self.banks).iter().any(|b| b.serves(cfg))
    }

    /// Compute every PSF the simulator will ask its bank for (so that the timing of its first exposure
    /// shows integration alone).
    pub fn warm(&self, sim: &Simulator) {
        for s in &sim.stars {
            sim.psf_for(s);
        }
        if sim.stars.is_empty() {
            let bank = sim.bank();
            bank.get(sim.cfg.scene.j_minus_h, &bank.centre_key());
        }
    }
}

impl Session {
    /// The analysis pipeline on one image read for analysis (`jsim analyze`, the Python module's
    /// `Session.analyze`): `cfg` gives the analysis knobs — crowding among them — (`epsf_zones` overrides its
    /// zones); the
    /// calibration is what the instrument supplied beside the image (`input`'s products and headers), never
    /// the image's CONFIG or TRUTH. The oracles are controls asked for by name: `exact-epsf` asks the
    /// image's own simulation (its CONFIG) for the exact ePSF, `plate-*@oracle` takes the given truth's
    /// positions as its reference. The truth, when given, then scores the result
    /// ([`crate::scoring::image`]); without one every accuracy is absent.
    pub fn analyze_input(
        &self,
        cfg: &Config,
        input: &AnalysisInput,
        epsf_zones: Option<usize>,
        countermeasure: Countermeasure,
    ) -> Result<Scored, SourceError> {
        let mut analysis_cfg = cfg.analysis.clone();
        if let Some(z) = epsf_zones {
            analysis_cfg.epsf_zones = z;
        }
        let plan = Plan::new(vec![countermeasure])?;
        let exact = match (&input.provenance, countermeasure) {
            (Some((c, index)), Countermeasure::ExactEpsf) => {
                let mut c = c.clone();
                c.fidelity.backend = Backend::Cpu;
                c.fidelity.images = index + 1;
                let sim = self.simulator(&c)?;
                let src = Source::new(&sim, *index);
                src.exact_epsf(&analysis_cfg)?
            }
            _ => None,
        };
        let truth = input.truth.as_deref();
        let oracle = source::oracle_reference(&plan, truth);
        let reference_px = input
            .reference
            .as_deref()
            .map(crate::analysis::crowded::forced::positions_px);
        let supplied = Supplied {
            reference: reference_px.as_deref(),
            catalogue: input.reference.as_deref(),
            model_psf: input.model_psf.as_ref(),
            model_psf_terms: input.model_psf_terms.as_deref(),
            telemetry: input.telemetry.as_ref(),
            readout: input.readout,
            exact_epsf: exact.as_ref(),
            oracle_reference: oracle.as_deref(),
            ..Default::default()
        };
        let res = if crowding::is_crowded(&input.img, &analysis_cfg, analysis_cfg.crowding).0 {
            let r = analyse_crowded_image(&input.img, &analysis_cfg, &plan, &supplied)?;
            if r.global.stars.is_empty() {
                return Err(AnalysisError::NoStars(analysis_cfg.crowded_detect_sigma).into());
            }
            r
        } else {
            analyse_image(&input.img, &analysis_cfg, &plan, &supplied)?
        };
        let analysis = res.into_of(&countermeasure).ok_or_else(|| {
            SourceError::from(AnalysisError::NotApplicable {
                countermeasure: countermeasure.to_string(),
            })
        })?;
        // a countermeasure referenced to the catalogue gives positions in the catalogue's (the header's) frame:
        // scored against the truth in that frame when the file carries it
        let scored_truth = if countermeasure.is_catalogue_plate() {
            input.truth_in_header.as_deref().or(truth)
        } else {
            truth
        };
        Ok(score(&analysis, scored_truth, input.img.plate_scale_mas))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulators_are_shared_while_only_the_analysis_changes() {
        let s = Session::new();
        let mut cfg = Config::default();
        cfg.fidelity.backend = Backend::Cpu;
        cfg.ace.case = crate::config::AceCase::Gaussian;
        cfg.scene.grid_n = 2;
        cfg.optics.pupil_samples = 64;
        let a = s.simulator(&cfg).expect("sim");
        cfg.analysis.epsf_iterations += 1;
        let b = s.simulator(&cfg).expect("sim");
        assert!(Arc::ptr_eq(&a, &b));
        cfg.scene.mag_hw += 1.0;
        let c = s.simulator(&cfg).expect("sim");
        assert!(!Arc::ptr_eq(&a, &c));
        // a different magnitude shares the optics: one bank
        assert!(Arc::ptr_eq(&a.bank(), &c.bank()));
        assert!(s.take_notes().is_empty());
    }

    /// The banks kept stay within the session's memory budget, the newest always kept: with a budget
    /// smaller than one bank, a second optics drops the first bank (the count limit alone kept it).
    #[test]
    fn the_banks_kept_stay_within_the_memory_budget() {
        let cfg = crate::testkit::coarse_psf_config(32, 2, 3);
        let s = Session::new();
        let a = s.bank(&cfg);
        a.get(2.0, &a.centre_key());
        let one = a.bytes();
        assert!(one > 0);
        let mut other = cfg.clone();
        other.optics.psf_radius_px = 4;
        s.bank(&other);
        assert_eq!(s.banks_kept(), 2, "the default budget keeps both");
        // a focus of its own: a bank of its own configuration, sharing the PSFs
        let mut focus = cfg.clone();
        focus.optics.fringe = vec![0.0, 0.0, 0.0, 0.01];
        let f = s.bank(&focus);
        assert!(f.serves(&focus) && f.shares_with(&a) && !f.shares_with(&s.bank(&other)));
        let s = Session::new().with_bank_bytes(one - 1);
        let a = s.bank(&cfg);
        a.get(2.0, &a.centre_key());
        s.bank(&other);
        assert_eq!(
            s.banks_kept(),
            1,
            "the first bank's {one} B pass the budget"
        );
        assert!(s.bank(&other).serves(&other));
        // the newest is kept however large
        let s = Session::new().with_bank_bytes(1);
        let a = s.bank(&cfg);
        a.get(2.0, &a.centre_key());
        assert!(Arc::ptr_eq(&a, &s.bank(&cfg)));
    }
}
