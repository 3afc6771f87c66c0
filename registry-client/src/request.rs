//! What a caller sends to a registry and gets back, the same for the store and the client:
//! [`PutRequest`] (with its builder), [`ListFilter`], [`PutOutcome`], [`TagOutcome`].

use l3p_proto::registry::{
    AliasEvent, ArtifactKind, ArtifactMeta, ArtifactSpec, LineageInput, LineageRole,
};

/// A new version to store: its spec and its bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct PutRequest {
    pub spec: ArtifactSpec,
    pub bytes: Vec<u8>,
    /// The writer's sha256 of `bytes` (hex); when given, a mismatch refuses the put.
    pub expected_sha256: Option<String>,
}

impl PutRequest {
    pub fn new(name: &str, kind: ArtifactKind, bytes: Vec<u8>) -> Self {
        Self {
            spec: ArtifactSpec::new(name, kind),
            bytes,
            expected_sha256: None,
        }
    }

    pub fn robot(mut self, robot: &str) -> Self {
        self.spec.robot = Some(robot.to_string());
        self
    }

    pub fn dim(mut self, key: &str, value: u64) -> Self {
        self.spec.dims.insert(key.to_string(), value);
        self
    }

    pub fn config(mut self, config: serde_json::Value) -> Self {
        self.spec.config = config;
        self
    }

    pub fn metric(mut self, key: &str, value: f64) -> Self {
        self.spec.metrics.insert(key.to_string(), value);
        self
    }

    pub fn producer(mut self, producer: &str) -> Self {
        self.spec.producer = producer.to_string();
        self
    }

    pub fn extra(mut self, extra: serde_json::Value) -> Self {
        self.spec.extra = extra;
        self
    }

    /// Record a dependency (`artifact` is `name@version|alias`, resolved at put time).
    pub fn lineage(mut self, role: LineageRole, artifact: &str) -> Self {
        self.spec.lineage.push(LineageInput {
            role,
            artifact: artifact.to_string(),
        });
        self
    }

    /// Point a user alias at the new version.
    pub fn alias(mut self, alias: &str) -> Self {
        self.spec.aliases.push(alias.to_string());
        self
    }
}

/// Result of a put: the stored version; `created` is `false` when the same name already held the same
/// bytes and that version was returned (aliases in the request are still applied).
#[derive(Debug, Clone, PartialEq)]
pub struct PutOutcome {
    pub meta: ArtifactMeta,
    pub created: bool,
}

/// Result of a tag: the alias move; `moved` is `false` when it already pointed there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TagOutcome {
    pub event: AliasEvent,
    pub moved: bool,
}

/// Which versions a list returns (every given field must match).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ListFilter {
    pub kind: Option<ArtifactKind>,
    pub name: Option<String>,
    pub robot: Option<String>,
}
