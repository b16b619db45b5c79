//! The configuration as TOML text: reading ([`Config::load`], [`Config::from_toml_str`]), writing
//! ([`Config::to_toml`], the commented [`DEFAULT_TOML`]), overrides by dotted path and the hash.

use super::{Config, ConfigError, invalid};
use crate::digest;
use std::path::{Path, PathBuf};

impl Config {
    /// Read and validate a TOML file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let cfg = Self::from_toml_str(&text).map_err(|e| match e {
            ConfigError::Parse { message, .. } => ConfigError::Parse {
                path: path.to_path_buf(),
                message,
            },
            other => other,
        })?;
        Ok(cfg)
    }

    /// Parse and validate TOML text.
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        let cfg: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: PathBuf::from("<text>"),
            message: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The configuration as TOML (no comments; see [`DEFAULT_TOML`] for the commented default).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self)
            .unwrap_or_else(|e| format!("# could not serialise config: {e}\n"))
    }

    /// A copy with one field set from text, by dotted path (`ace.sigma_mas`, `readout.order`,
    /// `ace.modes.0.freq_hz` for array elements). The value is read as TOML (`300`, `"rolling"`, `true`,
    /// `[1.0, 2.0]`), or as a plain string when it is not valid TOML. Unknown fields and bad values are
    /// errors naming the field. The ranges are not checked here: apply every override, then
    /// [`Config::validate`] once, so that the order of the overrides never matters.
    pub fn with_override(&self, path: &str, value: &str) -> Result<Config, ConfigError> {
        let parsed: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut root = toml::Value::try_from(self)
            .map_err(|e| invalid(path, value, &format!("cannot represent the config: {e}")))?;
        // `[as_built]` is left out of a design configuration's TOML: put it back so that it can be overridden
        if let toml::Value::Table(t) = &mut root
            && !t.contains_key("as_built")
            && let Ok(v) = toml::Value::try_from(&self.as_built)
        {
            t.insert("as_built".to_string(), v);
        }
        let keys: Vec<&str> = path.split('.').collect();
        if keys.iter().any(|k| k.is_empty()) {
            return Err(invalid(
                path,
                value,
                "a dotted field path such as ace.sigma_mas",
            ));
        }
        let mut node = &mut root;
        for (depth, key) in keys.iter().enumerate() {
            let last = depth + 1 == keys.len();
            let here = keys[..=depth].join(".");
            node = match node {
                toml::Value::Table(t) => {
                    if !t.contains_key(*key) {
                        // optional fields that are unset (e.g. scene.catalogue) may be created at the leaf
                        if !last {
                            return Err(invalid(&here, value, "no such config field"));
                        }
                        t.insert((*key).to_string(), parsed.clone());
                    }
                    t.get_mut(*key)
                        .ok_or_else(|| invalid(&here, value, "no such config field"))?
                }
                toml::Value::Array(a) => {
                    let i: usize = key
                        .parse()
                        .map_err(|_| invalid(&here, value, "an array index"))?;
                    let len = a.len();
                    a.get_mut(i)
                        .ok_or_else(|| invalid(&here, value, &format!("index < {len}")))?
                }
                _ => return Err(invalid(&here, value, "is not a section or array")),
            };
        }
        *node = parsed;
        root.try_into()
            .map_err(|e: toml::de::Error| invalid(path, value, &e.to_string()))
    }

    /// SHA-256 of the canonical TOML, first 16 hex digits: identifies a configuration in outputs.
    pub fn hash_hex(&self) -> String {
        digest::sha256_short_hex(self.to_toml().as_bytes())
    }
}

/// The default configuration, with comments: what `jsim config --print-default` writes.
pub const DEFAULT_TOML: &str = include_str!("default.toml");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ReadoutOrder;

    #[test]
    fn commented_default_equals_builtin_default() {
        let parsed: Config = toml::from_str(DEFAULT_TOML).expect("default TOML parses");
        assert_eq!(parsed, Config::default());
        Config::default().validate().expect("default validates");
    }

    #[test]
    fn round_trip_through_toml() {
        let c = Config::default();
        let back = Config::from_toml_str(&c.to_toml()).expect("round trip");
        assert_eq!(back, c);
        assert_eq!(back.hash_hex(), c.hash_hex());
    }

    /// Every u64 seed, 2⁶³ and above included, is given by `--set`, survives further overrides and
    /// round-trips through the TOML.
    #[test]
    fn a_seed_of_the_full_u64_range_round_trips() {
        let c = Config::default();
        for seed in [u64::MAX, 1 << 63, 7] {
            let d = c
                .with_override("seed", &seed.to_string())
                .expect("seed override");
            assert_eq!(d.seed, seed);
            let e = d
                .with_override("sky.ra_deg", "1.0")
                .expect("a later override");
            assert_eq!((e.seed, e.sky.ra_deg), (seed, 1.0));
            let f = e
                .with_override("as_built.seed", &seed.to_string())
                .expect("as-built seed");
            assert_eq!(f.as_built.seed, seed);
            assert_eq!(Config::from_toml_str(&e.to_toml()).expect("round trip"), e);
        }
        // a plain integer in a file still reads, and a bad one names the field
        let g = Config::from_toml_str("seed = 18446744073709551615\n").expect("u64 in a file");
        assert_eq!(g.seed, u64::MAX);
        let err = c
            .with_override("seed", "-1")
            .expect_err("negative")
            .to_string();
        assert!(err.contains("seed"), "{err}");
    }

    #[test]
    fn overrides_by_dotted_path() {
        let c = Config::default();
        let d = c.with_override("ace.sigma_mas", "150").expect("number");
        assert_eq!(d.ace.sigma_mas, 150.0);
        let d = c
            .with_override("readout.order", "sample-hold")
            .expect("bare string");
        assert_eq!(d.readout.order, ReadoutOrder::SampleHold);
        let d = c
            .with_override("ace.modes.2.freq_hz", "65")
            .expect("array element");
        assert_eq!(d.ace.modes[2].freq_hz, 65.0);
        let d = c
            .with_override("scene.catalogue", "stars.csv")
            .expect("optional field");
        assert_eq!(d.scene.catalogue.as_deref(), Some(Path::new("stars.csv")));
        assert!(
            c.with_override("ace.sigma_mass", "1")
                .expect_err("typo")
                .to_string()
                .contains("sigma_mass")
        );
        assert!(
            c.with_override("nosuch.field", "1")
                .expect_err("section")
                .to_string()
                .contains("nosuch")
        );
        assert!(
            c.with_override("ace.sigma_mas", "-5")
                .expect("applied; ranges are checked once, after every override")
                .validate()
                .expect_err("range")
                .to_string()
                .contains("ace.sigma_mas")
        );
        // the order of overrides does not matter: a catalogue scene and its file, either way round
        let a = c
            .with_override("scene.kind", "catalogue")
            .and_then(|c| c.with_override("scene.catalogue", "stars.csv"))
            .expect("kind first");
        let b = c
            .with_override("scene.catalogue", "stars.csv")
            .and_then(|c| c.with_override("scene.kind", "catalogue"))
            .expect("file first");
        assert_eq!(a, b);
        assert!(a.validate().is_ok());
        assert!(c.with_override("readout.order", "diagonal").is_err());
    }

    #[test]
    fn missing_file_is_a_clear_error() {
        let e = Config::load(Path::new("/nonexistent/jsim.toml")).expect_err("missing file");
        assert!(e.to_string().contains("/nonexistent/jsim.toml"));
    }
}
