//! The settings persist across restarts: what eframe saves on exit is what the next start restores.

use app::ExplorerApp;
use app::settings::Settings;
use engine::config::ReadoutOrder;
use std::collections::HashMap;

/// eframe's storage, in memory (the window keeps it in a file).
#[derive(Default)]
struct Memory(HashMap<String, String>);

impl eframe::Storage for Memory {
    fn get_string(&self, key: &str) -> Option<String> {
        self.0.get(key).cloned()
    }
    fn set_string(&mut self, key: &str, value: String) {
        self.0.insert(key.to_string(), value);
    }
    fn remove_string(&mut self, key: &str) {
        self.0.remove(key);
    }
    fn flush(&mut self) {}
}

#[test]
fn settings_saved_on_exit_are_restored_at_the_next_start() {
    let mut first = ExplorerApp::from_args(None, std::iter::empty());
    assert_eq!(first.settings, Settings::default());
    first.settings.cfg.ace.sigma_mas = 210.0;
    first.settings.cfg.readout.order = ReadoutOrder::GlobalReset;
    first.settings.countermeasure = "telemetry".parse().expect("a countermeasure");
    first.set_mags(vec![12.0, 14.0]);
    first.settings.view.image_index = 2;
    first.settings.view.show_stars = true;
    first.settings.view.auto_curve = false;
    let mut storage = Memory::default();
    eframe::App::save(&mut first, &mut storage);

    let second = ExplorerApp::from_args(Some(&storage), std::iter::empty());
    assert_eq!(second.settings, first.settings);
    assert_eq!(
        second.rt.mags_text, "12, 14",
        "the magnitude field shows them too"
    );

    // a configuration file on the command line wins over the stored configuration
    let dir = std::env::temp_dir().join(format!("jsim-app-persist-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let file = dir.join("given.toml");
    std::fs::write(&file, "[ace]\nsigma_mas = 99.0\n").expect("write");
    let third = ExplorerApp::from_args(Some(&storage), std::iter::once(file.clone().into()));
    assert_eq!(third.settings.cfg.ace.sigma_mas, 99.0);
    assert_eq!(
        third.settings.view, first.settings.view,
        "the view settings stay"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn settings_survive_the_storage_round_trip() {
    let mut s = Settings::default();
    s.cfg.ace.sigma_mas = 123.0;
    s.cfg.readout.order = engine::config::ReadoutOrder::SampleHold;
    s.cfg.ace.modes.pop();
    s.countermeasure = "plate-poly:3".parse().expect("a countermeasure");
    s.mags = vec![11.0, 13.5];
    s.view.stretch = app::view::Stretch::Log;
    s.view.pixel = Some((12, 34));
    s.view.auto_curve = false;
    s.config_path = "somewhere/else.toml".into();
    let mut m = Memory::default();
    s.save(&mut m);
    assert_eq!(Settings::load(&m), Some(s));
    assert_eq!(Settings::load(&Memory::default()), None);
    // a stored value this version cannot read is ignored, not fatal
    let mut bad = Memory::default();
    eframe::Storage::set_string(&mut bad, app::settings::STORAGE_KEY, "(cfg: 3)".into());
    assert_eq!(Settings::load(&bad), None);
}
