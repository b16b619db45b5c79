//! A windowed exposure of the simulator: the stars integrated along one track ([`Simulator::stamps`]), each
//! read in its own window through the detector's windowed readout ([`crate::detector::window`]) — a transit
//! stare's plate is this, the same integration and detector as the array's exposure.

use super::{SimError, Simulator};
use crate::detector::window::{Window, WindowReadout};
use crate::integrate::StarJob;
use crate::integrate::track::Track;

/// One window of a windowed exposure: as read (ADU) and its noise-free electrons (e⁻), row-major.
#[derive(Debug, Clone)]
pub struct WindowRead {
    pub adu: Vec<f32>,
    pub clean_e: Vec<f64>,
}

impl Simulator {
    /// Star k of `jobs` integrated along `track` and read in `windows[k]` through `flats[k]` (the flat cut
    /// to the window) by `readout`, every window's noise from `r` in window order. `None` when a star's
    /// light left the detector (its stamp is gone, so the windows no longer match their stars) or when
    /// `windows` and `flats` are not one per job.
    pub fn read_windows(
        &self,
        jobs: &[StarJob],
        track: &Track,
        windows: &[Window],
        flats: &[Vec<f32>],
        readout: &WindowReadout,
        r: &mut impl rand::Rng,
    ) -> Result<Option<Vec<WindowRead>>, SimError> {
        let stamps = self.stamps(jobs, Some(track))?;
        if stamps.len() != jobs.len() || windows.len() != jobs.len() || flats.len() != jobs.len() {
            return Ok(None);
        }
        let reads = windows
            .iter()
            .zip(&stamps)
            .zip(flats)
            .map(|((wdw, st), flat)| {
                let (adu, clean_e) = readout.read(wdw, |x, y| st.at(x, y), flat, r);
                WindowRead { adu, clean_e }
            })
            .collect();
        Ok(Some(reads))
    }
}
