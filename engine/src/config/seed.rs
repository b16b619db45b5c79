//! A seed's TOML form: an integer up to 2⁶³ − 1, a decimal string above (TOML's integers, and so `--set`'s
//! values, are i64), read back from either so that every u64 seed round-trips.

use serde::{Deserializer, Serializer, de};

/// An integer where TOML has one, else the decimal string.
pub fn serialize<S: Serializer>(seed: &u64, s: S) -> Result<S::Ok, S::Error> {
    match i64::try_from(*seed) {
        Ok(v) => s.serialize_i64(v),
        Err(_) => s.serialize_str(&seed.to_string()),
    }
}

/// An integer or a decimal string in 0 … 2⁶⁴ − 1.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    d.deserialize_any(SeedVisitor)
}

struct SeedVisitor;

impl de::Visitor<'_> for SeedVisitor {
    type Value = u64;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "a seed: an integer 0 … {}", u64::MAX)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
        Ok(v)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
        u64::try_from(v).map_err(|_| E::custom(format!("seed {v}: allowed 0 … {}", u64::MAX)))
    }

    fn visit_u128<E: de::Error>(self, v: u128) -> Result<u64, E> {
        u64::try_from(v).map_err(|_| E::custom(format!("seed {v}: allowed 0 … {}", u64::MAX)))
    }

    fn visit_i128<E: de::Error>(self, v: i128) -> Result<u64, E> {
        u64::try_from(v).map_err(|_| E::custom(format!("seed {v}: allowed 0 … {}", u64::MAX)))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<u64, E> {
        v.trim()
            .parse()
            .map_err(|_| E::custom(format!("seed {v:?}: allowed 0 … {}", u64::MAX)))
    }
}
