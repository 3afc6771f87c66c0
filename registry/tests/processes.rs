//! Real processes against one database: concurrent writers never lose or duplicate a version, a
//! writer killed with SIGKILL in the middle of a put leaves a valid database without the partial
//! version, and a gc killed before its commit leaves every version in place.
//!
//! The child processes are this test binary run again with `L3P_REGISTRY_CHILD` set: it then runs
//! only the ignored helper test `child`, which does what the variable says.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use l3p_registry::{ArtifactKind, ListFilter, PutRequest, Registry, RetentionPolicy};

const CHILD_ENV: &str = "L3P_REGISTRY_CHILD";
const DIR_ENV: &str = "L3P_REGISTRY_CHILD_DIR";
const MARK: &str = "L3P-CHILD";

fn spawn_child(role: &str, dir: &Path) -> Child {
    Command::new(std::env::current_exe().unwrap())
        .args([
            "child",
            "--exact",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, role)
        .env(DIR_ENV, dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap()
}

/// Lines of the child's stdout that carry our marker, with the marker removed.
fn marked_lines(child: &mut Child) -> impl Iterator<Item = String> + use<> {
    let stdout = child.stdout.take().unwrap();
    BufReader::new(stdout)
        .lines()
        .map_while(Result::ok)
        // libtest prints `test child ... ` without a newline before the first line of the body.
        .filter_map(|line| {
            line.find(MARK)
                .map(|at| line[at + MARK.len()..].trim().to_string())
        })
}

fn blob(writer: &str, i: usize, len: usize) -> Vec<u8> {
    let mut bytes = format!("{writer}:{i}:").into_bytes();
    bytes.resize(len, (i % 251) as u8);
    bytes
}

#[test]
fn concurrent_writers_never_lose_or_duplicate_a_version() {
    const PER_WRITER: usize = 15;
    let dir = tempfile::tempdir().unwrap();
    Registry::open(dir.path()).unwrap();
    let mut children: Vec<Child> = ["writer-a", "writer-b"]
        .iter()
        .map(|role| spawn_child(role, dir.path()))
        .collect();
    // Release both writers at once so that their puts interleave.
    std::fs::write(dir.path().join("go"), b"").unwrap();
    let mut claimed: Vec<Vec<u64>> = Vec::new();
    for child in &mut children {
        let versions: Vec<u64> = marked_lines(child)
            .filter_map(|l| l.strip_prefix("put ").and_then(|v| v.parse().ok()))
            .collect();
        assert!(child.wait().unwrap().success());
        assert_eq!(versions.len(), PER_WRITER);
        claimed.push(versions);
    }

    let reg = Registry::open(dir.path()).unwrap();
    let all = reg
        .list(&ListFilter {
            name: Some("shared-ckpt".into()),
            ..Default::default()
        })
        .unwrap();
    let numbers: Vec<u64> = all.iter().map(|m| m.version).collect();
    let expected: Vec<u64> = (1..=2 * PER_WRITER as u64).collect();
    assert_eq!(
        numbers, expected,
        "versions must be exactly 1..=30, no gap, no duplicate"
    );
    let a: BTreeSet<u64> = claimed[0].iter().copied().collect();
    let b: BTreeSet<u64> = claimed[1].iter().copied().collect();
    assert!(
        a.is_disjoint(&b),
        "two writers were given the same version: {a:?} {b:?}"
    );
    assert_eq!(a.union(&b).copied().collect::<Vec<_>>(), expected);
    // Every write is there with its own bytes.
    for (writer, versions) in ["writer-a", "writer-b"].iter().zip(&claimed) {
        for (i, version) in versions.iter().enumerate() {
            let (meta, bytes) = reg.get_blob(&format!("shared-ckpt@{version}")).unwrap();
            assert_eq!(bytes, blob(writer, i, 4096), "{}", meta.reference());
            assert_eq!(meta.producer, *writer);
        }
    }
    let latest = reg.alias_history("shared-ckpt", Some("latest")).unwrap();
    assert_eq!(
        latest.iter().map(|e| e.version).collect::<Vec<_>>(),
        expected
    );
    assert!(reg.check_integrity().unwrap().is_ok());
}

#[test]
fn a_writer_killed_inside_its_transaction_leaves_no_trace() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = spawn_child("killed-in-commit", dir.path());
    let mut lines = marked_lines(&mut child);
    assert_eq!(lines.next().as_deref(), Some("committed 1"));
    assert_eq!(lines.next().as_deref(), Some("in-transaction 2"));
    // The child now holds the write lock with version 2's rows written (and spilled to the WAL).
    child.kill().unwrap(); // SIGKILL
    let status = child.wait().unwrap();
    assert!(!status.success());
    let wal = dir.path().join("registry.db-wal");
    let wal_len = std::fs::metadata(&wal).map(|m| m.len()).unwrap_or(0);
    eprintln!("WAL left by the killed writer: {wal_len} bytes");

    let reg = Registry::open(dir.path()).unwrap();
    let report = reg.check_integrity().unwrap();
    assert!(report.is_ok(), "{report:?}");
    assert_eq!(
        report.blobs_checked, 1,
        "the partial version's blob must be absent"
    );
    let versions: Vec<u64> = reg
        .list(&ListFilter::default())
        .unwrap()
        .iter()
        .map(|m| m.version)
        .collect();
    assert_eq!(versions, [1]);
    assert_eq!(reg.get_meta("crash@latest").unwrap().version, 1);
    assert_eq!(reg.alias_history("crash", None).unwrap().len(), 1);
    assert!(reg.get_meta("crash@2").unwrap_err().is_not_found());
    // The database is writable again and the number of the lost put is reused.
    let next = reg
        .put(PutRequest::new(
            "crash",
            ArtifactKind::Checkpoint,
            b"after".to_vec(),
        ))
        .unwrap();
    assert_eq!(next.meta.version, 2);
}

#[test]
fn a_writer_killed_at_a_random_moment_leaves_a_valid_database() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = spawn_child("writer-loop", dir.path());
    let mut committed = 0;
    // Keep reading the pipe open until the kill: a closed pipe would make the child's println fail.
    let mut lines = marked_lines(&mut child);
    for line in lines.by_ref() {
        if let Some(v) = line.strip_prefix("put ") {
            committed = v.parse().unwrap();
        }
        if committed >= 3 {
            break;
        }
    }
    // Somewhere in the next put (they take a few ms each with 1 MB blobs and synchronous=FULL).
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    std::thread::sleep(Duration::from_micros(500 + u64::from(nanos % 20_000)));
    child.kill().unwrap();
    child.wait().unwrap();
    drop(lines);

    let reg = Registry::open(dir.path()).unwrap();
    assert!(reg.check_integrity().unwrap().is_ok());
    let all = reg.list(&ListFilter::default()).unwrap();
    let numbers: Vec<u64> = all.iter().map(|m| m.version).collect();
    assert!(
        numbers.len() as u64 >= committed,
        "a reported commit was lost: {numbers:?} < {committed}"
    );
    assert_eq!(numbers, (1..=numbers.len() as u64).collect::<Vec<_>>());
    for meta in &all {
        let (_, bytes) = reg.get_blob(&meta.reference()).unwrap();
        assert_eq!(bytes, blob("loop", meta.version as usize, 1 << 20));
    }
    assert_eq!(
        reg.get_meta("looped@latest").unwrap().version,
        numbers.len() as u64
    );
}

#[test]
fn a_gc_killed_inside_its_transaction_leaves_every_version() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = spawn_child("gc-killed", dir.path());
    let mut lines = marked_lines(&mut child);
    assert_eq!(lines.next().as_deref(), Some("stored 12"));
    assert_eq!(lines.next().as_deref(), Some("in-gc 7"));
    // The child has deleted 7 versions, their blobs and the deletion triggers, uncommitted.
    child.kill().unwrap(); // SIGKILL
    assert!(!child.wait().unwrap().success());
    drop(lines);

    let reg = Registry::open(dir.path()).unwrap();
    let report = reg.check_integrity().unwrap();
    assert!(report.is_ok(), "{report:?}");
    assert_eq!(report.blobs_checked, 12);
    let versions: Vec<u64> = reg
        .list(&ListFilter::default())
        .unwrap()
        .iter()
        .map(|m| m.version)
        .collect();
    assert_eq!(versions, (1..=12).collect::<Vec<_>>());
    for version in 1..=12 {
        let (_, bytes) = reg.get_blob(&format!("gc-crash@{version}")).unwrap();
        assert_eq!(bytes, blob("gc", version as usize, 64 << 10));
    }
    {
        let raw = rusqlite::Connection::open(reg.path()).unwrap();
        let err = raw.execute("DELETE FROM versions", []).unwrap_err();
        assert!(err.to_string().contains("immutable"), "{err}");
    }
    // A normal gc then does the job.
    let done = reg.gc(&RetentionPolicy::default(), false).unwrap();
    assert_eq!(done.versions_removed, 7);
    assert_eq!(reg.check_integrity().unwrap().blobs_checked, 5);
}

/// Child process body (run only through `spawn_child`).
#[test]
#[ignore = "helper run as a child process by the other tests in this file"]
fn child() {
    let Ok(role) = std::env::var(CHILD_ENV) else {
        eprintln!("skipped: child helper, started by the other tests of this file");
        return;
    };
    let dir = std::path::PathBuf::from(std::env::var(DIR_ENV).unwrap());
    match role.as_str() {
        "writer-a" | "writer-b" => {
            let go = dir.join("go");
            let deadline = Instant::now() + Duration::from_secs(30);
            while !go.exists() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(2));
            }
            let reg = Registry::open(&dir).unwrap();
            for i in 0..15 {
                let req = PutRequest::new(
                    "shared-ckpt",
                    ArtifactKind::Checkpoint,
                    blob(&role, i, 4096),
                )
                .producer(&role);
                let outcome = reg.put(req).unwrap();
                assert!(outcome.created);
                println!("{MARK} put {}", outcome.meta.version);
            }
        }
        "killed-in-commit" => {
            let mut reg = Registry::open(&dir).unwrap();
            let first = reg
                .put(PutRequest::new(
                    "crash",
                    ArtifactKind::Checkpoint,
                    b"before".to_vec(),
                ))
                .unwrap();
            println!("{MARK} committed {}", first.meta.version);
            reg.set_before_commit_hook(|meta| {
                use std::io::Write;
                println!("{MARK} in-transaction {}", meta.version);
                std::io::stdout().flush().unwrap();
                std::thread::sleep(Duration::from_secs(120));
            });
            // 8 MB: larger than SQLite's page cache, so uncommitted pages reach the WAL file.
            reg.put(PutRequest::new(
                "crash",
                ArtifactKind::Checkpoint,
                vec![7u8; 8 << 20],
            ))
            .unwrap();
            unreachable!("the parent kills this process before the commit");
        }
        "gc-killed" => {
            let mut reg = Registry::open(&dir).unwrap();
            for i in 1..=12 {
                reg.put(PutRequest::new(
                    "gc-crash",
                    ArtifactKind::Checkpoint,
                    blob("gc", i, 64 << 10),
                ))
                .unwrap();
            }
            println!("{MARK} stored 12");
            reg.set_before_gc_commit_hook(|report| {
                use std::io::Write;
                println!("{MARK} in-gc {}", report.versions_removed);
                std::io::stdout().flush().unwrap();
                std::thread::sleep(Duration::from_secs(120));
            });
            reg.gc(&RetentionPolicy::default(), false).unwrap();
            unreachable!("the parent kills this process before the commit");
        }
        "writer-loop" => {
            let reg = Registry::open(&dir).unwrap();
            for i in 1.. {
                let req =
                    PutRequest::new("looped", ArtifactKind::Checkpoint, blob("loop", i, 1 << 20));
                let outcome = reg.put(req).unwrap();
                println!("{MARK} put {}", outcome.meta.version);
            }
        }
        other => panic!("unknown child role {other}"),
    }
}
