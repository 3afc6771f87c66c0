//! A Zenoh client that is not part of this project — the `eclipse-zenoh` Python package — lists
//! versions, reads metadata and errors, and pulls a blob using only the JSON protocol of NOTES.md.
//! Skipped (with a message) when `python3` with `zenoh` is not installed.

use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_registry::{
    ArtifactKind, ListFilter, PutRequest, Registry, RegistryClient, ServiceLimits, serve_with,
};
use tokio_util::sync::CancellationToken;

const SCRIPT: &str = r#"
import json, sys, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
conf.insert_json5("scouting/multicast/enabled", "false")
with zenoh.open(conf) as session:
    for reply in session.get("l3p/registry/list", payload=json.dumps({"wire_version": 2, "kind": "core"})):
        if reply.ok:
            for a in json.loads(reply.ok.payload.to_string())["artifacts"]:
                print("artifact", a["name"], a["version"], a["sha256"], ",".join(a["aliases"]))
    for reply in session.get("l3p/registry/show", payload=json.dumps({"wire_version": 2, "artifact": "a1-core@9"})):
        if reply.err:
            e = json.loads(reply.err.payload.to_string())
            print("error", e["code"], e["message"])
    for reply in session.get("l3p/registry/pull", payload=json.dumps({"wire_version": 2, "artifact": "a1-core@prod"})):
        if reply.ok:
            meta = json.loads(reply.ok.attachment.to_string())["artifact"]
            print("pulled", meta["name"], meta["version"], reply.ok.payload.to_bytes().decode())
"#;

fn python_with_zenoh() -> bool {
    Command::new("python3")
        .args(["-c", "import zenoh"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_eclipse_zenoh_client_reads_the_registry() {
    if !python_with_zenoh() {
        eprintln!("skipped: python3 with the eclipse-zenoh package is not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let registry = Arc::new(Registry::open(dir.path()).unwrap());
    let v1 = registry
        .put(PutRequest::new(
            "a1-core",
            ArtifactKind::Core,
            b"core one".to_vec(),
        ))
        .unwrap();
    let v2 = registry
        .put(PutRequest::new(
            "a1-core",
            ArtifactKind::Core,
            b"core two".to_vec(),
        ))
        .unwrap();
    registry.tag("a1-core@1", "prod").unwrap();
    registry
        .put(PutRequest::new("go1-adapter", ArtifactKind::Adapter, b"a".to_vec()).robot("go1"))
        .unwrap();

    let port = free_loopback_port().unwrap();
    let session = open_session(&ZenohSettings::loopback(Some(port), &[]))
        .await
        .unwrap();
    let cancel = CancellationToken::new();
    let server = tokio::spawn({
        let cancel = cancel.clone();
        async move { serve_with(&session, registry, ServiceLimits::default(), cancel).await }
    });
    // Wait until the service answers on the port the script connects to.
    let probe = open_session(&ZenohSettings::loopback(None, &[port]))
        .await
        .unwrap();
    let client = RegistryClient::new(&probe);
    let deadline = Instant::now() + Duration::from_secs(20);
    while let Err(e) = client.list(&ListFilter::default()).await {
        assert!(
            Instant::now() < deadline,
            "registry service never answered: {e}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    probe.close().await.unwrap();

    let script = dir.path().join("client.py");
    std::fs::write(&script, SCRIPT).unwrap();
    let output = tokio::task::spawn_blocking(move || {
        Command::new("python3")
            .arg(&script)
            .arg(format!("tcp/127.0.0.1:{port}"))
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "python failed: {stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines,
        [
            format!("artifact a1-core 1 {} prod", v1.meta.sha256).as_str(),
            format!("artifact a1-core 2 {} latest", v2.meta.sha256).as_str(),
            "error not_found a1-core has no version 9 (latest is 2)",
            "pulled a1-core 1 core one",
        ]
    );
    cancel.cancel();
    server.await.unwrap().unwrap();
}
