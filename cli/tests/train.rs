//! `l3p train` (local mode) end to end: registry, learner and an actor process on loopback, with
//! collection overlapping updates (`max_policy_lag = 1`); the run leaves metrics, a checkpoint, a
//! deployable policy in the registry that `l3p eval` can play, and a report.

use std::process::Command;

fn l3p(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn local_mode_trains_checkpoints_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        r#"
[run]
name = "local"
[env]
height_scan = false
[env.terrain]
preset = "flat"
[model]
encoder_hidden = [32]
core_hidden = [32]
critic_hidden = [32]
[model.recovery]
obs_hidden = [32]
diffusion_steps = 10
eval_samples = 32
[learner]
max_policy_lag = 1
max_iterations = 5
checkpoint_every = 2
registry_checkpoint_every = 4
[rollout]
steps_per_env = 8
[[actors]]
robot = "a1"
envs = 4
"#,
    )
    .unwrap();
    let data = dir.path().join("data");
    let data_arg = data.to_str().unwrap();
    let out = l3p(&[
        "train",
        config.to_str().unwrap(),
        "--data-dir",
        data_arg,
        "--quiet",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("stopped at iteration 5"), "{stdout}");

    let metrics = std::fs::read_to_string(data.join("local/metrics.jsonl")).unwrap();
    let learner_lines = metrics
        .lines()
        .filter(|l| l.contains("\"source\":\"learner\""))
        .count();
    assert_eq!(learner_lines, 5, "{metrics}");
    assert!(data.join("local/checkpoints/latest.ckpt").exists());
    // Local checkpoints at 2, 4 and 5 (shutdown); the registry keeps 4 and the final 5.
    let out = l3p(&[
        "registry",
        "list",
        "--name",
        "local-checkpoint",
        "--json",
        "--data",
        data_arg,
    ]);
    let listed: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
    let text = listed.to_string();
    assert!(
        text.contains("\"iteration\":4.0") && text.contains("\"iteration\":5.0"),
        "{text}"
    );
    assert!(!text.contains("\"iteration\":2.0"), "{text}");

    let out = l3p(&[
        "eval",
        "--policy",
        "local-a1@latest",
        "--data-dir",
        data_arg,
        "--robot",
        "a1",
        "--episodes",
        "2",
        "--envs",
        "2",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("xy-velocity tracking error"), "{stdout}");
    assert!(stdout.contains("base height above ground"), "{stdout}");

    let out = l3p(&["report", "local", "--data-dir", data_arg]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("| local | 5 |"), "{stdout}");
    assert!(
        data.join("local/report/episode_return.svg").exists()
            || !metrics.contains("episode_return")
    );
}
