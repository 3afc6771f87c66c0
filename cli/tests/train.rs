//! `l3p train` (local mode) end to end: registry, learner and an actor process on loopback, with
//! collection overlapping updates (`max_policy_lag = 1`); the run leaves metrics, a checkpoint, a
//! deployable policy in the registry that `l3p eval` can play, and a report.

use std::process::Command;

mod common;
use common::TINY_FLAT_TASK;

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
        format!("[run]\nname = \"local\"\n{TINY_FLAT_TASK}")
            + r#"
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
    // The same records as TensorBoard scalars, steps 1..=5, in the run's directory.
    let events: Vec<_> = std::fs::read_dir(data.join("local"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains("events.out.tfevents."))
        .collect();
    assert_eq!(events.len(), 1, "{events:?}");
    let steps: Vec<i64> = l3p_report::tensorboard::read_events(&events[0])
        .unwrap()
        .iter()
        .filter(|e| e.scalars.iter().any(|(t, _)| t == "Perf/total_fps"))
        .map(|e| e.step)
        .collect();
    assert_eq!(steps, vec![1, 2, 3, 4, 5]);
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

    // Per-terrain skill: one type in every column, every env held at one level.
    let small = dir.path().join("small-terrain.toml");
    std::fs::write(
        &small,
        "[env.terrain]\nnum_rows = 4\nmax_init_level = 3\nnum_cols = 2\nborder_width = 1.0\nvertical_faces = true\n",
    )
    .unwrap();
    let pinned = |kind: &str, level: &str| {
        l3p(&[
            "eval",
            "--policy",
            "local-a1@latest",
            "--data-dir",
            data_arg,
            "--robot",
            "a1",
            "--config",
            small.to_str().unwrap(),
            "--terrain-type",
            kind,
            "--level",
            level,
            "--episodes",
            "2",
            "--envs",
            "2",
            "--json",
        ])
    };
    let out = pinned("pyramid_stairs", "3");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["terrain_type"], "pyramid_stairs", "{json}");
    assert_eq!(
        json["rows"][0]["terrain_level"], 3.0,
        "held at level 3: {json}"
    );
    let out = pinned("pyramid_stairs", "4");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("levels 0..=3"),
        "{stderr}"
    );
    let out = pinned("stairs", "1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("inverted_pyramid_stairs"),
        "{stderr}"
    );

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
    // Several runs overlay into one set of charts (here the run with itself).
    let out = l3p(&["report", "local", "local", "--data-dir", data_arg]);
    assert!(out.status.success());
    if metrics.contains("lin_vel_error") {
        assert!(data.join("local/report/lin_vel_error.png").exists());
        let overlay = data.join("reports/local_vs_local/lin_vel_error.svg");
        let svg = std::fs::read_to_string(&overlay).unwrap();
        assert_eq!(svg.matches("<polyline").count(), 2, "{svg}");
        assert!(
            data.join("reports/local_vs_local/lin_vel_error.png")
                .exists()
        );
    }
}

/// Pids of the processes whose parent is `parent` and whose command line holds `needle`.
#[cfg(target_os = "linux")]
fn children_with(parent: u32, needle: &str) -> Vec<u32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        // `pid (comm) state ppid ...`: the fields after the last ')'.
        let ppid = stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().nth(1))
            .and_then(|p| p.parse::<u32>().ok());
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        if ppid == Some(parent) && String::from_utf8_lossy(&cmdline).contains(needle) {
            out.push(pid);
        }
    }
    out
}

/// Whether `pid` still runs (a zombie has exited).
#[cfg(target_os = "linux")]
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            s.rsplit_once(')')
                .and_then(|(_, rest)| rest.split_whitespace().next().map(|st| st != "Z"))
        })
        .unwrap_or(false)
}

/// SIGKILL of `l3p train` leaves no actor behind: its actors watch the stdin pipe it holds.
#[cfg(target_os = "linux")]
#[test]
fn killed_train_leaves_no_orphan_actor() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        "[run]\nname = \"orphan\"\n[env]\nheight_scan = false\n[env.terrain]\npreset = \"flat\"\n\
         [model]\nencoder_hidden = [16]\ncore_hidden = [16]\ncritic_hidden = [16]\n\
         [model.recovery]\nobs_hidden = [16]\ndiffusion_steps = 5\neval_samples = 8\n\
         [learner]\nmax_iterations = 0\n[rollout]\nsteps_per_env = 4\n\
         [[actors]]\nrobot = \"a1\"\nenvs = 2\n",
    )
    .unwrap();
    let mut train = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["train", config.to_str().unwrap(), "--quiet", "--data-dir"])
        .arg(dir.path().join("data"))
        // The actors share this stderr; their "ready" line is the cue below.
        .env_remove("RUST_LOG")
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(dir.path().join("train.err")).unwrap())
        .spawn()
        .unwrap();
    let log = || std::fs::read_to_string(dir.path().join("train.err")).unwrap_or_default();
    let deadline = Instant::now() + Duration::from_secs(60);
    let actors = loop {
        let found = children_with(train.id(), "--exit-with-parent");
        if !found.is_empty() {
            break found;
        }
        assert!(
            Instant::now() < deadline,
            "no actor started; l3p train said:\n{}",
            log()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    // Let the actor get going (connected, its loop running) before the parent dies.
    while !log().contains("actor ready, waiting for a policy") {
        assert!(
            Instant::now() < deadline,
            "the actor never got ready; the log says:\n{}",
            log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    train.kill().unwrap();
    train.wait().unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    while actors.iter().any(|&pid| running(pid)) {
        assert!(
            Instant::now() < deadline,
            "actor {actors:?} still running 30 s after its parent was killed"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// `--until-walks` evaluates the latest checkpoint every `--eval-every` iterations and records every
/// check (a policy this young does not walk, so the run goes to its last iteration).
#[test]
fn until_walks_records_every_walk_check() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        format!("[run]\nname = \"walks\"\n{TINY_FLAT_TASK}")
            + r#"
[learner]
max_iterations = 4
[rollout]
steps_per_env = 8
[[actors]]
robot = "a1"
envs = 4
"#,
    )
    .unwrap();
    // checkpoint_every stays at its default (25): --until-walks checkpoints as often as it checks,
    // so the first check plays the policy of iteration 2, not an older one.
    let data = dir.path().join("data");
    let out = l3p(&[
        "train",
        config.to_str().unwrap(),
        "--data-dir",
        data.to_str().unwrap(),
        "--quiet",
        "--until-walks",
        "--eval-every",
        "2",
        "--screen-every",
        "1",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("did not hold"), "{stdout}");
    let walk: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("walks/walk.json")).unwrap())
            .unwrap();
    assert_eq!(walk["walks"], false);
    // Only a run that walked keeps the policy its passing check played (`walked/`).
    assert!(!data.join("walks/walked").exists());
    let checks = std::fs::read_to_string(data.join("walks/walk_checks.jsonl")).unwrap();
    let checks: Vec<serde_json::Value> = checks
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!checks.is_empty(), "no walk check recorded");
    assert_eq!(checks[0]["iteration"], 2, "{:?}", checks[0]["iteration"]);
    for c in &checks {
        // The harder speed is evaluated first; while it fails, the 0.5 m/s row is not run.
        let rows = c["rows"].as_array().unwrap();
        assert_eq!(rows.len(), 1, "{c}");
        assert_eq!(rows[0]["forward"], 1.0);
        assert!(
            !rows[0]["walk_failures"].as_array().unwrap().is_empty(),
            "{c}"
        );
        assert!(
            rows[0]["gait"]["target_change_rms"].as_f64().is_some(),
            "{c}"
        );
    }
    // Between checks, quick screens at 1.0 m/s; a policy this young is far off the command, so no
    // screen is promising (a promising one would start a full check at once).
    let screens = std::fs::read_to_string(data.join("walks/walk_screens.jsonl")).unwrap();
    let screens: Vec<serde_json::Value> = screens
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!screens.is_empty(), "no walk screen recorded");
    for s in &screens {
        assert_eq!(s["forward"], 1.0, "{s}");
        assert!(s["lin_vel_error"].as_f64().unwrap() > 0.25, "{s}");
        assert_eq!(s["promising"], false, "{s}");
    }
}

/// A transfer run with `--until-walks` checks the policy it starts from before training changes it
/// (iteration 0: a morphology-mapped start can already walk, and fine-tuning could break it); a
/// run from scratch has no such check (`until_walks_records_every_walk_check`).
#[test]
fn a_transfer_run_until_it_walks_first_checks_the_policy_it_starts_from() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("base.toml");
    std::fs::write(
        &config,
        format!("[run]\nname = \"pre\"\n{TINY_FLAT_TASK}")
            + "[learner]\nmax_iterations = 2\n[rollout]\nsteps_per_env = 8\n[[actors]]\nrobot = \"a1\"\nenvs = 4\nthreads = 1\n",
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
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let core = data.join("pre/checkpoints/latest.ckpt");
    let out = l3p(&[
        "transfer",
        "--robot",
        "go1",
        "--from",
        core.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--data-dir",
        data_arg,
        "--iterations",
        "2",
        "--quiet",
        "--until-walks",
        "--eval-every",
        "2",
        "--screen-every",
        "0",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A two-iteration core does not walk on Go1: the run trains to its end and says so.
    assert!(stdout.contains("did not hold"), "{stdout}");
    let checks = std::fs::read_to_string(data.join("go1-transfer/walk_checks.jsonl")).unwrap();
    let checks: Vec<serde_json::Value> = checks
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(checks[0]["iteration"], 0, "{:?}", checks[0]);
    let rows = checks[0]["rows"].as_array().unwrap();
    assert_eq!(rows[0]["forward"], 1.0, "{rows:?}");
    assert!(
        !rows[0]["walk_failures"].as_array().unwrap().is_empty(),
        "{rows:?}"
    );
}
