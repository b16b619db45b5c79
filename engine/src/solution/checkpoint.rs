//! A solution's checkpoint: where an interrupted solution stands — its rejection round, the iterations so
//! far, every source's, attitude's and calibration term's current value and every observation's rejection
//! flag — written (atomically, by rank 0) at the end of each of the conjugate gradients' relinearisations
//! and of each rejection round. Rerun with the same input, the solution resumes from it and ends with the
//! same bits as if it had never stopped (on any number of ranks: they all give one process's bits); a
//! checkpoint of another input is a named error. It is removed once the solution is done.
//!
//! Within a relinearisation the conjugate gradients write one too every few steps: the state at the
//! relinearisation's start with where the gradients stand (the steps, the solution so far, the residual and
//! the search direction, in the whole problem's layout), so that a rank killed halfway through a long run of
//! steps loses at most those few.
//!
//! The file is little-endian binary: `JSIMCKP1`, the input's fingerprint, the round, the iterations before
//! it, the observations rejected, the iterations within it (u64::MAX: the round's start), the counts, then
//! 12 doubles per source (parameters, errors, observations, χ²), 4 per attitude, the calibration's terms,
//! one byte per observation; then 0, or 1, the steps, the unknowns n and 3 n doubles (x, r, d).

use super::blocks::State;
use super::calibration::Calibration;
use super::cg::Steps;
use super::{
    Attitude, ExposureGeometry, Observation, Options, Reference, SolutionError, SolvedSource,
};

const MAGIC: &[u8; 8] = b"JSIMCKP1";

/// Where a solution stands in its rounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct At {
    pub round: usize,
    /// Iterations of the rounds before this one.
    pub iterations_before: usize,
    pub rejected: usize,
    /// Iterations of this round so far; None: at the round's start.
    pub in_round: Option<usize>,
}

/// A checkpoint read back.
pub(super) struct Saved {
    pub at: At,
    pub state: State,
    pub active: Vec<bool>,
    /// Where the gradients stood within a relinearisation (None: at its start).
    pub steps: Option<Steps>,
}

/// The input's fingerprint: SHA-256 (its first 64 bits) over the observations, exposures, references, the
/// sources' count and the options.
pub(super) fn fingerprint(
    obs: &[Observation],
    exposures: &[ExposureGeometry],
    refs: &[Reference],
    n_sources: usize,
    opt: &Options,
) -> u64 {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let f = |h: &mut Sha256, v: f64| h.update(v.to_le_bytes());
    let u = |h: &mut Sha256, v: usize| h.update((v as u64).to_le_bytes());
    u(&mut h, n_sources);
    for o in obs {
        u(&mut h, o.exposure());
        u(&mut h, o.source());
        u(&mut h, o.array());
        for v in [
            o.xi_mas,
            o.eta_mas,
            o.sigma_mas,
            o.focal_px()[0],
            o.focal_px()[1],
        ] {
            f(&mut h, v);
        }
    }
    for g in exposures {
        for v in [g.t_yr, g.parallax_factor[0], g.parallax_factor[1]]
            .into_iter()
            .chain(g.centre_mas)
            .chain(g.to_plane)
        {
            f(&mut h, v);
        }
        u(&mut h, g.stare);
        u(&mut h, g.visit);
    }
    for r in refs {
        u(&mut h, r.source);
        for v in r.params.iter().chain(&r.sigma) {
            f(&mut h, *v);
        }
    }
    h.update(format!("{opt:?}").as_bytes());
    let d = h.finalize();
    u64::from_le_bytes([d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]])
}

/// Where a checkpoint is kept. The analysis makes and reads its bytes; a front end keeps them (a file:
/// `io::checkpoint::FileStore`, written atomically).
pub trait CheckpointStore {
    /// The checkpoint's bytes, or None when there is none.
    fn load(&self) -> Result<Option<Vec<u8>>, String>;
    /// Keep `bytes` as the checkpoint, replacing the last one whole.
    fn save(&self, bytes: &[u8]) -> Result<(), String>;
    /// The solution is done: drop the checkpoint.
    fn clear(&self);
    /// What to call it in a message (its path).
    fn name(&self) -> String;
}

/// Where a solution stands (`at`, `state`, `active`, and within a relinearisation the gradients' `steps`)
/// for the input `fingerprint`, as the checkpoint's bytes.
pub(super) fn encode(
    fingerprint: u64,
    at: &At,
    state: &State,
    active: &[bool],
    steps: Option<&Steps>,
) -> Vec<u8> {
    let mut b: Vec<u8> = MAGIC.to_vec();
    let cal = cal_values(&state.cal);
    for v in [
        fingerprint,
        at.round as u64,
        at.iterations_before as u64,
        at.rejected as u64,
        at.in_round.map_or(u64::MAX, |k| k as u64),
        state.sources.len() as u64,
        state.attitudes.len() as u64,
        cal.len() as u64,
        active.len() as u64,
    ] {
        b.extend(v.to_le_bytes());
    }
    let mut put = |v: f64| b.extend(v.to_le_bytes());
    for s in &state.sources {
        s.params.iter().chain(&s.sigma).for_each(|v| put(*v));
        put(s.observations as f64);
        put(s.chi2);
    }
    for a in &state.attitudes {
        [a.p, a.q, a.offset_mas[0], a.offset_mas[1]]
            .into_iter()
            .for_each(&mut put);
    }
    cal.into_iter().for_each(&mut put);
    b.extend(active.iter().map(|a| u8::from(*a)));
    match steps {
        None => b.extend(0u64.to_le_bytes()),
        Some(g) => {
            for v in [1, g.steps as u64, g.x.len() as u64] {
                b.extend(v.to_le_bytes());
            }
            for v in g.x.iter().chain(&g.r).chain(&g.d) {
                b.extend(v.to_le_bytes());
            }
        }
    }
    b
}

/// A checkpoint's bytes read back (`name` for the messages): they must be of the input `fingerprint`, with
/// a calibration of `template`'s model (the values replaced).
pub(super) fn decode(
    b: &[u8],
    name: &str,
    fingerprint: u64,
    template: &Calibration,
) -> Result<Saved, SolutionError> {
    let bad = || checkpoint_error(name, "not a jsim solution checkpoint, or cut short");
    if b.len() < 8 + 9 * 8 || &b[..8] != MAGIC {
        return Err(bad());
    }
    let word = |k: usize| -> u64 {
        let mut w = [0u8; 8];
        w.copy_from_slice(&b[8 + 8 * k..16 + 8 * k]);
        u64::from_le_bytes(w)
    };
    if word(0) != fingerprint {
        return Err(checkpoint_error(
            name,
            "written for another input (other observations, references or options): remove it to start \
             afresh",
        ));
    }
    let (n_src, n_att, n_cal, n_obs) = (
        word(5) as usize,
        word(6) as usize,
        word(7) as usize,
        word(8) as usize,
    );
    let mut cal = template.clone();
    let doubles = 12 * n_src + 4 * n_att + n_cal;
    let at = 8 + 9 * 8;
    let tail = at + 8 * doubles + n_obs;
    if n_cal != cal_values(&cal).len() || b.len() < tail + 8 {
        return Err(bad());
    }
    let word_at = |k: usize| -> u64 {
        let mut w = [0u8; 8];
        w.copy_from_slice(&b[k..k + 8]);
        u64::from_le_bytes(w)
    };
    let steps = match word_at(tail) {
        0 if b.len() == tail + 8 => None,
        1 if b.len() >= tail + 24 => {
            let (taken, len) = (word_at(tail + 8) as usize, word_at(tail + 16) as usize);
            if b.len() != tail + 24 + 24 * len {
                return Err(bad());
            }
            let v = |k: usize| -> Vec<f64> {
                (0..len)
                    .map(|i| f64::from_bits(word_at(tail + 24 + 8 * (k * len + i))))
                    .collect()
            };
            Some(Steps {
                steps: taken,
                x: v(0),
                r: v(1),
                d: v(2),
            })
        }
        _ => return Err(bad()),
    };
    let mut vals = b[at..at + 8 * doubles].chunks_exact(8).map(|c| {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        f64::from_le_bytes(w)
    });
    let mut next = || vals.next().unwrap_or(f64::NAN);
    let sources = (0..n_src)
        .map(|_| {
            let params = std::array::from_fn(|_| next());
            let sigma = std::array::from_fn(|_| next());
            SolvedSource {
                params,
                sigma,
                observations: next() as usize,
                chi2: next(),
            }
        })
        .collect();
    let attitudes = (0..n_att)
        .map(|_| Attitude {
            p: next(),
            q: next(),
            offset_mas: [next(), next()],
        })
        .collect();
    let values: Vec<f64> = (0..n_cal).map(|_| next()).collect();
    set_cal_values(&mut cal, &values);
    Ok(Saved {
        at: At {
            round: word(1) as usize,
            iterations_before: word(2) as usize,
            rejected: word(3) as usize,
            in_round: (word(4) != u64::MAX).then_some(word(4) as usize),
        },
        state: State {
            sources,
            attitudes,
            cal,
        },
        active: b[at + 8 * doubles..tail].iter().map(|v| *v != 0).collect(),
        steps,
    })
}

pub(super) fn checkpoint_error(name: &str, why: &str) -> SolutionError {
    SolutionError::Checkpoint {
        path: name.to_string(),
        why: why.to_string(),
    }
}

/// Every coefficient of a calibration: each array's x then y terms, then the distortion's x then y.
fn cal_values(c: &Calibration) -> Vec<f64> {
    let mut v = Vec::new();
    for a in &c.arrays {
        v.extend(a[0].iter().chain(&a[1]));
    }
    v.extend(c.distortion[0].iter().chain(&c.distortion[1]));
    v
}

fn set_cal_values(c: &mut Calibration, values: &[f64]) {
    let mut it = values.iter();
    let slots = c
        .arrays
        .iter_mut()
        .flat_map(|a| a.iter_mut())
        .chain(c.distortion.iter_mut())
        .flat_map(|axis| axis.iter_mut());
    for (slot, v) in slots.zip(&mut it) {
        *slot = *v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solution::CalibrationModel;

    #[test]
    fn a_checkpoint_reads_back_bit_for_bit_and_refuses_another_input() {
        let model = CalibrationModel {
            arrays: 2,
            array_order: 1,
            distortion_order: 2,
        };
        let mut cal = Calibration::zero(model, 3000.0);
        let n = cal_values(&cal).len();
        set_cal_values(
            &mut cal,
            &(0..n).map(|k| k as f64 * 0.1 - 0.35).collect::<Vec<_>>(),
        );
        let at = At {
            round: 2,
            iterations_before: 57,
            rejected: 3,
            in_round: Some(11),
        };
        let state = State {
            sources: vec![
                SolvedSource {
                    params: [1.0, -2.5, 1e-9, f64::NAN, 0.3],
                    sigma: [0.1, 0.2, 0.3, 0.4, f64::NAN],
                    observations: 12,
                    chi2: 9.5,
                };
                3
            ],
            attitudes: vec![
                Attitude {
                    p: 1.000_000_2,
                    q: -3e-5,
                    offset_mas: [12.0, -7.25],
                };
                2
            ],
            cal: cal.clone(),
        };
        let active = vec![true, false, true, true];
        let steps = Steps {
            steps: 40,
            x: vec![1.5, -2.0, f64::MIN_POSITIVE],
            r: vec![0.25, 3e300, -0.0],
            d: vec![7.0, 8.0, 9.0],
        };
        let template = Calibration::zero(model, 3000.0);
        let with_steps = decode(
            &encode(42, &at, &state, &active, Some(&steps)),
            "c",
            42,
            &template,
        )
        .expect("read");
        assert_eq!(with_steps.steps, Some(steps));
        let back =
            decode(&encode(42, &at, &state, &active, None), "c", 42, &template).expect("read");
        assert_eq!(back.at, at);
        assert_eq!(back.steps, None);
        assert_eq!(back.active, active);
        assert_eq!(back.state.cal, state.cal);
        // NaN ≠ NaN: compare the bits
        assert_eq!(
            format!("{:?}", back.state.sources),
            format!("{:?}", state.sources)
        );
        assert_eq!(back.state.attitudes, state.attitudes);
        let bytes = encode(42, &at, &state, &active, None);
        let Err(e) = decode(&bytes, "c", 43, &template) else {
            panic!("another input must be refused")
        };
        assert!(e.to_string().contains("another input"), "{e}");
        let Err(e) = decode(&bytes[..bytes.len() - 3], "c", 42, &template) else {
            panic!("a checkpoint cut short must be refused")
        };
        assert!(e.to_string().contains("cut short"), "{e}");
    }
}
