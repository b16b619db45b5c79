//! Seeded random streams. Every random draw of the simulator comes from a ChaCha8 generator whose 256-bit
//! seed is derived (SplitMix64 mixing) from the run's master seed, a named [`Stream`] and an index (image
//! number, row, star…). Streams never share state, so results do not depend on thread scheduling or on
//! how work is split; the master seed is written to every FITS header.

use rand::SeedableRng;
pub use rand_chacha::ChaCha8Rng as Rng;

/// The independent random streams of a simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    AceX = 1,
    AceY = 2,
    SceneOffsets = 3,
    InterPixelFlat = 4,
    ShotNoise = 5,
    ReadNoise = 6,
    Telemetry = 7,
    Sweep = 8,
    ReferenceCatalogue = 9,
    /// The calibration flat's own error (what the instrument team's flat field got wrong).
    CalibrationFlat = 10,
    /// The mock bulge field's stars.
    Bulge = 11,
    /// Each array's own flat and noise streams (a derived seed per array of the quad focal plane).
    Array = 12,
    /// The mock bulge's distances and proper motions (apart from its positions and magnitudes).
    BulgeMotion = 13,
    /// A sequence's per-stare pointing and roll errors.
    Sequence = 14,
    /// Each image's cosmic-ray hits.
    CosmicRays = 15,
    /// The synthetic sequences of the astrometric solution's benchmark.
    Solution = 16,
    /// The reference catalogue of a sequence's region (`studies::sequence::reference`).
    SkyReference = 17,
    /// A transit stare's field, its plates' noise and telemetry (`studies::transit`).
    Transit = 18,
    /// The instrument as built: its deviations from the design, from the instrument's own seed.
    AsBuilt = 19,
    Test = 99,
}

/// SplitMix64 step: a bijective 64-bit mixer (Steele, Lea & Flood 2014).
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Derive a sub-seed from a seed and a sequence of indices (order matters).
pub fn derive_seed(seed: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(splitmix64(seed), |acc, &p| {
        splitmix64(acc ^ splitmix64(p.wrapping_add(0x51_7C_C1_B7)))
    })
}

/// The generator of `stream` number `index` of a run with master `seed`.
pub fn stream(seed: u64, which: Stream, index: u64) -> Rng {
    let base = derive_seed(seed, &[which as u64, index]);
    let mut key = [0u8; 32];
    for (k, chunk) in key.chunks_mut(8).enumerate() {
        chunk.copy_from_slice(
            &splitmix64(base ^ (k as u64).wrapping_mul(0xA076_1D64_78BD_642F)).to_le_bytes(),
        );
    }
    Rng::from_seed(key)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngExt;

    #[test]
    fn same_seed_same_stream_and_streams_differ() {
        let a: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(stream(7, Stream::AceX, 0), |r, _: u64| {
                Some(r.random::<u64>())
            })
            .collect();
        let b: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(stream(7, Stream::AceX, 0), |r, _: u64| {
                Some(r.random::<u64>())
            })
            .collect();
        let c: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(stream(7, Stream::AceY, 0), |r, _: u64| {
                Some(r.random::<u64>())
            })
            .collect();
        let d: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(stream(7, Stream::AceX, 1), |r, _: u64| {
                Some(r.random::<u64>())
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d);
    }
}
