//! The toolbar: the view (an exposure or a sequence), configuration file (open, save, copy as CLI), progress
//! with Cancel, messages.

use crate::action::Action;
use crate::settings::CentralView;
use crate::state::Status;

/// The toolbar; `config_path` and `central` are edited in place. The configuration's buttons are the
/// exposure view's.
pub fn toolbar_ui(
    ui: &mut egui::Ui,
    config_path: &mut String,
    central: &mut CentralView,
    status: &Status,
    actions: &mut Vec<Action>,
) {
    ui.horizontal_wrapped(|ui| {
        ui.heading("JASMINE astrometry explorer");
        ui.separator();
        for v in CentralView::ALL {
            ui.selectable_value(central, v, v.name())
                .on_hover_text(match v {
                    CentralView::Exposure => "simulate and analyse an exposure of the configuration",
                    CentralView::Sequence => {
                        "a step-stare sequence's coverage and astrometric solution (jsim sequence, jsim solve)"
                    }
                    CentralView::Transit => {
                        "transit photometry: a bright target's light curve and noise budget (jsim transit)"
                    }
                });
        }
        ui.separator();
        if *central == CentralView::Exposure {
            config_ui(ui, config_path, actions);
            status_ui(ui, status, actions);
        } else if status.busy {
            status_ui(ui, status, actions);
        }
    });
    if let Some(inv) = status
        .invalid
        .as_ref()
        .filter(|_| *central == CentralView::Exposure)
    {
        ui.colored_label(
            ui.visuals().error_fg_color,
            format!("Parameters not run: {inv}"),
        );
    }
    if let Some(n) = &status.note {
        let color = if n.is_error {
            ui.visuals().error_fg_color
        } else {
            ui.visuals().weak_text_color()
        };
        let prefix = if n.is_error { "Error: " } else { "" };
        ui.colored_label(color, format!("{prefix}{}", n.text));
    }
}

/// The configuration file: its path, Open, Save, Copy as CLI.
fn config_ui(ui: &mut egui::Ui, config_path: &mut String, actions: &mut Vec<Action>) {
    let l = ui.label("config file");
    ui.add(egui::TextEdit::singleline(config_path).desired_width(220.0))
        .labelled_by(l.id)
        .on_hover_text("path for Open, Save and Copy as CLI (relative to the working directory)");
    if ui
        .button("Open config")
        .on_hover_text("load this TOML file")
        .clicked()
    {
        actions.push(Action::Open);
    }
    if ui
        .button("Save config")
        .on_hover_text("write the TOML that reproduces what is on screen")
        .clicked()
    {
        actions.push(Action::Save);
    }
    if ui
        .button("Copy as CLI: experiment")
        .on_hover_text(
            "save the config, then copy the `jsim experiment` command of the magnitude curve",
        )
        .clicked()
    {
        actions.push(Action::CopyExperimentCli);
    }
    if ui
        .button("Copy as CLI: simulate")
        .on_hover_text("save the config, then copy the `jsim simulate` command of these images")
        .clicked()
    {
        actions.push(Action::CopySimulateCli);
    }
    ui.separator();
}

/// The work's progress with Cancel, or idle with Run again.
fn status_ui(ui: &mut egui::Ui, status: &Status, actions: &mut Vec<Action>) {
    if status.busy {
        ui.add(egui::Spinner::new());
        let (frac, text) = match &status.progress {
            Some(p) if p.total > 0 => (
                p.done as f32 / p.total as f32,
                format!("{}: {}", p.stage.name(), p.note),
            ),
            Some(p) => (0.0, format!("{}: {}", p.stage.name(), p.note)),
            None => (0.0, "starting".into()),
        };
        ui.add(egui::ProgressBar::new(frac).desired_width(220.0).text(text));
        if ui
            .button("Cancel")
            .on_hover_text("stop the running work")
            .clicked()
        {
            actions.push(Action::Cancel);
        }
    } else {
        let idle = ui.label("idle");
        if let Some(t) = status.last_job_s {
            idle.on_hover_text(format!("the last run took {t:.1} s"));
        }
        if ui
            .button("Run again")
            .on_hover_text("recompute everything for the parameters on screen")
            .clicked()
        {
            actions.push(Action::RunAll);
        }
    }
}
