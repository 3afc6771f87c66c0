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

/// `l3p registry serve --gc-keep 5 --gc-every-s 1`: the service applies the retention at start and
/// again to versions stored while it runs, and keeps serving.
#[test]
fn the_service_applies_retention_while_it_serves() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let port = l3p_net::free_loopback_port().unwrap();
    let log = std::fs::File::create(dir.path().join("serve.log")).unwrap();
    let mut service = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["registry", "serve", "--data-dir"])
        .arg(dir.path())
        .args(["--listen", &format!("tcp/127.0.0.1:{port}")])
        .args(["--gc-keep", "5", "--gc-every-s", "1"])
        .env("RUST_LOG", "info")
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .unwrap();
    let wait_for = |want: &[u64]| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while run_versions(dir.path()) != want {
            assert!(
                std::time::Instant::now() < deadline,
                "versions {:?}, want {want:?}; log:\n{}",
                run_versions(dir.path()),
                std::fs::read_to_string(dir.path().join("serve.log")).unwrap_or_default()
            );
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    };
    wait_for(&[2, 3, 8, 9, 10, 11, 12]);
    let reg = Registry::open(dir.path()).unwrap();
    for i in 13..=15 {
        reg.put(ckpt("run", i)).unwrap();
    }
    wait_for(&[2, 3, 11, 12, 13, 14, 15]);
    assert!(service.try_wait().unwrap().is_none(), "the service stopped");
    service.kill().unwrap();
    service.wait().unwrap();
    let log = std::fs::read_to_string(dir.path().join("serve.log")).unwrap();
    assert!(
        log.contains("registry gc") && log.contains("versions_removed"),
        "{log}"
    );
}
