//! Reproducing a view outside the explorer: the TOML file of the configuration on screen (the app's own
//! choices ride along as comments, which the engine ignores) and the `jsim` commands that reproduce it.

use crate::settings::{Settings, format_mags, parse_mags};
use engine::analysis::countermeasures::Countermeasure;
use engine::config::Config;
use engine::io::shell_quote;
use std::path::{Path, PathBuf};

/// Marker of the app's own lines in a saved configuration.
const APP_TAG: &str = "# jsim-app";

/// A configuration file as the app reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    pub cfg: Config,
    /// The app's choices, if the file was saved by the app.
    pub countermeasure: Option<Countermeasure>,
    pub mags: Option<Vec<f64>>,
}

/// Read a configuration file (the engine validates it; errors name the file or the field).
pub fn load_config(path: &Path) -> Result<Loaded, String> {
    let cfg = Config::load(path).map_err(|e| e.to_string())?;
    let mut loaded = Loaded {
        cfg,
        countermeasure: None,
        mags: None,
    };
    if let Ok(text) = std::fs::read_to_string(path) {
        for line in text.lines() {
            let Some(rest) = line.strip_prefix(APP_TAG) else {
                continue;
            };
            let rest = rest.trim();
            if let Some(cm) = rest.strip_prefix("countermeasure =") {
                loaded.countermeasure = cm
                    .trim()
                    .parse()
                    .ok()
                    .filter(|c| Countermeasure::OFFERED.contains(c));
            } else if let Some(m) = rest.strip_prefix("mags =") {
                loaded.mags = parse_mags(m).ok();
            }
        }
    }
    Ok(loaded)
}

/// The TOML that reproduces the settings: the engine configuration, with the app's choices and the
/// equivalent commands as comments.
pub fn config_text(s: &Settings, path: &Path) -> String {
    format!(
        "{APP_TAG} countermeasure = {}\n{APP_TAG} mags = {}\n# reproduce: {}\n#            {}\n\n{}",
        s.countermeasure,
        format_mags(&s.mags),
        experiment_cli(s, path),
        simulate_cli(path),
        s.cfg.to_toml()
    )
}

/// Write the configuration; returns the absolute path written.
pub fn save_config(s: &Settings, path: &Path) -> Result<PathBuf, String> {
    if path.as_os_str().is_empty() {
        return Err("give a file name for the configuration".into());
    }
    s.cfg.validate().map_err(|e| format!("not saved: {e}"))?;
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    std::fs::write(&abs, config_text(s, &abs))
        .map_err(|e| format!("cannot write {}: {e}", abs.display()))?;
    Ok(abs)
}

/// `jsim experiment` for the curve on screen.
pub fn experiment_cli(s: &Settings, path: &Path) -> String {
    let cms = match s.request().plan() {
        Ok(p) => p.countermeasures.iter().map(|c| c.to_string()).collect(),
        Err(_) => vec![Countermeasure::None.to_string()],
    };
    format!(
        "jsim experiment --config {} --aces {} --readouts {} --mags {} --countermeasures {} --out out/explorer",
        shell_quote(path),
        s.cfg.ace.case.name(),
        s.cfg.readout.order.name(),
        s.mags
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
            .join(","),
        cms.join(",")
    )
}

/// `jsim simulate` for the images on screen.
pub fn simulate_cli(path: &Path) -> String {
    format!(
        "jsim simulate --config {} --out out/explorer-images",
        shell_quote(path)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saved_config_reloads_identically() {
        let mut s = Settings::default();
        s.cfg.ace.sigma_mas = 123.0;
        s.countermeasure = "plate-poly:3".parse().expect("a countermeasure");
        s.mags = vec![12.0, 13.0];
        let dir = std::env::temp_dir().join(format!("jsim-app-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("cfg with space.toml");
        let written = save_config(&s, &path).expect("saved");
        assert_eq!(Config::load(&written).expect("loads"), s.cfg);
        let back = load_config(&written).expect("loads");
        assert_eq!(back.cfg, s.cfg);
        assert_eq!(back.countermeasure, Some(s.countermeasure));
        assert_eq!(back.mags, Some(vec![12.0, 13.0]));
        assert!(
            experiment_cli(&s, &written).contains("'"),
            "paths with spaces are quoted"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
