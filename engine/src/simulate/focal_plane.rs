//! The quad focal plane: four [`Simulator`]s, one per array, sharing the PSF bank, the kernels, the
//! integrator and the ACE series — the jitter is one pointing error for the whole telescope, turned into
//! each array's pixel axes — while each array has its own stars, readout (in its own pixel frame, so the
//! rolling pattern points a different way on the sky on each array), flat and noise streams
//! ([`super::array_seed`]).

use super::{ArrayPlace, ArraySpec, Exposure, SimError, Simulator, array_seed, check_memory};
use crate::config::Config;
use crate::integrate::Integrator;
use crate::integrate::kernel::KernelCache;
use crate::optics::PsfBank;
use crate::scene::{self, PlacementCounts};
use std::sync::Arc;

/// The simulators of every array of the configured focal plane.
pub struct FocalPlaneSimulator {
    pub cfg: Config,
    /// One per array, in array order.
    pub arrays: Vec<Simulator>,
    /// Where the scene's stars fell (`None` for a scene in pixels).
    pub counts: Option<PlacementCounts>,
}

/// One exposure of the whole focal plane: the same instant on every array.
#[derive(Debug, Clone)]
pub struct FocalPlaneExposure {
    pub index: usize,
    /// One per array, in array order.
    pub arrays: Vec<Exposure>,
    pub counts: Option<PlacementCounts>,
}

/// A focal plane's arrays: what the product writers take (a single [`Simulator`] is a focal plane of one).
impl AsRef<[Simulator]> for FocalPlaneSimulator {
    fn as_ref(&self) -> &[Simulator] {
        &self.arrays
    }
}

impl AsRef<[Simulator]> for Simulator {
    fn as_ref(&self) -> &[Simulator] {
        std::slice::from_ref(self)
    }
}

impl FocalPlaneSimulator {
    /// Build every array's simulator from shared parts (a fresh PSF bank when `bank` does not serve
    /// `cfg`). A single-array configuration gives one simulator.
    pub fn build(
        cfg: &Config,
        bank: Arc<PsfBank>,
        kernels: Arc<KernelCache>,
        integrator: Integrator,
    ) -> Result<Self, SimError> {
        cfg.validate()?;
        // the instrument as built images the stars (its optics, distortion): each array draws the same one
        let built = crate::instrument::realise(cfg)?;
        let bank = PsfBank::serving(bank, &built);
        let scene = scene::build(&built, &cfg.sky)?;
        check_memory(
            cfg,
            scene.arrays.iter().map(Vec::len).sum(),
            scene.arrays.len(),
        )?;
        let mut arrays: Vec<Simulator> = Vec::with_capacity(scene.arrays.len());
        for (k, stars) in scene.arrays.into_iter().enumerate() {
            let spec = ArraySpec {
                place: ArrayPlace {
                    index: k,
                    rotation_deg: crate::sky::array_rotation_deg(cfg, k),
                    seed: array_seed(cfg.seed, k),
                },
                stars,
            };
            let series = arrays.first().and_then(|a| a.series_arc());
            arrays.push(Simulator::build_array(
                cfg,
                spec,
                scene.counts,
                bank.clone(),
                kernels.clone(),
                integrator.clone(),
                series,
            )?);
        }
        Ok(Self {
            cfg: cfg.clone(),
            arrays,
            counts: scene.counts,
        })
    }

    /// Build alone (fresh bank and kernels, the configured backend).
    pub fn new(cfg: &Config) -> Result<Self, SimError> {
        let (integrator, _) = Integrator::choose(cfg.fidelity.backend);
        Self::build(
            cfg,
            Arc::new(PsfBank::new(cfg)),
            Arc::new(KernelCache::default()),
            integrator,
        )
    }

    /// The one array of a single-array focal plane (an error naming the layout for the quad).
    pub fn into_single(self) -> Result<Simulator, SimError> {
        let mut arrays = self.arrays;
        match (arrays.pop(), arrays.is_empty()) {
            (Some(one), true) => Ok(one),
            _ => Err(SimError::NotSingleArray("a single-array simulator")),
        }
    }

    /// Stars simulated over all arrays (a star near an edge counts on each array its light reaches).
    pub fn star_count(&self) -> usize {
        self.arrays.iter().map(|a| a.stars.len()).sum()
    }

    /// Exposure `index` on every array.
    pub fn exposure(&self, index: usize) -> Result<FocalPlaneExposure, SimError> {
        self.exposure_with(index, &[])
    }

    /// Exposure `index` on every array, array k with the persistence `released_e[k]` (none where the
    /// slice is short): [`Simulator::exposure_with`].
    pub fn exposure_with(
        &self,
        index: usize,
        released_e: &[Vec<f32>],
    ) -> Result<FocalPlaneExposure, SimError> {
        let arrays = self
            .arrays
            .iter()
            .enumerate()
            .map(|(k, a)| a.exposure_with(index, released_e.get(k).map(Vec::as_slice)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(FocalPlaneExposure {
            index,
            arrays,
            counts: self.counts,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A single-array simulator of the quad is a named error, from the session as from `Simulator::new`, and
    /// an invalid quad configuration names its field first (validation before the layout); a single array
    /// of the focal-plane simulator is the single-array simulator.
    #[test]
    fn the_quad_is_not_a_single_array_and_one_array_is() {
        let mut quad = crate::testkit::small_config();
        quad.focal_plane.layout = crate::config::Layout::Quad;
        let single_err = |r: Result<Simulator, SimError>| match r {
            Err(SimError::NotSingleArray(_)) => true,
            Err(e) => panic!("another error: {e}"),
            Ok(_) => false,
        };
        assert!(single_err(Simulator::new(&quad)));
        assert!(single_err(
            crate::session::Session::new().new_simulator(&quad)
        ));
        let mut bad = quad.clone();
        bad.scene.mag_hw = f64::NAN;
        let msg = Simulator::new(&bad)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(msg.contains("scene.mag_hw"), "{msg}");
        let c = crate::testkit::small_config();
        let one = FocalPlaneSimulator::new(&c)
            .expect("focal plane")
            .into_single()
            .expect("one");
        let direct = Simulator::new(&c).expect("simulator");
        assert_eq!(one.stars, direct.stars);
        assert_eq!(one.array, direct.array);
        let (a, b) = (one.exposure(0).expect("a"), direct.exposure(0).expect("b"));
        assert_eq!(a.image.adu, b.image.adu, "the same image, bit for bit");
    }
}
