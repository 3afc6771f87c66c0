//! [`RegistryAccess`]: one registry API over either the database itself or a service reached over
//! Zenoh, for tools that work either way (`l3p registry list|show|…` with `--data` or without).

use crate::{
    AliasEvent, ArtifactMeta, LineageGraph, ListFilter, PutOutcome, PutRequest, Registry,
    RegistryClient, StoreError, TagOutcome,
};

/// The registry a tool talks to: the SQLite store opened in this process, or a running service.
/// Every method mirrors [`Registry`]'s; a remote refusal arrives as [`StoreError::Registry`].
pub enum RegistryAccess {
    /// `<dir>/registry.db`, opened directly (SQLite locking keeps that safe beside a service).
    Local(Registry),
    /// A registry service, through its Zenoh client.
    Remote(RegistryClient),
}

impl RegistryAccess {
    pub async fn list(&self, filter: &ListFilter) -> Result<Vec<ArtifactMeta>, StoreError> {
        match self {
            Self::Local(r) => r.list(filter),
            Self::Remote(c) => Ok(c.list(filter).await?),
        }
    }

    pub async fn get_meta(&self, reference: &str) -> Result<ArtifactMeta, StoreError> {
        match self {
            Self::Local(r) => r.get_meta(reference),
            Self::Remote(c) => Ok(c.get_meta(reference).await?),
        }
    }

    /// The blob and its metadata, sha256 checked on either side.
    pub async fn get_blob(&self, reference: &str) -> Result<(ArtifactMeta, Vec<u8>), StoreError> {
        match self {
            Self::Local(r) => r.get_blob(reference),
            Self::Remote(c) => Ok(c.get_blob(reference).await?),
        }
    }

    pub async fn put(&self, req: PutRequest) -> Result<PutOutcome, StoreError> {
        match self {
            Self::Local(r) => r.put(req),
            Self::Remote(c) => Ok(c.put(req).await?),
        }
    }

    pub async fn tag(&self, reference: &str, alias: &str) -> Result<TagOutcome, StoreError> {
        match self {
            Self::Local(r) => r.tag(reference, alias),
            Self::Remote(c) => Ok(c.tag(reference, alias).await?),
        }
    }

    pub async fn alias_history(
        &self,
        name: &str,
        alias: Option<&str>,
    ) -> Result<Vec<AliasEvent>, StoreError> {
        match self {
            Self::Local(r) => r.alias_history(name, alias),
            Self::Remote(c) => Ok(c.alias_history(name, alias).await?),
        }
    }

    pub async fn lineage(&self, reference: &str) -> Result<LineageGraph, StoreError> {
        match self {
            Self::Local(r) => r.lineage(reference),
            Self::Remote(c) => Ok(c.lineage(reference).await?),
        }
    }
}
