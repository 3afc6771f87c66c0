//! [`Registry`]: the artifact store, one SQLite database (`<data>/registry.db`, WAL mode).
//!
//! # Storage
//! Blobs live **inside** the database, in a `blobs` table keyed by their hex sha256 (content
//! addressed: two versions with the same bytes share one row). Keeping them in SQLite makes a put one
//! transaction — blob, version row, lineage and alias moves commit together or not at all — so a
//! process killed mid-write leaves nothing behind (no orphan files, no rename races, no fsync order to
//! get right). Policies, adapters and checkpoints of this project are kilobytes to tens of megabytes,
//! well inside SQLite's blob limit ([`MAX_BLOB_BYTES`], SQLite's default `SQLITE_MAX_LENGTH` of 10⁹).
//!
//! Versions are numbered per name from 1 under `BEGIN IMMEDIATE` (the write lock is taken before the
//! next number is read), so writers in several processes never lose or duplicate a version; SQL
//! triggers make versions, blobs, lineage and alias history append-only. `PRAGMA synchronous=FULL`:
//! a committed put survives power loss, not only a process crash.
//!
//! Retention: [`Registry::gc`] is the one way versions leave — old checkpoint versions under a
//! [`RetentionPolicy`], in one transaction that lifts the deletion triggers only inside itself.
//! Numbers are never reused (the newest version of a name is always kept), so a removed version's
//! number leaves a gap that resolves as not found.
//!
//! Main types: [`Registry`], [`IntegrityReport`], [`RetentionPolicy`] and [`GcReport`]; what it takes and returns ([`PutRequest`],
//! [`PutOutcome`], [`ListFilter`], [`TagOutcome`], [`CoreCheck`]) is shared with the client, in
//! `l3p-registry-client`.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use l3p_proto::registry::{
    AliasEvent, ArtifactKind, ArtifactMeta, ArtifactRef, ArtifactSpec, LATEST, LineageEdge,
    LineageGraph, LineageLink, LineageRole, VersionSelector, validate_alias, validate_name,
};
use l3p_registry_client::{
    CoreCheck, ListFilter, PutOutcome, PutRequest, RegistryError, TagOutcome, check_blob,
    check_core, sha256_hex,
};
use rusqlite::{Connection, OpenFlags, OptionalExtension, TransactionBehavior, params};
use serde::{Deserialize, Serialize};

use crate::error::{StoreError, sql};

/// File name of the database inside the data directory.
pub const DB_FILE: &str = "registry.db";

/// Largest blob the store accepts (SQLite's default maximum string/blob length).
pub const MAX_BLOB_BYTES: u64 = 1_000_000_000;

/// Schema version written to `PRAGMA user_version`.
const SCHEMA_VERSION: i64 = 1;

/// How long a writer waits for another process's write lock before giving up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(60);

const SCHEMA: &str = r#"
CREATE TABLE IF NOT EXISTS blobs (
    sha256 TEXT PRIMARY KEY NOT NULL,
    size INTEGER NOT NULL,
    data BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS artifacts (
    name TEXT PRIMARY KEY NOT NULL,
    kind TEXT NOT NULL,
    created_unix_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS versions (
    name TEXT NOT NULL REFERENCES artifacts(name),
    version INTEGER NOT NULL CHECK (version >= 1),
    kind TEXT NOT NULL,
    sha256 TEXT NOT NULL REFERENCES blobs(sha256),
    size INTEGER NOT NULL,
    robot TEXT,
    meta_json TEXT NOT NULL,
    created_unix_ms INTEGER NOT NULL,
    PRIMARY KEY (name, version)
);
CREATE INDEX IF NOT EXISTS versions_by_sha ON versions(name, sha256);
CREATE TABLE IF NOT EXISTS lineage (
    name TEXT NOT NULL,
    version INTEGER NOT NULL,
    role TEXT NOT NULL,
    parent_name TEXT NOT NULL,
    parent_version INTEGER NOT NULL,
    parent_sha256 TEXT NOT NULL,
    PRIMARY KEY (name, version, role, parent_name, parent_version),
    FOREIGN KEY (name, version) REFERENCES versions(name, version),
    FOREIGN KEY (parent_name, parent_version) REFERENCES versions(name, version)
);
CREATE INDEX IF NOT EXISTS lineage_by_parent ON lineage(parent_name, parent_version);
CREATE TABLE IF NOT EXISTS aliases (
    name TEXT NOT NULL,
    alias TEXT NOT NULL,
    version INTEGER NOT NULL,
    updated_unix_ms INTEGER NOT NULL,
    PRIMARY KEY (name, alias),
    FOREIGN KEY (name, version) REFERENCES versions(name, version)
);
CREATE TABLE IF NOT EXISTS alias_history (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    alias TEXT NOT NULL,
    version INTEGER NOT NULL,
    previous INTEGER,
    unix_ms INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS alias_history_by_name ON alias_history(name, alias);
CREATE TRIGGER IF NOT EXISTS versions_immutable BEFORE UPDATE ON versions
    BEGIN SELECT RAISE(ABORT, 'artifact versions are immutable'); END;
CREATE TRIGGER IF NOT EXISTS blobs_immutable BEFORE UPDATE ON blobs
    BEGIN SELECT RAISE(ABORT, 'blobs are immutable'); END;
CREATE TRIGGER IF NOT EXISTS lineage_immutable BEFORE UPDATE ON lineage
    BEGIN SELECT RAISE(ABORT, 'lineage is immutable'); END;
CREATE TRIGGER IF NOT EXISTS alias_history_immutable BEFORE UPDATE ON alias_history
    BEGIN SELECT RAISE(ABORT, 'alias history is append-only'); END;
CREATE TRIGGER IF NOT EXISTS alias_history_permanent BEFORE DELETE ON alias_history
    BEGIN SELECT RAISE(ABORT, 'alias history is append-only'); END;
"#;

/// The triggers that refuse deletions of versions and lineage rows, kept apart from [`SCHEMA`]
/// because [`Registry::gc`] drops and re-creates them inside its transaction (the reason is on
/// `gc`). Part of schema version 1: [`Registry::open`] creates them with the rest.
const PERMANENT_TRIGGERS: &str = r#"
CREATE TRIGGER IF NOT EXISTS versions_permanent BEFORE DELETE ON versions
    BEGIN SELECT RAISE(ABORT, 'artifact versions are immutable'); END;
CREATE TRIGGER IF NOT EXISTS lineage_permanent BEFORE DELETE ON lineage
    BEGIN SELECT RAISE(ABORT, 'lineage is immutable'); END;
"#;

/// Newest versions of each checkpoint artifact that [`RetentionPolicy::default`] keeps.
pub const DEFAULT_KEEP_LAST: u64 = 5;

/// What [`Registry::gc`] keeps. Beyond the newest [`keep_last`](Self::keep_last) versions of every
/// checkpoint artifact, gc always keeps every version an alias points at (`latest` included), every
/// version of the other kinds (cores, adapters, MLPs, deploy policies and robots are few, small next to
/// checkpoints, and what deployments and transfer runs name by number), and, transitively, every
/// lineage parent of a kept version.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RetentionPolicy {
    /// Newest versions kept of each checkpoint artifact; at least 1, so the newest version (and with
    /// it the numbering of the next put) always survives.
    pub keep_last: u64,
}

impl Default for RetentionPolicy {
    fn default() -> Self {
        Self {
            keep_last: DEFAULT_KEEP_LAST,
        }
    }
}

/// Why [`Registry::gc`] kept a checkpoint version older than the newest `keep_last`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum KeepReason {
    /// An alias points at it.
    Alias { alias: String },
    /// A kept version names it in its lineage.
    Lineage { child: String, role: LineageRole },
}

/// A version [`Registry::gc`] kept only because of a [`KeepReason`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct KeptVersion {
    /// `name@version`.
    pub reference: String,
    pub reason: KeepReason,
}

/// One artifact name's share of a [`GcReport`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct GcArtifact {
    pub name: String,
    pub kind: ArtifactKind,
    /// Version numbers that stay, ascending.
    pub kept: Vec<u64>,
    /// Version numbers removed (or, in a dry run, that would be), ascending.
    pub removed: Vec<u64>,
}

/// What [`Registry::gc`] removed, or in a dry run would remove, and what kept the rest alive.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct GcReport {
    pub dry_run: bool,
    pub keep_last: u64,
    /// Every artifact name, ordered by name.
    pub artifacts: Vec<GcArtifact>,
    /// Checkpoint versions older than the newest `keep_last` that an alias or lineage kept.
    pub kept_because: Vec<KeptVersion>,
    pub versions_removed: usize,
    /// Lineage rows of removed versions, and those of kept deploy artifacts naming a removed
    /// checkpoint as the one they were exported from (the only parent gc may remove).
    pub lineage_removed: usize,
    /// Of those, the edges of kept deploy artifacts to removed checkpoints.
    pub lineage_cut: usize,
    /// Blobs no remaining version references.
    pub blobs_removed: usize,
    /// Sum of the removed blobs' sizes.
    pub blob_bytes_removed: u64,
    /// Size of the database file and its WAL before gc.
    pub file_bytes_before: u64,
    /// Size of the database file and its WAL after gc and `VACUUM` (equal to `file_bytes_before` in
    /// a dry run).
    pub file_bytes_after: u64,
}

/// Result of [`Registry::check_integrity`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IntegrityReport {
    /// `PRAGMA integrity_check` output (`["ok"]` when healthy).
    pub sqlite: Vec<String>,
    pub blobs_checked: usize,
    /// sha256 keys whose bytes no longer hash to the key.
    pub bad_blobs: Vec<String>,
}

impl IntegrityReport {
    pub fn is_ok(&self) -> bool {
        self.sqlite == ["ok"] && self.bad_blobs.is_empty()
    }
}

/// Metadata columns kept as one JSON document per version (internal storage, not a wire format).
#[derive(Debug, Serialize, Deserialize)]
struct StoredMeta {
    dims: BTreeMap<String, u64>,
    config: serde_json::Value,
    metrics: BTreeMap<String, f64>,
    producer: String,
    extra: serde_json::Value,
}

type BeforeCommitHook = Box<dyn Fn(&ArtifactMeta) + Send + Sync>;
type BeforeGcCommitHook = Box<dyn Fn(&GcReport) + Send + Sync>;

/// The artifact store. Cheap to share behind an `Arc`: one connection, serialised by a mutex;
/// other processes open their own and SQLite's locking keeps them consistent.
pub struct Registry {
    conn: Mutex<Connection>,
    path: PathBuf,
    before_commit: Option<BeforeCommitHook>,
    before_gc_commit: Option<BeforeGcCommitHook>,
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registry")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

impl Registry {
    /// Open (creating if needed) the registry in `dir` (`dir/registry.db`).
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        std::fs::create_dir_all(dir).map_err(|source| StoreError::Dir {
            path: dir.to_path_buf(),
            source,
        })?;
        Self::open_with(dir, OpenFlags::SQLITE_OPEN_CREATE)
    }

    /// Open the registry in `dir`, refusing to create one: for maintenance (`l3p registry gc`),
    /// where a mistyped directory must be an error, not a new empty database.
    pub fn open_existing(dir: &Path) -> Result<Self, StoreError> {
        let path = dir.join(DB_FILE);
        if !path.is_file() {
            return Err(StoreError::Missing { path });
        }
        Self::open_with(dir, OpenFlags::empty())
    }

    fn open_with(dir: &Path, create: OpenFlags) -> Result<Self, StoreError> {
        let path = dir.join(DB_FILE);
        let open_err = |source| StoreError::Open {
            path: path.clone(),
            source,
        };
        let flags = OpenFlags::SQLITE_OPEN_READ_WRITE | create | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let mut conn = Connection::open_with_flags(&path, flags).map_err(open_err)?;
        conn.busy_timeout(BUSY_TIMEOUT).map_err(open_err)?;
        let mode: String = conn
            .query_row("PRAGMA journal_mode=WAL", [], |row| row.get(0))
            .map_err(open_err)?;
        if !mode.eq_ignore_ascii_case("wal") {
            tracing::warn!(path = %path.display(), mode, "registry database is not in WAL mode");
        }
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(open_err)?;
        conn.pragma_update(None, "foreign_keys", "ON")
            .map_err(open_err)?;
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(open_err)?;
        let found: i64 = tx
            .query_row("PRAGMA user_version", [], |row| row.get(0))
            .map_err(open_err)?;
        if found > SCHEMA_VERSION {
            return Err(StoreError::SchemaTooNew {
                path,
                found,
                supported: SCHEMA_VERSION,
            });
        }
        if found < SCHEMA_VERSION {
            tx.execute_batch(SCHEMA).map_err(open_err)?;
            tx.execute_batch(PERMANENT_TRIGGERS).map_err(open_err)?;
            tx.pragma_update(None, "user_version", SCHEMA_VERSION)
                .map_err(open_err)?;
        }
        tx.commit().map_err(open_err)?;
        tracing::debug!(path = %path.display(), "registry opened");
        Ok(Self {
            conn: Mutex::new(conn),
            path,
            before_commit: None,
            before_gc_commit: None,
        })
    }

    /// Path of the database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Test seam: called inside the put transaction, after every row is written and before commit.
    /// Crash tests use it to kill a writer at the worst moment.
    #[doc(hidden)]
    pub fn set_before_commit_hook(&mut self, hook: impl Fn(&ArtifactMeta) + Send + Sync + 'static) {
        self.before_commit = Some(Box::new(hook));
    }

    /// Test seam: called inside the gc transaction, after every deletion and before commit.
    #[doc(hidden)]
    pub fn set_before_gc_commit_hook(&mut self, hook: impl Fn(&GcReport) + Send + Sync + 'static) {
        self.before_gc_commit = Some(Box::new(hook));
    }

    fn lock(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the lock cannot leave a transaction open (rusqlite rolls back on
        // drop), so a poisoned connection is still consistent.
        self.conn
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Store a new immutable version of `req.spec.name` (see [`PutOutcome`] for deduplication).
    pub fn put(&self, req: PutRequest) -> Result<PutOutcome, StoreError> {
        let PutRequest {
            spec,
            bytes,
            expected_sha256,
        } = req;
        let lineage = validate_spec(&spec)?;
        let size = bytes.len() as u64;
        if size > MAX_BLOB_BYTES {
            return Err(RegistryError::TooLarge {
                what: format!("blob for {}", spec.name),
                len: size,
                limit: MAX_BLOB_BYTES,
            }
            .into());
        }
        let sha256 = sha256_hex(&bytes);
        if let Some(expected) = expected_sha256
            && !expected.eq_ignore_ascii_case(&sha256)
        {
            return Err(RegistryError::Integrity {
                what: format!("blob received for {}", spec.name),
                expected,
                actual: sha256,
            }
            .into());
        }
        let stored = StoredMeta {
            dims: spec.dims.clone(),
            config: spec.config.clone(),
            metrics: spec.metrics.clone(),
            producer: spec.producer.clone(),
            extra: spec.extra.clone(),
        };
        let meta_json = serde_json::to_string(&stored).map_err(|e| {
            RegistryError::Invalid(format!("metadata of {} is not JSON: {e}", spec.name))
        })?;

        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(sql("starting a write transaction"))?;
        let now = now_ms();
        let name = spec.name.as_str();
        let existing_kind: Option<String> = tx
            .query_row(
                "SELECT kind FROM artifacts WHERE name = ?1",
                [name],
                |row| row.get(0),
            )
            .optional()
            .map_err(sql("reading the artifact kind"))?;
        match existing_kind {
            Some(kind) if kind != spec.kind.as_str() => {
                return Err(RegistryError::KindMismatch {
                    name: name.to_string(),
                    existing: kind,
                    requested: spec.kind.to_string(),
                }
                .into());
            }
            Some(_) => {}
            None => {
                tx.execute(
                    "INSERT INTO artifacts (name, kind, created_unix_ms) VALUES (?1, ?2, ?3)",
                    params![name, spec.kind.as_str(), now as i64],
                )
                .map_err(sql("creating the artifact"))?;
            }
        }

        // Identical bytes under the same name: return that version (idempotent retries).
        let duplicate: Option<i64> = tx
            .query_row(
                "SELECT version FROM versions WHERE name = ?1 AND sha256 = ?2 ORDER BY version LIMIT 1",
                params![name, sha256],
                |row| row.get(0),
            )
            .optional()
            .map_err(sql("looking for identical content"))?;
        if let Some(version) = duplicate {
            let version = version as u64;
            for alias in &spec.aliases {
                set_alias(&tx, name, alias, version, now)?;
            }
            let meta = load_meta(&tx, name, version)?;
            tx.commit().map_err(sql("committing alias moves"))?;
            tracing::info!(artifact = %meta.reference(), "put deduplicated: identical content already stored");
            return Ok(PutOutcome {
                meta,
                created: false,
            });
        }

        let mut edges = Vec::with_capacity(lineage.len());
        for (role, reference) in &lineage {
            let version = resolve(&tx, reference)?;
            let (kind, parent_sha): (String, String) = tx
                .query_row(
                    "SELECT kind, sha256 FROM versions WHERE name = ?1 AND version = ?2",
                    params![reference.name, version as i64],
                    |row| Ok((row.get(0)?, row.get(1)?)),
                )
                .map_err(sql("reading a lineage parent"))?;
            let wanted = match role {
                LineageRole::TrainedAgainst | LineageRole::FrozenCore => Some(ArtifactKind::Core),
                LineageRole::FromCheckpoint => Some(ArtifactKind::Checkpoint),
                LineageRole::InitialisedFrom | LineageRole::DerivedFrom => None,
            };
            if let Some(wanted) = wanted
                && kind != wanted.as_str()
            {
                return Err(RegistryError::Invalid(format!(
                    "lineage role {role} must name a {wanted} artifact, but {}@{version} is a {kind}",
                    reference.name
                )).into());
            }
            edges.push(LineageEdge {
                role: *role,
                name: reference.name.clone(),
                version,
                sha256: parent_sha,
            });
        }

        let next: i64 = tx
            .query_row(
                "SELECT COALESCE(MAX(version), 0) + 1 FROM versions WHERE name = ?1",
                [name],
                |row| row.get(0),
            )
            .map_err(sql("numbering the new version"))?;
        let version = next as u64;
        tx.execute(
            "INSERT OR IGNORE INTO blobs (sha256, size, data) VALUES (?1, ?2, ?3)",
            params![sha256, size as i64, bytes],
        )
        .map_err(sql("storing the blob"))?;
        tx.execute(
            "INSERT INTO versions (name, version, kind, sha256, size, robot, meta_json, created_unix_ms)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
            params![name, next, spec.kind.as_str(), sha256, size as i64, spec.robot, meta_json, now as i64],
        )
        .map_err(sql("storing the version"))?;
        for edge in &edges {
            tx.execute(
                "INSERT OR IGNORE INTO lineage (name, version, role, parent_name, parent_version, parent_sha256)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                params![name, next, edge.role.as_str(), edge.name, edge.version as i64, edge.sha256],
            )
            .map_err(sql("storing lineage"))?;
        }
        set_alias(&tx, name, LATEST, version, now)?;
        for alias in &spec.aliases {
            set_alias(&tx, name, alias, version, now)?;
        }
        let meta = load_meta(&tx, name, version)?;
        if let Some(hook) = &self.before_commit {
            hook(&meta);
        }
        tx.commit().map_err(sql("committing the new version"))?;
        tracing::info!(artifact = %meta.reference(), kind = %meta.kind, size, sha256 = %meta.sha256, "stored");
        Ok(PutOutcome {
            meta,
            created: true,
        })
    }

    /// Metadata of the version `reference` (`name@version|alias`) resolves to.
    pub fn get_meta(&self, reference: &str) -> Result<ArtifactMeta, StoreError> {
        let reference = ArtifactRef::parse(reference)?;
        let conn = self.lock();
        let version = resolve(&conn, &reference)?;
        load_meta(&conn, &reference.name, version)
    }

    /// Metadata and bytes; the bytes are hashed and compared with the stored sha256.
    pub fn get_blob(&self, reference: &str) -> Result<(ArtifactMeta, Vec<u8>), StoreError> {
        let parsed = ArtifactRef::parse(reference)?;
        let mut conn = self.lock();
        let tx = conn
            .transaction()
            .map_err(sql("starting a read transaction"))?;
        let version = resolve(&tx, &parsed)?;
        let meta = load_meta(&tx, &parsed.name, version)?;
        let bytes: Vec<u8> = tx
            .query_row(
                "SELECT data FROM blobs WHERE sha256 = ?1",
                [&meta.sha256],
                |row| row.get(0),
            )
            .map_err(sql("reading the blob"))?;
        tx.finish().map_err(sql("ending a read transaction"))?;
        drop(conn);
        check_blob(
            || format!("stored blob of {}", meta.reference()),
            &meta,
            &bytes,
        )?;
        Ok((meta, bytes))
    }

    /// Every version matching `filter`, ordered by name then version.
    pub fn list(&self, filter: &ListFilter) -> Result<Vec<ArtifactMeta>, StoreError> {
        let conn = self.lock();
        let mut stmt = conn
            .prepare(
                "SELECT name, version FROM versions
                 WHERE (?1 IS NULL OR kind = ?1) AND (?2 IS NULL OR name = ?2) AND (?3 IS NULL OR robot = ?3)
                 ORDER BY name, version",
            )
            .map_err(sql("listing versions"))?;
        let rows = stmt
            .query_map(
                params![filter.kind.map(|k| k.as_str()), filter.name, filter.robot],
                |row| Ok((row.get::<_, String>(0)?, row.get::<_, i64>(1)?)),
            )
            .map_err(sql("listing versions"))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(sql("listing versions"))?;
        rows.into_iter()
            .map(|(name, version)| load_meta(&conn, &name, version as u64))
            .collect()
    }

    /// Point `alias` of the artifact's name at the version `reference` resolves to. `latest` is
    /// reserved: the registry moves it on every put.
    pub fn tag(&self, reference: &str, alias: &str) -> Result<TagOutcome, StoreError> {
        let parsed = ArtifactRef::parse(reference)?;
        validate_alias(alias)?;
        if alias == LATEST {
            return Err(RegistryError::Invalid(format!(
                "alias {LATEST:?} is moved by the registry on every put and cannot be set by hand\nhint: use another alias, e.g. prod"
            )).into());
        }
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(sql("starting a write transaction"))?;
        let version = resolve(&tx, &parsed)?;
        let (event, moved) = set_alias(&tx, &parsed.name, alias, version, now_ms())?;
        tx.commit().map_err(sql("committing the alias move"))?;
        if moved {
            tracing::info!(name = %parsed.name, alias, version, previous = ?event.previous, "alias moved");
        }
        Ok(TagOutcome { event, moved })
    }

    /// Every recorded move of `alias` of `name` (all aliases when `None`), oldest first.
    pub fn alias_history(
        &self,
        name: &str,
        alias: Option<&str>,
    ) -> Result<Vec<AliasEvent>, StoreError> {
        validate_name(name)?;
        let conn = self.lock();
        ensure_name(&conn, name)?;
        let mut stmt = conn
            .prepare(
                "SELECT alias, version, previous, unix_ms FROM alias_history
                 WHERE name = ?1 AND (?2 IS NULL OR alias = ?2) ORDER BY id",
            )
            .map_err(sql("reading alias history"))?;
        let events = stmt
            .query_map(params![name, alias], |row| {
                Ok(AliasEvent {
                    name: name.to_string(),
                    alias: row.get(0)?,
                    version: row.get::<_, i64>(1)? as u64,
                    previous: row.get::<_, Option<i64>>(2)?.map(|v| v as u64),
                    unix_ms: row.get::<_, i64>(3)? as u64,
                })
            })
            .map_err(sql("reading alias history"))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(sql("reading alias history"))?;
        Ok(events)
    }

    /// The version `reference` resolves to, with its transitive dependencies and dependents.
    pub fn lineage(&self, reference: &str) -> Result<LineageGraph, StoreError> {
        let parsed = ArtifactRef::parse(reference)?;
        let conn = self.lock();
        let version = resolve(&conn, &parsed)?;
        let artifact = load_meta(&conn, &parsed.name, version)?;
        let start = (parsed.name.clone(), version);
        let upstream = walk(&conn, &start, Direction::Up)?;
        let downstream = walk(&conn, &start, Direction::Down)?;
        Ok(LineageGraph {
            artifact,
            upstream,
            downstream,
        })
    }

    /// Check that the adapter `adapter_ref` may be loaded with the core `core_ref` (see [`check_core`]).
    pub fn check_adapter_against_core(
        &self,
        adapter_ref: &str,
        core_ref: &str,
        allow_mismatch: bool,
    ) -> Result<CoreCheck, StoreError> {
        let adapter = self.get_meta(adapter_ref)?;
        let core = self.get_meta(core_ref)?;
        Ok(check_core(adapter, core, allow_mismatch)?)
    }

    /// Remove what `policy` does not keep (see [`RetentionPolicy`]): the versions, their lineage rows
    /// and the blobs no remaining version references; then `VACUUM` to give the space back to the
    /// file system. With `dry_run`, only report what would go.
    ///
    /// One transaction: a crash or an error before the commit leaves the database as it was. The
    /// deletion triggers (`versions_permanent`, `lineage_permanent`) are dropped and re-created
    /// inside that transaction. SQLite's DDL is transactional, so no other connection ever sees the
    /// database without them, and a rollback (crash, error, the test hook panicking) restores them
    /// with everything else. A guarded trigger (`WHEN NOT EXISTS (SELECT 1 FROM gc_permit)`) would
    /// need a permit any writer could also insert — triggers of the main schema cannot read a
    /// connection's private TEMP tables — and a schema migration for existing databases.
    pub fn gc(&self, policy: &RetentionPolicy, dry_run: bool) -> Result<GcReport, StoreError> {
        if policy.keep_last == 0 {
            return Err(RegistryError::Invalid(
                "gc must keep at least the newest version of each checkpoint (keep_last >= 1)"
                    .into(),
            )
            .into());
        }
        let file_bytes_before = self.file_bytes();
        let mut conn = self.lock();
        let tx = if dry_run {
            conn.transaction()
                .map_err(sql("starting a read transaction"))?
        } else {
            conn.transaction_with_behavior(TransactionBehavior::Immediate)
                .map_err(sql("starting a write transaction"))?
        };
        let plan = plan_gc(&tx, policy.keep_last)?;
        let mut report = GcReport {
            dry_run,
            keep_last: policy.keep_last,
            artifacts: plan.artifacts,
            kept_because: plan.kept_because,
            versions_removed: plan.removed.len(),
            lineage_removed: plan.lineage_removed,
            lineage_cut: plan.lineage_cut,
            blobs_removed: plan.blobs.len(),
            blob_bytes_removed: plan.blob_bytes,
            file_bytes_before,
            file_bytes_after: file_bytes_before,
        };
        if dry_run || (plan.removed.is_empty() && plan.blobs.is_empty()) {
            tx.finish().map_err(sql("ending the gc transaction"))?;
            return Ok(report);
        }

        tx.execute_batch(
            "DROP TRIGGER IF EXISTS versions_permanent; DROP TRIGGER IF EXISTS lineage_permanent;",
        )
        .map_err(sql("lifting the deletion triggers"))?;
        let mut lineage_removed = 0;
        {
            let mut drop_lineage = tx
                .prepare("DELETE FROM lineage WHERE name = ?1 AND version = ?2")
                .map_err(sql("removing lineage"))?;
            // A kept deploy artifact's edge to the checkpoint it was exported from (see `plan_gc`);
            // no other edge to a removed version may exist.
            let mut cut_lineage = tx
                .prepare(
                    "DELETE FROM lineage WHERE parent_name = ?1 AND parent_version = ?2 \
                     AND role = 'from_checkpoint' AND EXISTS (SELECT 1 FROM versions v \
                     WHERE v.name = lineage.name AND v.version = lineage.version \
                     AND v.kind = 'deploy')",
                )
                .map_err(sql("removing lineage"))?;
            let mut drop_version = tx
                .prepare("DELETE FROM versions WHERE name = ?1 AND version = ?2")
                .map_err(sql("removing versions"))?;
            // Edges first (a removed parent may sort before its removed child), then versions.
            for (name, version) in &plan.removed {
                lineage_removed += drop_lineage
                    .execute(params![name, *version as i64])
                    .map_err(sql("removing lineage"))?;
            }
            for (name, version) in &plan.removed {
                lineage_removed += cut_lineage
                    .execute(params![name, *version as i64])
                    .map_err(sql("removing lineage"))?;
            }
            for (name, version) in &plan.removed {
                // `foreign_keys` is on: deleting a version some remaining lineage row names as its
                // parent fails here, so lineage can never be left dangling.
                drop_version
                    .execute(params![name, *version as i64])
                    .map_err(sql("removing versions"))?;
            }
        }
        let blobs_removed = tx
            .execute(
                "DELETE FROM blobs WHERE NOT EXISTS (SELECT 1 FROM versions WHERE versions.sha256 = blobs.sha256)",
                [],
            )
            .map_err(sql("removing blobs"))?;
        tx.execute_batch(PERMANENT_TRIGGERS)
            .map_err(sql("restoring the deletion triggers"))?;
        if lineage_removed != report.lineage_removed || blobs_removed != report.blobs_removed {
            // The plan was made in this transaction, so this would be a bug: keep the database as
            // it was rather than report something else than what was done.
            return Err(corrupt(
                "gc plan",
                format!(
                    "planned {} lineage rows and {} blobs, removed {lineage_removed} and {blobs_removed}",
                    report.lineage_removed, report.blobs_removed
                ),
            ));
        }
        if let Some(hook) = &self.before_gc_commit {
            hook(&report);
        }
        tx.commit().map_err(sql("committing the gc"))?;
        tracing::info!(
            versions = report.versions_removed,
            blobs = report.blobs_removed,
            bytes = report.blob_bytes_removed,
            "gc removed old checkpoint versions"
        );
        // Give the freed pages back to the file system. In WAL mode VACUUM writes the new file into
        // the WAL; the TRUNCATE checkpoint copies it back, shrinks the database file and empties the
        // WAL. Both are after the commit: if either fails (another process holds the database),
        // the gc stands and the space is reused by later puts.
        if let Err(e) = conn.execute_batch("VACUUM; PRAGMA wal_checkpoint(TRUNCATE);") {
            tracing::warn!(path = %self.path.display(), error = %e, "gc committed, but VACUUM failed; the file keeps its size");
        }
        drop(conn);
        report.file_bytes_after = self.file_bytes();
        Ok(report)
    }

    /// Bytes of the database file plus its WAL.
    fn file_bytes(&self) -> u64 {
        let len = |path: &Path| std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        let mut wal = self.path.clone().into_os_string();
        wal.push("-wal");
        len(&self.path) + len(Path::new(&wal))
    }

    /// `PRAGMA integrity_check` plus a re-hash of every blob.
    pub fn check_integrity(&self) -> Result<IntegrityReport, StoreError> {
        let conn = self.lock();
        let mut stmt = conn
            .prepare("PRAGMA integrity_check")
            .map_err(sql("checking integrity"))?;
        let sqlite = stmt
            .query_map([], |row| row.get::<_, String>(0))
            .map_err(sql("checking integrity"))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(sql("checking integrity"))?;
        let mut stmt = conn
            .prepare("SELECT sha256, data FROM blobs")
            .map_err(sql("checking blobs"))?;
        let mut rows = stmt.query([]).map_err(sql("checking blobs"))?;
        let (mut blobs_checked, mut bad_blobs) = (0, Vec::new());
        while let Some(row) = rows.next().map_err(sql("checking blobs"))? {
            let sha: String = row.get(0).map_err(sql("checking blobs"))?;
            let data: Vec<u8> = row.get(1).map_err(sql("checking blobs"))?;
            blobs_checked += 1;
            if sha256_hex(&data) != sha {
                bad_blobs.push(sha);
            }
        }
        Ok(IntegrityReport {
            sqlite,
            blobs_checked,
            bad_blobs,
        })
    }
}

/// What [`Registry::gc`] will remove, decided from one consistent read of the database.
struct GcPlan {
    artifacts: Vec<GcArtifact>,
    kept_because: Vec<KeptVersion>,
    /// `(name, version)` of every version to remove.
    removed: Vec<(String, u64)>,
    lineage_removed: usize,
    lineage_cut: usize,
    /// sha256 of every blob no kept version references.
    blobs: Vec<String>,
    blob_bytes: u64,
}

fn plan_gc(conn: &Connection, keep_last: u64) -> Result<GcPlan, StoreError> {
    type Key = (String, u64);
    // Every version, newest first within a name.
    let mut stmt = conn
        .prepare("SELECT name, version, kind, sha256 FROM versions ORDER BY name, version DESC")
        .map_err(sql("planning gc"))?;
    let versions = stmt
        .query_map([], |row| {
            Ok((
                row.get::<_, String>(0)?,
                row.get::<_, i64>(1)? as u64,
                row.get::<_, String>(2)?,
                row.get::<_, String>(3)?,
            ))
        })
        .map_err(sql("planning gc"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("planning gc"))?;
    let versions = versions
        .into_iter()
        .map(|(name, version, kind, sha256)| {
            let kind: ArtifactKind = kind
                .parse()
                .map_err(|e| corrupt(&format!("kind of {name}@{version}"), e))?;
            Ok((name, version, kind, sha256))
        })
        .collect::<Result<Vec<_>, StoreError>>()?;
    let mut kept: BTreeSet<Key> = BTreeSet::new();
    let mut seen_of_name: BTreeMap<&str, u64> = BTreeMap::new();
    for (name, version, kind, _) in &versions {
        let seen = seen_of_name.entry(name).or_insert(0);
        *seen += 1;
        if *kind != ArtifactKind::Checkpoint || *seen <= keep_last {
            kept.insert((name.clone(), *version));
        }
    }

    let mut kept_because = Vec::new();
    let mut stmt = conn
        .prepare("SELECT name, alias, version FROM aliases ORDER BY name, alias")
        .map_err(sql("planning gc"))?;
    let aliases = stmt
        .query_map([], |row| {
            Ok((
                row.get::<_, String>(0)?,
                row.get::<_, String>(1)?,
                row.get::<_, i64>(2)? as u64,
            ))
        })
        .map_err(sql("planning gc"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("planning gc"))?;
    for (name, alias, version) in aliases {
        if kept.insert((name.clone(), version)) {
            kept_because.push(KeptVersion {
                reference: format!("{name}@{version}"),
                reason: KeepReason::Alias { alias },
            });
        }
    }

    // Lineage parents of kept versions, transitively (breadth-first from every kept version).
    let mut stmt = conn
        .prepare(
            "SELECT name, version, role, parent_name, parent_version FROM lineage ORDER BY rowid",
        )
        .map_err(sql("planning gc"))?;
    let edges = stmt
        .query_map([], lineage_edge)
        .map_err(sql("planning gc"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("planning gc"))?;
    let kinds: BTreeMap<Key, ArtifactKind> = versions
        .iter()
        .map(|(name, version, kind, _)| ((name.clone(), *version), *kind))
        .collect();
    let mut parents: BTreeMap<Key, Vec<(LineageRole, Key)>> = BTreeMap::new();
    let mut all_edges: Vec<(Key, Key)> = Vec::new();
    for (name, version, role, parent, parent_version) in edges {
        let role: LineageRole = role.parse().map_err(|e| corrupt("lineage role", e))?;
        let (child, parent) = ((name, version), (parent, parent_version));
        all_edges.push((child.clone(), parent.clone()));
        // A deploy artifact is self-contained: the checkpoint it was exported from does not have
        // to outlive it (every run uploads one with each registry checkpoint, so that edge would
        // keep every checkpoint). Its edge goes with the checkpoint; every other role pins.
        if role == LineageRole::FromCheckpoint && kinds.get(&child) == Some(&ArtifactKind::Deploy) {
            continue;
        }
        parents.entry(child).or_default().push((role, parent));
    }
    let mut queue: VecDeque<Key> = kept.iter().cloned().collect();
    while let Some(child) = queue.pop_front() {
        for (role, parent) in parents.get(&child).into_iter().flatten() {
            if kept.insert(parent.clone()) {
                kept_because.push(KeptVersion {
                    reference: format!("{}@{}", parent.0, parent.1),
                    reason: KeepReason::Lineage {
                        child: format!("{}@{}", child.0, child.1),
                        role: *role,
                    },
                });
                queue.push_back(parent.clone());
            }
        }
    }

    let mut artifacts: BTreeMap<String, GcArtifact> = BTreeMap::new();
    let mut removed = Vec::new();
    let mut kept_blobs = BTreeSet::new();
    for (name, version, kind, sha256) in versions.into_iter().rev() {
        let entry = artifacts.entry(name.clone()).or_insert_with(|| GcArtifact {
            name: name.clone(),
            kind,
            kept: Vec::new(),
            removed: Vec::new(),
        });
        let key = (name, version);
        if kept.contains(&key) {
            entry.kept.push(version);
            kept_blobs.insert(sha256);
        } else {
            entry.removed.push(version);
            removed.push(key);
        }
    }
    let gone: BTreeSet<&Key> = removed.iter().collect();
    let lineage_removed = all_edges
        .iter()
        .filter(|(child, parent)| gone.contains(child) || gone.contains(parent))
        .count();
    let lineage_cut = all_edges
        .iter()
        .filter(|(child, parent)| !gone.contains(child) && gone.contains(parent))
        .count();

    let mut stmt = conn
        .prepare("SELECT sha256, size FROM blobs ORDER BY sha256")
        .map_err(sql("planning gc"))?;
    let all_blobs = stmt
        .query_map([], |row| {
            Ok((row.get::<_, String>(0)?, row.get::<_, i64>(1)? as u64))
        })
        .map_err(sql("planning gc"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("planning gc"))?;
    let (mut blobs, mut blob_bytes) = (Vec::new(), 0);
    for (sha256, size) in all_blobs {
        if !kept_blobs.contains(&sha256) {
            blobs.push(sha256);
            blob_bytes += size;
        }
    }
    Ok(GcPlan {
        artifacts: artifacts.into_values().collect(),
        kept_because,
        removed,
        lineage_removed,
        lineage_cut,
        blobs,
        blob_bytes,
    })
}

/// Validate what a writer sent; returns the parsed lineage references.
fn validate_spec(spec: &ArtifactSpec) -> Result<Vec<(LineageRole, ArtifactRef)>, RegistryError> {
    validate_name(&spec.name)?;
    let invalid =
        |message: String| Err(RegistryError::Invalid(format!("{}: {message}", spec.name)));
    match &spec.robot {
        Some(robot) => {
            if let Err(e) = l3p_proto::keys::validate_segment("robot", robot) {
                return invalid(e.to_string());
            }
        }
        None if spec.kind == ArtifactKind::Adapter => {
            return invalid("an adapter must name its robot\nhint: set `robot`".into());
        }
        None => {}
    }
    if let Some((key, value)) = spec.metrics.iter().find(|(_, v)| !v.is_finite()) {
        return invalid(format!("metric {key:?} is {value}, metrics must be finite"));
    }
    for alias in &spec.aliases {
        validate_alias(alias)?;
        if alias == LATEST {
            return invalid(format!("alias {LATEST:?} is set by the registry itself"));
        }
    }
    spec.lineage
        .iter()
        .map(|input| {
            let reference = ArtifactRef::parse(&input.artifact)?;
            if reference.name == spec.name {
                return Err(RegistryError::Invalid(format!(
                    "{}: lineage may not point at the artifact's own name",
                    spec.name
                )));
            }
            Ok((input.role, reference))
        })
        .collect()
}

fn ensure_name(conn: &Connection, name: &str) -> Result<(), StoreError> {
    let exists: Option<i64> = conn
        .query_row("SELECT 1 FROM artifacts WHERE name = ?1", [name], |row| {
            row.get(0)
        })
        .optional()
        .map_err(sql("looking up a name"))?;
    match exists {
        Some(_) => Ok(()),
        None => Err(RegistryError::UnknownName {
            name: name.to_string(),
        }
        .into()),
    }
}

/// The version number a reference points to, or a not-found error saying what exists.
fn resolve(conn: &Connection, reference: &ArtifactRef) -> Result<u64, StoreError> {
    let name = reference.name.as_str();
    match &reference.selector {
        VersionSelector::Version(version) => {
            let latest: Option<i64> = conn
                .query_row(
                    "SELECT MAX(version) FROM versions WHERE name = ?1",
                    [name],
                    |row| row.get(0),
                )
                .map_err(sql("resolving a version"))?;
            match latest {
                None => Err(RegistryError::UnknownName {
                    name: name.to_string(),
                }
                .into()),
                Some(latest) if *version > latest as u64 => Err(RegistryError::UnknownVersion {
                    name: name.to_string(),
                    version: *version,
                    latest: latest as u64,
                }
                .into()),
                Some(latest) => {
                    // `gc` leaves gaps below the latest version.
                    let exists: Option<i64> = conn
                        .query_row(
                            "SELECT 1 FROM versions WHERE name = ?1 AND version = ?2",
                            params![name, *version as i64],
                            |row| row.get(0),
                        )
                        .optional()
                        .map_err(sql("resolving a version"))?;
                    match exists {
                        Some(_) => Ok(*version),
                        None => Err(RegistryError::UnknownVersion {
                            name: name.to_string(),
                            version: *version,
                            latest: latest as u64,
                        }
                        .into()),
                    }
                }
            }
        }
        VersionSelector::Alias(alias) => {
            let version: Option<i64> = conn
                .query_row(
                    "SELECT version FROM aliases WHERE name = ?1 AND alias = ?2",
                    params![name, alias],
                    |row| row.get(0),
                )
                .optional()
                .map_err(sql("resolving an alias"))?;
            if let Some(version) = version {
                return Ok(version as u64);
            }
            ensure_name(conn, name)?;
            let mut stmt = conn
                .prepare("SELECT alias FROM aliases WHERE name = ?1 ORDER BY alias")
                .map_err(sql("listing aliases"))?;
            let known = stmt
                .query_map([name], |row| row.get::<_, String>(0))
                .map_err(sql("listing aliases"))?
                .collect::<Result<Vec<_>, _>>()
                .map_err(sql("listing aliases"))?;
            Err(RegistryError::UnknownAlias {
                name: name.to_string(),
                alias: alias.clone(),
                known: known.join(", "),
            }
            .into())
        }
    }
}

/// Move (or create) an alias and record the move; no-op when it already points at `version`.
fn set_alias(
    conn: &Connection,
    name: &str,
    alias: &str,
    version: u64,
    now: u64,
) -> Result<(AliasEvent, bool), StoreError> {
    let previous: Option<i64> = conn
        .query_row(
            "SELECT version FROM aliases WHERE name = ?1 AND alias = ?2",
            params![name, alias],
            |row| row.get(0),
        )
        .optional()
        .map_err(sql("reading an alias"))?;
    let previous = previous.map(|v| v as u64);
    let event = AliasEvent {
        name: name.to_string(),
        alias: alias.to_string(),
        version,
        previous,
        unix_ms: now,
    };
    if previous == Some(version) {
        return Ok((event, false));
    }
    conn.execute(
        "INSERT INTO aliases (name, alias, version, updated_unix_ms) VALUES (?1, ?2, ?3, ?4)
         ON CONFLICT (name, alias) DO UPDATE SET version = excluded.version, updated_unix_ms = excluded.updated_unix_ms",
        params![name, alias, version as i64, now as i64],
    )
    .map_err(sql("moving an alias"))?;
    conn.execute(
        "INSERT INTO alias_history (name, alias, version, previous, unix_ms) VALUES (?1, ?2, ?3, ?4, ?5)",
        params![name, alias, version as i64, previous.map(|v| v as i64), now as i64],
    )
    .map_err(sql("recording an alias move"))?;
    Ok((event, true))
}

fn corrupt(what: &str, message: impl std::fmt::Display) -> StoreError {
    StoreError::Corrupt {
        what: what.to_string(),
        message: message.to_string(),
    }
}

/// Read one version's metadata, lineage and current aliases.
fn load_meta(conn: &Connection, name: &str, version: u64) -> Result<ArtifactMeta, StoreError> {
    let row = conn
        .query_row(
            "SELECT kind, sha256, size, robot, meta_json, created_unix_ms FROM versions WHERE name = ?1 AND version = ?2",
            params![name, version as i64],
            |row| {
                Ok((
                    row.get::<_, String>(0)?,
                    row.get::<_, String>(1)?,
                    row.get::<_, i64>(2)?,
                    row.get::<_, Option<String>>(3)?,
                    row.get::<_, String>(4)?,
                    row.get::<_, i64>(5)?,
                ))
            },
        )
        .optional()
        .map_err(sql("reading a version"))?;
    let Some((kind, sha256, size, robot, meta_json, created)) = row else {
        return Err(RegistryError::UnknownVersion {
            name: name.to_string(),
            version,
            latest: 0,
        }
        .into());
    };
    let reference = format!("{name}@{version}");
    let kind: ArtifactKind = kind
        .parse()
        .map_err(|e| corrupt(&format!("kind of {reference}"), e))?;
    let stored: StoredMeta = serde_json::from_str(&meta_json)
        .map_err(|e| corrupt(&format!("metadata of {reference}"), e))?;
    let mut stmt = conn
        .prepare(
            "SELECT role, parent_name, parent_version, parent_sha256 FROM lineage
             WHERE name = ?1 AND version = ?2 ORDER BY rowid",
        )
        .map_err(sql("reading lineage"))?;
    let raw = stmt
        .query_map(params![name, version as i64], |row| {
            Ok((
                row.get::<_, String>(0)?,
                row.get::<_, String>(1)?,
                row.get::<_, i64>(2)?,
                row.get::<_, String>(3)?,
            ))
        })
        .map_err(sql("reading lineage"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("reading lineage"))?;
    let lineage = raw
        .into_iter()
        .map(|(role, parent, parent_version, sha)| {
            let role = role
                .parse()
                .map_err(|e| corrupt(&format!("lineage of {reference}"), e))?;
            Ok(LineageEdge {
                role,
                name: parent,
                version: parent_version as u64,
                sha256: sha,
            })
        })
        .collect::<Result<Vec<_>, StoreError>>()?;
    let mut stmt = conn
        .prepare("SELECT alias FROM aliases WHERE name = ?1 AND version = ?2 ORDER BY alias")
        .map_err(sql("reading aliases"))?;
    let aliases = stmt
        .query_map(params![name, version as i64], |row| row.get::<_, String>(0))
        .map_err(sql("reading aliases"))?
        .collect::<Result<Vec<_>, _>>()
        .map_err(sql("reading aliases"))?;
    Ok(ArtifactMeta {
        name: name.to_string(),
        version,
        kind,
        sha256,
        size: size as u64,
        robot,
        dims: stored.dims,
        config: stored.config,
        metrics: stored.metrics,
        producer: stored.producer,
        extra: stored.extra,
        created_unix_ms: created as u64,
        lineage,
        aliases,
    })
}

#[derive(Clone, Copy)]
enum Direction {
    Up,
    Down,
}

/// Breadth-first walk of lineage edges from `start` (the graph is acyclic: a parent must exist before
/// its child is stored).
fn walk(
    conn: &Connection,
    start: &(String, u64),
    direction: Direction,
) -> Result<Vec<LineageLink>, StoreError> {
    let query = match direction {
        Direction::Up => {
            "SELECT name, version, role, parent_name, parent_version FROM lineage WHERE name = ?1 AND version = ?2 ORDER BY rowid"
        }
        Direction::Down => {
            "SELECT name, version, role, parent_name, parent_version FROM lineage
             WHERE parent_name = ?1 AND parent_version = ?2 ORDER BY name, version"
        }
    };
    let mut stmt = conn.prepare(query).map_err(sql("walking lineage"))?;
    let mut seen = BTreeSet::from([start.clone()]);
    let mut queue = VecDeque::from([start.clone()]);
    let mut links = Vec::new();
    while let Some((name, version)) = queue.pop_front() {
        let rows = stmt
            .query_map(params![name, version as i64], lineage_edge)
            .map_err(sql("walking lineage"))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(sql("walking lineage"))?;
        for (child, child_version, role, parent, parent_version) in rows {
            let role: LineageRole = role.parse().map_err(|e| corrupt("lineage role", e))?;
            links.push(LineageLink {
                child: format!("{child}@{child_version}"),
                role,
                parent: format!("{parent}@{parent_version}"),
            });
            let next = match direction {
                Direction::Up => (parent, parent_version),
                Direction::Down => (child, child_version),
            };
            if seen.insert(next.clone()) {
                queue.push_back(next);
            }
        }
    }
    Ok(links)
}

/// A `lineage` row read as `(name, version, role, parent_name, parent_version)` (the columns in
/// that order).
fn lineage_edge(row: &rusqlite::Row<'_>) -> rusqlite::Result<(String, u64, String, String, u64)> {
    Ok((
        row.get::<_, String>(0)?,
        row.get::<_, i64>(1)? as u64,
        row.get::<_, String>(2)?,
        row.get::<_, String>(3)?,
        row.get::<_, i64>(4)? as u64,
    ))
}
