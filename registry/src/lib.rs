//! The registry: versioned artifacts (cores, adapters, MLPs, checkpoints, deployable policies) in one
//! SQLite database, served over Zenoh. Also [`net`]: the Zenoh session set-up every daemon shares.
//!
//! - [`Registry`] (module `store`): the store. Immutable numbered versions per name, content-addressed
//!   blobs (sha256, checked on write and on read), aliases (`latest` moved on every put, user aliases
//!   such as `prod`) with their full history, and lineage (which core an adapter was trained against,
//!   which core a transfer run froze, which checkpoint a version came from).
//! - [`serve`] / [`serve_with`] (module `service`): the queryable on `l3p/registry/**` answering JSON
//!   requests with JSON metadata or raw blobs; protocol in `NOTES.md`.
//! - [`RegistryClient`] (module `client`): the async client mirroring [`Registry`].
//! - [`check_core`]: the rule for loading an adapter with a core.
//!
//! Wire types ([`ArtifactMeta`], [`ArtifactSpec`], [`ArtifactKind`], ...) live in
//! [`l3p_proto::registry`] and are re-exported here.

mod client;
mod error;
mod service;
mod store;

pub use client::RegistryClient;
pub use error::RegistryError;
pub use l3p_proto::registry::{
    AliasEvent, ArtifactKind, ArtifactMeta, ArtifactRef, ArtifactSpec, ErrorCode, LATEST,
    LineageEdge, LineageGraph, LineageInput, LineageLink, LineageRole, VersionSelector,
};
pub use service::{ServiceLimits, serve, serve_with};
pub use store::{
    CoreCheck, DB_FILE, IntegrityReport, ListFilter, MAX_BLOB_BYTES, PutOutcome, PutRequest,
    Registry, TagOutcome, check_core, sha256_hex,
};
