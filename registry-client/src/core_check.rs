//! [`check_core`]: the rule for loading an adapter with a core, applied by the store and the client
//! alike to two versions' metadata; [`CoreCheck`] is its verdict.

use l3p_proto::registry::{ArtifactKind, ArtifactMeta};

use crate::error::RegistryError;

/// Result of [`check_core`]: both versions and whether the adapter's lineage names this core.
#[derive(Debug, Clone, PartialEq)]
pub struct CoreCheck {
    pub adapter: ArtifactMeta,
    pub core: ArtifactMeta,
    /// `false` only when the mismatch was allowed explicitly.
    pub matches: bool,
}

/// The rule for loading an adapter with a core: the adapter's lineage must hold a `trained_against`
/// or `frozen_core` edge to exactly this core version. A mismatch is an error naming both versions,
/// unless `allow_mismatch` (then it is logged and reported in [`CoreCheck::matches`]).
pub fn check_core(
    adapter: ArtifactMeta,
    core: ArtifactMeta,
    allow_mismatch: bool,
) -> Result<CoreCheck, RegistryError> {
    if core.kind != ArtifactKind::Core {
        return Err(RegistryError::Invalid(format!(
            "{} is a {}, not a core",
            core.reference(),
            core.kind
        )));
    }
    let error = match adapter.core_edge() {
        Some(edge)
            if edge.name == core.name
                && edge.version == core.version
                && edge.sha256 == core.sha256 =>
        {
            return Ok(CoreCheck {
                adapter,
                core,
                matches: true,
            });
        }
        Some(edge) => RegistryError::CoreMismatch {
            adapter: adapter.reference(),
            expected_core: edge.reference(),
            given_core: core.reference(),
        },
        None => RegistryError::NoCoreLineage {
            adapter: adapter.reference(),
            given_core: core.reference(),
        },
    };
    if allow_mismatch {
        tracing::warn!("{error} (allowed by override)");
        Ok(CoreCheck {
            adapter,
            core,
            matches: false,
        })
    } else {
        Err(error)
    }
}

#[cfg(test)]
mod tests {
    use l3p_proto::registry::{ErrorCode, LineageEdge, LineageRole};

    use super::*;

    fn meta(
        name: &str,
        kind: ArtifactKind,
        sha256: &str,
        lineage: Vec<LineageEdge>,
    ) -> ArtifactMeta {
        ArtifactMeta {
            name: name.into(),
            version: 1,
            kind,
            sha256: sha256.into(),
            size: 1,
            robot: None,
            dims: Default::default(),
            config: serde_json::Value::Null,
            metrics: Default::default(),
            producer: String::new(),
            extra: serde_json::Value::Null,
            created_unix_ms: 0,
            lineage,
            aliases: Vec::new(),
        }
    }

    /// A core with the same `name@version` but other bytes (e.g. another registry's) is not the
    /// core the adapter was trained against; the store alone cannot produce this case.
    #[test]
    fn the_core_must_match_by_content_not_only_by_name_and_version() {
        let edge = LineageEdge {
            role: LineageRole::TrainedAgainst,
            name: "a1-core".into(),
            version: 1,
            sha256: "aa".into(),
        };
        let adapter = meta("go1-adapter", ArtifactKind::Adapter, "bb", vec![edge]);
        let same = meta("a1-core", ArtifactKind::Core, "aa", Vec::new());
        let other_bytes = meta("a1-core", ArtifactKind::Core, "cc", Vec::new());

        assert!(check_core(adapter.clone(), same, false).unwrap().matches);
        let err = check_core(adapter.clone(), other_bytes.clone(), false).unwrap_err();
        assert!(matches!(err, RegistryError::CoreMismatch { .. }), "{err}");
        assert_eq!(err.code(), ErrorCode::Conflict);
        assert!(!check_core(adapter, other_bytes, true).unwrap().matches);
    }
}
