//! `l3p registry gc` with the real binary: a dry run reports and changes nothing, a real run removes
//! old checkpoint versions and says what kept the others, and a missing or corrupt database is a
//! clear error, not a panic.

use std::path::Path;
use std::process::{Command, Output};

use l3p_registry::{ArtifactKind, LineageRole, ListFilter, PutRequest, Registry};

fn l3p(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap()
}

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn ckpt(name: &str, i: u64) -> PutRequest {
    let mut bytes = format!("{name}:{i}:").into_bytes();
    bytes.resize(16 * 1024, (i % 251) as u8);
    PutRequest::new(name, ArtifactKind::Checkpoint, bytes)
}

/// `run` with 12 checkpoint versions, alias `prod` on 3, and `transfer@1` initialised from `run@2`.
fn fixture(dir: &Path) {
    let reg = Registry::open(dir).unwrap();
    for i in 1..=12 {
        reg.put(ckpt("run", i)).unwrap();
    }
    reg.tag("run@3", "prod").unwrap();
    reg.put(ckpt("transfer", 1).lineage(LineageRole::InitialisedFrom, "run@2"))
        .unwrap();
}

fn run_versions(dir: &Path) -> Vec<u64> {
    Registry::open(dir)
        .unwrap()
        .list(&ListFilter {
            name: Some("run".into()),
            ..Default::default()
        })
        .unwrap()
        .iter()
        .map(|m| m.version)
        .collect()
}

#[test]
fn gc_dry_run_then_real_run() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let data = dir.path().to_str().unwrap();
    let db = dir.path().join("registry.db");
    let before = std::fs::read(&db).unwrap();

    let out = l3p(&[
        "registry",
        "gc",
        "--data-dir",
        data,
        "--keep",
        "5",
        "--dry-run",
    ]);
    let dry = text(&out);
    assert!(out.status.success(), "{dry}");
    assert!(dry.contains("would remove 5 versions"), "{dry}");
    assert!(dry.contains("1,4,5,6,7"), "{dry}");
    assert!(dry.contains("run@3") && dry.contains("alias prod"), "{dry}");
    assert!(
        dry.contains("run@2") && dry.contains("transfer@1 --initialised_from-->"),
        "{dry}"
    );
    assert_eq!(run_versions(dir.path()).len(), 12);
    assert!(
        std::fs::read(&db).unwrap() == before,
        "a dry run changed the file"
    );

    let out = l3p(&["registry", "gc", "--data-dir", data, "--keep", "5"]);
    let real = text(&out);
    assert!(out.status.success(), "{real}");
    assert!(
        real.contains("removed 5 versions, 0 lineage rows, 5 blobs"),
        "{real}"
    );
    assert!(real.contains("database file: "), "{real}");
    assert_eq!(run_versions(dir.path()), [2, 3, 8, 9, 10, 11, 12]);

    // The JSON report of a second run: nothing left to remove.
    let out = l3p(&["registry", "gc", "--data", data, "--json"]);
    assert!(out.status.success(), "{}", text(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["versions_removed"], 0);
    assert_eq!(report["keep_last"], 5);
}

#[test]
fn gc_on_a_missing_or_corrupt_database_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-dir");
    let out = l3p(&["registry", "gc", "--data-dir", missing.to_str().unwrap()]);
    let msg = text(&out);
    assert!(!out.status.success());
    assert!(msg.contains("no registry database"), "{msg}");
    assert!(msg.contains("hint:"), "{msg}");
    assert!(!msg.contains("panicked"), "{msg}");
    assert!(!missing.exists(), "gc must not create a database");

    std::fs::write(dir.path().join("registry.db"), vec![0x42; 4096]).unwrap();
    let out = l3p(&["registry", "gc", "--data-dir", dir.path().to_str().unwrap()]);
    let msg = text(&out);
    assert!(!out.status.success());
    assert!(msg.contains("not a database"), "{msg}");
    assert!(!msg.contains("panicked"), "{msg}");

    let out = l3p(&[
        "registry",
        "gc",
        "--data-dir",
        dir.path().to_str().unwrap(),
        "--keep",
        "0",
    ]);
    let msg = text(&out);
    assert!(!out.status.success());
    assert!(msg.contains("--keep"), "{msg}");
    assert!(!msg.contains("panicked"), "{msg}");
}
