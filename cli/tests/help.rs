//! `l3p --help` lists exactly the commands that exist, and every command's help renders.
//! A failed command prints `error:` and its chain of causes, a backtrace only when asked for.

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

/// A URDF whose leg joints have no effort limits fails `l3p robots add` with its hint; CI's
/// `RUST_BACKTRACE=1` (meant for panics) does not add a stack backtrace, `-v` does.
#[test]
fn an_error_prints_its_chain_and_a_backtrace_only_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .split(" effort=\"")
        .enumerate()
        .map(|(i, part)| match i {
            0 => part,
            // Drop the attribute's value and its closing quote.
            _ => part.split_once('"').map_or(part, |(_, rest)| rest),
        })
        .collect::<String>();
    std::fs::write(dir.path().join("no_limits.urdf"), urdf).unwrap();
    let add = |extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
            .args(["robots", "add", "no_limits.urdf", "--name", "no_limits"])
            .args(extra)
            .current_dir(dir.path())
            .env_remove("L3P_ROBOTS_DIR")
            .env_remove("RUST_LIB_BACKTRACE")
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = add(&[]);
    assert!(
        err.lines().any(|l| l.starts_with("error: "))
            && err.contains("without limits")
            && err.contains("\nhint: "),
        "{err}"
    );
    assert!(!err.to_lowercase().contains("backtrace"), "{err}");
    let err = add(&["-v"]);
    assert!(
        err.lines().any(|l| l.starts_with("error: "))
            && err.contains("\nhint: ")
            && err.contains("Stack backtrace"),
        "{err}"
    );
}
