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
use serde::Serialize;
use tokio::sync::Semaphore;
use tokio_util::sync::CancellationToken;
use zenoh::bytes::Encoding;
use zenoh::query::Query;

use crate::error::RegistryError;
use crate::store::{ListFilter, PutRequest, Registry};

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
                Err(e) => Err(RegistryError::BadReply {
                    key: key.to_string(),
                    message: format!("handler failed: {e}"),
                }),
            }
        }
        Err(e) => Err(e),
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

fn json<T: Serialize + WireMessage>(message: &T) -> Result<Answer, RegistryError> {
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
) -> Result<Answer, RegistryError> {
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
                ));
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
                    actual: crate::store::sha256_hex(&payload),
                });
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
        ))),
    }
}
