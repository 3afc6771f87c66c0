//! Registry messages: JSON round trips, wrong versions and garbage are errors (never panics), and
//! artifact references round-trip through their text form.

use std::collections::BTreeMap;

use l3p_proto::codec::{self, CodecError};
use l3p_proto::registry::*;
use l3p_proto::{WIRE_VERSION, WireMessage};
use proptest::prelude::*;

fn name() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_-]{0,15}"
}

fn kind() -> impl Strategy<Value = ArtifactKind> {
    prop::sample::select(ArtifactKind::ALL.to_vec())
}

fn role() -> impl Strategy<Value = LineageRole> {
    prop::sample::select(LineageRole::ALL.to_vec())
}

/// Floats with a short exact decimal form (serde_json without `float_roundtrip` may be 1 ULP off on
/// arbitrary doubles).
fn float() -> impl Strategy<Value = f64> {
    (-4_000_000i32..4_000_000).prop_map(|v| f64::from(v) / 4.0)
}

fn json_value() -> impl Strategy<Value = serde_json::Value> {
    prop_oneof![
        Just(serde_json::Value::Null),
        (name(), float()).prop_map(|(k, v)| serde_json::json!({ k: v, "list": [1, 2, 3] })),
        name().prop_map(serde_json::Value::String),
    ]
}

fn meta() -> impl Strategy<Value = ArtifactMeta> {
    (
        name(),
        1u64..1000,
        kind(),
        "[0-9a-f]{64}",
        any::<u64>(),
        prop::option::of(name()),
        prop::collection::btree_map(name(), any::<u64>(), 0..4),
        json_value(),
        prop::collection::btree_map(name(), float(), 0..4),
        prop::collection::vec((role(), name(), 1u64..100, "[0-9a-f]{64}"), 0..3),
        prop::collection::vec(name(), 0..3),
    )
        .prop_map(
            |(
                name,
                version,
                kind,
                sha256,
                size,
                robot,
                dims,
                config,
                metrics,
                lineage,
                aliases,
            )| {
                ArtifactMeta {
                    name,
                    version,
                    kind,
                    sha256,
                    size,
                    robot,
                    dims,
                    config: config.clone(),
                    metrics,
                    producer: "learner/run".into(),
                    extra: config,
                    created_unix_ms: 1_795_000_000_000,
                    lineage: lineage
                        .into_iter()
                        .map(|(role, name, version, sha256)| LineageEdge {
                            role,
                            name,
                            version,
                            sha256,
                        })
                        .collect(),
                    aliases,
                }
            },
        )
}

fn spec() -> impl Strategy<Value = ArtifactSpec> {
    (
        name(),
        kind(),
        prop::option::of(name()),
        json_value(),
        prop::collection::vec((role(), name()), 0..3),
    )
        .prop_map(|(name, kind, robot, config, lineage)| {
            let mut spec = ArtifactSpec::new(&name, kind);
            spec.robot = robot;
            spec.config = config;
            spec.lineage = lineage
                .into_iter()
                .map(|(role, parent)| LineageInput {
                    role,
                    artifact: format!("{parent}@latest"),
                })
                .collect();
            spec.aliases = vec!["prod".into()];
            spec.dims = BTreeMap::from([("obs_dim".to_string(), 48)]);
            spec
        })
}

fn check_json<T>(message: &T)
where
    T: serde::Serialize + serde::de::DeserializeOwned + WireMessage + PartialEq + std::fmt::Debug,
{
    let bytes = codec::encode_json(message).unwrap();
    let back: T = codec::decode_json(&bytes).unwrap();
    assert_eq!(&back, message);
    assert!(codec::decode_json::<T>(&bytes[..bytes.len() / 2]).is_err());
    // Another wire version is refused before the layout is trusted.
    let mut value: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    value["wire_version"] = serde_json::json!(WIRE_VERSION + 1);
    let other = serde_json::to_vec(&value).unwrap();
    assert!(matches!(
        codec::decode_json::<T>(&other),
        Err(CodecError::WrongVersion { .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn replies_round_trip(m in meta(), events in prop::collection::vec((name(), 1u64..9, prop::option::of(1u64..9)), 0..4)) {
        check_json(&MetaReply { wire_version: WIRE_VERSION, artifact: m.clone() });
        check_json(&ListReply { wire_version: WIRE_VERSION, artifacts: vec![m.clone(), m.clone()] });
        check_json(&PutReply { wire_version: WIRE_VERSION, artifact: m.clone(), created: true });
        let events: Vec<AliasEvent> = events
            .into_iter()
            .map(|(alias, version, previous)| AliasEvent { name: m.name.clone(), alias, version, previous, unix_ms: 5 })
            .collect();
        check_json(&HistoryReply { wire_version: WIRE_VERSION, events: events.clone() });
        if let Some(event) = events.first() {
            check_json(&TagReply { wire_version: WIRE_VERSION, event: event.clone(), moved: false });
        }
        let link = LineageLink { child: m.reference(), role: LineageRole::TrainedAgainst, parent: "a1-core@1".into() };
        check_json(&LineageReply {
            wire_version: WIRE_VERSION,
            lineage: LineageGraph { artifact: m, upstream: vec![link.clone()], downstream: vec![link] },
        });
    }

    #[test]
    fn requests_round_trip(s in spec(), n in name(), version in 1u64..1_000_000, k in prop::option::of(kind())) {
        check_json(&PutHeader { wire_version: WIRE_VERSION, spec: s, sha256: "ab".repeat(32), size: 9 });
        check_json(&RefRequest::new(&format!("{n}@{version}")));
        check_json(&ListRequest { wire_version: WIRE_VERSION, kind: k, name: Some(n.clone()), robot: None });
        check_json(&TagRequest { wire_version: WIRE_VERSION, artifact: format!("{n}@{version}"), alias: "prod".into() });
        check_json(&HistoryRequest { wire_version: WIRE_VERSION, name: n, alias: None });
        check_json(&ErrorReply::new(ErrorCode::NotFound, "a1-core has no version 9"));
    }

    #[test]
    fn refs_round_trip_through_text(n in name(), version in 1u64..u64::MAX, alias in "[a-z][a-z_-]{0,10}") {
        let by_version = ArtifactRef::version(&n, version);
        prop_assert_eq!(ArtifactRef::parse(&by_version.to_string()).unwrap(), by_version);
        let by_alias = ArtifactRef::alias(&n, &alias);
        prop_assert_eq!(ArtifactRef::parse(&by_alias.to_string()).unwrap(), by_alias);
    }

    #[test]
    fn garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..512), text in ".{0,80}") {
        let _ = codec::decode_json::<PutHeader>(&bytes);
        let _ = codec::decode_json::<ListReply>(&bytes);
        let _ = codec::decode_json::<ErrorReply>(&bytes);
        let _ = ArtifactRef::parse(&text);
    }
}

#[test]
fn unknown_fields_are_refused() {
    let err =
        codec::decode_json::<RefRequest>(br#"{"wire_version":2,"artifact":"a@1","extra":true}"#)
            .unwrap_err();
    assert!(err.to_string().contains("unknown field"), "{err}");
}

#[test]
fn enums_are_snake_case_strings() {
    let reply = ErrorReply::new(ErrorCode::WrongVersion, "x");
    let text = String::from_utf8(codec::encode_json(&reply).unwrap()).unwrap();
    assert!(text.contains(r#""code":"wrong_version""#), "{text}");
    let edge = LineageEdge {
        role: LineageRole::FrozenCore,
        name: "a1-core".into(),
        version: 2,
        sha256: "00".into(),
    };
    assert!(
        serde_json::to_string(&edge)
            .unwrap()
            .contains(r#""role":"frozen_core""#)
    );
}
