//! The control panel: every knob edits the engine configuration (or the countermeasure / magnitudes) in
//! place; the app notices the change after the frame and starts the work it invalidates.

use crate::settings::ViewSettings;
use egui::{DragValue, Slider};
use engine::analysis::countermeasures::Countermeasure;
use engine::config::{
    AceCase, AsBuilt, Config, InstrumentModel, Layout, Mode, ReadoutOrder, RowDirection, SceneKind,
};

fn section(ui: &mut egui::Ui, title: &str) {
    ui.add_space(6.0);
    ui.strong(title);
    ui.separator();
}

/// Draw the controls.
pub fn controls_ui(
    ui: &mut egui::Ui,
    cfg: &mut Config,
    countermeasure: &mut Countermeasure,
    view: &mut ViewSettings,
    mags_text: &mut String,
    mags_error: Option<&str>,
) {
    egui::ScrollArea::vertical().show(ui, |ui| {
        ui.spacing_mut().slider_width = 150.0;

        section(ui, "Attitude control error (ACE)");
        ui.horizontal(|ui| {
            ui.radio_value(&mut cfg.ace.case, AceCase::Realistic, "realistic")
                .on_hover_text("a time series from the PSD: every pixel integrates its own window");
            ui.radio_value(&mut cfg.ace.case, AceCase::Gaussian, "Gaussian")
                .on_hover_text("an isotropic Gaussian blur of σ, the same for every pixel");
            ui.radio_value(&mut cfg.ace.case, AceCase::None, "still")
                .on_hover_text("no attitude error");
        });
        ui.add(Slider::new(&mut cfg.ace.sigma_mas, 0.0..=1000.0).step_by(1.0).text("ACE σ [mas]"))
            .on_hover_text("per-axis σ of the ACE (realistic: median over exposures of the per-exposure σ)");
        ui.add(
            Slider::new(&mut cfg.ace.boundary_freq_hz, 0.001..=10.0)
                .logarithmic(true)
                .text("boundary f_b [Hz]"),
        )
        .on_hover_text("PSD continuum: flat below f_b, falling as f^−α above");
        ui.add(Slider::new(&mut cfg.ace.power_law_index, 0.0..=6.0).step_by(0.05).text("power-law index α"));
        ui.add(
            Slider::new(&mut cfg.ace.span_s, 30.0..=3600.0)
                .logarithmic(true)
                .step_by(1.0)
                .text("series span [s]"),
        )
        .on_hover_text("length of the generated ACE series: it must cover every exposure of the dataset");
        modes_ui(ui, &mut cfg.ace.modes);

        section(ui, "Readout");
        ui.horizontal(|ui| {
            ui.radio_value(&mut cfg.readout.order, ReadoutOrder::Rolling, "rolling")
                .on_hover_text("each pixel integrates [t1, t1 + T], t1 rolling along the channel");
            ui.radio_value(&mut cfg.readout.order, ReadoutOrder::GlobalReset, "global reset")
                .on_hover_text("all pixels start together; the reads still roll");
            ui.radio_value(&mut cfg.readout.order, ReadoutOrder::SampleHold, "sample-hold")
                .on_hover_text("global shutter: identical windows");
        });
        ui.horizontal(|ui| {
            ui.label("rows read");
            ui.radio_value(&mut cfg.readout.row_direction, RowDirection::Up, "upwards");
            ui.radio_value(&mut cfg.readout.row_direction, RowDirection::Down, "downwards");
        });

        scene_ui(ui, cfg);

        section(ui, "Stars and exposure");
        ui.add(Slider::new(&mut cfg.scene.mag_hw, 8.0..=16.0).step_by(0.1).text("magnitude Hw"));
        ui.add(Slider::new(&mut cfg.scene.j_minus_h, -0.5..=4.0).step_by(0.05).text("colour J−H"))
            .on_hover_text("a new colour needs a new polychromatic PSF (about a second)");
        ui.add(
            Slider::new(&mut cfg.detector.exposure_s, 1.0..=30.0)
                .step_by(0.1)
                .text("exposure [s]"),
        );

        section(ui, "Dataset");
        ui.horizontal(|ui| {
            let l = ui.label("images");
            ui.add(DragValue::new(&mut cfg.fidelity.images).range(1..=100))
                .labelled_by(l.id)
                .on_hover_text("images per dataset: per point of the magnitude curve, and the predictor's mean");
            let l = ui.label("seed");
            ui.add(DragValue::new(&mut cfg.seed).speed(1.0)).labelled_by(l.id);
            if ui.button("new seed").clicked() {
                cfg.seed = cfg
                    .seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407)
                    >> 16;
            }
        });
        ui.horizontal(|ui| {
            let l = ui.label("shown image #");
            let max = cfg.fidelity.images.saturating_sub(1);
            ui.add(DragValue::new(&mut view.image_index).range(0..=max))
                .labelled_by(l.id);
        });

        section(ui, "Analysis");
        ui.add(Slider::new(&mut cfg.analysis.epsf_iterations, 0..=10).text("ePSF iterations"))
            .on_hover_text("0 = iterate to convergence");
        ui.add(Slider::new(&mut cfg.analysis.epsf_zones, 1..=8).text("ePSF Y zones"))
            .on_hover_text("zones of the Y-dependent ePSF (used by the yzones countermeasure)");
        ui.label("countermeasure");
        ui.horizontal_wrapped(|ui| {
            for cm in Countermeasure::OFFERED {
                ui.selectable_value(countermeasure, cm, cm.to_string());
            }
        });

        section(ui, "Magnitude curve");
        ui.horizontal(|ui| {
            let l = ui.label("magnitudes");
            ui.add(egui::TextEdit::singleline(mags_text).desired_width(170.0))
                .labelled_by(l.id);
        });
        if let Some(e) = mags_error {
            ui.colored_label(ui.visuals().error_fg_color, e);
        }
        ui.checkbox(&mut view.auto_curve, "run the curve after every change")
            .on_hover_text("the curve simulates images × magnitudes: minutes at the reference setting");
    });
}

/// The scene (the paper's grid, the mock bulge field, a catalogue file) and the focal plane (one array or
/// the 2 × 2 of four). Choosing the bulge also chooses the quad, as `jsim simulate --scene bulge` does.
fn scene_ui(ui: &mut egui::Ui, cfg: &mut Config) {
    section(ui, "Scene and focal plane");
    ui.horizontal(|ui| {
        ui.radio_value(&mut cfg.scene.kind, SceneKind::Grid, "paper grid")
            .on_hover_text("the paper's 20 × 20 grid of equal stars on one array");
        if ui
            .radio_value(&mut cfg.scene.kind, SceneKind::Bulge, "mock bulge")
            .on_hover_text("the Galactic-centre field: stars from Hw 8 to 17, reddened, on the sky")
            .clicked()
        {
            cfg.focal_plane.layout = Layout::Quad;
        }
        ui.radio_value(&mut cfg.scene.kind, SceneKind::Catalogue, "catalogue")
            .on_hover_text("a CSV or FITS table: x, y (pixels) or ra, dec; hw, j_h or j, h");
    });
    match cfg.scene.kind {
        SceneKind::Catalogue => {
            let mut path = cfg
                .scene
                .catalogue
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_default();
            ui.horizontal(|ui| {
                let l = ui.label("file");
                if ui
                    .add(egui::TextEdit::singleline(&mut path).desired_width(220.0))
                    .labelled_by(l.id)
                    .changed()
                {
                    cfg.scene.catalogue = (!path.trim().is_empty()).then(|| path.trim().into());
                }
            });
        }
        SceneKind::Bulge => {
            ui.add(
                Slider::new(&mut cfg.scene.bulge.density_per_arcmin2, 1.0..=300.0)
                    .logarithmic(true)
                    .text("stars per arcmin²"),
            )
            .on_hover_text(
                "100 is the Galactic-centre field to Hw 17 (about 1e5 stars on the four arrays: about a \
                 minute per exposure with the realistic ACE on 2 cores)",
            );
        }
        SceneKind::Grid => {}
    }
    instrument_ui(ui, cfg);
    ui.horizontal(|ui| {
        ui.label("focal plane");
        ui.radio_value(&mut cfg.focal_plane.layout, Layout::Single, "one array")
            .on_hover_text("one 1968² array in its pixel axes: every analysis panel");
        ui.radio_value(&mut cfg.focal_plane.layout, Layout::Quad, "2 × 2 arrays")
            .on_hover_text(
                "four arrays turned 0/90/180/270° on the sky with gaps: the frame view shows them \
                 in their sky layout (the analysis panels are those of one array)",
            );
    });
}

/// Which telescope takes the images: the instrument as built (the configuration's `[as_built]` deviations; a
/// click restores the typical ones) or exactly as designed (every deviation 0: `--instrument design`), and the
/// as-built wavefront's deviation. The products the analysis reads come from the design either way.
fn instrument_ui(ui: &mut egui::Ui, cfg: &mut Config) {
    let designed = cfg.as_built.has_no_deviation();
    ui.horizontal(|ui| {
        ui.label("instrument");
        if ui
            .radio(!designed, "as built")
            .on_hover_text(
                "the telescope as built: its wavefront, distortion, gain, read noise and pointing off the \
                 design by seeded, typical amounts; every product the analysis reads from the design",
            )
            .clicked()
            && designed
        {
            cfg.as_built = cfg.as_built.with_deviations_of(AsBuilt::default());
        }
        if ui
            .radio(designed, "as designed")
            .on_hover_text("every deviation 0: the telescope exactly as designed (the control)")
            .clicked()
        {
            cfg.as_built = cfg.as_built.for_instrument(InstrumentModel::Design);
        }
    });
    if !designed {
        ui.add(
            Slider::new(&mut cfg.as_built.wavefront_rms_nm, 0.0..=150.0)
                .text("wavefront off the design [nm rms]"),
        )
        .on_hover_text("the static Z4–Z11 deviation at the field centre (30 nm rms: typical)");
    }
}

/// The natural modes of the ACE PSD: centre, half-width and amplitude of each Lorentzian; add and remove.
fn modes_ui(ui: &mut egui::Ui, modes: &mut Vec<Mode>) {
    egui::CollapsingHeader::new(format!("natural modes ({})", modes.len()))
        .id_salt("modes")
        .default_open(false)
        .show(ui, |ui| {
            let mut remove = None;
            egui::Grid::new("modes_grid")
                .num_columns(4)
                .spacing([6.0, 2.0])
                .show(ui, |ui| {
                    ui.label("f [Hz]");
                    ui.label("width [Hz]");
                    ui.label("amplitude");
                    ui.label("");
                    ui.end_row();
                    for (k, m) in modes.iter_mut().enumerate() {
                        let n = k + 1;
                        ui.add(
                            DragValue::new(&mut m.freq_hz)
                                .range(0.001..=3000.0)
                                .speed(0.1),
                        )
                        .on_hover_text(format!("mode {n} centre frequency [Hz]"));
                        ui.add(
                            DragValue::new(&mut m.width_hz)
                                .range(0.001..=100.0)
                                .speed(0.01),
                        )
                        .on_hover_text(format!("mode {n} half-width [Hz]"));
                        ui.add(
                            DragValue::new(&mut m.amplitude)
                                .range(0.0..=1.0)
                                .speed(1e-5)
                                .custom_formatter(|v, _| format!("{v:.2e}"))
                                .custom_parser(|s| s.trim().parse().ok()),
                        )
                        .on_hover_text(format!("mode {n} amplitude (PSD units × Hz)"));
                        if ui
                            .small_button("del")
                            .on_hover_text(format!("remove mode {n}"))
                            .clicked()
                        {
                            remove = Some(k);
                        }
                        ui.end_row();
                    }
                });
            if let Some(k) = remove {
                modes.remove(k);
            }
            if ui.button("add mode").clicked() {
                let f = modes.last().map(|m| m.freq_hz + 20.0).unwrap_or(20.0);
                modes.push(Mode {
                    freq_hz: f,
                    width_hz: 0.5,
                    amplitude: 1e-3,
                });
            }
        });
}
