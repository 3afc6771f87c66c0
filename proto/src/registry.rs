//! Registry wire types: artifact kinds and metadata, artifact references (`name@version|alias`), and
//! the request / reply messages of the registry's Zenoh queryables (`l3p/registry/<op>`).
//!
//! Main types: [`ArtifactKind`], [`ArtifactRef`], [`ArtifactSpec`] (what a writer supplies),
//! [`ArtifactMeta`] (what the registry stores and returns), [`LineageEdge`], [`AliasEvent`],
//! [`LineageGraph`], and the messages [`ListRequest`], [`RefRequest`], [`PutHeader`], [`TagRequest`],
//! [`HistoryRequest`] with their replies ([`ListReply`], [`MetaReply`], [`PutReply`], [`TagReply`],
//! [`HistoryReply`], [`LineageReply`], [`ErrorReply`]).
//!
//! Every registry message is JSON (through [`crate::codec::encode_json`] / [`crate::codec::decode_json`])
//! so that any Zenoh client can speak it; the only binary payloads are artifact blobs themselves, which
//! travel as raw bytes next to a JSON header in the query/reply attachment. Free-form metadata
//! (`config`, `extra`) is therefore plain `serde_json::Value`.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::keys::validate_segment;
use crate::{WIRE_VERSION, WireMessage};

/// The queryable operations under `l3p/registry/<op>` (see [`crate::keys::registry`]).
pub const OPS: [&str; 7] = ["list", "show", "pull", "lineage", "history", "put", "tag"];

/// The alias the registry moves to the newest version on every put; users cannot set it.
pub const LATEST: &str = "latest";

/// What an artifact holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ArtifactKind {
    /// The shared latent-to-latent policy core.
    Core,
    /// One robot's encoder + decoder + critic.
    Adapter,
    /// An end-to-end MLP policy (baseline).
    Mlp,
    /// Model + optimiser + iteration + config, for resuming training.
    Checkpoint,
    /// What deployment loads: policy weights + config, no optimiser.
    Deploy,
    /// A robot added with `l3p robots add`: its description (TOML) and URDF, so that actors on
    /// other machines simulate the same robot.
    Robot,
}

l3p_names::string_enum!(ArtifactKind {
    Core => "core",
    Adapter => "adapter",
    Mlp => "mlp",
    Checkpoint => "checkpoint",
    Deploy => "deploy",
    Robot => "robot",
});

impl FromStr for ArtifactKind {
    type Err = RefError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_name(s).ok_or_else(|| RefError {
            input: s.to_string(),
            reason: format!("unknown artifact kind (expected {})", Self::names()),
        })
    }
}

/// How one artifact version depends on another.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LineageRole {
    /// The core version an adapter (or a whole policy) was trained against.
    TrainedAgainst,
    /// The core a transfer run froze.
    FrozenCore,
    /// The checkpoint this version was exported or resumed from.
    FromCheckpoint,
    /// The version whose weights initialised this one (e.g. `mlp-transfer` from the A1 MLP).
    InitialisedFrom,
    /// Any other dependency.
    DerivedFrom,
}

l3p_names::string_enum!(LineageRole {
    TrainedAgainst => "trained_against",
    FrozenCore => "frozen_core",
    FromCheckpoint => "from_checkpoint",
    InitialisedFrom => "initialised_from",
    DerivedFrom => "derived_from",
});

impl LineageRole {
    /// Roles that name the core a version must be loaded with.
    pub fn is_core_role(self) -> bool {
        matches!(self, Self::TrainedAgainst | Self::FrozenCore)
    }
}

impl FromStr for LineageRole {
    type Err = RefError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_name(s).ok_or_else(|| RefError {
            input: s.to_string(),
            reason: format!("unknown lineage role (expected {})", Self::names()),
        })
    }
}

/// A reference that could not be parsed, or a name / alias that is not allowed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid artifact reference {input:?}: {reason}\nhint: write <name>@<version|alias>, e.g. a1-core@3 or a1-core@latest"
)]
pub struct RefError {
    pub input: String,
    pub reason: String,
}

/// Which version of a name a reference means.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum VersionSelector {
    /// A version number (1, 2, ...).
    Version(u64),
    /// An alias (`latest`, `prod`, ...).
    Alias(String),
}

/// `name@version` or `name@alias`; a bare `name` means `name@latest`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ArtifactRef {
    pub name: String,
    pub selector: VersionSelector,
}

impl ArtifactRef {
    pub fn version(name: &str, version: u64) -> Self {
        Self {
            name: name.to_string(),
            selector: VersionSelector::Version(version),
        }
    }

    pub fn alias(name: &str, alias: &str) -> Self {
        Self {
            name: name.to_string(),
            selector: VersionSelector::Alias(alias.to_string()),
        }
    }

    /// Parse `name[@version|@vN|@alias]`.
    pub fn parse(input: &str) -> Result<Self, RefError> {
        let fail = |reason: String| RefError {
            input: input.to_string(),
            reason,
        };
        let (name, selector) = match input.split_once('@') {
            Some((name, sel)) => (name, sel),
            None => (input, LATEST),
        };
        validate_name(name).map_err(|e| fail(e.reason))?;
        if selector.is_empty() {
            return Err(fail("nothing after '@'".into()));
        }
        let digits = selector.strip_prefix('v').unwrap_or(selector);
        if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
            let version: u64 = digits
                .parse()
                .map_err(|_| fail("version number out of range".into()))?;
            if version == 0 {
                return Err(fail("versions start at 1".into()));
            }
            return Ok(Self {
                name: name.to_string(),
                selector: VersionSelector::Version(version),
            });
        }
        validate_alias(selector).map_err(|e| fail(e.reason))?;
        Ok(Self {
            name: name.to_string(),
            selector: VersionSelector::Alias(selector.to_string()),
        })
    }
}

impl fmt::Display for ArtifactRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.selector {
            VersionSelector::Version(v) => write!(f, "{}@{v}", self.name),
            VersionSelector::Alias(a) => write!(f, "{}@{a}", self.name),
        }
    }
}

impl FromStr for ArtifactRef {
    type Err = RefError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

/// Check an artifact name: a valid key segment (letters, digits, `-`, `_`, `.`, at most 64).
pub fn validate_name(name: &str) -> Result<(), RefError> {
    validate_segment("artifact", name).map_err(|e| RefError {
        input: name.to_string(),
        reason: e.reason.into(),
    })
}

/// Check an alias: a valid key segment that does not look like a version number (`3`, `v3`).
pub fn validate_alias(alias: &str) -> Result<(), RefError> {
    let fail = |reason: &str| {
        Err(RefError {
            input: alias.to_string(),
            reason: reason.into(),
        })
    };
    if let Err(e) = validate_segment("alias", alias) {
        return fail(e.reason);
    }
    let digits = alias.strip_prefix('v').unwrap_or(alias);
    if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
        return fail("an alias may not look like a version number");
    }
    Ok(())
}

/// A dependency named by a writer, resolved by the registry at put time (an alias such as
/// `a1-core@latest` is recorded as the concrete version it pointed to).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineageInput {
    pub role: LineageRole,
    /// `name@version|alias`.
    pub artifact: String,
}

/// A resolved lineage edge stored with a version: it depends on `name@version` (content `sha256`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineageEdge {
    pub role: LineageRole,
    pub name: String,
    pub version: u64,
    pub sha256: String,
}

impl LineageEdge {
    pub fn reference(&self) -> String {
        format!("{}@{}", self.name, self.version)
    }
}

/// What a writer supplies with a new version. Everything except `name` and `kind` is optional.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArtifactSpec {
    pub name: String,
    pub kind: ArtifactKind,
    /// The robot an adapter / checkpoint / deploy artifact is for (required for adapters).
    #[serde(default)]
    pub robot: Option<String>,
    /// Dimensions (`obs_dim`, `action_dim`, `d_h`, `d_z`, ...).
    #[serde(default)]
    pub dims: BTreeMap<String, u64>,
    /// The configuration that produced it (free JSON, usually the run's config).
    #[serde(default)]
    pub config: serde_json::Value,
    /// Metrics summary (finite numbers only).
    #[serde(default)]
    pub metrics: BTreeMap<String, f64>,
    /// Who wrote it: `learner/<run>`, `cli`, ...
    #[serde(default)]
    pub producer: String,
    /// Anything else (free JSON).
    #[serde(default)]
    pub extra: serde_json::Value,
    #[serde(default)]
    pub lineage: Vec<LineageInput>,
    /// User aliases to point at the new version (`latest` moves by itself).
    #[serde(default)]
    pub aliases: Vec<String>,
}

impl ArtifactSpec {
    /// A spec with only a name and a kind.
    pub fn new(name: &str, kind: ArtifactKind) -> Self {
        Self {
            name: name.to_string(),
            kind,
            robot: None,
            dims: BTreeMap::new(),
            config: serde_json::Value::Null,
            metrics: BTreeMap::new(),
            producer: String::new(),
            extra: serde_json::Value::Null,
            lineage: Vec::new(),
            aliases: Vec::new(),
        }
    }
}

/// One stored, immutable artifact version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArtifactMeta {
    pub name: String,
    pub version: u64,
    pub kind: ArtifactKind,
    /// Hex sha256 of the blob.
    pub sha256: String,
    /// Blob size in bytes.
    pub size: u64,
    pub robot: Option<String>,
    pub dims: BTreeMap<String, u64>,
    pub config: serde_json::Value,
    pub metrics: BTreeMap<String, f64>,
    pub producer: String,
    pub extra: serde_json::Value,
    /// Milliseconds since the Unix epoch.
    pub created_unix_ms: u64,
    pub lineage: Vec<LineageEdge>,
    /// Aliases that point at this version now.
    pub aliases: Vec<String>,
}

impl ArtifactMeta {
    /// `name@version`.
    pub fn reference(&self) -> String {
        format!("{}@{}", self.name, self.version)
    }

    /// The core this version must be loaded with (its `trained_against` or `frozen_core` edge).
    pub fn core_edge(&self) -> Option<&LineageEdge> {
        self.lineage.iter().find(|e| e.role.is_core_role())
    }
}

/// One move of an alias (`previous` is `None` when the alias was created).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AliasEvent {
    pub name: String,
    pub alias: String,
    pub version: u64,
    pub previous: Option<u64>,
    pub unix_ms: u64,
}

/// One edge of a lineage graph: `child` depends on `parent` in `role`. Both are `name@version`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineageLink {
    pub child: String,
    pub role: LineageRole,
    pub parent: String,
}

/// An artifact with everything it transitively depends on (`upstream`) and everything that
/// transitively depends on it (`downstream`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineageGraph {
    pub artifact: ArtifactMeta,
    pub upstream: Vec<LineageLink>,
    pub downstream: Vec<LineageLink>,
}

/// `l3p/registry/list` request: every version matching all given filters (none: everything).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListRequest {
    pub wire_version: u32,
    #[serde(default)]
    pub kind: Option<ArtifactKind>,
    #[serde(default)]
    pub name: Option<String>,
    #[serde(default)]
    pub robot: Option<String>,
}
wire_message!(ListRequest, "registry list request");

impl ListRequest {
    pub fn all() -> Self {
        Self {
            wire_version: WIRE_VERSION,
            ..Self::default()
        }
    }
}

/// `l3p/registry/list` reply, ordered by name then version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListReply {
    pub wire_version: u32,
    pub artifacts: Vec<ArtifactMeta>,
}
wire_message!(ListReply, "registry list reply");

/// Request naming one artifact (`show`, `pull`, `lineage`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RefRequest {
    pub wire_version: u32,
    /// `name@version|alias`.
    pub artifact: String,
}
wire_message!(RefRequest, "registry ref request");

impl RefRequest {
    pub fn new(artifact: &str) -> Self {
        Self {
            wire_version: WIRE_VERSION,
            artifact: artifact.to_string(),
        }
    }
}

/// `show` reply, and the JSON attachment of a `pull` reply (whose payload is the raw blob).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MetaReply {
    pub wire_version: u32,
    pub artifact: ArtifactMeta,
}
wire_message!(MetaReply, "registry metadata reply");

/// JSON attachment of a `put` query, whose payload is the raw blob. `sha256` and `size` are the
/// writer's view of the blob: the registry refuses the put when the bytes it received differ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PutHeader {
    pub wire_version: u32,
    pub spec: ArtifactSpec,
    pub sha256: String,
    pub size: u64,
}
wire_message!(PutHeader, "registry put header");

/// `put` reply: the stored version; `created` is `false` when identical content was already stored
/// under this name and that version is returned instead.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PutReply {
    pub wire_version: u32,
    pub artifact: ArtifactMeta,
    pub created: bool,
}
wire_message!(PutReply, "registry put reply");

/// `tag` request: point `alias` at the version `artifact` resolves to.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagRequest {
    pub wire_version: u32,
    pub artifact: String,
    pub alias: String,
}
wire_message!(TagRequest, "registry tag request");

/// `tag` reply; `moved` is `false` when the alias already pointed there (nothing recorded).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagReply {
    pub wire_version: u32,
    pub event: AliasEvent,
    pub moved: bool,
}
wire_message!(TagReply, "registry tag reply");

/// `history` request: the moves of one alias of `name`, or of all its aliases.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryRequest {
    pub wire_version: u32,
    pub name: String,
    #[serde(default)]
    pub alias: Option<String>,
}
wire_message!(HistoryRequest, "registry history request");

/// `history` reply, oldest first.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HistoryReply {
    pub wire_version: u32,
    pub events: Vec<AliasEvent>,
}
wire_message!(HistoryReply, "registry history reply");

/// `lineage` reply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineageReply {
    pub wire_version: u32,
    pub lineage: LineageGraph,
}
wire_message!(LineageReply, "registry lineage reply");

/// Class of a registry error, for programs that branch on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// Unknown name, version or alias.
    NotFound,
    /// Malformed JSON, unknown field, invalid reference, unknown operation, invalid metadata.
    BadRequest,
    /// Request or blob over the service's limits.
    TooLarge,
    /// The request's `wire_version` is not the service's.
    WrongVersion,
    /// A hash did not match (on write: the bytes received; on read: the bytes stored).
    Integrity,
    /// The request contradicts stored state (e.g. another kind under the same name, lineage mismatch).
    Conflict,
    /// Storage failure on the service side.
    Internal,
}

l3p_names::string_enum!(ErrorCode {
    NotFound => "not_found",
    BadRequest => "bad_request",
    TooLarge => "too_large",
    WrongVersion => "wrong_version",
    Integrity => "integrity",
    Conflict => "conflict",
    Internal => "internal",
});

/// Error reply of every registry operation (sent with Zenoh `reply_err`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ErrorReply {
    pub wire_version: u32,
    pub code: ErrorCode,
    pub message: String,
}
wire_message!(ErrorReply, "registry error reply");

impl ErrorReply {
    pub fn new(code: ErrorCode, message: impl Into<String>) -> Self {
        Self {
            wire_version: WIRE_VERSION,
            code,
            message: message.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enum_names_are_their_serde_names_and_parse_back() {
        fn check<T>(all: &[T], as_str: fn(&T) -> &'static str)
        where
            T: Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
        {
            for v in all {
                let json = serde_json::to_string(v).unwrap();
                assert_eq!(json, format!("\"{}\"", as_str(v)));
                assert_eq!(&serde_json::from_str::<T>(&json).unwrap(), v);
            }
        }
        check(&ArtifactKind::ALL, |k| k.as_str());
        check(&LineageRole::ALL, |r| r.as_str());
        check(&ErrorCode::ALL, |c| c.as_str());
        for k in ArtifactKind::ALL {
            assert_eq!(k.as_str().parse::<ArtifactKind>(), Ok(k));
        }
        let err = "cores".parse::<ArtifactKind>().unwrap_err();
        assert!(
            err.reason
                .contains("expected core, adapter, mlp, checkpoint, deploy or robot"),
            "{}",
            err.reason
        );
        assert_eq!(
            format!("{:>6}", ArtifactKind::Mlp),
            "   mlp",
            "Display pads"
        );
    }

    #[test]
    fn refs_parse_versions_and_aliases() {
        assert_eq!(
            ArtifactRef::parse("a1-core@3").unwrap(),
            ArtifactRef::version("a1-core", 3)
        );
        assert_eq!(
            ArtifactRef::parse("a1-core@v3").unwrap(),
            ArtifactRef::version("a1-core", 3)
        );
        assert_eq!(
            ArtifactRef::parse("a1-core@prod").unwrap(),
            ArtifactRef::alias("a1-core", "prod")
        );
        assert_eq!(
            ArtifactRef::parse("a1-core").unwrap(),
            ArtifactRef::alias("a1-core", "latest")
        );
        assert_eq!(
            ArtifactRef::parse("go1.adapter_2@latest")
                .unwrap()
                .to_string(),
            "go1.adapter_2@latest"
        );
    }

    #[test]
    fn bad_refs_are_errors_with_a_hint() {
        for bad in [
            "",
            "@3",
            "a@",
            "a@0",
            "a b@1",
            "a/b@1",
            "a@1@2",
            "a@*",
            "a@99999999999999999999999",
        ] {
            let err = ArtifactRef::parse(bad).unwrap_err().to_string();
            assert!(
                err.contains("invalid artifact reference") && err.contains("hint:"),
                "{bad}: {err}"
            );
        }
        assert!(validate_alias("v12").is_err());
        assert!(validate_alias("42").is_err());
        assert!(validate_alias("prod").is_ok());
        assert!(validate_alias("v1-rc").is_ok());
    }

    #[test]
    fn kinds_and_roles_round_trip_as_strings() {
        for kind in ArtifactKind::ALL {
            assert_eq!(kind.as_str().parse::<ArtifactKind>().unwrap(), kind);
            assert_eq!(serde_json::to_string(&kind).unwrap(), format!("\"{kind}\""));
        }
        for role in LineageRole::ALL {
            assert_eq!(role.as_str().parse::<LineageRole>().unwrap(), role);
            assert_eq!(serde_json::to_string(&role).unwrap(), format!("\"{role}\""));
        }
        assert!("model".parse::<ArtifactKind>().is_err());
    }
}
