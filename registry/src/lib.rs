//! The registry: versioned artifacts (cores, adapters, MLPs, checkpoints, deployable policies) in one
//! SQLite database, served over Zenoh. The client side (crate `l3p-registry-client`, no SQLite) is
//! re-exported here, so one import serves a process that holds the store.
//!
//! - [`Registry`] (module `store`): the store. Immutable numbered versions per name, content-addressed
//!   blobs (sha256, checked on write and on read), aliases (`latest` moved on every put, user aliases
//!   such as `prod`) with their full history, and lineage (which core an adapter was trained against,
//!   which core a transfer run froze, which checkpoint a version came from); [`Registry::gc`] removes
//!   old checkpoint versions under a [`RetentionPolicy`].
//! - [`StoreError`] (module `error`): the database's own failures around a [`RegistryError`].
//! - [`RegistryAccess`] (module `access`): the same API over the store or a service, for tools that
//!   work either way.
//! - [`serve`] / [`serve_with`] (module `service`): the queryable on `l3p/registry/**` answering JSON
//!   requests with JSON metadata or raw blobs; protocol in `NOTES.md`.
//! - Re-exported from `l3p-registry-client`: [`RegistryClient`], the async client mirroring
//!   [`Registry`]; [`RegistryError`]; [`PutRequest`], [`ListFilter`], [`PutOutcome`],
//!   [`TagOutcome`]; [`check_core`], the rule for loading an adapter with a core.
//!
//! Wire types ([`ArtifactMeta`], [`ArtifactSpec`], [`ArtifactKind`], ...) live in
//! [`l3p_proto::registry`] and are re-exported here.

mod access;
mod error;
mod service;
mod store;

pub use access::RegistryAccess;
pub use error::StoreError;
pub use l3p_registry_client::{
    AliasEvent, ArtifactKind, ArtifactMeta, ArtifactRef, ArtifactSpec, CoreCheck, ErrorCode,
    LATEST, LineageEdge, LineageGraph, LineageInput, LineageLink, LineageRole, ListFilter,
    PutOutcome, PutRequest, RegistryClient, RegistryError, TagOutcome, VersionSelector, check_core,
    sha256_hex,
};
pub use service::{ServiceLimits, serve, serve_with};
pub use store::{
    DB_FILE, DEFAULT_KEEP_LAST, GcArtifact, GcReport, IntegrityReport, KeepReason, KeptVersion,
    MAX_BLOB_BYTES, Registry, RetentionPolicy,
};
