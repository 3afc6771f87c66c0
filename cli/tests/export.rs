//! `l3p export --format safetensors`: from a deploy export missing the robot I/O contract and from a
//! checkpoint-less export alike, the written policy.safetensors + policy.json carry weights and the
//! controller contract, and `deploy/examples/numpy_policy.py` (the README's numpy snippet) computes the
//! same actions as the deploy controller's inference. The Python half is skipped, saying so, when
//! python3 with numpy is not installed.

use std::path::Path;
use std::process::Command;

use l3p_policy::DeployPolicy;

fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

#[test]
fn export_then_numpy_gives_the_deploy_actions() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("export");
    let source = repo().join("docs/a1-flat-session1/policy");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args([
            "export",
            source.to_str().unwrap(),
            "--format",
            "safetensors",
            "-o",
        ])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let policy = DeployPolicy::load(&out_dir).unwrap();
    let io = policy
        .config
        .io
        .clone()
        .expect("export carries the robot I/O contract");
    assert_eq!(io.joint_names.len(), 12);
    assert_eq!(io.obs_layout.iter().map(|s| s.len).sum::<usize>(), 48);
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("policy.json")).unwrap()).unwrap();
    assert_eq!(json["robot"], "a1");
    assert!((json["io"]["control_dt"].as_f64().unwrap() - 0.02).abs() < 1e-6);

    // A wrong --robot is refused.
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["export", source.to_str().unwrap(), "--robot", "go1", "-o"])
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not go1"));

    // Observations around the standing pose and some far from it.
    let mut obs = Vec::new();
    for k in 0..16 {
        let row: Vec<f32> = (0..48)
            .map(|i| ((i * 7 + k * 13) % 17) as f32 / 17.0 - 0.5)
            .map(|v| v * (1.0 + k as f32 / 4.0))
            .collect();
        obs.push(row);
    }
    let flat: Vec<f32> = obs.iter().flatten().copied().collect();
    let expected = policy.act(&flat).unwrap();

    let numpy_ok = Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !numpy_ok {
        eprintln!(
            "SKIPPED numpy half of export_then_numpy_gives_the_deploy_actions: python3 with numpy is \
             not installed (pip install numpy)"
        );
        return;
    }
    let obs_file = dir.path().join("obs.json");
    std::fs::write(&obs_file, serde_json::to_vec(&obs).unwrap()).unwrap();
    let out = Command::new("python3")
        .arg(repo().join("deploy/examples/numpy_policy.py"))
        .arg(&out_dir)
        .arg(&obs_file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: Vec<Vec<f32>> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(got.len(), 16);
    for (k, row) in got.iter().enumerate() {
        for (j, a) in row.iter().enumerate() {
            let e = expected[k * 12 + j];
            assert!(
                (a - e).abs() <= 1e-4 * (1.0 + e.abs()),
                "obs {k} action {j}: numpy {a} vs l3p {e}"
            );
        }
    }
}

/// `--format onnx` writes policy.onnx (the library's ONNX model of the same export, controller
/// contract included; `infer/tests/onnx_runtime.rs` runs that in onnxruntime) beside the same
/// policy.json; an unknown format is refused with the known ones.
#[test]
fn export_onnx_writes_the_model_of_the_same_export() {
    let dir = tempfile::tempdir().unwrap();
    let source = repo().join("docs/a1-flat-session1/policy");
    let export = |format: &str, out_dir: &Path| {
        Command::new(env!("CARGO_BIN_EXE_l3p"))
            .args(["export", source.to_str().unwrap(), "--format", format, "-o"])
            .arg(out_dir)
            .output()
            .unwrap()
    };
    let (st_dir, onnx_dir) = (dir.path().join("st"), dir.path().join("onnx"));
    for (format, out_dir) in [("safetensors", &st_dir), ("onnx", &onnx_dir)] {
        let out = export(format, out_dir);
        assert!(
            out.status.success(),
            "{format}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert!(!onnx_dir.join("policy.safetensors").exists());
    let onnx = std::fs::read(onnx_dir.join("policy.onnx")).unwrap();
    let policy = DeployPolicy::load(&st_dir).unwrap();
    assert!(policy.config.io.is_some());
    assert_eq!(onnx, policy.to_onnx().unwrap());
    assert_eq!(
        std::fs::read(onnx_dir.join("policy.json")).unwrap(),
        std::fs::read(st_dir.join("policy.json")).unwrap()
    );

    let out = export("tflite", &dir.path().join("x"));
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("tflite") && stderr.contains("safetensors") && stderr.contains("onnx"),
        "{stderr}"
    );
}

/// `l3p export --symmetrized` writes the policy averaged with its mirror image: the same contract,
/// hidden layers twice as wide, actions the mean of the policy's and its mirror image's.
#[test]
fn a_symmetrized_export_is_the_mean_of_the_policy_and_its_mirror() {
    let dir = tempfile::tempdir().unwrap();
    let source = repo().join("docs/a1-flat-session27/policy");
    let out_dir = dir.path().join("sym");
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["export", source.to_str().unwrap(), "--symmetrized", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let original = DeployPolicy::load(&source).unwrap();
    let symmetric = DeployPolicy::load(&out_dir).unwrap();
    assert_eq!(symmetric.config.io, original.config.io);
    assert_eq!(
        symmetric.config.layers[0].output,
        2 * original.config.layers[0].output
    );
    // Its own mirror image is itself: exactly symmetric.
    let robot = l3p_robot::catalog::RobotSpec::by_name("a1").unwrap();
    let clock = original.config.io.as_ref().unwrap().gait_clock_hz > 0.0;
    let mirror = l3p_task::mirror::TaskMirror::new(
        &robot.model().unwrap(),
        &robot.joint_names,
        &robot.default_pose,
        false,
        clock,
    )
    .unwrap();
    let mirrored = symmetric
        .permuted(
            &mirror.observation.index,
            &mirror.observation.sign,
            &mirror.action.index,
            &mirror.action.sign,
        )
        .unwrap();
    let obs: Vec<f32> = (0..2 * original.obs_dim())
        .map(|i| 0.3 * (i as f32 * 0.83).sin())
        .collect();
    for (a, b) in symmetric
        .act(&obs)
        .unwrap()
        .iter()
        .zip(&mirrored.act(&obs).unwrap())
    {
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    }
}
