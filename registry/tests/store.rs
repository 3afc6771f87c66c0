//! The store on its own: immutable numbered versions, deduplication, alias moves with history,
//! lineage, the adapter/core rule, and integrity checks on read.

use l3p_registry::{ArtifactKind, ListFilter, PutRequest, Registry, RegistryError, StoreError};
use l3p_registry::{LineageRole, sha256_hex};
use serde_json::json;

fn core(bytes: &[u8]) -> PutRequest {
    PutRequest::new("a1-core", ArtifactKind::Core, bytes.to_vec())
        .dim("d_h", 64)
        .dim("d_z", 16)
        .config(json!({"lr": 1e-3, "layers": [256, 128]}))
        .metric("mean_reward", 12.5)
        .producer("learner/test")
}

#[test]
fn versions_are_numbered_immutable_and_deduplicated() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    let v1 = reg.put(core(b"weights one")).unwrap();
    assert!(v1.created);
    assert_eq!((v1.meta.name.as_str(), v1.meta.version), ("a1-core", 1));
    assert_eq!(v1.meta.sha256, sha256_hex(b"weights one"));
    assert_eq!(v1.meta.size, 11);
    assert_eq!(v1.meta.dims["d_h"], 64);
    assert_eq!(v1.meta.config["layers"][1], 128);
    assert_eq!(v1.meta.aliases, ["latest"]);

    let v2 = reg.put(core(b"weights two")).unwrap();
    assert!(v2.created);
    assert_eq!(v2.meta.version, 2);

    // The same bytes again under the same name: the existing version comes back, nothing new.
    let again = reg
        .put(core(b"weights one").metric("mean_reward", 99.0))
        .unwrap();
    assert!(!again.created);
    assert_eq!(again.meta.version, 1);
    assert_eq!(
        again.meta.metrics["mean_reward"], 12.5,
        "a duplicate put must not rewrite metadata"
    );
    assert_eq!(reg.list(&ListFilter::default()).unwrap().len(), 2);

    // The same bytes under another name: a new version that shares the blob row.
    let other = reg
        .put(PutRequest::new(
            "a1-core-copy",
            ArtifactKind::Core,
            b"weights one".to_vec(),
        ))
        .unwrap();
    assert!(other.created);
    assert_eq!(other.meta.version, 1);
    assert_eq!(reg.check_integrity().unwrap().blobs_checked, 2);

    // Version 1 still holds its original bytes and metadata after later puts.
    let (meta, bytes) = reg.get_blob("a1-core@1").unwrap();
    assert_eq!(bytes, b"weights one");
    assert_eq!(meta.metrics["mean_reward"], 12.5);
    assert_eq!(reg.get_meta("a1-core@latest").unwrap().version, 2);
    assert_eq!(reg.get_meta("a1-core").unwrap().version, 2);
    assert_eq!(reg.get_meta("a1-core@v1").unwrap().version, 1);

    // Immutability is enforced by the database itself, not only by the API.
    let raw = rusqlite::Connection::open(reg.path()).unwrap();
    let err = raw
        .execute("UPDATE versions SET size = 0 WHERE name = 'a1-core'", [])
        .unwrap_err();
    assert!(err.to_string().contains("immutable"), "{err}");
    let err = raw.execute("DELETE FROM versions", []).unwrap_err();
    assert!(err.to_string().contains("immutable"), "{err}");
}

#[test]
fn reopening_keeps_everything() {
    let dir = tempfile::tempdir().unwrap();
    {
        let reg = Registry::open(dir.path()).unwrap();
        reg.put(core(b"a")).unwrap();
        reg.put(core(b"b")).unwrap();
        reg.tag("a1-core@1", "prod").unwrap();
    }
    let reg = Registry::open(dir.path()).unwrap();
    assert_eq!(reg.get_meta("a1-core@prod").unwrap().version, 1);
    assert_eq!(reg.put(core(b"c")).unwrap().meta.version, 3);
    assert!(reg.check_integrity().unwrap().is_ok());
}

#[test]
fn aliases_move_and_keep_their_history() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    for content in [b"1", b"2", b"3"] {
        reg.put(core(content)).unwrap();
    }
    let first = reg.tag("a1-core@1", "prod").unwrap();
    assert!(first.moved);
    assert_eq!((first.event.version, first.event.previous), (1, None));
    let second = reg.tag("a1-core@3", "prod").unwrap();
    assert_eq!((second.event.version, second.event.previous), (3, Some(1)));
    let same = reg.tag("a1-core@3", "prod").unwrap();
    assert!(!same.moved, "re-tagging the same version records nothing");
    reg.tag("a1-core@latest", "staging").unwrap();
    let back = reg.tag("a1-core@2", "prod").unwrap();
    assert_eq!(back.event.previous, Some(3));

    assert_eq!(reg.get_meta("a1-core@prod").unwrap().version, 2);
    let prod: Vec<_> = reg
        .alias_history("a1-core", Some("prod"))
        .unwrap()
        .iter()
        .map(|e| (e.version, e.previous))
        .collect();
    assert_eq!(prod, [(1, None), (3, Some(1)), (2, Some(3))]);
    let latest: Vec<_> = reg
        .alias_history("a1-core", Some("latest"))
        .unwrap()
        .iter()
        .map(|e| e.version)
        .collect();
    assert_eq!(
        latest,
        [1, 2, 3],
        "latest moves on every put and its moves are recorded too"
    );
    assert_eq!(reg.alias_history("a1-core", None).unwrap().len(), 3 + 3 + 1);
    let meta = reg.get_meta("a1-core@3").unwrap();
    assert_eq!(meta.aliases, ["latest", "staging"]);

    // A put can set aliases too.
    let v4 = reg.put(core(b"4").alias("prod")).unwrap();
    assert_eq!(
        reg.get_meta("a1-core@prod").unwrap().version,
        v4.meta.version
    );

    // `latest` is the registry's, and aliases cannot look like versions.
    let err = reg.tag("a1-core@1", "latest").unwrap_err().to_string();
    assert!(err.contains("latest") && err.contains("hint:"), "{err}");
    assert!(reg.tag("a1-core@1", "v7").is_err());
    assert!(reg.tag("a1-core@1", "no spaces").is_err());
}

#[test]
fn unknown_references_name_what_exists() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"x")).unwrap();
    reg.tag("a1-core@1", "prod").unwrap();

    let err = reg.get_meta("go1-core@1").unwrap_err();
    assert!(err.is_not_found());
    assert!(err.to_string().contains("\"go1-core\" not found"), "{err}");
    let err = reg.get_meta("a1-core@7").unwrap_err();
    assert!(err.is_not_found());
    assert!(
        err.to_string().contains("no version 7 (latest is 1)"),
        "{err}"
    );
    let err = reg.get_blob("a1-core@beta").unwrap_err();
    assert!(
        err.to_string()
            .contains("no alias \"beta\" (aliases: latest, prod)"),
        "{err}"
    );
    let err = reg.get_meta("a1 core@1").unwrap_err();
    assert!(
        matches!(err, StoreError::Registry(RegistryError::BadRef(_))),
        "{err}"
    );
    assert!(
        reg.alias_history("nothing", None)
            .unwrap_err()
            .is_not_found()
    );
}

#[test]
fn invalid_puts_are_refused_and_store_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"x")).unwrap();

    let err = reg
        .put(PutRequest::new("a1-core", ArtifactKind::Adapter, b"y".to_vec()).robot("a1"))
        .unwrap_err();
    assert!(err.to_string().contains("holds core artifacts"), "{err}");
    let err = reg
        .put(PutRequest::new(
            "go1-adapter",
            ArtifactKind::Adapter,
            b"y".to_vec(),
        ))
        .unwrap_err();
    assert!(err.to_string().contains("must name its robot"), "{err}");
    let err = reg.put(core(b"z").metric("kl", f64::NAN)).unwrap_err();
    assert!(err.to_string().contains("finite"), "{err}");
    let mut tampered = core(b"z");
    tampered.expected_sha256 = Some(sha256_hex(b"something else"));
    let err = reg.put(tampered).unwrap_err();
    assert!(
        matches!(err, StoreError::Registry(RegistryError::Integrity { .. })),
        "{err}"
    );
    let err = reg
        .put(core(b"z").lineage(LineageRole::TrainedAgainst, "missing-core@1"))
        .unwrap_err();
    assert!(err.is_not_found(), "{err}");
    let err = reg.put(core(b"z").alias("latest")).unwrap_err();
    assert!(err.to_string().contains("latest"), "{err}");

    assert_eq!(reg.list(&ListFilter::default()).unwrap().len(), 1);
    assert_eq!(
        reg.put(core(b"z")).unwrap().meta.version,
        2,
        "refused puts must not use up version numbers"
    );
}

#[test]
fn lineage_links_adapters_checkpoints_and_cores() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"core v1")).unwrap();
    reg.put(core(b"core v2")).unwrap();
    let ckpt = reg
        .put(
            PutRequest::new(
                "go1-transfer-ckpt",
                ArtifactKind::Checkpoint,
                b"ckpt".to_vec(),
            )
            .robot("go1")
            .lineage(LineageRole::FrozenCore, "a1-core@latest"),
        )
        .unwrap();
    // `latest` was resolved at put time: the edge names version 2, even after the alias moves.
    assert_eq!(ckpt.meta.lineage[0].reference(), "a1-core@2");
    let adapter = reg
        .put(
            PutRequest::new("go1-adapter", ArtifactKind::Adapter, b"adapter".to_vec())
                .robot("go1")
                .dim("obs_dim", 48)
                .lineage(LineageRole::TrainedAgainst, "a1-core@2")
                .lineage(LineageRole::FromCheckpoint, "go1-transfer-ckpt@1"),
        )
        .unwrap();
    reg.put(core(b"core v3")).unwrap();
    let deploy = reg
        .put(
            PutRequest::new("go1-deploy", ArtifactKind::Deploy, b"deploy".to_vec())
                .robot("go1")
                .lineage(LineageRole::DerivedFrom, "go1-adapter@1")
                .lineage(LineageRole::DerivedFrom, "a1-core@2"),
        )
        .unwrap();
    assert_eq!(deploy.meta.lineage.len(), 2);

    let graph = reg.lineage("go1-deploy@1").unwrap();
    let up: Vec<_> = graph
        .upstream
        .iter()
        .map(|l| (l.child.as_str(), l.role, l.parent.as_str()))
        .collect();
    assert_eq!(
        up,
        [
            ("go1-deploy@1", LineageRole::DerivedFrom, "go1-adapter@1"),
            ("go1-deploy@1", LineageRole::DerivedFrom, "a1-core@2"),
            ("go1-adapter@1", LineageRole::TrainedAgainst, "a1-core@2"),
            (
                "go1-adapter@1",
                LineageRole::FromCheckpoint,
                "go1-transfer-ckpt@1"
            ),
            ("go1-transfer-ckpt@1", LineageRole::FrozenCore, "a1-core@2"),
        ]
    );
    assert!(graph.downstream.is_empty());

    let graph = reg.lineage("a1-core@2").unwrap();
    assert!(graph.upstream.is_empty());
    let mut children: Vec<_> = graph.downstream.iter().map(|l| l.child.as_str()).collect();
    children.sort();
    children.dedup();
    assert_eq!(
        children,
        ["go1-adapter@1", "go1-deploy@1", "go1-transfer-ckpt@1"]
    );
    assert!(reg.lineage("a1-core@1").unwrap().downstream.is_empty());

    // Role constraints: a core role must name a core, a checkpoint role a checkpoint.
    let err = reg
        .put(
            PutRequest::new("bad", ArtifactKind::Adapter, b"b".to_vec())
                .robot("go1")
                .lineage(LineageRole::TrainedAgainst, "go1-adapter@1"),
        )
        .unwrap_err();
    assert!(
        err.to_string().contains("must name a core artifact"),
        "{err}"
    );
    assert_eq!(adapter.meta.core_edge().unwrap().reference(), "a1-core@2");
}

#[test]
fn adapters_must_be_loaded_with_their_core() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"core v1")).unwrap();
    reg.put(core(b"core v2")).unwrap();
    reg.put(
        PutRequest::new("go1-adapter", ArtifactKind::Adapter, b"adapter".to_vec())
            .robot("go1")
            .lineage(LineageRole::TrainedAgainst, "a1-core@1"),
    )
    .unwrap();
    reg.put(
        PutRequest::new("orphan-adapter", ArtifactKind::Adapter, b"orphan".to_vec()).robot("go1"),
    )
    .unwrap();

    let ok = reg
        .check_adapter_against_core("go1-adapter@latest", "a1-core@1", false)
        .unwrap();
    assert!(ok.matches);
    let err = reg
        .check_adapter_against_core("go1-adapter@1", "a1-core@latest", false)
        .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("go1-adapter@1") && text.contains("a1-core@1") && text.contains("a1-core@2"),
        "{text}"
    );
    assert!(text.contains("--allow-core-mismatch"), "{text}");
    let allowed = reg
        .check_adapter_against_core("go1-adapter@1", "a1-core@2", true)
        .unwrap();
    assert!(!allowed.matches);
    let err = reg
        .check_adapter_against_core("orphan-adapter@1", "a1-core@2", false)
        .unwrap_err();
    assert!(err.to_string().contains("records no core"), "{err}");
    let err = reg
        .check_adapter_against_core("go1-adapter@1", "go1-adapter@1", true)
        .unwrap_err();
    assert!(err.to_string().contains("not a core"), "{err}");
}

#[test]
fn corrupted_blobs_are_refused_on_read() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"healthy bytes")).unwrap();
    reg.put(core(b"other bytes")).unwrap();
    {
        // Simulate on-disk corruption: bypass the immutability trigger and flip the stored bytes.
        let raw = rusqlite::Connection::open(reg.path()).unwrap();
        raw.execute_batch("DROP TRIGGER blobs_immutable").unwrap();
        raw.execute(
            "UPDATE blobs SET data = ?1 WHERE sha256 = ?2",
            rusqlite::params![b"healthy bytez".to_vec(), sha256_hex(b"healthy bytes")],
        )
        .unwrap();
    }
    let err = reg.get_blob("a1-core@1").unwrap_err();
    assert!(
        matches!(err, StoreError::Registry(RegistryError::Integrity { .. })),
        "{err}"
    );
    assert!(err.to_string().contains("a1-core@1"), "{err}");
    assert_eq!(reg.get_blob("a1-core@2").unwrap().1, b"other bytes");
    let report = reg.check_integrity().unwrap();
    assert_eq!(report.bad_blobs, [sha256_hex(b"healthy bytes")]);
    assert!(!report.is_ok());
}

#[test]
fn list_filters_by_kind_name_and_robot() {
    let dir = tempfile::tempdir().unwrap();
    let reg = Registry::open(dir.path()).unwrap();
    reg.put(core(b"c")).unwrap();
    reg.put(PutRequest::new("go1-adapter", ArtifactKind::Adapter, b"g".to_vec()).robot("go1"))
        .unwrap();
    reg.put(PutRequest::new("go1-adapter", ArtifactKind::Adapter, b"g2".to_vec()).robot("go1"))
        .unwrap();
    reg.put(
        PutRequest::new("anymal-adapter", ArtifactKind::Adapter, b"a".to_vec()).robot("anymal_c"),
    )
    .unwrap();

    let names = |filter: ListFilter| -> Vec<String> {
        reg.list(&filter)
            .unwrap()
            .iter()
            .map(|m| m.reference())
            .collect()
    };
    assert_eq!(
        names(ListFilter::default()),
        [
            "a1-core@1",
            "anymal-adapter@1",
            "go1-adapter@1",
            "go1-adapter@2"
        ]
    );
    assert_eq!(
        names(ListFilter {
            kind: Some(ArtifactKind::Adapter),
            ..Default::default()
        }),
        ["anymal-adapter@1", "go1-adapter@1", "go1-adapter@2"]
    );
    assert_eq!(
        names(ListFilter {
            robot: Some("go1".into()),
            ..Default::default()
        }),
        ["go1-adapter@1", "go1-adapter@2"]
    );
    assert_eq!(
        names(ListFilter {
            name: Some("a1-core".into()),
            ..Default::default()
        }),
        ["a1-core@1"]
    );
    assert!(
        names(ListFilter {
            kind: Some(ArtifactKind::Deploy),
            ..Default::default()
        })
        .is_empty()
    );
}
