//! `jsim-app`: the desktop explorer. `main` only builds the window options and starts the app.

fn main() -> eframe::Result<()> {
    let options = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_inner_size([1400.0, 900.0])
            .with_title("JASMINE astrometry explorer"),
        ..Default::default()
    };
    eframe::run_native(
        "JASMINE astrometry explorer",
        options,
        Box::new(|_cc| Ok(Box::new(Explorer))),
    )
}

struct Explorer;

impl eframe::App for Explorer {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        egui::CentralPanel::default().show(ui, |ui| {
            ui.heading("JASMINE astrometry explorer");
        });
    }
}
