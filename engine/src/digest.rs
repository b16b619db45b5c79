//! Content digests: the SHA-256 hex strings that identify configurations (`Config::hash_hex`),
//! sweeps, sweep rows and the files a sweep writes. A foundation module: it depends on nothing else in the
//! crate, so that any stage may name its inputs by content.

use sha2::{Digest, Sha256};

/// SHA-256 of `bytes` as 64 lower-case hex digits.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// The first 16 hex digits (64 bits) of [`sha256_hex`]: the short identifiers written beside
/// configurations, sweeps and rows, where a collision is not a security concern.
pub fn sha256_short_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes)[..8])
}

/// The first 48 bits of SHA-256 of `bytes` as an integer: an identifier a table stores exactly in any
/// numeric column (a double holds integers to 2⁵³).
pub fn sha256_id48(bytes: &[u8]) -> u64 {
    Sha256::digest(bytes)[..6]
        .iter()
        .fold(0u64, |id, b| (id << 8) | u64::from(*b))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_digests() {
        // FIPS 180-2, appendix B.1
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(sha256_short_hex(b"abc"), "ba7816bf8f01cfea");
        assert_eq!(sha256_id48(b"abc"), 0xba7816bf8f01);
        assert_eq!(sha256_hex(b"").len(), 64);
    }
}
