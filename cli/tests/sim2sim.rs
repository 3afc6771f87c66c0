//! `l3p sim2sim` end to end: the binary writes its embedded script, the policy and the robot's
//! URDF to a temporary directory, plays the shipped A1 export in MuJoCo and returns its verdict;
//! and the script's own tests (`deploy/examples/test_sim2sim.py`: a zero-action export stands, the
//! shipped export walks, a flipped joint is caught, the observation matches the Rust builder).
//! Skipped, saying so, where python3 with numpy and mujoco is not installed.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn mujoco_available(test: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import numpy, mujoco"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!(
            "SKIPPED {test}: python3 with numpy and mujoco is not installed (pip install mujoco)"
        );
    }
    ok
}

#[test]
fn the_script_tests_pass() {
    if !mujoco_available("the_script_tests_pass") {
        return;
    }
    let out = Command::new("python3")
        .arg(root().join("deploy/examples/test_sim2sim.py"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "test_sim2sim.py failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn sim2sim_plays_the_shipped_export_on_its_own_urdf() {
    if !mujoco_available("sim2sim_plays_the_shipped_export_on_its_own_urdf") {
        return;
    }
    let export = root().join("docs/a1-flat-session31/policy");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .arg("sim2sim")
        .arg("--policy")
        .arg(&export)
        .args(["--forward", "0.5", "--seconds", "6", "--seeds", "1"])
        .args(["--joint-damping", "2", "--json"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "l3p sim2sim failed: {stderr}");
    let runs: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let runs = runs.as_array().unwrap();
    assert_eq!(runs.len(), 1);
    let result = &runs[0]["result"];
    // The robot's own URDF was found from the export's robot name.
    assert!(
        result["model"].as_str().unwrap().ends_with("a1.urdf"),
        "{result}"
    );
    assert_eq!(result["contract"]["ok"], true);
    let walk = &result["commands"][0]["seeds"][0];
    assert_eq!(walk["fell"], false, "{walk}");
    assert!(walk["xy_error"].as_f64().unwrap() < 0.2, "{walk}");
    assert!(walk["base_height_pct"].as_f64().unwrap() >= 80.0, "{walk}");

    // --require-pass turns a failing verdict into an error naming the variant: a 1 s episode at a
    // 1.5 m/s command is never tracked within 0.2 m/s from a standstill.
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .arg("sim2sim")
        .arg("--policy")
        .arg(&export)
        .args(["--forward", "1.5", "--seconds", "1", "--seeds", "1"])
        .arg("--require-pass")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("fails in MuJoCo"), "{stderr}");
}

#[test]
fn sim2sim_refuses_a_missing_model_clearly() {
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .arg("sim2sim")
        .arg("--policy")
        .arg(root().join("docs/a1-flat-session31/policy"))
        .args(["--model", "/nonexistent/robot.xml"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("/nonexistent/robot.xml"), "{stderr}");
}
