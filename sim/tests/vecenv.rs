//! The vectorised env: shapes, determinism-free sanity, resets, NaN actions, rough terrain.

use l3p_robot::catalog::RobotSpec;
use l3p_sim::vecenv::VecEnv;
use l3p_task::config::{EnvConfig, GainsOverride, TerrainPreset};

fn cfg(preset: TerrainPreset) -> EnvConfig {
    EnvConfig {
        terrain: l3p_task::config::TerrainConfig::with_preset(preset),
        height_scan: preset != TerrainPreset::Flat,
        ..Default::default()
    }
}

#[test]
fn flat_env_steps_with_zero_actions_and_robots_stand() {
    let spec = RobotSpec::by_name("a1").unwrap();
    let mut env = VecEnv::new(spec, &cfg(TerrainPreset::Flat), 8, 2, 1).unwrap();
    assert_eq!(env.obs_dim(), 48);
    assert_eq!(env.action_dim(), 12);
    let obs = env.reset_all().to_vec();
    assert_eq!(obs.len(), 8 * 48);
    assert!(obs.iter().all(|v| v.is_finite()));
    let actions = vec![0.0; 8 * 12];
    let mut terminated = 0;
    for _ in 0..100 {
        let out = env.step(&actions).unwrap();
        assert_eq!(out.rewards.len(), 8);
        assert!(out.obs.iter().all(|v| v.is_finite()));
        assert!(out.rewards.iter().all(|v| v.is_finite()));
        terminated += out.terminated.iter().filter(|t| **t).count();
    }
    // Holding the default pose on flat ground nobody falls.
    assert_eq!(terminated, 0);
    for e in 0..8 {
        let s = env.robot_state(e).unwrap();
        assert!(s.base_pos[2] > 0.2, "env {e} sank to {}", s.base_pos[2]);
    }
    assert_eq!(env.nan_resets(), 0);
    assert!(
        env.step(&actions[..5]).is_err(),
        "wrong action length must be an error"
    );
}

#[test]
fn rough_env_with_random_and_nan_actions_never_panics() {
    let spec = RobotSpec::by_name("a1").unwrap();
    // IsaacLab's recipe: without l3p's joint damping, random actions topple the robots within 6 s.
    let rough = EnvConfig {
        recipe: l3p_task::config::Recipe::Isaaclab,
        ..cfg(TerrainPreset::Curriculum)
    };
    let mut env = VecEnv::new(spec, &rough, 6, 2, 7).unwrap();
    assert_eq!(env.obs_dim(), 235);
    env.reset_all();
    let mut x: u32 = 12345;
    let mut actions = vec![0.0f32; 6 * 12];
    let mut episodes = 0;
    for step in 0..300 {
        for a in actions.iter_mut() {
            x = x.wrapping_mul(1664525).wrapping_add(1013904223);
            *a = (x >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 2.0;
        }
        if step % 50 == 0 {
            actions[3] = f32::NAN;
        }
        let out = env.step(&actions).unwrap();
        assert!(out.obs.iter().all(|v| v.is_finite()));
        episodes += out.episodes.len();
    }
    // Random actions make robots fall: episodes end and are reported.
    assert!(episodes > 0);
    // Every stage is timed (no comparison of durations: that would depend on the machine's load).
    let t = env.timings();
    assert_eq!(t.steps, 300);
    for (stage, time) in [
        ("physics", t.physics),
        ("observations", t.observations),
        ("rewards", t.rewards),
        ("total", t.total),
    ] {
        assert!(time > std::time::Duration::ZERO, "{stage} was not timed");
    }
}

#[test]
fn gait_meter_sees_standing_and_chatter_in_the_real_env() {
    let spec = RobotSpec::by_name("a1").unwrap();
    let mut env = VecEnv::new(spec, &cfg(TerrainPreset::Flat), 4, 1, 3).unwrap();
    env.reset_all();
    // Robots spawn 5 cm above standing height: let them land before measuring.
    for _ in 0..25 {
        env.step(&[0.0; 4 * 12]).unwrap();
    }
    env.enable_gait_meter();
    for _ in 0..100 {
        env.step(&[0.0; 4 * 12]).unwrap();
    }
    let standing = env.gait_report();
    assert_eq!(standing.steps, 400);
    assert!(
        (80.0..115.0).contains(&standing.base_height_pct),
        "standing at {}%",
        standing.base_height_pct
    );
    assert!(
        standing.swing_share.iter().all(|s| *s < 0.01),
        "{:?}",
        standing.swing_share
    );
    assert_eq!(standing.non_foot_contact_share, 0.0);
    assert!(standing.target_change_rms < 1e-6);
    // Uniform ±2 actions, independent per step: Δa has variance 2·4²/12, so the target change is
    // action_scale · sqrt(8/3) = 0.25 · 1.633 ≈ 0.41 rad RMS.
    env.enable_gait_meter();
    let mut x: u32 = 99;
    let mut actions = vec![0.0f32; 4 * 12];
    for _ in 0..200 {
        for a in actions.iter_mut() {
            x = x.wrapping_mul(1664525).wrapping_add(1013904223);
            *a = (x >> 8) as f32 / (1u32 << 24) as f32 * 4.0 - 2.0;
        }
        env.step(&actions).unwrap();
    }
    let chatter = env.gait_report();
    assert!(
        (chatter.target_change_rms - 0.408).abs() < 0.04,
        "{}",
        chatter.target_change_rms
    );
    assert!(chatter.mean_power > standing.mean_power);
}

/// The flat training task with the randomisation pinned at its nominal values.
fn nominal_flat() -> EnvConfig {
    let mut nominal = cfg(TerrainPreset::Flat);
    let r = &mut nominal.randomization;
    r.static_friction = Some([0.8, 0.8]);
    r.dynamic_friction = Some([0.6, 0.6]);
    r.added_base_mass = Some([0.0, 0.0]);
    r.base_com_offset = Some([0.0; 3]);
    r.pushes = Some(false);
    r.reset_base_velocity = Some(0.0);
    r.reset_joint_pos_scale = Some([1.0, 1.0]);
    r.motor_strength = Some([1.0, 1.0]);
    r.kp_scale = Some([1.0, 1.0]);
    r.kd_scale = Some([1.0, 1.0]);
    r.latency_s = Some([0.0, 0.0]);
    nominal
}

/// Mean base height (m) of `envs` robots after 2 s of zero actions.
fn zero_action_height(spec: &RobotSpec, env_cfg: &EnvConfig) -> f32 {
    let envs = 4;
    let mut env = VecEnv::new(spec, env_cfg, envs, 2, 5).unwrap();
    env.reset_all();
    let actions = vec![0.0; envs * env.action_dim()];
    for _ in 0..100 {
        env.step(&actions).unwrap();
    }
    (0..envs)
        .map(|e| env.robot_state(e).unwrap().base_pos[2])
        .sum::<f32>()
        / envs as f32
}

/// `[env.gains.a1]` reaches the simulated actuators: soft gains let the trunk sag under its weight,
/// stiff ones hold it up, and a robot the table does not name keeps its catalog gains.
#[test]
fn per_robot_gains_reach_the_simulated_motors() {
    let a1 = RobotSpec::by_name("a1").unwrap();
    let go1 = RobotSpec::by_name("go1").unwrap();
    let with_a1_kp = |kp: f32| {
        let mut c = nominal_flat();
        c.gains.insert(
            "a1".into(),
            GainsOverride {
                kp: Some(kp),
                kd: None,
            },
        );
        c
    };
    let soft = zero_action_height(a1, &with_a1_kp(6.0));
    let stiff = zero_action_height(a1, &with_a1_kp(120.0));
    assert!(soft + 0.03 < stiff, "kp 6: {soft} m, kp 120: {stiff} m");
    let go1_catalog = zero_action_height(go1, &nominal_flat());
    let go1_beside = zero_action_height(go1, &with_a1_kp(6.0));
    assert!(
        (go1_catalog - go1_beside).abs() < 1e-4,
        "{go1_catalog} {go1_beside}"
    );
}

/// Every catalog robot, holding its default pose (zero actions) under nominal conditions (the
/// training task with the randomisation pinned at its nominal values), stands for 4 s: nobody
/// terminates and the base stays near standing height. A target that falls or terminates at once
/// learns nothing (issue 12 found ANYmal-B/D ending after one step and Spot falling); ANYmal sagged
/// to 80-92% here with IsaacLab's simple-actuator gains (kp 40 / kd 5); legged_gym's kp 80 / kd 2,
/// which the catalog uses, holds it at 92-97%.
#[test]
fn every_catalog_robot_stands_with_zero_actions_in_the_task() {
    let nominal = nominal_flat();
    let mut failures = Vec::new();
    for spec in RobotSpec::all() {
        let standing = spec.nominal_standing_height().unwrap();
        let envs = 4;
        let mut env = VecEnv::new(spec, &nominal, envs, 2, 3).unwrap();
        env.reset_all();
        let actions = vec![0.0; envs * env.action_dim()];
        let mut ended = 0;
        for _ in 0..200 {
            let out = env.step(&actions).unwrap();
            ended += out.terminated.iter().filter(|t| **t).count();
        }
        let lowest = (0..envs)
            .map(|e| env.robot_state(e).unwrap().base_pos[2] / standing)
            .fold(f32::INFINITY, f32::min);
        if ended > 0 || lowest < 0.8 {
            failures.push(format!(
                "{}: {ended} terminations, lowest base at {:.0}% of standing",
                spec.name,
                100.0 * lowest
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

#[test]
fn staggered_time_outs_spread_the_first_episode_ends_and_keep_later_episodes_full() {
    let spec = RobotSpec::by_name("a1").unwrap();
    // 1 s episodes (50 control steps): standing robots on flat ground end only by time-out.
    let short = EnvConfig {
        episode_length_s: 1.0,
        ..cfg(TerrainPreset::Flat)
    };
    let first_ends = |stagger: bool| {
        let mut env = VecEnv::new(spec, &short, 16, 2, 3).unwrap();
        env.reset_all();
        if stagger {
            env.stagger_time_outs();
        }
        let actions = vec![0.0; 16 * 12];
        let mut first: Vec<Option<usize>> = vec![None; 16];
        let mut second_lengths = Vec::new();
        for step in 1..=100 {
            let out = env.step(&actions).unwrap();
            assert!(out.terminated.iter().all(|t| !t), "a standing robot fell");
            for (e, ended) in out.truncated.iter().enumerate() {
                if *ended {
                    match first[e] {
                        None => first[e] = Some(step),
                        Some(at) if second_lengths.len() < 16 => second_lengths.push(step - at),
                        Some(_) => {}
                    }
                }
            }
        }
        (
            first.into_iter().map(Option::unwrap).collect::<Vec<_>>(),
            second_lengths,
        )
    };
    // Without: every env times out together after one episode length (~50 steps), then again.
    let (plain, plain_second) = first_ends(false);
    let length = plain[0];
    assert!((50..=51).contains(&length), "{plain:?}");
    assert!(plain.iter().all(|&s| s == length), "{plain:?}");
    assert!(
        plain_second.iter().all(|&l| l == length),
        "{plain_second:?}"
    );
    // With: the first ends spread over the episode; every later episode is full length.
    let (staggered, second) = first_ends(true);
    assert!(
        staggered.iter().all(|&s| (1..=length).contains(&s)),
        "{staggered:?}"
    );
    let distinct: std::collections::BTreeSet<_> = staggered.iter().collect();
    assert!(
        distinct.len() >= 8,
        "16 envs, few distinct ends: {staggered:?}"
    );
    assert_eq!(second.len(), 16, "{second:?}");
    assert!(second.iter().all(|&l| l == length), "{second:?}");
}
