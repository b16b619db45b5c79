//! `jsim-app [CONFIG.toml] [--sequence DIR]`: the desktop explorer. `main` answers `--help` and `--version`
//! without a window, rejects a malformed command line with the usage, builds the window options and starts
//! the app (on the settings of the last session, which eframe keeps); without a display it says so in one
//! line instead of a windowing library's debug error.

const USAGE: &str = "\
jsim-app — the JASMINE astrometry explorer (a desktop window)

Usage: jsim-app [CONFIG.toml] [--sequence DIR]
       jsim-app --help | --version

CONFIG.toml      a jsim configuration to open (default: the last session's settings)
--sequence DIR   show a sequence's directory (`jsim sequence --out DIR`): its coverage map and, once
                 `jsim solve --sequence DIR` has run, the precision against the number of exposures and
                 the distortion residual map

Every number it shows comes from the jsim engine; `jsim --help` is the command line.";

fn main() -> std::process::ExitCode {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    match args.first().and_then(|a| a.to_str()) {
        Some("-h" | "--help") => {
            println!("{USAGE}");
            return std::process::ExitCode::SUCCESS;
        }
        Some("-V" | "--version") => {
            println!("jsim-app {}", env!("CARGO_PKG_VERSION"));
            return std::process::ExitCode::SUCCESS;
        }
        _ => {}
    }
    if let Err(e) = app::app::CliArgs::parse(args.iter().cloned()) {
        eprintln!("jsim-app: {e}\n\n{USAGE}");
        return std::process::ExitCode::FAILURE;
    }
    if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        eprintln!(
            "jsim-app: no display (neither DISPLAY nor WAYLAND_DISPLAY is set): the explorer needs a desktop \
             session, or a virtual one (xvfb-run jsim-app); the command line `jsim` needs none"
        );
        return std::process::ExitCode::FAILURE;
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1600.0, 1000.0])
            .with_min_inner_size([1000.0, 700.0])
            .with_title("JASMINE astrometry explorer"),
        ..Default::default()
    };
    let run = eframe::run_native(
        "JASMINE astrometry explorer",
        options,
        Box::new(move |cc| {
            Ok(Box::new(app::ExplorerApp::from_args(
                cc.storage,
                args.into_iter(),
            )))
        }),
    );
    match run {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("jsim-app: the window could not be opened: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
