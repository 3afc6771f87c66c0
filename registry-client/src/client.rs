//! [`RegistryClient`]: the async client the learner, actors, deploy controller and CLI use to talk to
//! a registry service over Zenoh. Its methods mirror the store's (`l3p_registry::Registry`); blobs
//! are hash-checked on arrival and service-side errors come back as [`RegistryError::Remote`] with
//! their [`ErrorCode`].

use std::time::{Duration, Instant};

use l3p_proto::codec;
use l3p_proto::keys;
use l3p_proto::registry::{
    AliasEvent, ArtifactMeta, ErrorCode, ErrorReply, HistoryReply, HistoryRequest, LineageGraph,
    LineageReply, ListReply, ListRequest, MetaReply, PutHeader, PutReply, RefRequest, TagReply,
    TagRequest,
};
use l3p_proto::{WIRE_VERSION, WireMessage};
use serde::Serialize;
use serde::de::DeserializeOwned;
use zenoh::bytes::ZBytes;

use crate::core_check::{CoreCheck, check_core};
use crate::error::{RegistryError, check_blob};
use crate::request::{ListFilter, PutOutcome, PutRequest, TagOutcome};
use crate::sha256_hex;

/// Longest pause between two tries of a query no registry has answered yet.
const MAX_RETRY_PAUSE: Duration = Duration::from_millis(500);

/// How long after a client is made a query that no registry has matched is sent again: a session
/// that has just opened (a process started beside its registry, a one-shot CLI command) may not
/// have learnt of the service's queryable yet. Later, no match means the registry is gone, and the
/// caller hears it at once (the learner's uploader counts the attempt and backs off).
pub const DISCOVERY_WINDOW: Duration = Duration::from_secs(5);

/// Client of the registry service. Cheap to clone (the Zenoh session is shared).
#[derive(Clone)]
pub struct RegistryClient {
    session: zenoh::Session,
    timeout: Duration,
    blob_timeout: Duration,
    /// Until then a query no registry has matched is sent again (see [`DISCOVERY_WINDOW`]).
    discovery_until: Instant,
}

impl std::fmt::Debug for RegistryClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RegistryClient")
            .field("timeout", &self.timeout)
            .field("blob_timeout", &self.blob_timeout)
            .finish_non_exhaustive()
    }
}

impl RegistryClient {
    /// A client on `session`, with a 10 s timeout for metadata and 120 s for blob transfers.
    pub fn new(session: &zenoh::Session) -> Self {
        Self {
            session: session.clone(),
            timeout: Duration::from_secs(10),
            blob_timeout: Duration::from_secs(120),
            discovery_until: Instant::now() + DISCOVERY_WINDOW,
        }
    }

    /// Change the metadata and blob timeouts.
    pub fn with_timeouts(mut self, metadata: Duration, blob: Duration) -> Self {
        self.timeout = metadata;
        self.blob_timeout = blob;
        self
    }

    /// Store a new version (the service re-hashes the bytes and refuses a mismatch).
    pub async fn put(&self, req: PutRequest) -> Result<PutOutcome, RegistryError> {
        let header = PutHeader {
            wire_version: WIRE_VERSION,
            sha256: sha256_hex(&req.bytes),
            size: req.bytes.len() as u64,
            spec: req.spec,
        };
        let header = codec::encode_json(&header)?;
        let (payload, _) = self
            .query("put", req.bytes, Some(header), self.blob_timeout)
            .await?;
        let reply: PutReply = decode("put", &payload)?;
        Ok(PutOutcome {
            meta: reply.artifact,
            created: reply.created,
        })
    }

    /// Metadata of `reference` (`name@version|alias`).
    pub async fn get_meta(&self, reference: &str) -> Result<ArtifactMeta, RegistryError> {
        let reply: MetaReply = self.call("show", &RefRequest::new(reference)).await?;
        Ok(reply.artifact)
    }

    /// Metadata and bytes of `reference`, the bytes checked against the metadata's sha256 and size.
    pub async fn get_blob(
        &self,
        reference: &str,
    ) -> Result<(ArtifactMeta, Vec<u8>), RegistryError> {
        let request = codec::encode_json(&RefRequest::new(reference))?;
        let (bytes, attachment) = self.query("pull", request, None, self.blob_timeout).await?;
        let key = keys::registry("pull");
        let Some(header) = attachment else {
            return Err(RegistryError::BadReply {
                key,
                message: "blob reply without its metadata attachment".into(),
            });
        };
        let meta = decode::<MetaReply>("pull", &header)?.artifact;
        check_blob(
            || format!("blob received for {}", meta.reference()),
            &meta,
            &bytes,
        )?;
        Ok((meta, bytes))
    }

    /// [`Self::get_blob`], with `None` when the name, version or alias does not exist (e.g. the
    /// learner asking for `<run>-checkpoint@latest` on a fresh start).
    pub async fn try_get_blob(
        &self,
        reference: &str,
    ) -> Result<Option<(ArtifactMeta, Vec<u8>)>, RegistryError> {
        match self.get_blob(reference).await {
            Ok(found) => Ok(Some(found)),
            Err(e) if e.is_not_found() => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Every version matching `filter`, ordered by name then version.
    pub async fn list(&self, filter: &ListFilter) -> Result<Vec<ArtifactMeta>, RegistryError> {
        let request = ListRequest {
            wire_version: WIRE_VERSION,
            kind: filter.kind,
            name: filter.name.clone(),
            robot: filter.robot.clone(),
        };
        let reply: ListReply = self.call("list", &request).await?;
        Ok(reply.artifacts)
    }

    /// Point `alias` at the version `reference` resolves to.
    pub async fn tag(&self, reference: &str, alias: &str) -> Result<TagOutcome, RegistryError> {
        let request = TagRequest {
            wire_version: WIRE_VERSION,
            artifact: reference.to_string(),
            alias: alias.to_string(),
        };
        let reply: TagReply = self.call("tag", &request).await?;
        Ok(TagOutcome {
            event: reply.event,
            moved: reply.moved,
        })
    }

    /// Recorded moves of one alias of `name` (all aliases when `None`), oldest first.
    pub async fn alias_history(
        &self,
        name: &str,
        alias: Option<&str>,
    ) -> Result<Vec<AliasEvent>, RegistryError> {
        let request = HistoryRequest {
            wire_version: WIRE_VERSION,
            name: name.to_string(),
            alias: alias.map(str::to_string),
        };
        let reply: HistoryReply = self.call("history", &request).await?;
        Ok(reply.events)
    }

    /// Transitive dependencies and dependents of `reference`.
    pub async fn lineage(&self, reference: &str) -> Result<LineageGraph, RegistryError> {
        let reply: LineageReply = self.call("lineage", &RefRequest::new(reference)).await?;
        Ok(reply.lineage)
    }

    /// Check that `adapter_ref` may be loaded with `core_ref` (see [`check_core`]).
    pub async fn check_adapter_against_core(
        &self,
        adapter_ref: &str,
        core_ref: &str,
        allow_mismatch: bool,
    ) -> Result<CoreCheck, RegistryError> {
        let adapter = self.get_meta(adapter_ref).await?;
        let core = self.get_meta(core_ref).await?;
        check_core(adapter, core, allow_mismatch)
    }

    async fn call<Req, Rep>(&self, op: &str, request: &Req) -> Result<Rep, RegistryError>
    where
        Req: Serialize + WireMessage,
        Rep: DeserializeOwned + WireMessage,
    {
        let payload = codec::encode_json(request)?;
        let (bytes, _) = self.query(op, payload, None, self.timeout).await?;
        decode(op, &bytes)
    }

    /// One query, first reply: payload and attachment, or the service's error.
    ///
    /// A query that no registry has matched ends at once with no reply. Within
    /// [`DISCOVERY_WINDOW`] of the client's creation it is sent again, with a growing pause, until
    /// `timeout` or the window has passed. Retrying is safe for every operation: reads have no
    /// effect and a put of identical bytes returns the version it already made.
    async fn query(
        &self,
        op: &str,
        payload: Vec<u8>,
        attachment: Option<Vec<u8>>,
        timeout: Duration,
    ) -> Result<(Vec<u8>, Option<Vec<u8>>), RegistryError> {
        let key = keys::registry(op);
        let zenoh_err = |e: zenoh::Error| RegistryError::Zenoh {
            key: key.clone(),
            message: e.to_string(),
        };
        // Reference-counted: a retry does not copy a blob.
        let (payload, attachment) = (ZBytes::from(payload), attachment.map(ZBytes::from));
        let started = Instant::now();
        let deadline = started + timeout;
        let no_reply = |key: String| RegistryError::NoReply {
            key,
            waited: started.elapsed(),
        };
        let mut pause = Duration::from_millis(20);
        let reply = loop {
            let remaining = deadline.saturating_duration_since(Instant::now());
            if remaining.is_zero() {
                return Err(no_reply(key));
            }
            // First reply at once, not when every matching queryable has answered (a registry
            // killed a moment ago keeps its queryable until its lease expires).
            let get = self
                .session
                .get(&key)
                .payload(payload.clone())
                .consolidation(zenoh::query::ConsolidationMode::None)
                .timeout(remaining);
            let replies = match &attachment {
                Some(attachment) => get.attachment(attachment.clone()).await,
                None => get.await,
            }
            .map_err(zenoh_err)?;
            if let Ok(reply) = replies.recv_async().await {
                break reply;
            }
            if Instant::now() >= self.discovery_until {
                return Err(no_reply(key));
            }
            let remaining = deadline
                .min(self.discovery_until)
                .saturating_duration_since(Instant::now());
            tokio::time::sleep(pause.min(remaining)).await;
            pause = (pause * 2).min(MAX_RETRY_PAUSE);
        };
        match reply.into_result() {
            Ok(sample) => Ok((
                sample.payload().to_bytes().into_owned(),
                sample.attachment().map(|a| a.to_bytes().into_owned()),
            )),
            Err(error) => {
                let bytes = error.payload().to_bytes();
                match codec::decode_json::<ErrorReply>(&bytes) {
                    Ok(reply) => Err(RegistryError::Remote {
                        code: reply.code,
                        message: reply.message,
                    }),
                    // Zenoh's own error replies (e.g. "Timeout") are plain strings.
                    Err(_) => {
                        let text = String::from_utf8_lossy(&bytes).into_owned();
                        if text.eq_ignore_ascii_case("timeout") {
                            Err(no_reply(key))
                        } else {
                            Err(RegistryError::Remote {
                                code: ErrorCode::Internal,
                                message: text,
                            })
                        }
                    }
                }
            }
        }
    }
}

fn decode<T: DeserializeOwned + WireMessage>(op: &str, bytes: &[u8]) -> Result<T, RegistryError> {
    codec::decode_json(bytes).map_err(|e| RegistryError::BadReply {
        key: keys::registry(op),
        message: e.to_string(),
    })
}
