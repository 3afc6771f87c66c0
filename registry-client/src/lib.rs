//! The registry as its users see it: the async [`RegistryClient`] that the learner, actors, deploy
//! controller and CLI use to talk to a registry service over Zenoh, without linking the SQLite store
//! (crate `l3p-registry`, which depends on this one and re-exports it).
//!
//! - [`RegistryClient`] (module `client`): put, show, pull (hash-checked), list, tag, history,
//!   lineage, and the adapter/core check, each one Zenoh query.
//! - [`RegistryError`] (module `error`): what a registry can refuse, each with its wire
//!   [`ErrorCode`].
//! - [`PutRequest`], [`ListFilter`], [`PutOutcome`], [`TagOutcome`] (module `request`): what the store
//!   and the client take and return.
//! - [`check_core`] / [`CoreCheck`] (module `core_check`): the rule for loading an adapter with a core.
//!
//! Wire types ([`ArtifactMeta`], [`ArtifactSpec`], [`ArtifactKind`], ...) live in
//! [`l3p_proto::registry`] and are re-exported here.

mod client;
mod core_check;
mod error;
mod request;

pub use client::{DISCOVERY_WINDOW, RegistryClient};
pub use core_check::{CoreCheck, check_core};
pub use error::{RegistryError, check_blob};
pub use l3p_proto::registry::{
    AliasEvent, ArtifactKind, ArtifactMeta, ArtifactRef, ArtifactSpec, ErrorCode, LATEST,
    LineageEdge, LineageGraph, LineageInput, LineageLink, LineageRole, VersionSelector,
};
/// Hex sha256 of `bytes` (one helper for the whole project, in `proto`).
pub use l3p_proto::sha256_hex;
pub use request::{ListFilter, PutOutcome, PutRequest, TagOutcome};
