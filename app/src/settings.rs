//! The explorer's settings: what reproduces a view and persists across restarts (eframe's storage) — the
//! engine configuration, the countermeasure, the curve's magnitudes, the view settings, the path of the
//! configuration file and the sequence directory last opened.

use crate::view::{Colormap, Stretch};
use crate::worker::Request;
use engine::analysis::countermeasures::Countermeasure;
use engine::config::Config;
use serde::{Deserialize, Serialize};

/// Default magnitudes of the accuracy curve (the paper's).
pub const DEFAULT_MAGS: [f64; 6] = [12.0, 12.5, 13.0, 13.5, 14.0, 14.5];

/// Key of the settings in eframe's storage.
pub const STORAGE_KEY: &str = "jsim-explorer-settings";

/// What the central area shows: the exposure simulated from the settings, or a sequence's products read
/// from its directory.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CentralView {
    #[default]
    Exposure,
    Sequence,
    Transit,
}

impl CentralView {
    pub const ALL: [CentralView; 3] = [
        CentralView::Exposure,
        CentralView::Sequence,
        CentralView::Transit,
    ];
    pub fn name(self) -> &'static str {
        match self {
            CentralView::Exposure => "Exposure",
            CentralView::Sequence => "Sequence",
            CentralView::Transit => "Transit",
        }
    }
}

/// The transit view's controls: the stare's knobs the view offers (the rest as `jsim transit`'s defaults)
/// and the ACE's σ (set on a copy of the configuration for the stare only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TransitControls {
    pub target_hw: f64,
    pub hours: f64,
    pub comparisons: usize,
    pub ace_sigma_mas: f64,
    pub intra_pixel_amplitude: f64,
    pub plate_s: f64,
    /// The sub-exposure, s (0: the longest that does not saturate).
    pub exposure_s: f64,
    pub depth: f64,
    /// The aperture radius, px (0: chosen per stare).
    pub aperture_px: f64,
}

impl Default for TransitControls {
    fn default() -> Self {
        Self {
            target_hw: 9.7,
            hours: 2.0,
            comparisons: 10,
            ace_sigma_mas: 300.0,
            intra_pixel_amplitude: 0.12,
            plate_s: 12.5,
            exposure_s: 0.0,
            depth: 0.003,
            aperture_px: 0.0,
        }
    }
}

impl TransitControls {
    /// The stare these controls describe (`jsim transit`'s defaults otherwise).
    pub fn spec(&self) -> engine::studies::transit::Spec {
        engine::studies::transit::Spec {
            target_hw: self.target_hw,
            duration_h: self.hours,
            comparisons: self.comparisons,
            intra_pixel_amplitude: self.intra_pixel_amplitude,
            plate_s: self.plate_s,
            exposure_s: self.exposure_s,
            depth: self.depth,
            aperture_px: self.aperture_px,
            ..Default::default()
        }
    }

    /// The configuration of the stare: `cfg` with the ACE's σ of the controls.
    pub fn config(&self, cfg: &Config) -> Config {
        let mut c = cfg.clone();
        c.ace.sigma_mas = self.ace_sigma_mas;
        c
    }
}

/// View settings (they change no result).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ViewSettings {
    pub stretch: Stretch,
    pub colormap: Colormap,
    pub show_channels: bool,
    pub show_stars: bool,
    /// Index of the displayed exposure within the dataset.
    pub image_index: usize,
    /// The chosen star (index into the scene) and pixel (for the exposure window).
    pub star: usize,
    pub pixel: Option<(usize, usize)>,
    /// The chosen star of the quad focal plane: (array, index into that array's fitted stars).
    pub quad_star: Option<(usize, usize)>,
    pub closeup_radius_px: usize,
    /// Show the fit displacement the ACE predicts (the mechanism) beside the measured deviations.
    pub show_predicted_arrows: bool,
    /// Run the magnitude curve after every change.
    pub auto_curve: bool,
    /// The exposure or the sequence view.
    #[serde(default)]
    pub central: CentralView,
}

impl Default for ViewSettings {
    fn default() -> Self {
        Self {
            stretch: Stretch::Asinh,
            colormap: Colormap::Gray,
            show_channels: true,
            show_stars: false,
            image_index: 0,
            star: 0,
            pixel: None,
            quad_star: None,
            closeup_radius_px: 8,
            show_predicted_arrows: true,
            auto_curve: true,
            central: CentralView::Exposure,
        }
    }
}

/// Everything the user set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Settings {
    /// The engine configuration: every simulation and analysis knob on screen.
    pub cfg: Config,
    /// Countermeasure applied in the analysis (one of [`Countermeasure::OFFERED`]).
    #[serde(with = "countermeasure_name")]
    pub countermeasure: Countermeasure,
    /// Magnitudes of the accuracy curve.
    pub mags: Vec<f64>,
    pub view: ViewSettings,
    /// Path for Open / Save / Copy as CLI.
    pub config_path: String,
    /// The sequence directory for Open sequence (`jsim sequence --out DIR`).
    #[serde(default)]
    pub sequence_dir: String,
    /// The transit view's stare.
    #[serde(default)]
    pub transit: TransitControls,
}

impl Default for Settings {
    fn default() -> Self {
        Self::new(Config::default())
    }
}

impl Settings {
    pub fn new(cfg: Config) -> Self {
        Self {
            cfg,
            countermeasure: Countermeasure::None,
            mags: DEFAULT_MAGS.to_vec(),
            view: ViewSettings::default(),
            config_path: "jsim-explorer.toml".into(),
            sequence_dir: String::new(),
            transit: TransitControls::default(),
        }
    }

    /// The request that matches these settings.
    pub fn request(&self) -> Request {
        Request {
            cfg: self.cfg.clone(),
            countermeasure: self.countermeasure,
            image_index: self.view.image_index,
            mags: self.mags.clone(),
        }
    }

    /// The settings saved in `storage`, if any could be read back (a configuration that no longer
    /// validates is kept: the window says why it is not run).
    pub fn load(storage: &dyn eframe::Storage) -> Option<Settings> {
        let mut s: Settings = eframe::get_value(storage, STORAGE_KEY)?;
        if parse_mags(&format_mags(&s.mags)).as_ref() != Ok(&s.mags) {
            s.mags = DEFAULT_MAGS.to_vec();
        }
        Some(s)
    }

    pub fn save(&self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, STORAGE_KEY, self);
    }
}

/// A countermeasure stored by its name (`plate-poly:3`), read back with the engine's parser.
mod countermeasure_name {
    use engine::analysis::countermeasures::Countermeasure;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(cm: &Countermeasure, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(cm)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Countermeasure, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

pub fn format_mags(m: &[f64]) -> String {
    m.iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Parse a list of magnitudes: numbers separated by commas or spaces, each in −5…40, at most 20.
pub fn parse_mags(s: &str) -> Result<Vec<f64>, String> {
    let mut v = Vec::new();
    for tok in s.split([',', ' ', ';']).filter(|t| !t.trim().is_empty()) {
        let m: f64 = tok
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a magnitude", tok.trim()))?;
        if !(-5.0..=40.0).contains(&m) {
            return Err(format!("magnitude {m} outside −5…40"));
        }
        v.push(m);
    }
    if v.is_empty() {
        return Err("give at least one magnitude".into());
    }
    if v.len() > 20 {
        return Err("at most 20 magnitudes".into());
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v.dedup();
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mags_parse_and_reject() {
        assert_eq!(
            parse_mags("13, 12.5 12").expect("ok"),
            vec![12.0, 12.5, 13.0]
        );
        assert!(parse_mags("12, x").is_err());
        assert!(parse_mags("").is_err());
        assert!(parse_mags("99").is_err());
    }
}
