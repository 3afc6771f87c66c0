//! [`RegistryError`]: everything a registry can refuse — in the service, on the wire or in the client
//! — each mapped to a wire [`ErrorCode`] so that a remote error keeps its class. The SQLite store's
//! own failures (opening, SQL, corruption) are `l3p_registry::StoreError`, which wraps this type, so
//! this crate links no database.

use std::time::Duration;

use l3p_proto::codec::CodecError;
use l3p_proto::registry::{ErrorCode, RefError};

/// A registry operation failed.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    #[error("{0}")]
    BadRef(#[from] RefError),
    #[error("artifact {name:?} not found\nhint: `l3p registry list` shows what is stored")]
    UnknownName { name: String },
    #[error("{name} has no version {version} (latest is {latest})")]
    UnknownVersion {
        name: String,
        version: u64,
        latest: u64,
    },
    #[error("{name} has no alias {alias:?} (aliases: {known})")]
    UnknownAlias {
        name: String,
        alias: String,
        known: String,
    },
    #[error("bad request: {0}")]
    BadRequest(String),
    #[error("invalid artifact: {0}")]
    Invalid(String),
    #[error("{name} holds {existing} artifacts, cannot store a {requested} under the same name")]
    KindMismatch {
        name: String,
        existing: String,
        requested: String,
    },
    #[error("{what} of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge { what: String, len: u64, limit: u64 },
    #[error(
        "integrity check failed for {what}: expected sha256 {expected}, got {actual}\nhint: the bytes were corrupted in transit or on disk; retry, or restore registry.db from a backup"
    )]
    Integrity {
        what: String,
        expected: String,
        actual: String,
    },
    #[error(
        "adapter {adapter} was trained against {expected_core} but is being loaded with {given_core}\nhint: load it with {expected_core}, or override with --allow-core-mismatch"
    )]
    CoreMismatch {
        adapter: String,
        expected_core: String,
        given_core: String,
    },
    #[error(
        "{adapter} records no core in its lineage, so it cannot be checked against {given_core}\nhint: override with --allow-core-mismatch"
    )]
    NoCoreLineage { adapter: String, given_core: String },
    #[error("{0}")]
    Codec(#[from] CodecError),
    #[error("zenoh error on {key}: {message}")]
    Zenoh { key: String, message: String },
    #[error(
        "no registry answered on {key} (gave up after {waited:.1?})\nhint: start `l3p registry serve` and check the --connect endpoint"
    )]
    NoReply {
        key: String,
        /// How long the query was tried: its timeout, or less when no registry was reachable at
        /// all after the discovery window (then it fails at once).
        waited: Duration,
    },
    #[error("registry service replied with an error ({code}): {message}")]
    Remote { code: ErrorCode, message: String },
    #[error("malformed reply on {key}: {message}")]
    BadReply { key: String, message: String },
}

impl RegistryError {
    /// The wire class of this error (what the service sends in its [`l3p_proto::registry::ErrorReply`]).
    pub fn code(&self) -> ErrorCode {
        match self {
            Self::UnknownName { .. } | Self::UnknownVersion { .. } | Self::UnknownAlias { .. } => {
                ErrorCode::NotFound
            }
            Self::BadRef(_) | Self::Invalid(_) | Self::BadRequest(_) => ErrorCode::BadRequest,
            Self::KindMismatch { .. } | Self::CoreMismatch { .. } | Self::NoCoreLineage { .. } => {
                ErrorCode::Conflict
            }
            Self::TooLarge { .. } => ErrorCode::TooLarge,
            Self::Integrity { .. } => ErrorCode::Integrity,
            Self::Codec(CodecError::TooLarge { .. }) => ErrorCode::TooLarge,
            Self::Codec(CodecError::WrongVersion { .. }) => ErrorCode::WrongVersion,
            Self::Codec(_) => ErrorCode::BadRequest,
            Self::Remote { code, .. } => *code,
            Self::Zenoh { .. } | Self::NoReply { .. } | Self::BadReply { .. } => {
                ErrorCode::Internal
            }
        }
    }

    /// `true` when the artifact, version or alias does not exist (locally or on the service): the
    /// learner uses it to tell "no checkpoint yet" from a real failure.
    pub fn is_not_found(&self) -> bool {
        self.code() == ErrorCode::NotFound
    }
}

/// `bytes` are the blob `meta` describes (sha256 and size), else [`RegistryError::Integrity`]
/// naming `what` was checked: every blob is checked where it is read, in the store and on arrival.
pub fn check_blob(
    what: impl FnOnce() -> String,
    meta: &l3p_proto::registry::ArtifactMeta,
    bytes: &[u8],
) -> Result<(), RegistryError> {
    let actual = l3p_proto::sha256_hex(bytes);
    if actual != meta.sha256 || bytes.len() as u64 != meta.size {
        return Err(RegistryError::Integrity {
            what: what(),
            expected: meta.sha256.clone(),
            actual,
        });
    }
    Ok(())
}
