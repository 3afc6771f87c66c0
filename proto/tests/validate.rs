//! Chunk validation names the field and the index of what is wrong.

use l3p_proto::*;

fn chunk() -> RolloutChunk {
    let mut c = RolloutChunk::zeros("run", "a1", "actor-0", 3, 2, 3, 4, 2);
    c.action_stds.fill(1.0);
    c
}

#[test]
fn valid_chunk_passes() {
    chunk().validate().unwrap();
    chunk().validate_dims(4, 2).unwrap();
}

#[test]
fn wrong_length_names_field_and_sizes() {
    let mut c = chunk();
    c.rewards.pop();
    let err = c.validate().unwrap_err().to_string();
    assert!(
        err.contains("`rewards`") && err.contains("5 values") && err.contains("need 6"),
        "{err}"
    );
}

#[test]
fn nan_names_field_index_and_position() {
    let mut c = chunk();
    // step 1, env 1, dim 2 of [3, 2, 4]
    let index = 4 * 2 + 4 + 2;
    c.observations[index] = f32::NAN;
    let err = c.validate().unwrap_err().to_string();
    assert!(
        err.contains("`observations`") && err.contains(&format!("index {index}")),
        "{err}"
    );
    assert!(err.contains("step 1, env 1, dim 2"), "{err}");

    let mut c = chunk();
    c.rewards[5] = f32::INFINITY;
    let err = c.validate().unwrap_err().to_string();
    assert!(
        err.contains("`rewards`") && err.contains("index 5"),
        "{err}"
    );
}

#[test]
fn non_positive_std_is_rejected() {
    let mut c = chunk();
    c.action_stds[3] = 0.0;
    let err = c.validate().unwrap_err().to_string();
    assert!(
        err.contains("`action_stds`") && err.contains("index 3"),
        "{err}"
    );
}

#[test]
fn dimension_mismatch_and_bad_names_are_rejected() {
    let err = chunk().validate_dims(48, 12).unwrap_err().to_string();
    assert!(err.contains("obs_dim") && err.contains("48"), "{err}");
    let mut c = chunk();
    c.robot = "a1/../x".into();
    assert!(
        c.validate()
            .unwrap_err()
            .to_string()
            .contains("invalid robot name")
    );
    let mut c = chunk();
    c.wire_version = 0;
    assert!(
        c.validate()
            .unwrap_err()
            .to_string()
            .contains("wire version 0")
    );
    let mut c = chunk();
    c.num_envs = 0;
    assert!(
        c.validate()
            .unwrap_err()
            .to_string()
            .contains("num_envs must be positive")
    );
}

#[test]
fn overflowing_dimensions_are_an_error_not_a_panic() {
    let mut c = chunk();
    c.num_envs = u32::MAX;
    c.steps = u32::MAX;
    c.obs_dim = u32::MAX;
    assert!(c.validate().is_err());
}

#[test]
fn robot_state_checks_joint_count_and_quaternion() {
    let state = RobotState {
        wire_version: WIRE_VERSION,
        robot_id: "dog-1".into(),
        seq: 0,
        stamp_ns: 0,
        base_quat: [1.0, 0.0, 0.0, 0.0],
        base_lin_vel: [0.0; 3],
        base_ang_vel: [0.0; 3],
        joint_pos: vec![0.0; 12],
        joint_vel: vec![0.0; 12],
        command: [0.0; 3],
    };
    state.validate(12).unwrap();
    assert!(
        state
            .validate(16)
            .unwrap_err()
            .to_string()
            .contains("joint_pos")
    );
    let mut bad = state.clone();
    bad.base_quat = [2.0, 0.0, 0.0, 0.0];
    assert!(
        bad.validate(12)
            .unwrap_err()
            .to_string()
            .contains("unit quaternion")
    );
    let mut bad = state;
    bad.joint_vel[7] = f32::NAN;
    assert!(
        bad.validate(12)
            .unwrap_err()
            .to_string()
            .contains("index 7")
    );
}

#[test]
fn episode_means_average_and_split_by_terrain_type() {
    let mut chunk = RolloutChunk::zeros("r", "a1", "0", 0, 1, 1, 1, 1);
    for (level, kind, terminated) in [(2.0, 0, false), (4.0, 0, true), (1.0, 3, false)] {
        chunk.episodes.push(EpisodeStats {
            episode_return: 3.0,
            length: 100,
            terrain_level: level,
            terrain_type: kind,
            lin_vel_error: 0.1,
            yaw_rate_error: 0.2,
            terminated,
            reward_terms: vec![level, -1.0],
        });
        chunk.reward_terms = vec!["tracking".into(), "action_rate_l2".into()];
    }
    let mut record = MetricsRecord::new("r", "learner", 1, 0);
    record.insert_episode_means(&chunk.episodes);
    assert_eq!(record.values["episodes"], 3.0);
    assert!((record.values["terrain_level"] - 7.0 / 3.0).abs() < 1e-9);
    assert_eq!(record.values["terrain_level/type0"], 3.0);
    assert_eq!(record.values["terrain_level/type3"], 1.0);
    assert!((record.values["fall_fraction"] - 1.0 / 3.0).abs() < 1e-9);
    record.insert_reward_term_means([(chunk.reward_terms.as_slice(), chunk.episodes.as_slice())]);
    assert!((record.values["Episode_Reward/tracking"] - 7.0 / 3.0).abs() < 1e-9);
    assert_eq!(record.values["Episode_Reward/action_rate_l2"], -1.0);
    chunk.action_stds.fill(1.0);
    chunk.validate().unwrap();
    chunk.episodes[1].reward_terms.pop();
    let err = chunk.validate().unwrap_err().to_string();
    assert!(err.contains("reward_terms"), "{err}");
    chunk.episodes[1].reward_terms = vec![f32::NAN, 0.0];
    assert!(chunk.validate().is_err());
    chunk.episodes[1].reward_terms = vec![0.0, 0.0];
    chunk.reward_terms[0] = "bad name/with slash".into();
    assert!(chunk.validate().is_err());
    chunk.reward_terms[0] = "tracking".into();
    chunk.stage_seconds = vec![("physics".into(), 1.5), ("inference".into(), 0.2)];
    chunk.validate().unwrap();
    chunk.stage_seconds[1].1 = f32::NAN;
    assert!(
        chunk
            .validate()
            .unwrap_err()
            .to_string()
            .contains("stage_seconds")
    );
    chunk.stage_seconds[1].1 = -1.0;
    assert!(chunk.validate().is_err());
    chunk.stage_seconds = vec![("x".into(), 0.0); 17];
    assert!(chunk.validate().is_err());
}

/// Well-formed but odd chunks that used to end training: another step count than the run's
/// actors send, and finite values so large that the loss overflows.
#[test]
fn the_run_contract_refuses_odd_steps_and_huge_values() {
    // zeros(.., seq 3, num_envs 2, steps 3, obs 4, act 2)
    let c = chunk();
    c.validate_contract(4, 2, 3, 100.0).unwrap();
    let err = c
        .validate_contract(4, 2, 24, 100.0)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`steps`") && err.contains("expected 24, got 3"),
        "{err}"
    );
    let mut huge = chunk();
    huge.observations[5] = 3e38;
    let err = huge
        .validate_contract(4, 2, 3, 100.0)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`observations`") && err.contains("index 5"),
        "{err}"
    );
    let mut edge = chunk();
    edge.observations[5] = 100.0;
    edge.validate_contract(4, 2, 3, 100.0).unwrap();
    for field in [
        "actions",
        "log_probs",
        "action_means",
        "action_stds",
        "rewards",
    ] {
        let mut c = chunk();
        let values = match field {
            "actions" => &mut c.actions,
            "log_probs" => &mut c.log_probs,
            "action_means" => &mut c.action_means,
            "action_stds" => &mut c.action_stds,
            _ => &mut c.rewards,
        };
        values[1] = 3e38;
        let err = c.validate_contract(4, 2, 3, 100.0).unwrap_err().to_string();
        assert!(err.contains(&format!("`{field}`")), "{field}: {err}");
    }
}
