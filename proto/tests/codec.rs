//! Codec properties: every message round-trips; truncated, random, oversized and wrong-version bytes
//! give errors, never panics or unbounded allocation.

use l3p_proto::codec::{self, CodecError};
use l3p_proto::*;
use proptest::prelude::*;

fn name() -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_-]{0,11}"
}

fn finite() -> impl Strategy<Value = f32> {
    -1.0e6f32..1.0e6
}

fn floats(len: usize) -> impl Strategy<Value = Vec<f32>> {
    prop::collection::vec(finite(), len)
}

fn episode() -> impl Strategy<Value = EpisodeStats> {
    (
        finite(),
        any::<u32>(),
        0.0f32..10.0,
        0u8..6,
        finite(),
        finite(),
        any::<bool>(),
        prop::collection::vec(finite(), 2),
    )
        .prop_map(
            |(episode_return, length, terrain_level, terrain_type, lin, yaw, terminated, terms)| {
                EpisodeStats {
                    reward_terms: terms,
                    episode_return,
                    length,
                    terrain_level,
                    terrain_type,
                    lin_vel_error: lin,
                    yaw_rate_error: yaw,
                    terminated,
                }
            },
        )
}

fn chunk() -> impl Strategy<Value = RolloutChunk> {
    (
        1usize..4,
        1usize..4,
        1usize..6,
        1usize..4,
        name(),
        name(),
        any::<u64>(),
    )
        .prop_flat_map(|(envs, steps, obs, act, robot, actor, version)| {
            let samples = envs * steps;
            (
                floats(samples * obs),
                floats(samples * act),
                floats(samples),
                floats(samples * act),
                prop::collection::vec(0.01f32..5.0, samples * act),
                floats(samples),
                prop::collection::vec(any::<bool>(), samples),
                prop::collection::vec(any::<bool>(), samples),
                floats(envs * obs),
                prop::collection::vec(episode(), 0..3),
            )
                .prop_map(move |(o, a, lp, mu, sd, r, term, trunc, last, eps)| {
                    let mut c =
                        RolloutChunk::zeros("run", &robot, &actor, version, envs, steps, obs, act);
                    c.observations = o;
                    c.actions = a;
                    c.log_probs = lp;
                    c.action_means = mu;
                    c.action_stds = sd;
                    c.rewards = r;
                    c.terminated = term;
                    c.truncated = trunc;
                    c.last_observations = last;
                    c.episodes = eps;
                    c.reward_terms = vec!["track_lin_vel_xy_exp".into(), "trot_contact".into()];
                    c
                })
        })
}

fn announce() -> impl Strategy<Value = PolicyAnnounce> {
    (
        name(),
        any::<u64>(),
        prop::collection::vec((name(), "[0-9a-f]{64}", any::<u64>()), 0..4),
    )
        .prop_map(|(run, version, robots)| PolicyAnnounce {
            wire_version: WIRE_VERSION,
            run,
            version,
            incarnation: version ^ 0x5a5a,
            mode: "l3p".into(),
            robots: robots
                .into_iter()
                .map(|(robot, sha256, size)| RobotWeights {
                    robot,
                    sha256,
                    size,
                    obs_dim: 48,
                    action_dim: 12,
                })
                .collect(),
            max_policy_lag: 1,
        })
}

fn weights() -> impl Strategy<Value = WeightsBlob> {
    (
        name(),
        name(),
        any::<u64>(),
        prop::collection::vec(any::<u8>(), 0..512),
    )
        .prop_map(|(run, robot, version, bytes)| WeightsBlob {
            wire_version: WIRE_VERSION,
            run,
            robot,
            version,
            format: "l3p-export-v1".into(),
            sha256: "00".repeat(32),
            bytes,
        })
}

fn metrics() -> impl Strategy<Value = MetricsRecord> {
    (
        name(),
        name(),
        any::<u64>(),
        prop::collection::btree_map(name(), -1.0e9f64..1.0e9, 0..8),
    )
        .prop_map(|(run, source, iteration, values)| {
            let mut m = MetricsRecord::new(&run, &source, iteration, 1_700_000_000_000);
            m.values = values;
            m
        })
}

fn robot_state() -> impl Strategy<Value = RobotState> {
    (
        name(),
        any::<u64>(),
        floats(12),
        floats(12),
        prop::array::uniform3(finite()),
    )
        .prop_map(
            |(robot_id, seq, joint_pos, joint_vel, command)| RobotState {
                wire_version: WIRE_VERSION,
                robot_id,
                seq,
                stamp_ns: seq.wrapping_mul(20_000_000),
                base_quat: [1.0, 0.0, 0.0, 0.0],
                base_lin_vel: [0.1, 0.0, 0.0],
                base_ang_vel: [0.0, 0.0, 0.2],
                joint_pos,
                joint_vel,
                command,
            },
        )
}

fn robot_command() -> impl Strategy<Value = RobotCommand> {
    let mode = prop_oneof![
        Just(ControlMode::ZeroTorque),
        Just(ControlMode::Ramp),
        Just(ControlMode::Policy),
        Just(ControlMode::Damping)
    ];
    (
        name(),
        any::<u64>(),
        mode,
        floats(12),
        prop::collection::vec(0.0f32..200.0, 12),
    )
        .prop_map(|(robot_id, seq, mode, joint_pos_target, kp)| RobotCommand {
            wire_version: WIRE_VERSION,
            robot_id,
            seq,
            stamp_ns: 0,
            mode,
            joint_pos_target,
            kd: kp.iter().map(|k| k * 0.02).collect(),
            kp,
        })
}

/// Binary round trip plus the failure modes that must be errors.
fn check_binary<T>(message: &T)
where
    T: serde::Serialize + serde::de::DeserializeOwned + WireMessage + PartialEq + std::fmt::Debug,
{
    let bytes = codec::encode(message).unwrap();
    let back: T = codec::decode(&bytes).unwrap();
    assert_eq!(&back, message);
    // Every strict prefix is an error.
    for cut in [0, 1, bytes.len() / 2, bytes.len().saturating_sub(1)] {
        if cut < bytes.len() {
            assert!(
                codec::decode::<T>(&bytes[..cut]).is_err(),
                "prefix {cut} of {} decoded",
                bytes.len()
            );
        }
    }
    // Trailing garbage is an error.
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(
        codec::decode::<T>(&longer),
        Err(CodecError::TrailingBytes { .. })
    ));
    // Another wire version is refused before the layout is trusted.
    let mut other = bytes.clone();
    other[0] = (WIRE_VERSION + 1) as u8;
    assert!(matches!(
        codec::decode::<T>(&other),
        Err(CodecError::WrongVersion { .. })
    ));
}

fn check_json<T>(message: &T)
where
    T: serde::Serialize + serde::de::DeserializeOwned + WireMessage + PartialEq + std::fmt::Debug,
{
    let bytes = codec::encode_json(message).unwrap();
    let back: T = codec::decode_json(&bytes).unwrap();
    assert_eq!(&back, message);
    assert!(codec::decode_json::<T>(&bytes[..bytes.len() / 2]).is_err());
}

/// 64 cases per property; `L3P_FUZZ_CASES` raises it for a long run.
fn cases() -> u32 {
    std::env::var("L3P_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(64)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn rollout_chunks_round_trip_and_validate(c in chunk()) {
        c.validate().unwrap();
        check_binary(&c);
    }

    #[test]
    fn announces_round_trip(a in announce()) {
        check_binary(&a);
        check_json(&a);
    }

    #[test]
    fn weights_round_trip(w in weights()) {
        check_binary(&w);
    }

    #[test]
    fn metrics_round_trip(m in metrics()) {
        check_json(&m);
        check_binary(&m);
    }

    #[test]
    fn robot_states_round_trip(s in robot_state()) {
        s.validate(12).unwrap();
        check_binary(&s);
    }

    #[test]
    fn robot_commands_round_trip(c in robot_command()) {
        c.validate(12).unwrap();
        check_binary(&c);
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        let _ = codec::decode::<RolloutChunk>(&bytes);
        let _ = codec::decode::<WeightsBlob>(&bytes);
        let _ = codec::decode::<RobotState>(&bytes);
        let _ = codec::decode::<RobotCommand>(&bytes);
        let _ = codec::decode_json::<MetricsRecord>(&bytes);
        let _ = codec::decode_json::<PolicyAnnounce>(&bytes);
    }

    #[test]
    fn corrupted_chunks_are_errors_or_valid(c in chunk(), flips in prop::collection::vec((any::<usize>(), any::<u8>()), 1..8)) {
        let mut bytes = codec::encode(&c).unwrap();
        for (at, value) in flips {
            let i = at % bytes.len();
            bytes[i] = value;
        }
        // A corrupted message either fails to decode or decodes into something validate() judges;
        // what validate() accepts has the shape its header claims and only finite numbers.
        if let Ok(decoded) = codec::decode::<RolloutChunk>(&bytes)
            && decoded.validate().is_ok()
        {
            let (n, t) = (decoded.num_envs as usize, decoded.steps as usize);
            let (o, a) = (decoded.obs_dim as usize, decoded.action_dim as usize);
            prop_assert_eq!(decoded.observations.len(), t * n * o);
            prop_assert_eq!(decoded.actions.len(), t * n * a);
            prop_assert_eq!(decoded.rewards.len(), t * n);
            prop_assert_eq!(decoded.last_observations.len(), n * o);
            for values in [
                &decoded.observations,
                &decoded.actions,
                &decoded.log_probs,
                &decoded.action_means,
                &decoded.rewards,
                &decoded.last_observations,
            ] {
                prop_assert!(values.iter().all(|v| v.is_finite()));
            }
            prop_assert!(decoded.action_stds.iter().all(|s| s.is_finite() && *s > 0.0));
        }
    }
}

#[test]
fn huge_length_prefix_does_not_allocate() {
    // wire version 1, then strings/arrays claiming 2^60 elements: must fail fast on missing bytes.
    let mut bytes = vec![WIRE_VERSION as u8];
    bytes.push(0xfd); // varint u64 marker
    bytes.extend_from_slice(&(1u64 << 60).to_le_bytes());
    let err = codec::decode::<RolloutChunk>(&bytes).unwrap_err();
    assert!(matches!(err, CodecError::Decode { .. }), "{err}");
    let err = codec::decode::<WeightsBlob>(&bytes).unwrap_err();
    assert!(matches!(err, CodecError::Decode { .. }), "{err}");
}

#[test]
fn oversized_input_is_refused_before_parsing() {
    let bytes = vec![0u8; 1024];
    let err = codec::decode_with_limit::<RobotState>(&bytes, 512).unwrap_err();
    assert!(err.to_string().contains("exceeds the limit"), "{err}");
    let big_json = vec![b' '; codec::MAX_JSON_BYTES + 1];
    assert!(matches!(
        codec::decode_json::<MetricsRecord>(&big_json),
        Err(CodecError::TooLarge { .. })
    ));
}

#[test]
fn wrong_json_version_names_both_versions() {
    let mut m = MetricsRecord::new("r", "learner", 3, 0);
    m.wire_version = 99;
    let bytes = codec::encode_json(&m).unwrap();
    let err = codec::decode_json::<MetricsRecord>(&bytes)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("99") && err.contains(&WIRE_VERSION.to_string()),
        "{err}"
    );
}

#[test]
fn metrics_drop_non_finite_values() {
    let mut m = MetricsRecord::new("r", "learner", 0, 0);
    assert!(m.insert("reward", 1.5));
    assert!(!m.insert("kl", f64::NAN));
    assert!(!m.insert("lr", f64::INFINITY));
    assert_eq!(m.values.len(), 1);
}
