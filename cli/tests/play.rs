//! `l3p play --save`: the `.rrd` it writes is read back with the pinned Rerun SDK (its chunk store)
//! and holds the robot's bodies with one transform per control step, the time series, the contact
//! arrows and the summary. Uses the shipped walking A1 policy (docs/a1-flat-session31/policy).
#![cfg(feature = "rerun")]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use rerun::external::re_chunk_store::{ChunkStore, ChunkStoreConfig};

mod common;
use common::TINY_FLAT_TASK;

fn policy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/a1-flat-session31/policy")
}

/// Per entity: rows on the `step` timeline, and whether it has static data.
fn read_rrd(path: &Path) -> BTreeMap<String, (usize, bool)> {
    read_rrd_on(path, "step")
}

/// Per entity: rows on `timeline`, and whether it has static data.
fn read_rrd_on(path: &Path, timeline: &str) -> BTreeMap<String, (usize, bool)> {
    let mut file = std::fs::File::open(path).unwrap();
    let stores = ChunkStore::from_rrd_reader(&ChunkStoreConfig::default(), &mut file)
        .expect("the pinned SDK decodes the recording");
    let mut out: BTreeMap<String, (usize, bool)> = BTreeMap::new();
    for store in stores.values() {
        for chunk in store.iter_physical_chunks() {
            let entry = out.entry(chunk.entity_path().to_string()).or_default();
            if chunk.timelines().keys().any(|t| t.as_str() == timeline) {
                entry.0 += chunk.num_rows();
            } else if chunk.is_static() {
                entry.1 = true;
            }
        }
    }
    out
}

#[test]
fn play_saves_a_recording_the_rerun_sdk_reads_back_with_every_step() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("a1.rrd");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args([
            "play",
            "--robot",
            "a1",
            "--seconds",
            "1",
            "--command",
            "0.5,0,0",
        ])
        .arg("--policy")
        .arg(policy())
        .arg("--save")
        .arg(&rrd)
        .arg("--data-dir")
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("base height mean / min"), "{stdout}");
    let entities = read_rrd(&rrd);
    let steps = 50; // 1 s at 50 Hz
    let rows = |e: &str| entities.get(e).map(|x| x.0).unwrap_or(0);
    let has_static = |e: &str| entities.get(e).map(|x| x.1).unwrap_or(false);
    // The trunk and a foot-carrying calf move every step; their shapes are static.
    let bodies: BTreeSet<&String> = entities
        .keys()
        .filter(|e| e.starts_with("/world/a1/") && e.matches('/').count() == 3)
        .collect();
    assert!(bodies.len() >= 13, "{bodies:?}");
    for body in ["/world/a1/trunk", "/world/a1/FL_calf"] {
        assert_eq!(rows(body), steps, "{body}: {entities:?}");
        assert!(has_static(&format!("{body}/shape0")), "{body} shape");
    }
    assert!(has_static("/world/ground"));
    for series in [
        "/plots/a1/velocity/vx_command",
        "/plots/a1/velocity/vx_measured",
        "/plots/a1/base_height",
        "/plots/a1/joints/FL_calf_joint/target",
        "/plots/a1/joints/FL_calf_joint/position",
        "/plots/a1/torque/FR_hip_joint",
        "/plots/a1/gait_diagram/RR_foot",
        "/world/a1/contacts",
    ] {
        assert_eq!(rows(series), steps, "{series}: {entities:?}");
    }
    assert!(has_static("/summary/a1"));
}

#[test]
fn two_robots_side_by_side_and_bad_arguments_fail_before_simulating() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("two.rrd");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["play", "--robot", "a1,a1", "--seconds", "0.2"])
        .args(["--commands", "0:0.5,0,0;0.1:0,0,0.5"])
        .arg("--policy")
        .arg(policy())
        .arg("--save")
        .arg(&rrd)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let entities = read_rrd(&rrd);
    for label in ["a1_0", "a1_1"] {
        assert_eq!(entities[&format!("/world/{label}/trunk")].0, 10);
    }
    assert!(entities.contains_key("/events"), "schedule change logged");

    for (args, needle) in [
        (vec!["--robot", "a1"], "--save run.rrd"),
        (
            vec!["--robot", "a1", "--save", "x.rrd", "--commands", "1:0,0,0"],
            "start at time 0",
        ),
        (
            vec!["--robot", "a1,go1,spot", "--save", "x.rrd", "--policy", "p"],
            "--policy has 2 entries",
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
            .arg("play")
            .arg("--policy")
            .arg(policy())
            .args(&args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
    }
}

/// `l3p train --rerun <file>.rrd` writes every metric of every iteration on the `iteration`
/// timeline and, every `--rerun-every` iterations, a 5 s rollout with `l3p play`'s entities.
#[test]
fn train_streams_metrics_and_rollouts_to_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("run.toml");
    std::fs::write(
        &config,
        format!("[run]\nname = \"watched\"\n{TINY_FLAT_TASK}")
            + "[learner]\nmax_iterations = 4\n[rollout]\nsteps_per_env = 8\n[[actors]]\nrobot = \"a1\"\nenvs = 4\n",
    )
    .unwrap();
    let rrd = dir.path().join("train.rrd");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .arg("train")
        .arg(&config)
        .arg("--data-dir")
        .arg(dir.path().join("data"))
        .args(["--quiet", "--rerun-every", "2", "--rerun"])
        .arg(&rrd)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let by_iteration = read_rrd_on(&rrd, "iteration");
    let rows = |m: &BTreeMap<String, (usize, bool)>, e: &str| m.get(e).map(|x| x.0).unwrap_or(0);
    // One row per iteration for the learner's metrics, `a/b` names nested (no 2 s episode ends in
    // 4 × 8 steps, so there are no episode metrics to see here).
    for metric in [
        "/metrics/samples_per_second",
        "/metrics/update_seconds",
        "/metrics/time/physics_seconds",
    ] {
        assert_eq!(rows(&by_iteration, metric), 4, "{metric}: {by_iteration:?}");
    }
    // A rollout from iteration 2 on (one still running when the next is due is not doubled, and
    // the last is awaited when training stops), 250 control steps each, the trunk's pose every step.
    let by_step = read_rrd(&rrd);
    let trunk = rows(&by_step, "/world/a1/trunk");
    assert!(trunk > 0 && trunk % 250 == 0, "{trunk} rows: {by_step:?}");
    assert_eq!(rows(&by_step, "/plots/a1/velocity/vx_command"), trunk);
    assert!(
        by_step.get("/summary/a1").is_some_and(|x| x.1),
        "{by_step:?}"
    );
}
