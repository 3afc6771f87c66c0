//! Retention (`Registry::gc`): what is kept (the newest N checkpoint versions, aliased versions,
//! lineage parents transitively, every other kind), what goes (versions, their lineage, unreferenced
//! blobs), dry runs that change nothing, a gc that fails before its commit leaving the database as
//! it was, and the immutability triggers still guarding versions afterwards.

use std::panic::AssertUnwindSafe;
use std::path::Path;

use l3p_registry::{
    ArtifactKind, GcReport, KeepReason, KeptVersion, LineageRole, ListFilter, PutRequest, Registry,
    RetentionPolicy,
};

/// Distinct, compressible-enough bytes large enough that removing them shrinks the file.
fn blob(tag: &str, i: u64) -> Vec<u8> {
    let mut bytes = format!("{tag}:{i}:").into_bytes();
    bytes
        .extend((0..32 * 1024u32).map(|k| (k.wrapping_mul(31).wrapping_add(i as u32) % 251) as u8));
    bytes
}

fn checkpoint(name: &str, i: u64) -> PutRequest {
    PutRequest::new(name, ArtifactKind::Checkpoint, blob(name, i)).producer("learner/test")
}

/// The fixture of issue 46:
/// - `pre` (checkpoint): 7 versions.
/// - `run` (checkpoint): 12 versions; `run@2` was resumed from `pre@1`; `run@5` has the same bytes
///   as `copy@1`; alias `best` on `run@3`.
/// - `transfer` (checkpoint): 1 version initialised from `run@2`.
/// - `copy` (checkpoint): 1 version.
/// - `core` (core): 8 versions, none aliased but `latest`.
fn fixture(dir: &Path) -> Registry {
    let reg = Registry::open(dir).unwrap();
    for i in 1..=7 {
        reg.put(checkpoint("pre", i)).unwrap();
    }
    reg.put(PutRequest::new(
        "copy",
        ArtifactKind::Checkpoint,
        blob("run", 5),
    ))
    .unwrap();
    for i in 1..=12 {
        let mut req = checkpoint("run", i);
        if i == 2 {
            req = req.lineage(LineageRole::FromCheckpoint, "pre@1");
        }
        assert_eq!(reg.put(req).unwrap().meta.version, i);
    }
    reg.tag("run@3", "best").unwrap();
    reg.put(checkpoint("transfer", 1).lineage(LineageRole::InitialisedFrom, "run@2"))
        .unwrap();
    for i in 1..=8 {
        reg.put(PutRequest::new("core", ArtifactKind::Core, blob("core", i)))
            .unwrap();
    }
    reg
}

fn versions_of(reg: &Registry, name: &str) -> Vec<u64> {
    reg.list(&ListFilter {
        name: Some(name.into()),
        ..Default::default()
    })
    .unwrap()
    .iter()
    .map(|m| m.version)
    .collect()
}

/// Every row of every table (blob data as its length), to compare databases.
fn dump(db: &Path) -> Vec<String> {
    let raw = rusqlite::Connection::open(db).unwrap();
    let mut rows = Vec::new();
    for (table, columns) in [
        ("blobs", "sha256, size, length(data)"),
        ("artifacts", "*"),
        ("versions", "*"),
        ("lineage", "*"),
        ("aliases", "*"),
        ("alias_history", "*"),
        ("sqlite_master", "type, name, sql"),
    ] {
        let mut stmt = raw
            .prepare(&format!("SELECT {columns} FROM {table} ORDER BY 1, 2"))
            .unwrap();
        let n = stmt.column_count();
        let mut query = stmt.query([]).unwrap();
        while let Some(row) = query.next().unwrap() {
            let cells: Vec<String> = (0..n)
                .map(|k| format!("{:?}", row.get_ref(k).unwrap()))
                .collect();
            rows.push(format!("{table}: {}", cells.join(" | ")));
        }
    }
    rows
}

fn assert_triggers_guard_versions(db: &Path) {
    let raw = rusqlite::Connection::open(db).unwrap();
    for statement in [
        "DELETE FROM versions",
        "DELETE FROM lineage",
        "UPDATE versions SET size = 0",
        "DELETE FROM alias_history",
    ] {
        let err = raw.execute(statement, []).unwrap_err();
        assert!(
            err.to_string().contains("immutable") || err.to_string().contains("append-only"),
            "{statement}: {err}"
        );
    }
    let left: i64 = raw
        .query_row("SELECT COUNT(*) FROM versions", [], |row| row.get(0))
        .unwrap();
    assert!(left > 0);
}

fn keep(n: u64) -> RetentionPolicy {
    RetentionPolicy { keep_last: n }
}

#[test]
fn gc_keeps_recent_aliased_and_lineage_versions_and_removes_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let reg = fixture(dir.path());
    let blobs_before = reg.check_integrity().unwrap().blobs_checked;

    let report = reg.gc(&keep(5), false).unwrap();

    assert_eq!(versions_of(&reg, "run"), [2, 3, 8, 9, 10, 11, 12]);
    // pre@1 survives transitively: transfer@1 -> run@2 -> pre@1.
    assert_eq!(versions_of(&reg, "pre"), [1, 3, 4, 5, 6, 7]);
    assert_eq!(versions_of(&reg, "transfer"), [1]);
    assert_eq!(versions_of(&reg, "copy"), [1]);
    assert_eq!(
        versions_of(&reg, "core"),
        (1..=8).collect::<Vec<_>>(),
        "other kinds are kept whole"
    );
    let run = report.artifacts.iter().find(|a| a.name == "run").unwrap();
    assert_eq!(run.removed, [1, 4, 5, 6, 7]);
    assert_eq!(run.kept, [2, 3, 8, 9, 10, 11, 12]);
    assert_eq!(report.versions_removed, 6, "run@1,4,5,6,7 and pre@2");
    assert_eq!(report.lineage_removed, 0);
    assert_eq!(
        report.kept_because,
        [
            KeptVersion {
                reference: "run@3".into(),
                reason: KeepReason::Alias {
                    alias: "best".into()
                },
            },
            KeptVersion {
                reference: "run@2".into(),
                reason: KeepReason::Lineage {
                    child: "transfer@1".into(),
                    role: LineageRole::InitialisedFrom,
                },
            },
            KeptVersion {
                reference: "pre@1".into(),
                reason: KeepReason::Lineage {
                    child: "run@2".into(),
                    role: LineageRole::FromCheckpoint,
                },
            },
        ]
    );

    // Blobs: run@5's bytes live on as copy@1; the other five removed versions' blobs are gone.
    assert_eq!(report.blobs_removed, 5);
    let integrity = reg.check_integrity().unwrap();
    assert!(integrity.is_ok(), "{integrity:?}");
    assert_eq!(integrity.blobs_checked, blobs_before - 5);
    assert_eq!(reg.get_blob("copy@1").unwrap().1, blob("run", 5));
    assert_eq!(report.blob_bytes_removed, 5 * blob("run", 1).len() as u64);
    assert!(
        report.file_bytes_after < report.file_bytes_before,
        "VACUUM must shrink the file: {} -> {}",
        report.file_bytes_before,
        report.file_bytes_after
    );

    // Removed versions are not found (and the error names the latest); kept ones read back intact.
    let err = reg.get_meta("run@4").unwrap_err();
    assert!(err.is_not_found(), "{err}");
    assert!(err.to_string().contains("latest is 12"), "{err}");
    assert_eq!(reg.get_blob("run@2").unwrap().1, blob("run", 2));
    assert_eq!(reg.get_meta("run@best").unwrap().version, 3);
    let graph = reg.lineage("transfer@1").unwrap();
    let upstream: Vec<_> = graph.upstream.iter().map(|l| l.parent.as_str()).collect();
    assert_eq!(upstream, ["run@2", "pre@1"]);
    // Lineage never dangles: every parent of every row exists.
    let raw = rusqlite::Connection::open(reg.path()).unwrap();
    let dangling: i64 = raw
        .query_row(
            "SELECT COUNT(*) FROM lineage l WHERE NOT EXISTS
             (SELECT 1 FROM versions v WHERE v.name = l.parent_name AND v.version = l.parent_version)",
            [],
            |row| row.get(0),
        )
        .unwrap();
    assert_eq!(dangling, 0);

    // Numbering goes on after the newest version, never reusing a removed number.
    assert_eq!(reg.put(checkpoint("run", 13)).unwrap().meta.version, 13);
    // A second gc removes only what the new version pushed out of the window.
    let again = reg.gc(&keep(5), false).unwrap();
    assert_eq!(again.versions_removed, 1);
    assert_eq!(versions_of(&reg, "run"), [2, 3, 9, 10, 11, 12, 13]);
}

#[test]
fn a_dry_run_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    drop(fixture(dir.path()));
    let db = dir.path().join("registry.db");
    assert!(
        !dir.path().join("registry.db-wal").exists(),
        "closing checkpoints the WAL"
    );
    let (rows, bytes) = (dump(&db), std::fs::read(&db).unwrap());

    let reg = Registry::open(dir.path()).unwrap();
    let report: GcReport = reg.gc(&keep(5), true).unwrap();
    assert!(report.dry_run);
    assert_eq!(report.versions_removed, 6);
    assert_eq!(report.blobs_removed, 5);
    assert_eq!(report.file_bytes_after, report.file_bytes_before);
    assert_eq!(versions_of(&reg, "run").len(), 12);
    drop(reg);

    assert_eq!(dump(&db), rows);
    assert!(std::fs::read(&db).unwrap() == bytes, "the file changed");
    // The plan of the dry run is what a real gc then does.
    let reg = Registry::open(dir.path()).unwrap();
    let real = reg.gc(&keep(5), false).unwrap();
    assert_eq!(real.artifacts, report.artifacts);
    assert_eq!(real.kept_because, report.kept_because);
    assert_eq!(real.blobs_removed, report.blobs_removed);
}

#[test]
fn a_gc_that_fails_before_its_commit_leaves_the_database_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let mut reg = fixture(dir.path());
    let db = reg.path().to_path_buf();
    let rows = dump(&db);
    reg.set_before_gc_commit_hook(|report| {
        // Every deletion is done (the triggers are dropped) when this runs.
        assert_eq!(report.versions_removed, 6);
        panic!("simulated crash inside the gc transaction");
    });
    let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| reg.gc(&keep(5), false)));
    assert!(outcome.is_err(), "the hook must have panicked");

    assert_eq!(
        dump(&db),
        rows,
        "rows, blobs and triggers must be as before"
    );
    assert_triggers_guard_versions(&db);
    assert_eq!(versions_of(&reg, "run").len(), 12);
    assert!(reg.check_integrity().unwrap().is_ok());

    // The same registry (its connection went through the panic) still collects normally.
    reg.set_before_gc_commit_hook(|_| {});
    let report = reg.gc(&keep(5), false).unwrap();
    assert_eq!(report.versions_removed, 6);
    assert_eq!(versions_of(&reg, "run"), [2, 3, 8, 9, 10, 11, 12]);
}

#[test]
fn versions_stay_immutable_after_a_gc() {
    let dir = tempfile::tempdir().unwrap();
    let reg = fixture(dir.path());
    reg.gc(&keep(5), false).unwrap();
    assert_triggers_guard_versions(reg.path());
    assert_eq!(versions_of(&reg, "run").len(), 7);
    assert!(reg.check_integrity().unwrap().is_ok());
}

#[test]
fn gc_refuses_to_keep_nothing_and_has_nothing_to_do_on_a_small_registry() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    for i in 1..=3 {
        reg.put(checkpoint("small", i)).unwrap();
    }
    let err = reg.gc(&keep(0), false).unwrap_err();
    assert!(err.to_string().contains("at least"), "{err}");
    let report = reg.gc(&RetentionPolicy::default(), false).unwrap();
    assert_eq!(report.keep_last, 5);
    assert_eq!(report.versions_removed, 0);
    assert_eq!(report.blobs_removed, 0);
    assert_eq!(versions_of(&reg, "small"), [1, 2, 3]);
}

#[test]
fn open_existing_refuses_a_missing_or_corrupt_database() {
    let dir = tempfile::tempdir().unwrap();
    let err = Registry::open_existing(&dir.path().join("nowhere")).unwrap_err();
    assert!(err.to_string().contains("no registry database"), "{err}");
    assert!(!dir.path().join("nowhere").exists(), "nothing is created");
    std::fs::write(dir.path().join("registry.db"), vec![0x5a; 8192]).unwrap();
    let err = Registry::open_existing(dir.path()).unwrap_err();
    assert!(err.to_string().contains("not a database"), "{err}");
}

/// A training run uploads a deploy artifact with every registry checkpoint, its lineage naming the
/// checkpoint it was exported from. Every deploy artifact stays, but that edge does not keep the
/// checkpoint: gc removes the old checkpoints (the soak's 195 versions were all kept before) and
/// the edges to them, leaving no lineage row dangling. A checkpoint resumed from another still
/// keeps it.
#[test]
fn deploy_artifacts_stay_without_pinning_the_checkpoints_they_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    for i in 1..=10 {
        reg.put(checkpoint("run-checkpoint", i)).unwrap();
        reg.put(
            PutRequest::new("run-a1", ArtifactKind::Deploy, blob("deploy", i))
                .robot("a1")
                .lineage(LineageRole::FromCheckpoint, &format!("run-checkpoint@{i}")),
        )
        .unwrap();
    }
    // Another run resumed from an older checkpoint: that one must stay.
    reg.put(checkpoint("resumed", 1).lineage(LineageRole::FromCheckpoint, "run-checkpoint@2"))
        .unwrap();
    let report = reg.gc(&keep(3), false).unwrap();
    assert_eq!(versions_of(&reg, "run-checkpoint"), [2, 8, 9, 10]);
    assert_eq!(versions_of(&reg, "run-a1"), (1..=10).collect::<Vec<_>>());
    assert_eq!(report.versions_removed, 6);
    assert_eq!(
        (report.lineage_removed, report.lineage_cut),
        (6, 6),
        "the edges of run-a1@1,3,4,5,6,7"
    );
    let upstream = |r: &str| -> Vec<String> {
        reg.lineage(r)
            .unwrap()
            .upstream
            .iter()
            .map(|l| l.parent.clone())
            .collect()
    };
    assert!(upstream("run-a1@4").is_empty());
    assert_eq!(upstream("run-a1@9"), ["run-checkpoint@9"]);
    assert_eq!(upstream("run-a1@2"), ["run-checkpoint@2"]);
    assert_eq!(upstream("resumed@1"), ["run-checkpoint@2"]);
    let integrity = reg.check_integrity().unwrap();
    assert!(integrity.is_ok(), "{integrity:?}");
    assert_eq!(reg.get_blob("run-a1@1").unwrap().1, blob("deploy", 1));
    assert_triggers_guard_versions(reg.path());
}
