use super::*;

#[test]
fn every_reward_term_is_indexed_named_weighted_and_overridable_in_one_order() {
    let scales = RewardScales::default();
    let named = scales.named();
    for (k, term) in RewardTerm::ALL.iter().enumerate() {
        assert_eq!(*term as usize, k);
        assert_eq!(term.as_str(), named[k].0);
        // The name is the `[env.rewards]` key and reaches the same weight.
        let overrides: RewardOverrides =
            toml::from_str(&format!("{} = 123.5", term.as_str())).unwrap();
        let mut s = scales.clone();
        overrides.apply(&mut s);
        assert_eq!(s.named()[k].1, 123.5, "{}", term.as_str());
        assert_eq!(
            s.named().iter().filter(|(_, w)| *w == 123.5).count(),
            1,
            "{} set another weight too",
            term.as_str()
        );
    }
}

#[test]
fn default_is_isaaclab_rough_task() {
    let isaaclab = EnvConfig {
        recipe: Recipe::Isaaclab,
        ..EnvConfig::default()
    };
    let spec = isaaclab.resolve("anymal_c").unwrap();
    assert_eq!(spec.max_episode_steps, 1000);
    assert!((spec.step_dt - 0.02).abs() < 1e-7);
    assert_eq!(spec.obs_dim, 235);
    assert_eq!(spec.rewards, RewardScales::default());
    assert_eq!(spec.terrain.num_rows, 10);
    assert_eq!(spec.terrain.num_cols, 20);
    assert_eq!(spec.terrain.params.stairs_step_height, [0.05, 0.23]);
    assert_eq!(spec.terrain.params.slope, [0.0, 0.4]);
    assert!(spec.terrain.curriculum);
    assert!(spec.randomization.pushes);
    assert_eq!(spec.randomization.push_interval_s, [10.0, 15.0]);
    // The l3p recipe adds its gait terms and actuator ranges on top, nothing else.
    let l3p = EnvConfig::default().resolve("a1").unwrap();
    let mut expected = RewardScales::for_robot("a1", true);
    expected.base_height_l2 = -40.0;
    expected.trot_contact = 0.5;
    expected.joint_deviation_l1 = -0.1;
    expected.action_rate_l2 = -0.05;
    expected.action_smoothness_l2 = -0.1;
    expected.undesired_contacts = -1.0;
    assert_eq!(l3p.rewards, expected);
    assert_eq!(l3p.randomization.joint_damping, [0.0, 2.0]);
    assert_eq!(l3p.randomization.latency_s, [0.0, 0.02]);
    assert_eq!(l3p.randomization.static_friction, [0.4, 1.25]);
    assert!(l3p.randomization.pushes);
    let anymal = EnvConfig::default().resolve("anymal_b").unwrap();
    assert_eq!(anymal.randomization.joint_damping, [0.0, 5.0]);
    assert_eq!(anymal.rewards.undesired_contacts, -1.0);
}

#[test]
fn unitree_tables_differ_from_base() {
    let rough = RewardScales::for_robot("A1", true);
    assert_eq!(rough.track_lin_vel_xy_exp, 1.5);
    assert_eq!(rough.feet_air_time, 0.01);
    assert_eq!(rough.undesired_contacts, 0.0);
    assert_eq!(rough.dof_torques_l2, -2.0e-4);
    let flat = RewardScales::for_robot("go2", false);
    assert_eq!(flat.feet_air_time, 0.25);
    assert_eq!(flat.flat_orientation_l2, -2.5);
    let anymal_flat = RewardScales::for_robot("anymal-d", false);
    assert_eq!(anymal_flat.flat_orientation_l2, -5.0);
    assert_eq!(anymal_flat.feet_air_time, 0.5);
    assert_eq!(anymal_flat.undesired_contacts, -1.0);
    let r = RandomizationConfig::for_robot("go1");
    assert!(!r.pushes);
    assert_eq!(r.added_base_mass, [-1.0, 3.0]);
    let t = TerrainConfig::default().resolve("a1").unwrap();
    assert_eq!(t.params.boxes_height, [0.025, 0.1]);
    assert_eq!(t.params.rough_noise, [0.01, 0.06]);
}

#[test]
fn toml_overrides_apply_on_top_of_robot_table() {
    let cfg = EnvConfig::from_toml_str(
        r#"
            height_scan = false
            [terrain]
            preset = "paper"
            [rewards]
            feet_air_time = 0.3
            [randomization]
            pushes = true
            push_interval_s = [5.0, 6.0]
            "#,
    )
    .unwrap();
    let spec = cfg.resolve("a1").unwrap();
    assert_eq!(spec.obs_dim, 48);
    assert_eq!(spec.rewards.feet_air_time, 0.3);
    assert_eq!(
        spec.rewards.track_lin_vel_xy_exp, 1.5,
        "other weights keep the A1 table"
    );
    assert!(spec.randomization.pushes);
    assert_eq!(spec.randomization.push_interval_s, [5.0, 6.0]);
    assert_eq!(spec.randomization.added_base_mass, [-1.0, 3.0]);
    assert_eq!(spec.terrain.params.stairs_step_height, [0.05, 0.8]);
}

#[test]
fn serialised_config_round_trips() {
    let mut cfg = EnvConfig::default();
    cfg.terrain.preset = TerrainPreset::SimpleRough;
    cfg.terrain.slope = Some([0.1, 0.2]);
    cfg.rewards.feet_air_time = Some(0.7);
    cfg.randomization.pushes = Some(false);
    let text = toml::to_string(&cfg).unwrap();
    let back = EnvConfig::from_toml_str(&text).unwrap();
    assert_eq!(back.terrain, cfg.terrain);
    assert_eq!(back.rewards, cfg.rewards);
    assert_eq!(back.randomization, cfg.randomization);
    let spec = back.resolve("anymal_c").unwrap();
    assert_eq!(spec.terrain.params.slope, [0.1, 0.2]);
    assert!(!spec.terrain.curriculum);
    assert_eq!(spec.rewards.feet_air_time, 0.7);
    assert_eq!(
        spec.rewards.flat_orientation_l2, 0.0,
        "simple-rough uses the rough table"
    );
}

#[test]
fn gains_override_one_robot_and_leave_the_others_at_the_catalog() {
    let cfg = EnvConfig::from_toml_str("[gains.a1]\nkp = 60.0\nkd = 1.2\n[gains.go1]\nkd = 0.9\n")
        .unwrap();
    let a1 = RobotSpec::by_name("a1").unwrap();
    let go1 = RobotSpec::by_name("go1").unwrap();
    let spot = RobotSpec::by_name("spot").unwrap();
    assert_eq!(cfg.training_gains(a1), Gains { kp: 60.0, kd: 1.2 });
    assert_eq!(
        cfg.training_gains(go1),
        Gains {
            kp: go1.training_gains.kp,
            kd: 0.9
        }
    );
    assert_eq!(cfg.training_gains(spot), spot.training_gains);
    let task = cfg.resolve("a1").unwrap();
    assert_eq!(
        task.gains.apply(a1.training_gains),
        Gains { kp: 60.0, kd: 1.2 }
    );
    assert_eq!(cfg.resolve("spot").unwrap().gains, GainsOverride::default());
}

#[test]
fn gains_for_an_unknown_robot_or_a_bad_value_are_errors_naming_the_key() {
    let cfg = EnvConfig::from_toml_str("[gains.a2]\nkp = 60.0\n").unwrap();
    let msg = cfg.resolve("a1").unwrap_err().to_string();
    assert!(msg.contains("gains.a2") && msg.contains("a1, go1"), "{msg}");
    for bad in ["0.0", "-5.0", "nan", "inf"] {
        let cfg = EnvConfig::from_toml_str(&format!("[gains.a1]\nkd = {bad}\n")).unwrap();
        let msg = cfg.resolve("a1").unwrap_err().to_string();
        assert!(msg.contains("gains.a1.kd"), "{bad}: {msg}");
    }
    let err = EnvConfig::from_toml_str("[gains.a1]\nkp_scale = 2.0\n").unwrap_err();
    assert!(err.to_string().contains("kp_scale"), "{err}");
}

#[test]
fn misspelt_key_is_an_error_naming_it() {
    let err = EnvConfig::from_toml_str("[commands]\nheading_stifness = 0.5\n").unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("heading_stifness"), "{msg}");
    let err = EnvConfig::from_toml_str("[rewards]\nfeet_airtime = 1.0\n").unwrap_err();
    assert!(err.to_string().contains("feet_airtime"), "{err}");
}

#[test]
fn bad_values_are_named() {
    let mut cfg = EnvConfig::default();
    cfg.commands.lin_vel_x = [1.0, -1.0];
    let err = cfg.resolve("a1").unwrap_err().to_string();
    assert!(err.contains("commands.lin_vel_x"), "{err}");
    let mut cfg = EnvConfig::default();
    cfg.terrain.horizontal_resolution = 0.0;
    let err = cfg.resolve("a1").unwrap_err().to_string();
    assert!(err.contains("horizontal_resolution"), "{err}");
}

#[test]
fn physics_dt_keeps_the_control_step() {
    let mut env = EnvConfig {
        sim_dt: 0.02,
        decimation: 1,
        ..EnvConfig::default()
    };
    env.set_physics_dt(0.005).unwrap();
    assert_eq!(env.decimation, 4);
    assert!((env.sim_dt * env.decimation as f32 - 0.02).abs() < 1e-7);
    assert_eq!(env.resolve("a1").unwrap().max_episode_steps, 1000);
    env.set_physics_dt(0.02).unwrap();
    assert_eq!((env.sim_dt, env.decimation), (0.02, 1));
    for bad in [0.003, 0.04, 0.0, -0.005, f32::NAN] {
        let err = env.clone().set_physics_dt(bad).unwrap_err().to_string();
        assert!(err.contains("physics dt"), "{bad}: {err}");
    }
}
