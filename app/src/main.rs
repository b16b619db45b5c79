//! `jsim-app [CONFIG.toml]`: the desktop explorer. `main` only builds the window options and starts the app
//! (on the settings of the last session, which eframe keeps).

fn main() -> eframe::Result<()> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1600.0, 1000.0])
            .with_min_inner_size([1000.0, 700.0])
            .with_title("JASMINE astrometry explorer"),
        ..Default::default()
    };
    eframe::run_native(
        "JASMINE astrometry explorer",
        options,
        Box::new(|cc| {
            Ok(Box::new(app::ExplorerApp::from_args(
                cc.storage,
                std::env::args_os().skip(1),
            )))
        }),
    )
}
