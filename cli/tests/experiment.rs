//! `l3p experiment` end to end through real processes: a micro-experiment (A1 pretraining, two
//! target robots × {l3p, l3p-transfer}, one seed) interrupted mid-arm with Ctrl-C, resumed, finished,
//! reported; a finished experiment reruns without touching its arms. One `[[variants]]` arm (a
//! warm-started transfer) rides along.

#![cfg(target_os = "linux")]

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::TINY_FLAT_TASK;

fn l3p(args: &[&str], cwd: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn text(out: &std::process::Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Learner iterations recorded in a run's metrics file, in file order.
fn iterations(run_dir: &Path) -> Vec<u64> {
    std::fs::read_to_string(run_dir.join("metrics.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains("\"source\":\"learner\""))
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["iteration"].as_u64())
        .collect()
}

/// The base config every arm starts from (after `[run]` and [`TINY_FLAT_TASK`]).
const BASE_REST: &str = r#"
[learner]
checkpoint_every = 1
[rollout]
steps_per_env = 8
[[actors]]
robot = "a1"
envs = 4
"#;

const SPEC: &str = r#"
[experiment]
name = "micro"
base_config = "base.toml"
data_dir = "data"
seeds = [1]
parallel = 2
[pretrain]
robots = ["a1"]
methods = ["l3p"]
iterations = 12
[targets]
robots = ["go1", "spot"]
methods = ["l3p", "l3p-transfer"]
iterations = 3
[evaluation]
episodes = 2
envs = 2
forward = [0.5]
terrain_types = ["flat", "pyramid_slope"]
terrain_rounds = 2
[[variants]]
name = "warm"
robots = ["go1"]
methods = ["l3p-transfer"]
transfer_heads = "prototype"
"#;

#[test]
fn an_interrupted_experiment_resumes_finishes_and_reports() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    // A small terrain grid for the per-terrain-type evaluations (4 levels, 2 columns of 8 m).
    let task = TINY_FLAT_TASK.replace(
        "preset = \"flat\"",
        "preset = \"flat\"\nnum_rows = 4\nnum_cols = 2\ntile_size = 8.0\nborder_width = 2.0\nmax_init_level = 1",
    );
    assert_ne!(task, TINY_FLAT_TASK);
    let base = format!("[run]\nname = \"unused\"\n{task}{BASE_REST}");
    std::fs::write(cwd.join("base.toml"), base).unwrap();
    std::fs::write(cwd.join("micro.toml"), SPEC).unwrap();
    let exp = cwd.join("data/micro");
    let pretrain_run = exp.join("pretrain-l3p-s1/pretrain-l3p-s1");

    // The plan: one pretraining arm, then 2 robots × 2 methods, then the variant's warm-started
    // transfer arm, as `l3p train` invocations.
    let out = l3p(&["experiment", "plan", "micro.toml"], cwd);
    let plan = text(&out);
    assert!(out.status.success(), "{plan}");
    assert!(plan.contains("6 arms"), "{plan}");
    assert!(
        plan.contains("l3p train data/micro/arms/pretrain-l3p-s1.toml --quiet"),
        "{plan}"
    );
    assert!(
        plan.contains("data/micro/arms/spot-l3p-transfer-s1.toml"),
        "{plan}"
    );

    // Start the experiment in its own process group and interrupt it (Ctrl-C reaches the whole
    // group) while the pretraining arm is part-way.
    let mut run = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["experiment", "run", "micro.toml"])
        .current_dir(cwd)
        .process_group(0)
        // Asked for, a backtrace must still not decorate an interruption (an expected end).
        .env("RUST_BACKTRACE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(cwd.join("run.err")).unwrap())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(120);
    while iterations(&pretrain_run).len() < 3 {
        assert!(
            Instant::now() < deadline,
            "the pretraining arm never got going"
        );
        assert!(
            run.try_wait().unwrap().is_none(),
            "experiment run exited early"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = Command::new("kill")
        .args(["-INT", "--", &format!("-{}", run.id())])
        .status()
        .unwrap();
    assert!(status.success());
    let exit = run.wait().unwrap();
    let err = std::fs::read_to_string(cwd.join("run.err")).unwrap();
    assert_eq!(exit.code(), Some(130), "{err}");
    assert!(err.contains("interrupted\nhint: rerun"), "{err}");
    assert!(!err.to_lowercase().contains("backtrace"), "{err}");
    // Wait for the trainer (same group) to write its final checkpoint and exit.
    let deadline = Instant::now() + Duration::from_secs(60);
    while Path::new(&format!("/proc/{}", pid_of(&exp.join("pretrain-l3p-s1")))).exists() {
        assert!(
            Instant::now() < deadline,
            "the trainer did not stop on Ctrl-C"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let reached = iterations(&pretrain_run).len();
    assert!(
        reached < 12,
        "the arm finished before the interruption ({reached})"
    );
    assert!(!exp.join("pretrain-l3p-s1/done.json").exists());
    let out = l3p(&["experiment", "status", "micro.toml"], cwd);
    let status_text = text(&out);
    assert!(
        status_text.contains("interrupted at iteration"),
        "{status_text}"
    );
    // The scratch arms do not wait for the pretraining (`parallel = 2`): on a slow machine one can
    // finish its 3 iterations before the pretraining reaches its third. Nothing that depends on
    // the pretraining has run.
    let is_done = |arm: &str| {
        status_text
            .lines()
            .any(|l| l.trim_start().starts_with(arm) && l.contains(" done"))
    };
    assert!(!is_done("pretrain-l3p-s1"), "{status_text}");
    for arm in [
        "go1-l3p-transfer-s1",
        "spot-l3p-transfer-s1",
        "go1-l3p-transfer-warm-s1",
    ] {
        assert!(!is_done(arm), "{arm} ran before its core: {status_text}");
    }

    // Rerun: the pretraining arm resumes from its checkpoint (iterations continue, none repeats),
    // then the targets train, the transfer arms from the pretrained core.
    let out = l3p(&["experiment", "run", "micro.toml"], cwd);
    let log = text(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("6/6 arms done"), "{log}");
    let its = iterations(&pretrain_run);
    assert_eq!(
        its,
        (1..=12).collect::<Vec<u64>>(),
        "resumed, not restarted"
    );
    let done: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(exp.join("spot-l3p-transfer-s1/done.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(done["iterations"], 3);
    assert!(done["wall_seconds"].as_f64().unwrap() > 0.0);
    // The final policy under the command mix and at 0.5 m/s; zero-shot: A1's policy on Spot.
    assert_eq!(done["evaluations"]["spot"].as_array().unwrap().len(), 2);
    assert_eq!(done["zero_shot"].as_array().unwrap().len(), 2);
    // Each evaluated terrain type alone, curriculum on: a level reached within the 4 levels.
    for t in ["flat", "pyramid_slope"] {
        let row = &done["by_terrain"][t];
        let level = row["final_terrain_level"]
            .as_f64()
            .unwrap_or_else(|| panic!("{t}: {}", done["by_terrain"]));
        assert!((0.0..=3.0).contains(&level), "{t}: {row}");
        assert_eq!(row["episodes"].as_u64().unwrap(), 4, "{t}: {row}");
    }
    // Zero-shot per terrain: A1's pretrained policy on Spot on each type, before fine-tuning.
    for t in ["flat", "pyramid_slope"] {
        let row = &done["zero_shot_by_terrain"][t];
        assert_eq!(row["episodes"].as_u64(), Some(4), "{t}: {row}");
    }
    let pretrained: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(exp.join("pretrain-l3p-s1/done.json")).unwrap(),
    )
    .unwrap();
    assert!(pretrained["by_terrain"].as_object().unwrap().is_empty());
    assert!(
        pretrained["zero_shot_by_terrain"]
            .as_object()
            .unwrap()
            .is_empty()
    );
    let arm_config = std::fs::read_to_string(exp.join("arms/spot-l3p-transfer-s1.toml")).unwrap();
    assert!(
        arm_config.contains("mode = \"l3p-transfer\""),
        "{arm_config}"
    );
    assert!(
        arm_config.contains("pretrain-l3p-s1/pretrain-l3p-s1/checkpoints/latest.ckpt"),
        "{arm_config}"
    );
    let warm = std::fs::read_to_string(exp.join("arms/go1-l3p-transfer-warm-s1.toml")).unwrap();
    assert!(warm.contains("transfer_heads = \"prototype\""), "{warm}");

    // A finished experiment reruns without touching its arms.
    let stamp = |arm: &str| {
        std::fs::metadata(exp.join(arm).join("done.json"))
            .unwrap()
            .modified()
            .unwrap()
    };
    let before = stamp("go1-l3p-s1");
    let out = l3p(&["experiment", "run", "micro.toml"], cwd);
    assert!(out.status.success(), "{}", text(&out));
    assert!(!text(&out).contains("starting"), "{}", text(&out));
    assert_eq!(stamp("go1-l3p-s1"), before);

    // `evaluate` fills in what an arm finished by an older l3p lacks (here: its zero-shot
    // per-terrain levels), keeping the rest of its done.json; a second call has nothing to do.
    let go1_done = exp.join("go1-l3p-transfer-s1/done.json");
    let mut old: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&go1_done).unwrap()).unwrap();
    let wall = old["wall_seconds"].clone();
    old.as_object_mut().unwrap().remove("zero_shot_by_terrain");
    std::fs::write(&go1_done, old.to_string()).unwrap();
    let out = l3p(&["experiment", "evaluate", "micro.toml"], cwd);
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("1 of 6 finished arms updated"),
        "{}",
        text(&out)
    );
    let filled: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&go1_done).unwrap()).unwrap();
    assert_eq!(filled["wall_seconds"], wall);
    assert_eq!(
        filled["zero_shot_by_terrain"].as_object().unwrap().len(),
        2,
        "{filled}"
    );
    let out = l3p(&["experiment", "evaluate", "micro.toml"], cwd);
    assert!(
        text(&out).contains("0 of 6 finished arms updated"),
        "{}",
        text(&out)
    );

    // The report: one row per robot and method, curves per robot.
    let out = l3p(&["experiment", "report", "micro.toml"], cwd);
    let report = text(&out);
    assert!(out.status.success(), "{report}");
    for row in [
        "| a1 | l3p | 1 |",
        "| go1 | l3p-transfer | 1 |",
        "| go1 | l3p-transfer [warm] | 1 |",
        "| spot | l3p | 1 |",
    ] {
        assert!(report.contains(row), "{row}: {report}");
    }
    assert!(exp.join("report/README.md").exists());
    let svg = std::fs::read_to_string(exp.join("report/go1-episode_return.svg")).unwrap();
    assert!(svg.contains("l3p-transfer (1 seeds)"), "{svg}");
    assert!(svg.contains("l3p-transfer [warm] (1 seeds)"), "{svg}");
    // The simple→complex section: a table row per target arm group and a radar per robot.
    assert!(report.contains("| flat | pyramid_slope |"), "{report}");
    assert!(report.contains("| spot | zero-shot l3p | 1 |"), "{report}");
    let readme = std::fs::read_to_string(exp.join("report/README.md")).unwrap();
    assert!(readme.contains("## Simple → complex terrain"), "{readme}");
    // Iterations to the from-scratch final reward: in 3 iterations an episode ends only where a
    // robot falls, which the physics decides (it differs between machines). The section is there
    // exactly when a target robot's from-scratch arm has a final reward (the bar to reach), and
    // is never filled with NaN.
    let scratch_final_reward = report
        .lines()
        .filter(|line| {
            line.starts_with("| go1 | l3p | 1 |") || line.starts_with("| spot | l3p | 1 |")
        })
        .filter_map(|line| line.split('|').nth(9))
        .any(|final_reward| final_reward.contains('.'));
    assert_eq!(
        readme.contains("from-scratch final reward"),
        scratch_final_reward,
        "{readme}"
    );
    assert!(!readme.contains("NaN"), "{readme}");
    let radar = std::fs::read_to_string(exp.join("report/spot-terrains.svg")).unwrap();
    assert!(
        radar.contains("pyramid slope") && radar.contains("l3p-transfer (1 seeds)"),
        "{radar}"
    );
    assert!(exp.join("report/go1-terrains.png").exists());
    assert!(exp.join("report/go1-episode_return.png").exists());
}

/// The pid an arm's `running.pid` names (0 when gone).
fn pid_of(arm_dir: &Path) -> u32 {
    std::fs::read_to_string(arm_dir.join("running.pid"))
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0)
}

/// Samples to walk end to end: an `until_walks` micro-experiment (an A1 core, Go1 from scratch and
/// with the core under mapped transfer heads) whose arms cannot walk in 2 iterations. Every arm
/// trains with `--until-walks`, settles at its cap as "did not walk", records samples as a lower
/// bound and, for the transfer arm, the walk check of the policy it started from; the report opens
/// with the samples-to-walk table.
#[test]
fn an_until_walks_experiment_records_arms_that_do_not_walk_within_the_cap() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    let base = format!("[run]\nname = \"unused\"\n{TINY_FLAT_TASK}{BASE_REST}");
    std::fs::write(cwd.join("base.toml"), base).unwrap();
    let spec = r#"
[experiment]
name = "walks"
base_config = "base.toml"
data_dir = "data"
seeds = [1]
until_walks = true
by_robot = true
[pretrain]
robots = ["a1"]
methods = ["l3p"]
iterations = 2
[targets]
robots = ["go1"]
methods = ["l3p"]
iterations = 2
[evaluation]
episodes = 2
envs = 2
forward = [0.5]
[[variants]]
name = "mapped"
methods = ["l3p-transfer"]
transfer_heads = "mapped"
"#;
    std::fs::write(cwd.join("walks.toml"), spec).unwrap();
    let out = l3p(&["experiment", "plan", "walks.toml"], cwd);
    let plan = text(&out);
    assert!(out.status.success(), "{plan}");
    assert!(
        plan.contains("l3p train data/walks/arms/go1-l3p-s1.toml --quiet --until-walks"),
        "{plan}"
    );
    let out = l3p(&["experiment", "run", "walks.toml"], cwd);
    assert!(out.status.success(), "{}", text(&out));
    let exp = cwd.join("data/walks");
    let done = |arm: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(exp.join(arm).join("done.json")).unwrap())
            .unwrap()
    };
    // 4 envs × 8 steps per iteration; the cap of 2 iterations is a lower bound of 64 samples.
    for arm in [
        "pretrain-l3p-s1",
        "go1-l3p-s1",
        "go1-l3p-transfer-mapped-s1",
    ] {
        let walk = &done(arm)["walk"];
        assert_eq!(walk["walks"], false, "{arm}: {walk}");
        assert_eq!(
            (walk["iteration"].as_u64(), walk["samples"].as_u64()),
            (Some(2), Some(64)),
            "{arm}"
        );
        assert_eq!(done(arm)["iterations"], 2, "{arm}");
    }
    assert!(done("go1-l3p-s1")["zero_shot_walk"].is_null());
    let zero = &done("go1-l3p-transfer-mapped-s1")["zero_shot_walk"];
    assert_eq!(zero["walks"], false, "{zero}");
    assert!(!zero["rows"].as_array().unwrap().is_empty(), "{zero}");
    assert!(!zero["failures"].as_array().unwrap().is_empty(), "{zero}");

    let out = l3p(&["experiment", "status", "walks.toml"], cwd);
    let status = text(&out);
    assert!(
        status.contains("go1-l3p-s1") && status.contains("did not walk within its cap"),
        "{status}"
    );
    let out = l3p(&["experiment", "report", "walks.toml"], cwd);
    let report = text(&out);
    assert!(out.status.success(), "{report}");
    assert!(
        report.contains("| go1 | l3p | 0/1 | ≥ 0.00 | >0.00–>0.00 | 1× |"),
        "{report}"
    );
    assert!(
        report.contains("| go1 | l3p-transfer [mapped] | 0/1 |"),
        "{report}"
    );
    let readme = std::fs::read_to_string(exp.join("report/README.md")).unwrap();
    let (walk, paper) = (
        readme
            .find("## Samples to walk")
            .expect("a samples-to-walk section"),
        readme
            .find("| robot | method | seeds |")
            .expect("the paper's table"),
    );
    assert!(walk < paper, "samples to walk comes first:\n{readme}");
}
