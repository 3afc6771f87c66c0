//! `l3p --help` lists exactly the commands that exist, and every command's help renders.

use std::process::Command;

fn l3p(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

const COMMANDS: [&str; 17] = [
    "train",
    "play",
    "experiment",
    "transfer",
    "learner",
    "actor",
    "metrics",
    "eval",
    "report",
    "robots",
    "bench",
    "deploy",
    "sim-robot",
    "operate",
    "export",
    "registry",
    "config",
];

#[test]
fn top_level_help_lists_the_commands() {
    let (ok, text) = l3p(&["--help"]);
    assert!(ok);
    for command in COMMANDS {
        assert!(
            text.contains(&format!("  {command} ")),
            "{command} missing from:\n{text}"
        );
    }
}

#[test]
fn every_command_has_help() {
    for command in COMMANDS {
        let (ok, text) = l3p(&[command, "--help"]);
        assert!(
            ok && text.contains("Usage: l3p"),
            "{command} --help:\n{text}"
        );
    }
}

#[test]
fn bad_config_is_a_clear_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, "[learner]\nmax_iteration = 3\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["config", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("max_iteration") && err.contains("bad.toml") && !err.contains("panicked"),
        "{err}"
    );
}

#[test]
fn closed_stdout_is_not_a_panic() {
    // The reader goes away before `l3p` prints (`l3p robots list | head -0`).
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["robots", "list"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        matches!(out.status.code(), Some(0 | 141)),
        "{:?}",
        out.status
    );
}
