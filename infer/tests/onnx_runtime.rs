//! The ONNX form of an export runs in onnxruntime and computes what `deploy/examples/numpy_policy.py`
//! computes from the safetensors form (`deploy/examples/test_onnx.py` checks the model with
//! `onnx.checker` and compares on random observations). Skipped, saying so, when python3 is missing;
//! the Python script itself prints `skipped: ...` and passes without onnx/onnxruntime.

use std::path::Path;
use std::process::Command;

use l3p_infer::DeployPolicy;

fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

#[test]
fn onnxruntime_runs_the_export_like_numpy() {
    let source = repo().join("docs/a1-flat-session27/policy");
    let policy = DeployPolicy::load(&source).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let onnx = dir.path().join("policy.onnx");
    std::fs::write(&onnx, policy.to_onnx().unwrap()).unwrap();

    let out = match Command::new("python3")
        .arg(repo().join("deploy/examples/test_onnx.py"))
        .arg(&onnx)
        .arg(&source)
        .output()
    {
        Ok(out) => out,
        Err(e) => {
            eprintln!("SKIPPED onnxruntime_runs_the_export_like_numpy: no python3 ({e})");
            return;
        }
    };
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    eprintln!("{stdout}{stderr}");
    assert!(
        out.status.success(),
        "test_onnx.py failed:\n{stdout}{stderr}"
    );
}
