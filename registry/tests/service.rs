//! The Zenoh service over a real loopback session: the client mirrors the store, and bad requests
//! (unknown reference or operation, malformed JSON, another wire version, oversized payloads, a blob
//! that does not match its hash) get clear error replies while the service keeps running.

use std::sync::Arc;
use std::time::{Duration, Instant};

use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_proto::registry::{ErrorCode, ErrorReply, PutHeader};
use l3p_proto::{WIRE_VERSION, codec, keys};
use l3p_registry::{
    ArtifactKind, ArtifactSpec, LineageRole, ListFilter, PutRequest, Registry, RegistryClient,
    RegistryError, ServiceLimits, serve_with, sha256_hex,
};
use tokio_util::sync::CancellationToken;

struct Fixture {
    client: RegistryClient,
    session: zenoh::Session,
    cancel: CancellationToken,
    server: tokio::task::JoinHandle<Result<(), RegistryError>>,
    _dir: tempfile::TempDir,
}

async fn start(limits: ServiceLimits) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let server_session = open_session(&ZenohSettings::loopback(Some(port), &[]))
        .await
        .unwrap();
    let registry = Arc::new(Registry::open(dir.path()).unwrap());
    let cancel = CancellationToken::new();
    let server = tokio::spawn({
        let cancel = cancel.clone();
        async move { serve_with(&server_session, registry, limits, cancel).await }
    });
    let session = open_session(&ZenohSettings::loopback(None, &[port]))
        .await
        .unwrap();
    let client = RegistryClient::new(&session)
        .with_timeouts(Duration::from_secs(5), Duration::from_secs(30));
    // Wait until the queryable is declared and visible through the link.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        match client.list(&ListFilter::default()).await {
            Ok(_) => break,
            Err(e) if Instant::now() < deadline => {
                tracing::debug!("waiting for the service: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            Err(e) => panic!("registry service never answered: {e}"),
        }
    }
    Fixture {
        client,
        session,
        cancel,
        server,
        _dir: dir,
    }
}

/// A raw query, as a client outside this project would send it: the error reply, decoded.
async fn raw_error(
    session: &zenoh::Session,
    op: &str,
    payload: Vec<u8>,
    attachment: Option<Vec<u8>>,
) -> ErrorReply {
    let get = session
        .get(keys::registry(op))
        .payload(payload)
        .timeout(Duration::from_secs(5));
    let replies = match attachment {
        Some(a) => get.attachment(a).await,
        None => get.await,
    }
    .unwrap();
    let reply = replies.recv_async().await.expect("the service must answer");
    let error = reply.into_result().expect_err("expected an error reply");
    codec::decode_json::<ErrorReply>(&error.payload().to_bytes())
        .expect("error replies are JSON ErrorReply")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_round_trips_through_the_service() {
    let fx = start(ServiceLimits::default()).await;
    let c = &fx.client;
    let core1 = c
        .put(PutRequest::new("a1-core", ArtifactKind::Core, b"core one".to_vec()).dim("d_h", 64))
        .await
        .unwrap();
    assert!(core1.created);
    assert_eq!(core1.meta.version, 1);
    // A 3 MB checkpoint travels in fragments and comes back bit-exact.
    let big: Vec<u8> = (0..3_000_000u32).map(|i| (i * 7 % 256) as u8).collect();
    let ckpt = c
        .put(
            PutRequest::new("go1-ckpt", ArtifactKind::Checkpoint, big.clone())
                .robot("go1")
                .lineage(LineageRole::FrozenCore, "a1-core@latest")
                .config(serde_json::json!({"iteration": 120})),
        )
        .await
        .unwrap();
    let again = c
        .put(PutRequest::new(
            "a1-core",
            ArtifactKind::Core,
            b"core one".to_vec(),
        ))
        .await
        .unwrap();
    assert!(
        !again.created,
        "identical content is deduplicated over the wire too"
    );
    c.put(PutRequest::new(
        "a1-core",
        ArtifactKind::Core,
        b"core two".to_vec(),
    ))
    .await
    .unwrap();

    let (meta, bytes) = c.get_blob("go1-ckpt@latest").await.unwrap();
    assert_eq!(bytes, big);
    assert_eq!(meta, ckpt.meta);
    assert_eq!(meta.config["iteration"], 120);
    assert_eq!(c.get_meta("a1-core").await.unwrap().version, 2);
    let listed: Vec<String> = c
        .list(&ListFilter::default())
        .await
        .unwrap()
        .iter()
        .map(|m| m.reference())
        .collect();
    assert_eq!(listed, ["a1-core@1", "a1-core@2", "go1-ckpt@1"]);
    let cores = c
        .list(&ListFilter {
            kind: Some(ArtifactKind::Core),
            ..Default::default()
        })
        .await
        .unwrap();
    assert_eq!(cores.len(), 2);

    let tag = c.tag("a1-core@1", "prod").await.unwrap();
    assert!(tag.moved);
    c.tag("a1-core@2", "prod").await.unwrap();
    let history = c.alias_history("a1-core", Some("prod")).await.unwrap();
    assert_eq!(
        history
            .iter()
            .map(|e| (e.version, e.previous))
            .collect::<Vec<_>>(),
        [(1, None), (2, Some(1))]
    );
    let graph = c.lineage("a1-core@1").await.unwrap();
    assert_eq!(graph.downstream.len(), 1);
    assert_eq!(graph.downstream[0].child, "go1-ckpt@1");

    assert!(
        c.try_get_blob("nobody-ckpt@latest")
            .await
            .unwrap()
            .is_none()
    );
    let err = c
        .check_adapter_against_core("go1-ckpt@1", "a1-core@2", false)
        .await
        .unwrap_err();
    assert!(
        err.to_string().contains("a1-core@1") && err.to_string().contains("a1-core@2"),
        "{err}"
    );

    fx.cancel.cancel();
    fx.server.await.unwrap().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_get_clear_errors_and_the_service_keeps_running() {
    let limits = ServiceLimits {
        max_request_bytes: 1024,
        max_blob_bytes: 64 << 10,
        max_in_flight: 4,
    };
    let fx = start(limits).await;
    let c = &fx.client;
    c.put(PutRequest::new(
        "a1-core",
        ArtifactKind::Core,
        b"core".to_vec(),
    ))
    .await
    .unwrap();

    // Unknown references.
    let err = c.get_meta("go9-core@1").await.unwrap_err();
    assert!(err.is_not_found(), "{err}");
    assert!(err.to_string().contains("\"go9-core\" not found"), "{err}");
    let err = c.get_blob("a1-core@9").await.unwrap_err();
    assert!(
        err.to_string().contains("no version 9 (latest is 1)"),
        "{err}"
    );
    let err = c.get_meta("a1 core").await.unwrap_err();
    assert!(
        matches!(
            err,
            RegistryError::Remote {
                code: ErrorCode::BadRequest,
                ..
            }
        ),
        "{err}"
    );

    // Malformed JSON, unknown fields, missing payloads.
    let reply = raw_error(
        &fx.session,
        "show",
        b"{\"wire_version\": 2, \"artifact\": ".to_vec(),
        None,
    )
    .await;
    assert_eq!(reply.code, ErrorCode::BadRequest);
    assert!(
        reply.message.contains("malformed JSON"),
        "{}",
        reply.message
    );
    let reply = raw_error(
        &fx.session,
        "show",
        br#"{"wire_version":2,"artifact":"a1-core@1","x":2}"#.to_vec(),
        None,
    )
    .await;
    assert!(reply.message.contains("unknown field"), "{}", reply.message);
    let reply = raw_error(&fx.session, "tag", Vec::new(), None).await;
    assert!(
        reply.message.contains("needs a JSON payload") && reply.message.contains("hint:"),
        "{}",
        reply.message
    );

    // Another wire version.
    let reply = raw_error(
        &fx.session,
        "show",
        br#"{"wire_version":99,"artifact":"a1-core@1"}"#.to_vec(),
        None,
    )
    .await;
    assert_eq!(reply.code, ErrorCode::WrongVersion);
    assert!(
        reply.message.contains("99") && reply.message.contains(&WIRE_VERSION.to_string()),
        "{}",
        reply.message
    );

    // Unknown operation.
    let reply = raw_error(&fx.session, "frobnicate", b"{}".to_vec(), None).await;
    assert!(
        reply.message.contains("unknown registry operation") && reply.message.contains("list"),
        "{}",
        reply.message
    );

    // Oversized request and blob.
    let long = format!(r#"{{"wire_version":2,"artifact":"{}"}}"#, "a".repeat(4000));
    let reply = raw_error(&fx.session, "show", long.into_bytes(), None).await;
    assert_eq!(reply.code, ErrorCode::TooLarge);
    assert!(
        reply.message.contains("exceeds the limit of 1024 bytes"),
        "{}",
        reply.message
    );
    let err = c
        .put(PutRequest::new(
            "a1-core",
            ArtifactKind::Core,
            vec![1u8; 100 << 10],
        ))
        .await
        .unwrap_err();
    assert!(
        matches!(
            err,
            RegistryError::Remote {
                code: ErrorCode::TooLarge,
                ..
            }
        ),
        "{err}"
    );

    // A blob that does not match the hash its writer declared is refused.
    let header = PutHeader {
        wire_version: WIRE_VERSION,
        spec: ArtifactSpec::new("a1-core", ArtifactKind::Core),
        sha256: sha256_hex(b"what the writer meant"),
        size: 9,
    };
    let reply = raw_error(
        &fx.session,
        "put",
        b"corrupted".to_vec(),
        Some(codec::encode_json(&header).unwrap()),
    )
    .await;
    assert_eq!(reply.code, ErrorCode::Integrity);
    let reply = raw_error(&fx.session, "put", b"no header".to_vec(), None).await;
    assert!(reply.message.contains("PutHeader"), "{}", reply.message);

    // Nothing was stored by the refused requests, and the service still answers.
    let all = c.list(&ListFilter::default()).await.unwrap();
    assert_eq!(
        all.iter().map(|m| m.reference()).collect::<Vec<_>>(),
        ["a1-core@1"]
    );
    assert_eq!(
        c.put(PutRequest::new(
            "a1-core",
            ArtifactKind::Core,
            b"v2".to_vec()
        ))
        .await
        .unwrap()
        .meta
        .version,
        2
    );

    fx.cancel.cancel();
    fx.server.await.unwrap().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_service_is_a_clear_error() {
    let port = free_loopback_port().unwrap();
    let session = open_session(&ZenohSettings::loopback(Some(port), &[]))
        .await
        .unwrap();
    let client = RegistryClient::new(&session)
        .with_timeouts(Duration::from_millis(500), Duration::from_millis(500));
    let err = client.get_meta("a1-core@1").await.unwrap_err();
    assert!(matches!(err, RegistryError::NoReply { .. }), "{err}");
    assert!(err.to_string().contains("l3p registry serve"), "{err}");
}

/// A client that asks before the service's queryable is up (a process that has just started beside
/// its registry) waits for it within its timeout instead of failing at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_query_sent_before_the_service_starts_is_answered_once_it_does() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let server_session = open_session(&ZenohSettings::loopback(Some(port), &[]))
        .await
        .unwrap();
    let session = open_session(&ZenohSettings::loopback(None, &[port]))
        .await
        .unwrap();
    let client = RegistryClient::new(&session)
        .with_timeouts(Duration::from_secs(20), Duration::from_secs(20));
    let cancel = CancellationToken::new();
    let server = tokio::spawn({
        let cancel = cancel.clone();
        let registry = Arc::new(Registry::open(dir.path()).unwrap());
        async move {
            tokio::time::sleep(Duration::from_millis(500)).await;
            serve_with(&server_session, registry, ServiceLimits::default(), cancel).await
        }
    });
    let started = Instant::now();
    let listed = client.list(&ListFilter::default()).await;
    assert!(listed.is_ok(), "{listed:?}");
    assert!(listed.unwrap().is_empty());
    assert!(started.elapsed() >= Duration::from_millis(500));
    cancel.cancel();
    server.await.unwrap().unwrap();
}
