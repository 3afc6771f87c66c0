//! [`StoreError`]: what the SQLite store and the service in front of it can fail with — the
//! database's own failures, or a [`RegistryError`] (any refusal a client can also see). The service
//! sends each as its wire [`ErrorCode`].

use std::path::PathBuf;

use l3p_proto::codec::CodecError;
use l3p_proto::registry::{ErrorCode, RefError};
use l3p_registry_client::RegistryError;

/// A store operation failed.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("cannot open registry database {path}: {source}")]
    Open {
        path: PathBuf,
        #[source]
        source: rusqlite::Error,
    },
    #[error(
        "no registry database at {path}\nhint: pass --data-dir with the directory that holds registry.db"
    )]
    Missing { path: PathBuf },
    #[error("cannot create registry directory {path}: {source}")]
    Dir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "registry database {path} has schema version {found}, newer than this build's {supported}\nhint: use a newer l3p"
    )]
    SchemaTooNew {
        path: PathBuf,
        found: i64,
        supported: i64,
    },
    #[error("registry database error while {context}: {source}")]
    Sqlite {
        context: &'static str,
        #[source]
        source: rusqlite::Error,
    },
    #[error(
        "registry database holds an unreadable {what}: {message}\nhint: restore registry.db from a backup"
    )]
    Corrupt { what: String, message: String },
    #[error(transparent)]
    Registry(#[from] RegistryError),
}

impl StoreError {
    /// The wire class of this error: the database's own failures are internal.
    pub fn code(&self) -> ErrorCode {
        match self {
            Self::Registry(e) => e.code(),
            Self::Open { .. }
            | Self::Missing { .. }
            | Self::Dir { .. }
            | Self::SchemaTooNew { .. }
            | Self::Sqlite { .. }
            | Self::Corrupt { .. } => ErrorCode::Internal,
        }
    }

    /// `true` when the artifact, version or alias does not exist (see
    /// [`RegistryError::is_not_found`]).
    pub fn is_not_found(&self) -> bool {
        self.code() == ErrorCode::NotFound
    }
}

impl From<RefError> for StoreError {
    fn from(e: RefError) -> Self {
        Self::Registry(e.into())
    }
}

impl From<CodecError> for StoreError {
    fn from(e: CodecError) -> Self {
        Self::Registry(e.into())
    }
}

pub(crate) fn sql(context: &'static str) -> impl FnOnce(rusqlite::Error) -> StoreError {
    move |source| StoreError::Sqlite { context, source }
}
