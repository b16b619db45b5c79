//! `jsim-app` as a user meets it without a window: `--help` and `--version` answer on the terminal, an unknown
//! option is an error with the usage, and without a display the explorer says so in one line (exit 1), never a
//! windowing library's debug error.

use std::process::Command;

fn app() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jsim-app"))
}

#[test]
fn help_version_and_no_display_answer_without_a_window() {
    let out = app().arg("--help").output().expect("run");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Usage: jsim-app"), "{text}");
    let out = app().arg("--version").output().expect("run");
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("jsim-app "));
    let out = app().arg("--bogus").output().expect("run");
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown option --bogus"));
    let out = app()
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no display") && err.lines().count() == 1,
        "{err}"
    );
}
