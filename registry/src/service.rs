//! The registry's Zenoh service: one queryable on `l3p/registry/**` that answers `list`, `show`,
//! `pull`, `lineage`, `history`, `put` and `tag` (see `NOTES.md` for the JSON protocol).
//!
//! Every request is answered: a JSON reply, a blob reply (raw bytes, JSON [`MetaReply`] in the
//! attachment), or a Zenoh error reply carrying a JSON [`ErrorReply`]. Bad input (unknown operation or
//! reference, malformed JSON, another wire version, oversized request) gets an error reply and the
//! service keeps running. Database work runs on tokio's blocking pool, at most
//! [`ServiceLimits::max_in_flight`] requests at a time.
//!
//! Main items: [`serve`], [`serve_with`], [`ServiceLimits`].

use std::sync::Arc;

use l3p_proto::codec;
use l3p_proto::keys;
use l3p_proto::registry::{
    ErrorCode, ErrorReply, HistoryReply, HistoryRequest, LineageReply, ListReply, ListRequest,
    MetaReply, OPS, PutHeader, PutReply, RefRequest, TagReply, TagRequest,
};
use l3p_proto::{WIRE_VERSION, WireMessage};
use l3p_registry_client::{ListFilter, PutRequest, RegistryError, sha256_hex};
use serde::Serialize;
use tokio::sync::Semaphore;
use tokio_util::sync::CancellationToken;
use zenoh::bytes::Encoding;
use zenoh::query::Query;

use crate::error::StoreError;
use crate::store::Registry;

/// Bounds on what the service accepts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceLimits {
    /// Largest JSON request (payload, or a put's header attachment).
    pub max_request_bytes: usize,
    /// Largest blob a put may carry.
    pub max_blob_bytes: usize,
    /// Requests handled concurrently; further queries wait in Zenoh's queue.
    pub max_in_flight: usize,
}

impl Default for ServiceLimits {
    fn default() -> Self {
        Self {
            max_request_bytes: 64 << 10,
            max_blob_bytes: codec::MAX_MESSAGE_BYTES,
            max_in_flight: 16,
        }
    }
}

/// Serve `registry` on `session` with default limits until `cancel` fires.
pub async fn serve(
    session: &zenoh::Session,
    registry: Arc<Registry>,
    cancel: CancellationToken,
) -> Result<(), RegistryError> {
    serve_with(session, registry, ServiceLimits::default(), cancel).await
}

/// Serve `registry` on `session` until `cancel` fires (or the session closes).
pub async fn serve_with(
    session: &zenoh::Session,
    registry: Arc<Registry>,
    limits: ServiceLimits,
    cancel: CancellationToken,
) -> Result<(), RegistryError> {
    let key = keys::registry_all();
    let queryable = session
        .declare_queryable(&key)
        .await
        .map_err(|e| RegistryError::Zenoh {
            key: key.clone(),
            message: e.to_string(),
        })?;
    tracing::info!(%key, db = %registry.path().display(), "registry service ready");
    let permits = Arc::new(Semaphore::new(limits.max_in_flight.max(1)));
    loop {
        let query = tokio::select! {
            _ = cancel.cancelled() => break,
            query = queryable.recv_async() => match query {
                Ok(query) => query,
                Err(e) => {
                    tracing::warn!(error = %e, "registry queryable closed");
                    break;
                }
            },
        };
        let permit = tokio::select! {
            _ = cancel.cancelled() => break,
            permit = permits.clone().acquire_owned() => permit,
        };
        let registry = registry.clone();
        let limits = limits.clone();
        tokio::spawn(async move {
            let _permit = permit;
            answer(query, registry, limits).await;
        });
    }
    if let Err(e) = queryable.undeclare().await {
        tracing::debug!(error = %e, "undeclaring the registry queryable");
    }
    tracing::info!("registry service stopped");
    Ok(())
}

/// What a handled request sends back.
enum Answer {
    Json(Vec<u8>),
    Blob { header: Vec<u8>, bytes: Vec<u8> },
}

async fn answer(query: Query, registry: Arc<Registry>, limits: ServiceLimits) {
    let key = query.key_expr().clone();
    let op = key
        .as_str()
        .strip_prefix(&keys::registry(""))
        .unwrap_or("")
        .to_string();
    let outcome = match read_request(&query, &op, &limits) {
        Ok((payload, attachment)) => {
            let op = op.clone();
            match tokio::task::spawn_blocking(move || handle(&registry, &op, payload, attachment))
                .await
            {
                Ok(outcome) => outcome,
                Err(e) => Err(StoreError::from(RegistryError::BadReply {
                    key: key.to_string(),
                    message: format!("handler failed: {e}"),
                })),
            }
        }
        Err(e) => Err(e.into()),
    };
    let sent = match outcome {
        Ok(Answer::Json(bytes)) => {
            query
                .reply(key.clone(), bytes)
                .encoding(Encoding::APPLICATION_JSON)
                .await
        }
        Ok(Answer::Blob { header, bytes }) => {
            query
                .reply(key.clone(), bytes)
                .encoding(Encoding::APPLICATION_OCTET_STREAM)
                .attachment(header)
                .await
        }
        Err(error) => {
            let code = error.code();
            if code == ErrorCode::Internal {
                tracing::error!(%op, %error, "registry request failed");
            } else {
                tracing::debug!(%op, %error, "registry request refused");
            }
            let reply = ErrorReply::new(code, error.to_string());
            let bytes =
                codec::encode_json(&reply).unwrap_or_else(|_| error.to_string().into_bytes());
            query
                .reply_err(bytes)
                .encoding(Encoding::APPLICATION_JSON)
                .await
        }
    };
    if let Err(e) = sent {
        tracing::warn!(%op, error = %e, "cannot send registry reply");
    }
}

/// Payload and attachment bytes, after the size checks (done before anything is copied).
fn read_request(
    query: &Query,
    op: &str,
    limits: &ServiceLimits,
) -> Result<(Vec<u8>, Option<Vec<u8>>), RegistryError> {
    let payload_len = query.payload().map(|p| p.len()).unwrap_or(0);
    let attachment_len = query.attachment().map(|a| a.len()).unwrap_or(0);
    let too_large = |what: &str, len: usize, limit: usize| RegistryError::TooLarge {
        what: format!("{what} of `{op}` request"),
        len: len as u64,
        limit: limit as u64,
    };
    if op == "put" {
        if payload_len > limits.max_blob_bytes {
            return Err(too_large("blob", payload_len, limits.max_blob_bytes));
        }
        if attachment_len > limits.max_request_bytes {
            return Err(too_large(
                "header",
                attachment_len,
                limits.max_request_bytes,
            ));
        }
    } else if payload_len > limits.max_request_bytes {
        return Err(too_large("payload", payload_len, limits.max_request_bytes));
    }
    let payload = query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default();
    let attachment = query.attachment().map(|a| a.to_bytes().into_owned());
    Ok((payload, attachment))
}

fn json<T: Serialize + WireMessage>(message: &T) -> Result<Answer, StoreError> {
    Ok(Answer::Json(codec::encode_json(message)?))
}

fn request<T: serde::de::DeserializeOwned + WireMessage>(
    op: &str,
    payload: &[u8],
    example: &str,
) -> Result<T, RegistryError> {
    if payload.is_empty() {
        return Err(RegistryError::BadRequest(format!(
            "`{op}` needs a JSON payload\nhint: send e.g. {example}"
        )));
    }
    Ok(codec::decode_json(payload)?)
}

/// Run one request against the store (blocking).
fn handle(
    registry: &Registry,
    op: &str,
    payload: Vec<u8>,
    attachment: Option<Vec<u8>>,
) -> Result<Answer, StoreError> {
    let v = WIRE_VERSION;
    let ref_example = format!(r#"{{"wire_version":{v},"artifact":"a1-core@latest"}}"#);
    match op {
        "list" => {
            let req: ListRequest = if payload.is_empty() {
                ListRequest::all()
            } else {
                codec::decode_json(&payload)?
            };
            let filter = ListFilter {
                kind: req.kind,
                name: req.name,
                robot: req.robot,
            };
            json(&ListReply {
                wire_version: v,
                artifacts: registry.list(&filter)?,
            })
        }
        "show" => {
            let req: RefRequest = request(op, &payload, &ref_example)?;
            json(&MetaReply {
                wire_version: v,
                artifact: registry.get_meta(&req.artifact)?,
            })
        }
        "pull" => {
            let req: RefRequest = request(op, &payload, &ref_example)?;
            let (artifact, bytes) = registry.get_blob(&req.artifact)?;
            let header = codec::encode_json(&MetaReply {
                wire_version: v,
                artifact,
            })?;
            Ok(Answer::Blob { header, bytes })
        }
        "lineage" => {
            let req: RefRequest = request(op, &payload, &ref_example)?;
            json(&LineageReply {
                wire_version: v,
                lineage: registry.lineage(&req.artifact)?,
            })
        }
        "history" => {
            let req: HistoryRequest = request(
                op,
                &payload,
                &format!(r#"{{"wire_version":{v},"name":"a1-core","alias":"prod"}}"#),
            )?;
            json(&HistoryReply {
                wire_version: v,
                events: registry.alias_history(&req.name, req.alias.as_deref())?,
            })
        }
        "tag" => {
            let req: TagRequest = request(
                op,
                &payload,
                &format!(r#"{{"wire_version":{v},"artifact":"a1-core@3","alias":"prod"}}"#),
            )?;
            let outcome = registry.tag(&req.artifact, &req.alias)?;
            json(&TagReply {
                wire_version: v,
                event: outcome.event,
                moved: outcome.moved,
            })
        }
        "put" => {
            let Some(header) = attachment else {
                return Err(RegistryError::BadRequest(
                    "`put` needs a JSON PutHeader in the query attachment and the blob as payload"
                        .into(),
                )
                .into());
            };
            let header: PutHeader = codec::decode_json(&header)?;
            if header.size != payload.len() as u64 {
                return Err(RegistryError::Integrity {
                    what: format!(
                        "blob received for {} ({} bytes, header says {})",
                        header.spec.name,
                        payload.len(),
                        header.size
                    ),
                    expected: header.sha256,
                    actual: sha256_hex(&payload),
                }
                .into());
            }
            let outcome = registry.put(PutRequest {
                spec: header.spec,
                bytes: payload,
                expected_sha256: Some(header.sha256),
            })?;
            json(&PutReply {
                wire_version: v,
                artifact: outcome.meta,
                created: outcome.created,
            })
        }
        other => Err(RegistryError::BadRequest(format!(
            "unknown registry operation {other:?}\nhint: query {} with one of: {}",
            keys::registry("<op>"),
            OPS.join(", ")
        ))
        .into()),
    }
}

/// Fuzzing of the request decoding and handling on stable Rust (proptest): well-formed requests of
/// every operation with their JSON mutated (byte flips, cuts, duplicated spans, odd numbers and
/// strings spliced in), wrong operations and random bytes. Every request must be answered or refused
/// — no panic — and the store must still answer afterwards. `L3P_FUZZ_CASES` raises the case count
/// for a long run (`cargo test --release -p l3p-registry fuzz`).
#[cfg(test)]
mod fuzz {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, TestRunner};

    fn cases(default: u32) -> u32 {
        std::env::var("L3P_FUZZ_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    }

    /// Valid `(op, payload, attachment)` requests to mutate.
    fn seeds() -> Vec<(String, Vec<u8>, Option<Vec<u8>>)> {
        let v = WIRE_VERSION;
        let blob = b"weights".to_vec();
        let header = format!(
            r#"{{"wire_version":{v},"spec":{{"name":"a1-core","kind":"core","robot":"a1","dims":{{"d_h":64}},"metrics":{{"reward":1.5}},"producer":"fuzz","lineage":[],"aliases":["best"]}},"sha256":"{}","size":{}}}"#,
            sha256_hex(&blob),
            blob.len()
        );
        let json = |op: &str, text: String| (op.to_string(), text.into_bytes(), None);
        vec![
            json(
                "list",
                format!(r#"{{"wire_version":{v},"kind":"core","name":"a1-core"}}"#),
            ),
            json(
                "show",
                format!(r#"{{"wire_version":{v},"artifact":"a1-core@latest"}}"#),
            ),
            json(
                "pull",
                format!(r#"{{"wire_version":{v},"artifact":"a1-core@1"}}"#),
            ),
            json(
                "lineage",
                format!(r#"{{"wire_version":{v},"artifact":"a1-core@best"}}"#),
            ),
            json(
                "history",
                format!(r#"{{"wire_version":{v},"name":"a1-core","alias":"best"}}"#),
            ),
            json(
                "tag",
                format!(r#"{{"wire_version":{v},"artifact":"a1-core@1","alias":"stable"}}"#),
            ),
            ("put".to_string(), blob, Some(header.into_bytes())),
        ]
    }

    /// Splices: byte flips, cuts, duplicated spans, and tokens that are valid JSON but odd.
    fn mutate(mut bytes: Vec<u8>, edits: &[(usize, u8, u8)]) -> Vec<u8> {
        const TOKENS: [&str; 10] = [
            "1e999",
            "-1",
            "18446744073709551616",
            "null",
            "\"\"",
            "[]",
            "{}",
            "\"../..\"",
            "\"a@b@c\"",
            "\"\\u0000\"",
        ];
        for &(at, byte, op) in edits {
            if bytes.is_empty() {
                bytes.push(byte);
                continue;
            }
            let at = at % bytes.len();
            match op % 5 {
                0 => bytes[at] = byte,
                1 => bytes.truncate(at),
                2 => {
                    let end = (at + byte as usize % 16).min(bytes.len());
                    let span = bytes[at..end].to_vec();
                    bytes.splice(at..at, span);
                }
                3 => {
                    let token = TOKENS[byte as usize % TOKENS.len()].as_bytes();
                    bytes.splice(at..at, token.iter().copied());
                }
                _ => {
                    bytes.remove(at);
                }
            }
        }
        bytes
    }

    #[test]
    fn fuzzed_requests_are_answered_or_refused_and_the_store_survives() {
        let dir = tempfile::tempdir().unwrap();
        let registry = Registry::open(dir.path()).unwrap();
        let seeds = seeds();
        // Something to find: every valid seed once (the put first).
        for (op, payload, attachment) in seeds.iter().rev() {
            handle(&registry, op, payload.clone(), attachment.clone())
                .unwrap_or_else(|e| panic!("seed {op}: {e}"));
        }
        let n = seeds.len();
        let edits = prop::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 0..8);
        let ops = prop::sample::select(
            OPS.iter()
                .map(|s| s.to_string())
                .chain(["", "put/../list", "LIST"].map(String::from))
                .collect::<Vec<_>>(),
        );
        let strategy = (
            0..n,
            edits.clone(),
            edits,
            any::<bool>(),
            ops,
            prop::collection::vec(any::<u8>(), 0..256),
        );
        let mut runner = TestRunner::new(Config {
            cases: cases(512),
            failure_persistence: None,
            ..Config::default()
        });
        let (answered, refused) = (std::cell::Cell::new(0u32), std::cell::Cell::new(0u32));
        runner
            .run(
                &strategy,
                |(seed, payload_edits, header_edits, other_op, op, noise)| {
                    let (seed_op, payload, attachment) = &seeds[seed];
                    let op = if other_op { op } else { seed_op.clone() };
                    let payload = if payload.is_empty() {
                        noise
                    } else {
                        mutate(payload.clone(), &payload_edits)
                    };
                    let attachment = attachment.clone().map(|h| mutate(h, &header_edits));
                    match handle(&registry, &op, payload, attachment) {
                        Ok(_) => answered.set(answered.get() + 1),
                        Err(e) => {
                            prop_assert!(!e.to_string().is_empty());
                            refused.set(refused.get() + 1);
                        }
                    }
                    Ok(())
                },
            )
            .unwrap();
        let (answered, refused) = (answered.get(), refused.get());
        eprintln!("fuzzed registry requests: {answered} answered, {refused} refused, 0 panics");
        assert!(refused > 0, "the mutations never produced a bad request");
        // The store still answers, and the seed artifact is intact.
        let (op, payload, _) = &seeds[1];
        assert!(handle(&registry, op, payload.clone(), None).is_ok());
    }
}
