use super::*;
use crate::config::{EnvConfig, TerrainPreset};
use rand::SeedableRng;
use rand::rngs::StdRng;

const A1_DEFAULT: [f32; 12] = [
    0.1, 0.8, -1.5, -0.1, 0.8, -1.5, 0.1, 1.0, -1.5, -0.1, 1.0, -1.5,
];

fn a1_params() -> RobotTaskParams {
    RobotTaskParams {
        name: "a1".into(),
        default_joint_pos: A1_DEFAULT,
        joint_pos_limits: [
            [-0.8, 0.8],
            [-1.0, 4.2],
            [-2.7, -0.9],
            [-0.8, 0.8],
            [-1.0, 4.2],
            [-2.7, -0.9],
            [-0.8, 0.8],
            [-1.0, 4.2],
            [-2.7, -0.9],
            [-0.8, 0.8],
            [-1.0, 4.2],
            [-2.7, -0.9],
        ],
        soft_limit_factor: 0.9,
        action_scale: 0.25,
        num_penalised_bodies: 8,
        standing_height: 0.3,
    }
}

/// IsaacLab's recipe: the tests below check its semantics term by term.
fn flat_task(robot: &str) -> (Task, Terrain) {
    let mut cfg = EnvConfig {
        recipe: crate::config::Recipe::Isaaclab,
        ..EnvConfig::default()
    };
    cfg.terrain.preset = TerrainPreset::Flat;
    let spec = cfg.resolve(robot).unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let mut p = a1_params();
    p.name = robot.into();
    (Task::new(spec, p).unwrap(), terrain)
}

fn standing_state() -> SimState {
    SimState {
        base_pos: [0.0, 0.0, 0.3],
        joint_pos: A1_DEFAULT,
        foot_force: [30.0; 4],
        ..Default::default()
    }
}

#[test]
fn quaternion_helpers() {
    let s = std::f32::consts::FRAC_1_SQRT_2;
    // rolled +90° about x
    let g = projected_gravity([s, s, 0.0, 0.0]);
    assert!(
        (g[0]).abs() < 1e-6 && (g[1] + 1.0).abs() < 1e-6 && g[2].abs() < 1e-6,
        "{g:?}"
    );
    // pitched +90° about y (nose down): gravity along +x of the base
    let g = projected_gravity([s, 0.0, s, 0.0]);
    assert!((g[0] - 1.0).abs() < 1e-6 && g[2].abs() < 1e-6, "{g:?}");
    assert_eq!(projected_gravity([1.0, 0.0, 0.0, 0.0]), [0.0, 0.0, -1.0]);
    // yawed 90°: world +x velocity is base -y
    let q = quat_from_yaw(std::f32::consts::FRAC_PI_2);
    let v = quat_rotate_inverse(q, [1.0, 0.0, 0.0]);
    assert!(v[0].abs() < 1e-6 && (v[1] + 1.0).abs() < 1e-6, "{v:?}");
    assert!((yaw_of(q) - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    assert!((yaw_of(quat_from_yaw(-3.0)) + 3.0).abs() < 1e-5);
    assert!((wrap_to_pi(3.5) - (3.5 - 2.0 * std::f32::consts::PI)).abs() < 1e-6);
}

#[test]
fn heading_mode_yaw_rate() {
    // error 1.0 rad → 0.5 rad/s
    assert!((heading_yaw_rate(1.2, 0.2, 0.5, [-1.0, 1.0]) - 0.5).abs() < 1e-6);
    // error 3 rad → 1.5, clipped to 1
    assert_eq!(heading_yaw_rate(3.0, 0.0, 0.5, [-1.0, 1.0]), 1.0);
    // wrap: target −3.0, yaw 3.0 → error 2π − 6 = 0.283 (turn left, not right)
    let r = heading_yaw_rate(-3.0, 3.0, 0.5, [-1.0, 1.0]);
    assert!(
        (r - 0.5 * (2.0 * std::f32::consts::PI - 6.0)).abs() < 1e-5,
        "{r}"
    );
    // through the task: a robot yawed 0.4 rad with heading target 1.0
    let (task, _) = flat_task("a1");
    let mut cmd = Command {
        heading: 1.0,
        heading_mode: true,
        ..Default::default()
    };
    let st = SimState {
        base_quat: quat_from_yaw(0.4),
        ..standing_state()
    };
    task.apply_command_modes(&mut cmd, &st);
    assert!((cmd.wz - 0.3).abs() < 1e-5, "{}", cmd.wz);
    cmd.standing = true;
    task.apply_command_modes(&mut cmd, &st);
    assert_eq!(cmd.as_array(), [0.0; 3]);
}

#[test]
fn heading_hold_keeps_the_heading_at_the_commands_start() {
    let mut cfg = EnvConfig {
        recipe: crate::config::Recipe::Isaaclab,
        ..EnvConfig::default()
    };
    cfg.terrain.preset = TerrainPreset::Flat;
    cfg.commands.heading_hold = true;
    cfg.commands.rel_standing_envs = 0.0;
    let task = Task::new(cfg.resolve("a1").unwrap(), a1_params()).unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    let mut env = TaskEnvState::new();
    let yawed = |yaw| SimState {
        base_quat: quat_from_yaw(yaw),
        ..standing_state()
    };
    task.reset_env(&mut env, &yawed(0.7), [0.0; 3], &mut rng);
    assert!((env.command.heading - 0.7).abs() < 1e-6);
    assert!(env.command.wz.abs() < 1e-6, "{}", env.command.wz);
    // drifted 0.2 rad left: turn back right at 0.5 · 0.2 rad/s
    task.update_commands(&mut env, &yawed(0.9), &mut rng);
    assert!((env.command.wz + 0.1).abs() < 1e-5, "{}", env.command.wz);
}

#[test]
fn command_sampling_ranges_standing_share_and_resampling() {
    let (task, _) = flat_task("a1");
    let mut rng = StdRng::seed_from_u64(5);
    let mut standing = 0;
    for _ in 0..20000 {
        let mut c = Command::default();
        task.resample_command(&mut c, &mut rng);
        assert!((-1.0..=1.0).contains(&c.vx) && (-1.0..=1.0).contains(&c.vy));
        assert!(c.heading.abs() <= std::f32::consts::PI);
        assert!(c.heading_mode);
        assert_eq!(c.time_left, 10.0);
        standing += c.standing as usize;
    }
    let share = standing as f32 / 20000.0;
    assert!((0.01..0.03).contains(&share), "{share}");
    // resampled after 10 s = 500 steps
    let mut env = TaskEnvState::new();
    let st = standing_state();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    let first = env.command.heading;
    for _ in 0..499 {
        task.update_commands(&mut env, &st, &mut rng);
        assert_eq!(env.command.heading, first);
    }
    task.update_commands(&mut env, &st, &mut rng);
    assert_ne!(env.command.heading, first);
}

#[test]
fn perfect_tracking_reward() {
    let (task, terrain) = flat_task("a1");
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    let mut rng = StdRng::seed_from_u64(1);
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    env.command = Command {
        vx: 0.7,
        vy: -0.2,
        wz: 0.3,
        time_left: 10.0,
        ..Default::default()
    };
    // yawed base moving exactly at the command (in its own frame)
    let yaw: f32 = 0.6;
    st.base_quat = quat_from_yaw(yaw);
    st.base_lin_vel_w = [
        0.7 * yaw.cos() + 0.2 * yaw.sin(),
        0.7 * yaw.sin() - 0.2 * yaw.cos(),
        0.0,
    ];
    st.base_ang_vel_w = [0.0, 0.0, 0.3];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let dt = 0.02;
    // A1 rough table: 1.5 and 0.75 (flat table has the same tracking weights)
    assert!(
        (r.terms[RewardTerm::TrackLinVelXyExp as usize] - 1.5 * dt).abs() < 1e-6,
        "{:?}",
        r.terms
    );
    assert!((r.terms[RewardTerm::TrackAngVelZExp as usize] - 0.75 * dt).abs() < 1e-6);
    assert_eq!(r.terms[RewardTerm::LinVelZL2 as usize], 0.0);
    // 0.5 m/s error in vx: exp(-0.25 / 0.25) = e^-1
    st.base_lin_vel_w = quat_rotate_inv_inverse(st.base_quat, [0.2, -0.2, 0.0]);
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let got = r.terms[RewardTerm::TrackLinVelXyExp as usize];
    assert!((got - 1.5 * dt * (-1.0f32).exp()).abs() < 1e-6, "{got}");
    assert!(!r.done());
}

#[test]
fn yaw_rate_mean_term_sees_drift_not_the_stride_swing() {
    let mut cfg = EnvConfig {
        recipe: crate::config::Recipe::Isaaclab,
        ..EnvConfig::default()
    };
    cfg.terrain.preset = TerrainPreset::Flat;
    cfg.rewards.track_yaw_rate_mean_exp = Some(1.0);
    let task = Task::new(cfg.resolve("a1").unwrap(), a1_params()).unwrap();
    let terrain = Terrain::generate(&task.spec.terrain).unwrap();
    let term = |yaw_rates: &mut dyn Iterator<Item = f32>| {
        let mut env = TaskEnvState::new();
        let mut st = standing_state();
        task.reset_env(&mut env, &st, [0.0; 3], &mut StdRng::seed_from_u64(2));
        let mut last = 0.0;
        for wz in yaw_rates {
            env.command = Command {
                time_left: 10.0,
                ..Default::default()
            };
            st.base_ang_vel_w = [0.0, 0.0, wz];
            last = task.evaluate(&mut env, &st, &[0.0; 12], &terrain).terms
                [RewardTerm::TrackYawRateMeanExp as usize]
                / 0.02;
        }
        last
    };
    // a trot's ±0.3 rad/s yaw swing, flipping every 0.25 s, averages out
    let swing = term(&mut (0..500).map(|i| if (i / 12) % 2 == 0 { 0.3 } else { -0.3 }));
    assert!(swing > 0.6, "{swing}");
    // a steady 0.1 rad/s drift (115° in 20 s): e^-(0.1/0.05)² = e^-4
    let drift = term(&mut (0..500).map(|_| 0.1));
    assert!((drift - (-4.0f32).exp()).abs() < 1e-3, "{drift}");
}

/// An A1 task on flat ground with IsaacLab's tables and `configure`'s changes, reset from the
/// standing state, commanded `[vx, vy, wz]` for the next 10 s.
fn flat_isaaclab_task(
    configure: impl FnOnce(&mut EnvConfig),
    [vx, vy, wz]: [f32; 3],
) -> (Task, Terrain, TaskEnvState, SimState) {
    let mut cfg = EnvConfig {
        recipe: crate::config::Recipe::Isaaclab,
        ..EnvConfig::default()
    };
    cfg.terrain.preset = TerrainPreset::Flat;
    configure(&mut cfg);
    let spec = cfg.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let task = Task::new(spec, a1_params()).unwrap();
    let mut env = TaskEnvState::new();
    let st = standing_state();
    let mut rng = StdRng::seed_from_u64(1);
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    env.command = Command {
        vx,
        vy,
        wz,
        time_left: 10.0,
        ..Default::default()
    };
    (task, terrain, env, st)
}

#[test]
fn coarse_tracking_kernel_matches_hand_computation() {
    let (task, terrain, mut env, mut st) = flat_isaaclab_task(
        |cfg| {
            cfg.rewards.track_lin_vel_xy_coarse_exp = Some(0.8);
            cfg.reward_params.coarse_tracking_std = 1.2;
        },
        [1.0, 0.0, 0.0],
    );
    let dt = 0.02;
    // Standing at a 1 m/s command: error² 1 → 0.8 · dt · exp(−1/1.44); the sharp kernel
    // (std 0.5) pays exp(−4).
    st.base_lin_vel_w = [0.0, 0.0, 0.0];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let coarse = r.terms[RewardTerm::TrackLinVelXyCoarseExp as usize];
    assert!(
        (coarse - 0.8 * dt * (-1.0f32 / 1.44).exp()).abs() < 1e-6,
        "{coarse}"
    );
    let sharp = r.terms[RewardTerm::TrackLinVelXyExp as usize];
    assert!((sharp - 1.5 * dt * (-4.0f32).exp()).abs() < 1e-6, "{sharp}");
    // Moving at 0.4 m/s along a yawed heading: error 0.6 m/s.
    st.base_quat = quat_from_yaw(1.0);
    st.base_lin_vel_w = quat_rotate_inv_inverse(st.base_quat, [0.4, 0.0, 0.0]);
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let coarse = r.terms[RewardTerm::TrackLinVelXyCoarseExp as usize];
    assert!(
        (coarse - 0.8 * dt * (-0.36f32 / 1.44).exp()).abs() < 1e-6,
        "{coarse}"
    );
}

#[test]
fn coarse_yaw_kernel_matches_hand_computation() {
    let (task, terrain, mut env, mut st) = flat_isaaclab_task(
        |cfg| {
            cfg.rewards.track_ang_vel_z_coarse_exp = Some(0.4);
            cfg.reward_params.coarse_tracking_std = 1.2;
            cfg.reward_params.tracking_std = 0.35;
        },
        [0.0, 0.0, 0.5],
    );
    let dt = 0.02;
    // Turning at −0.3 rad/s against a 0.5 rad/s command: error 0.8 → 0.4 · dt · exp(−0.64/1.44);
    // the sharp kernel (std 0.35, IsaacLab weight 0.75 for A1) pays exp(−0.64/0.1225) ≈ 0.005.
    st.base_ang_vel_w = [0.0, 0.0, -0.3];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let coarse = r.terms[RewardTerm::TrackAngVelZCoarseExp as usize];
    assert!(
        (coarse - 0.4 * dt * (-0.64f32 / 1.44).exp()).abs() < 1e-6,
        "{coarse}"
    );
    let sharp = r.terms[RewardTerm::TrackAngVelZExp as usize];
    assert!(
        (sharp - 0.75 * dt * (-0.64f32 / 0.1225).exp()).abs() < 1e-6,
        "{sharp}"
    );
    assert_eq!(
        r.terms[RewardTerm::TrackLinVelXyCoarseExp as usize],
        0.0,
        "weight 0 by default"
    );
}

// rotate a base-frame vector into the world frame (test helper)
fn quat_rotate_inv_inverse(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    quat_rotate_inverse([q[0], -q[1], -q[2], -q[3]], v)
}

#[test]
fn penalty_terms_match_hand_computation() {
    let (task, terrain) = flat_task("a1");
    let w = task.spec.rewards.clone();
    let dt = 0.02;
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    let mut rng = StdRng::seed_from_u64(1);
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    env.command = Command {
        time_left: 10.0,
        ..Default::default()
    };
    env.last_action = [0.1; 12];
    env.last_mean_action = [0.1; 12]; // no means given below: the previous action was 0.1
    st.base_lin_vel_w = [0.0, 0.0, 0.5];
    st.base_ang_vel_w = [0.3, -0.4, 0.0];
    st.joint_torque = [2.0; 12];
    st.joint_vel = [0.0; 12];
    st.joint_vel[0] = 0.2; // acc = 0.2 / 0.02 = 10
    st.penalised_force[1] = 5.0;
    st.penalised_force[6] = 0.5; // below threshold
    st.joint_pos[1] = 4.2; // soft upper limit = 1.6 + 2.6 * 0.9 = 3.94 → violation 0.26
    let action = [0.3; 12];
    let r = task.evaluate(&mut env, &st, &action, &terrain);
    let t = |k: RewardTerm| r.terms[k as usize];
    assert!((t(RewardTerm::LinVelZL2) - w.lin_vel_z_l2 * 0.25 * dt).abs() < 1e-7);
    assert!((t(RewardTerm::AngVelXyL2) - w.ang_vel_xy_l2 * 0.25 * dt).abs() < 1e-7);
    assert!((t(RewardTerm::DofTorquesL2) - w.dof_torques_l2 * 48.0 * dt).abs() < 1e-7);
    assert!((t(RewardTerm::DofAccL2) - w.dof_acc_l2 * 100.0 * dt).abs() < 1e-9);
    assert!((t(RewardTerm::ActionRateL2) - w.action_rate_l2 * 12.0 * 0.04 * dt).abs() < 1e-7);
    assert!((t(RewardTerm::FlatOrientationL2)).abs() < 1e-9);
    assert!((t(RewardTerm::DofPosLimits) - w.dof_pos_limits * 0.26 * dt).abs() < 1e-6);
    let sum: f32 = r.terms.iter().sum();
    assert!((r.reward - sum).abs() < 1e-6);
    assert_eq!(env.episode.terms, r.terms);
    // undesired contacts (weight 0 for A1 in IsaacLab): use ANYmal's −1.0 with 4 thighs
    let mut cfg = EnvConfig::default();
    cfg.terrain.preset = TerrainPreset::Flat;
    let spec = cfg.resolve("anymal_c").unwrap();
    let mut p = a1_params();
    p.num_penalised_bodies = 4;
    let task = Task::new(spec, p.clone()).unwrap();
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    let r = task.evaluate(&mut env, &st, &action, &terrain);
    // one body above the 1 N threshold, weight -1.0
    assert!((r.terms[RewardTerm::UndesiredContacts as usize] + dt).abs() < 1e-7);
    // tilted 0.3 rad in roll: flat_orientation = sin²(0.3), ANYmal flat weight −5
    let (s, c) = (0.15f32.sin(), 0.15f32.cos());
    st.base_quat = [c, s, 0.0, 0.0];
    let r = task.evaluate(&mut env, &st, &action, &terrain);
    let want = -5.0 * 0.3f32.sin().powi(2) * dt;
    assert!((r.terms[RewardTerm::FlatOrientationL2 as usize] - want).abs() < 1e-6);
    // only_positive_rewards clips the negative total at 0 but keeps the per-term values
    assert!(r.reward < 0.0);
    let mut spec = cfg.resolve("anymal_c").unwrap();
    spec.reward_params.only_positive_rewards = true;
    let task = Task::new(spec, p).unwrap();
    let clipped = task.evaluate(&mut env, &st, &action, &terrain);
    assert_eq!(clipped.reward, 0.0);
    assert_eq!(clipped.terms, r.terms);
}

/// A freshly reset env commanded to walk forward at 0.5 m/s for 10 s.
/// A1 on flat ground, blind, with the 2 Hz trot clock and observation noise off; `set` adjusts
/// the config (e.g. a reward weight) before it is resolved.
fn clocked_flat_task(set: impl FnOnce(&mut EnvConfig)) -> (Task, Terrain) {
    let mut cfg = EnvConfig::default();
    cfg.terrain.preset = TerrainPreset::Flat;
    cfg.height_scan = false;
    cfg.gait_clock_hz = 2.0;
    set(&mut cfg);
    let spec = cfg.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let mut task = Task::new(spec, a1_params()).unwrap();
    task.spec.noise.enabled = false;
    (task, terrain)
}

fn commanded_half_speed(task: &Task, st: &SimState, rng: &mut StdRng) -> TaskEnvState {
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, st, [0.0; 3], rng);
    env.command = Command {
        vx: 0.5,
        time_left: 10.0,
        ..Default::default()
    };
    env
}

#[test]
fn gait_terms_match_hand_computation() {
    let mut cfg = EnvConfig::default(); // the l3p recipe
    cfg.terrain.preset = TerrainPreset::Flat;
    let spec = cfg.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let task = Task::new(spec, a1_params()).unwrap();
    let w = task.spec.rewards.clone();
    assert_eq!(
        (w.base_height_l2, w.trot_contact, w.joint_deviation_l1),
        (-40.0, 0.5, -0.1)
    );
    let dt = 0.02;
    let mut rng = StdRng::seed_from_u64(3);
    let mut st = standing_state();
    let mut env = commanded_half_speed(&task, &st, &mut rng);
    // Crouched at 0.18 m (standing 0.30): (0.18 − 0.30)² = 0.0144.
    st.base_pos[2] = 0.18;
    // Trot pattern: FL + RR down, FR + RL up.
    st.foot_force = [40.0, 0.0, 0.0, 40.0];
    // Hip abduction 0.3 rad off default on FL, −0.2 on RR: Σ|Δ| = 0.5 (thigh offsets ignored).
    st.joint_pos = A1_DEFAULT;
    st.joint_pos[0] += 0.3;
    st.joint_pos[9] -= 0.2;
    st.joint_pos[1] += 1.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let t = |k: RewardTerm| r.terms[k as usize];
    assert!((t(RewardTerm::BaseHeightL2) - (-40.0 * 0.0144 * dt)).abs() < 1e-6);
    assert!((t(RewardTerm::TrotContact) - 0.5 * dt).abs() < 1e-7);
    assert!((t(RewardTerm::JointDeviationL1) - (-0.1 * 0.5 * dt)).abs() < 1e-6);
    // Pace (left pair together) and all-down are not a trot; standing still earns nothing.
    assert_eq!(trot_contact(&[40.0, 0.0, 40.0, 0.0], 1.0), 0.0);
    assert_eq!(trot_contact(&[40.0; 4], 1.0), 0.0);
    assert_eq!(trot_contact(&[0.0, 40.0, 40.0, 0.0], 1.0), 1.0);
    env.command.vx = 0.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::TrotContact as usize], 0.0);
}

#[test]
fn gait_clock_phase_observation_and_reward_match_hand_computation() {
    // 2 Hz at 50 Hz: 25 steps per period; step 5 is 0.2 of the way, step 30 again 0.2.
    assert_eq!(gait_clock_phase(0, 2.0, 0.02), 0.0);
    assert!((gait_clock_phase(5, 2.0, 0.02) - 0.2).abs() < 1e-6);
    assert!((gait_clock_phase(30, 2.0, 0.02) - 0.2).abs() < 1e-5);
    // Days into a deployment the clock still advances 0.04 per step (f64 counting, no loss).
    let (a, b) = (
        gait_clock_phase(25_000_005, 2.0, 0.02),
        gait_clock_phase(25_000_006, 2.0, 0.02),
    );
    assert!((b - a - 0.04).abs() < 1e-5, "{a} → {b}");
    let [s, c] = gait_clock_observation(0.25);
    assert!((s - 1.0).abs() < 1e-6 && c.abs() < 1e-6);
    assert_eq!(gait_clock_stance(0.1), [true, false, false, true]);
    assert_eq!(gait_clock_stance(0.6), [false, true, true, false]);
    // FL + RR down in the first half: all four match; a pace matches two; all down two.
    assert_eq!(gait_clock_match(&[40.0, 0.0, 0.0, 40.0], 1.0, 0.1), 1.0);
    assert_eq!(gait_clock_match(&[40.0, 0.0, 0.0, 40.0], 1.0, 0.6), 0.0);
    assert_eq!(gait_clock_match(&[40.0, 0.0, 40.0, 0.0], 1.0, 0.1), 0.5);
    assert_eq!(gait_clock_match(&[40.0; 4], 1.0, 0.6), 0.5);

    let (task, terrain) = clocked_flat_task(|cfg| cfg.rewards.gait_clock = Some(0.8));
    assert_eq!(task.spec.obs_dim, PROPRIO_OBS + GAIT_CLOCK_OBS);
    let mut rng = StdRng::seed_from_u64(3);
    let mut st = standing_state();
    let mut env = commanded_half_speed(&task, &st, &mut rng);
    let mut obs = vec![0.0; task.obs_dim()];
    task.observe(&env, &st, &terrain, &mut rng, &mut obs)
        .unwrap();
    assert_eq!(&obs[48..], &[0.0, 1.0], "phase 0 at the episode's start");
    // Step 1 lands at phase 0.04 (first half): FR + RL should swing.
    st.foot_force = [40.0, 0.0, 0.0, 40.0];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert!((r.terms[RewardTerm::GaitClock as usize] - 0.8 * 0.02).abs() < 1e-7);
    task.observe(&env, &st, &terrain, &mut rng, &mut obs)
        .unwrap();
    let want = gait_clock_observation(0.04);
    assert!((obs[48] - want[0]).abs() < 1e-6 && (obs[49] - want[1]).abs() < 1e-6);
    // Thirteen steps in (phase 0.52) the same contacts are all wrong.
    for _ in 0..12 {
        task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    }
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::GaitClock as usize], 0.0);
    // Not commanded to move: no clock reward.
    env.command.vx = 0.0;
    st.foot_force = [0.0, 40.0, 40.0, 0.0];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::GaitClock as usize], 0.0);
}

#[test]
fn a_clock_started_half_a_period_late_swaps_the_diagonal_pairs() {
    let (task, terrain) = clocked_flat_task(|cfg| cfg.gait_clock_start = 0.5);
    let mut rng = StdRng::seed_from_u64(3);
    let st = standing_state();
    let mut env = commanded_half_speed(&task, &st, &mut rng);
    let mut obs = vec![0.0; task.obs_dim()];
    task.observe(&env, &st, &terrain, &mut rng, &mut obs)
        .unwrap();
    assert!(
        obs[48].abs() < 1e-6 && (obs[49] + 1.0).abs() < 1e-6,
        "{:?}",
        &obs[48..]
    );
    assert_eq!(
        gait_clock_stance(task.gait_phase(&env)),
        [false, true, true, false]
    );
    // 13 steps later (0.52 of a period) the phase wraps to 0.02.
    for _ in 0..13 {
        task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    }
    assert!((task.gait_phase(&env) - 0.02).abs() < 1e-5);
    let mut bad = crate::config::EnvConfig::default();
    bad.gait_clock_start = 1.0;
    assert!(bad.resolve("a1").is_err());
}

#[test]
fn feet_clearance_matches_hand_computation() {
    // Peak at mid-swing, zero at lift-off and touch-down, zero for stance feet.
    assert_eq!(gait_clock_swing_height(0.25, 0.08), [0.0, 0.08, 0.08, 0.0]);
    assert_eq!(gait_clock_swing_height(0.75, 0.08), [0.08, 0.0, 0.0, 0.08]);
    assert_eq!(gait_clock_swing_height(0.0, 0.08), [0.0; 4]);
    let h = gait_clock_swing_height(0.1, 0.08);
    assert!((h[1] - 0.08 * (0.2 * std::f32::consts::PI).sin()).abs() < 1e-7);

    let (task, terrain) = clocked_flat_task(|cfg| cfg.rewards.feet_clearance = Some(-30.0));
    let mut rng = StdRng::seed_from_u64(3);
    let mut st = standing_state();
    let mut env = commanded_half_speed(&task, &st, &mut rng);
    // Step 1 lands at phase 0.04: FR + RL swing towards 0.25 × standing height × sin(0.08π).
    // FR's sole is 1 cm up (short by the rest), RL's is above its target (no penalty), and
    // the stance feet sink 5 mm into the ground (not penalised: the term is about swing).
    let peak = 0.25 * task.robot.standing_height;
    let target = peak * (0.08 * std::f32::consts::PI).sin();
    st.foot_sole = [
        [0.2, 0.15, -0.005],
        [0.2, -0.15, 0.01],
        [-0.2, 0.15, target + 0.02],
        [-0.2, -0.15, -0.005],
    ];
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    let want = -30.0 * (target - 0.01).powi(2) * 0.02;
    let got = r.terms[RewardTerm::FeetClearance as usize];
    assert!(want < 0.0 && (got - want).abs() < 1e-8, "{got} vs {want}");
    // Not commanded to move: no clearance asked.
    env.command.vx = 0.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::FeetClearance as usize], 0.0);
}

#[test]
fn actuator_randomisation_honours_its_ranges_and_pins() {
    let mut cfg = EnvConfig::default();
    cfg.terrain.preset = TerrainPreset::Flat;
    let task = Task::new(cfg.resolve("a1").unwrap(), a1_params()).unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    let draws: Vec<BodyRandomization> = (0..2000)
        .map(|_| task.sample_body_randomization(&mut rng))
        .collect();
    let range = |f: fn(&BodyRandomization) -> f32| {
        let lo = draws.iter().map(f).fold(f32::INFINITY, f32::min);
        let hi = draws.iter().map(f).fold(f32::NEG_INFINITY, f32::max);
        (lo, hi)
    };
    // Inside the configured ranges and spread over them (not pinned at one end).
    for (name, (lo, hi), want) in [
        ("joint_damping", range(|b| b.joint_damping), [0.0, 2.0]),
        ("joint_friction", range(|b| b.joint_friction), [0.0, 0.3]),
        ("motor_strength", range(|b| b.motor_strength), [0.85, 1.15]),
        ("kp_scale", range(|b| b.kp_scale), [0.85, 1.15]),
        ("kd_scale", range(|b| b.kd_scale), [0.85, 1.15]),
        ("latency_s", range(|b| b.latency_s), [0.0, 0.02]),
        ("static_friction", range(|b| b.static_friction), [0.4, 1.25]),
    ] {
        let span = want[1] - want[0];
        assert!(
            lo >= want[0] && hi <= want[1],
            "{name}: [{lo}, {hi}] outside {want:?}"
        );
        assert!(
            lo < want[0] + 0.05 * span && hi > want[1] - 0.05 * span,
            "{name}: [{lo}, {hi}]"
        );
    }
    assert!(
        draws
            .iter()
            .all(|b| b.dynamic_friction <= b.static_friction)
    );
    // A pin (what `l3p eval --joint-damping 2` writes) gives that value every time.
    cfg.randomization.joint_damping = Some([2.0, 2.0]);
    let task = Task::new(cfg.resolve("a1").unwrap(), a1_params()).unwrap();
    assert!((0..100).all(|_| task.sample_body_randomization(&mut rng).joint_damping == 2.0));
}

#[test]
fn action_rate_penalises_the_mean_not_the_exploration_noise() {
    let (task, terrain) = flat_task("a1");
    let w = task.spec.rewards.action_rate_l2;
    let dt = 0.02;
    let mut rng = StdRng::seed_from_u64(4);
    let st = standing_state();
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    // A constant mean of 0.2 with noisy samples: only the first step's change (0 → 0.2) counts.
    let mean = [0.2; 12];
    let r1 = task.evaluate_with_mean(&mut env, &st, &[0.9; 12], Some(&mean), &terrain);
    let want = w * 12.0 * 0.04 * dt;
    assert!((r1.terms[RewardTerm::ActionRateL2 as usize] - want).abs() < 1e-7);
    let r2 = task.evaluate_with_mean(&mut env, &st, &[-0.7; 12], Some(&mean), &terrain);
    assert_eq!(r2.terms[RewardTerm::ActionRateL2 as usize], 0.0);
    // The observation still sees the applied (sampled) action.
    assert_eq!(env.last_action, [-0.7; 12]);
    // Without means the sampled action counts, against the last mean (0.2 → 0.5).
    let r3 = task.evaluate(&mut env, &st, &[0.5; 12], &terrain);
    let want = w * 12.0 * (0.5f32 - 0.2).powi(2) * dt;
    assert!((r3.terms[RewardTerm::ActionRateL2 as usize] - want).abs() < 1e-6);
}

#[test]
fn with_an_action_filter_the_rate_penalty_follows_the_filtered_mean() {
    let (mut task, terrain) = flat_task("a1");
    task.spec.action_filter_alpha = 0.5;
    let w = task.spec.rewards.action_rate_l2;
    let dt = 0.02;
    let mut rng = StdRng::seed_from_u64(4);
    let st = standing_state();
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    // A mean step 0 → 0.4 reaches the targets as 0.2, then 0.3: rates 0.2² and 0.1².
    let mean = [0.4; 12];
    let r1 = task.evaluate_with_mean(&mut env, &st, &[0.0; 12], Some(&mean), &terrain);
    let want = w * 12.0 * 0.04 * dt;
    assert!((r1.terms[RewardTerm::ActionRateL2 as usize] - want).abs() < 1e-7);
    let r2 = task.evaluate_with_mean(&mut env, &st, &[0.0; 12], Some(&mean), &terrain);
    let want = w * 12.0 * 0.01 * dt;
    assert!((r2.terms[RewardTerm::ActionRateL2 as usize] - want).abs() < 1e-7);
    assert!((env.last_mean_action[0] - 0.3).abs() < 1e-6);
}

#[test]
fn action_smoothness_is_zero_on_a_ramp_and_large_on_a_flip() {
    let mut cfg = EnvConfig::default(); // the l3p recipe
    cfg.terrain.preset = TerrainPreset::Flat;
    let spec = cfg.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let task = Task::new(spec, a1_params()).unwrap();
    let ws = task.spec.rewards.action_smoothness_l2;
    assert_eq!(ws, -0.1);
    let dt = 0.02;
    let mut rng = StdRng::seed_from_u64(5);
    let st = standing_state();
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    let smooth = |env: &mut TaskEnvState, m: f32| {
        let r = task.evaluate_with_mean(env, &st, &[0.0; 12], Some(&[m; 12]), &terrain);
        r.terms[RewardTerm::ActionSmoothnessL2 as usize]
    };
    // The first two steps of an episode have no second difference yet.
    assert_eq!(smooth(&mut env, 0.2), 0.0);
    assert_eq!(smooth(&mut env, 0.4), 0.0);
    // A ramp (0.2, 0.4, 0.6) is smooth however fast; a flip back (0.4, 0.6, 0.2) is not:
    // second difference 0.2 − 1.2 + 0.4 = −0.6 per joint.
    assert!(smooth(&mut env, 0.6).abs() < 1e-9);
    let want = ws * 12.0 * 0.36 * dt;
    assert!((smooth(&mut env, 0.2) - want).abs() < 1e-6);
}

#[test]
fn feet_air_time_on_touchdown() {
    let (task, terrain) = flat_task("a1");
    let w = task.spec.rewards.feet_air_time; // 0.25 on the A1 flat table
    let dt = 0.02;
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    let mut rng = StdRng::seed_from_u64(1);
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    env.command = Command {
        vx: 1.0,
        time_left: 100.0,
        ..Default::default()
    };
    // foot 0 in the air for 29 steps, touches down on the 30th: air time 0.6 s
    st.foot_force[0] = 0.0;
    for _ in 0..29 {
        let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
        assert_eq!(r.terms[RewardTerm::FeetAirTime as usize], 0.0);
    }
    st.foot_force[0] = 20.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert!((env.last_air_time[0] - 0.6).abs() < 1e-5);
    let got = r.terms[RewardTerm::FeetAirTime as usize];
    assert!((got - w * dt * 0.1).abs() < 1e-6, "{got}");
    // next step in contact: no reward
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::FeetAirTime as usize], 0.0);
    // a short (0.2 s) swing is penalised: 0.2 - 0.5 = -0.3
    st.foot_force[2] = 0.0;
    for _ in 0..9 {
        task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    }
    st.foot_force[2] = 20.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert!((r.terms[RewardTerm::FeetAirTime as usize] + w * dt * 0.3).abs() < 1e-6);
    // zero with a small command
    env.command.vx = 0.05;
    st.foot_force[2] = 0.0;
    for _ in 0..30 {
        task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    }
    st.foot_force[2] = 20.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.terms[RewardTerm::FeetAirTime as usize], 0.0);
}

#[test]
fn terminations_and_timeout() {
    let (task, terrain) = flat_task("a1");
    let mut rng = StdRng::seed_from_u64(1);
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    for i in 0..1000 {
        let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
        if i < 999 {
            assert!(!r.done());
        } else {
            assert!(r.truncated && !r.terminated);
            assert_eq!(r.reason, DoneReason::TimeOut);
        }
    }
    let sum = task.finish_episode(&env, &st);
    assert_eq!(sum.length, 1000);
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    st.base_force = 2.0;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert!(r.terminated && !r.truncated);
    assert_eq!(r.reason, DoneReason::BaseContact);
    st.base_force = 0.0;
    let s = std::f32::consts::FRAC_1_SQRT_2;
    st.base_quat = [s, s, 0.0, 0.0]; // rolled 90°
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert_eq!(r.reason, DoneReason::Tilt);
    st.base_quat = [1.0, 0.0, 0.0, 0.0];
    st.joint_vel[3] = f32::NAN;
    let r = task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    assert!(r.terminated);
    assert_eq!(r.reason, DoneReason::NonFinite);
    assert_eq!(r.reward, 0.0);
}

#[test]
fn observation_layout_and_noise() {
    let (mut task, terrain) = flat_task("a1");
    task.spec.noise.enabled = false;
    let mut rng = StdRng::seed_from_u64(1);
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
    env.command = Command {
        vx: 0.5,
        vy: -0.25,
        wz: 0.1,
        ..Default::default()
    };
    env.last_action = [0.7; 12];
    let yaw: f32 = 1.0;
    st.base_quat = quat_from_yaw(yaw);
    st.base_lin_vel_w = [yaw.cos(), yaw.sin(), 0.1]; // 1 m/s forward in base frame
    st.base_ang_vel_w = [0.0, 0.0, 0.4];
    st.joint_pos[5] += 0.2;
    st.joint_vel[7] = -3.0;
    let mut obs = vec![0.0; task.obs_dim()];
    assert_eq!(obs.len(), 235);
    task.observe(&env, &st, &terrain, &mut rng, &mut obs)
        .unwrap();
    let close = |a: f32, b: f32| (a - b).abs() < 1e-5;
    assert!(
        close(obs[0], 1.0) && close(obs[1], 0.0) && close(obs[2], 0.1),
        "{:?}",
        &obs[..3]
    );
    assert!(close(obs[5], 0.4));
    assert!(close(obs[8], -1.0));
    assert_eq!(&obs[9..12], &[0.5, -0.25, 0.1]);
    assert!(close(obs[12 + 5], 0.2));
    assert!(
        obs[12..24]
            .iter()
            .enumerate()
            .all(|(i, v)| i == 5 || v.abs() < 1e-6)
    );
    assert_eq!(obs[24 + 7], -3.0);
    assert!(obs[36..48].iter().all(|v| *v == 0.7));
    // base 0.3 m above flat ground: 0.3 - 0 - 0.5 = -0.2
    assert!(obs[48..].iter().all(|v| close(*v, -0.2)));
    // high above the ground the scan clips at 1
    st.base_pos[2] = 5.0;
    task.observe(&env, &st, &terrain, &mut rng, &mut obs)
        .unwrap();
    assert!(obs[48..].iter().all(|v| *v == 1.0));
    // wrong length is an error
    let mut short = vec![0.0; 48];
    assert!(
        task.observe(&env, &st, &terrain, &mut rng, &mut short)
            .is_err()
    );
    // noise stays within its bounds and is not zero
    task.spec.noise.enabled = true;
    st.base_pos[2] = 0.3;
    let mut clean = vec![0.0; 235];
    task.spec.noise.enabled = false;
    task.observe(&env, &st, &terrain, &mut rng, &mut clean)
        .unwrap();
    task.spec.noise.enabled = true;
    let bounds: Vec<f32> = [[0.1f32; 3], [0.2; 3], [0.05; 3], [0.0; 3]]
        .concat()
        .into_iter()
        .chain([0.01f32; 12])
        .chain([1.5f32; 12])
        .chain([0.0f32; 12])
        .chain([0.1f32; 187])
        .collect();
    let mut moved = 0;
    for _ in 0..20 {
        task.observe(&env, &st, &terrain, &mut rng, &mut obs)
            .unwrap();
        for i in 0..235 {
            let d = (obs[i] - clean[i]).abs();
            assert!(d <= bounds[i] + 1e-6, "obs {i}: {d} > {}", bounds[i]);
            moved += (d > 0.0) as usize;
        }
    }
    assert!(moved > 20 * 150);
}

#[test]
fn the_action_filter_is_an_exponential_moving_average_of_the_clipped_action() {
    let (mut task, _) = flat_task("a1");
    task.spec.action_filter_alpha = 0.25;
    let (mut a, mut q) = ([0.0; 12], [0.0; 12]);
    let mut previous = [0.0f32; 12];
    previous[1] = 0.8;
    let mut raw = [1.0f32; 12];
    raw[1] = 1e9; // clipped to 100 before filtering
    raw[2] = f32::NAN; // treated as 0
    task.process_action(&raw, &previous, &mut a, &mut q)
        .unwrap();
    assert!((a[0] - 0.25).abs() < 1e-6);
    assert!((a[1] - (0.8 + 0.25 * (100.0 - 0.8))).abs() < 1e-4);
    assert_eq!(a[2], 0.0);
    assert!((q[0] - (0.1 + 0.25 * 0.25)).abs() < 1e-6);
    // A step input converges geometrically: 1 − (1 − α)^n after n steps.
    let mut prev = [0.0; 12];
    for _ in 0..4 {
        task.process_action(&[1.0; 12], &prev, &mut a, &mut q)
            .unwrap();
        prev = a;
    }
    assert!((a[5] - (1.0 - 0.75f32.powi(4))).abs() < 1e-6);
    // A flip every step is attenuated to α / (2 − α) of its amplitude in steady state.
    let mut prev = [0.0; 12];
    let mut sign = 1.0;
    for _ in 0..60 {
        task.process_action(&[sign; 12], &prev, &mut a, &mut q)
            .unwrap();
        prev = a;
        sign = -sign;
    }
    assert!((a[7].abs() - 0.25 / 1.75).abs() < 1e-5);
}

#[test]
fn actions_targets_and_reset_sampling() {
    let (task, terrain) = flat_task("a1");
    let mut a = [0.0; 12];
    let mut q = [0.0; 12];
    let mut raw = [1.0f32; 12];
    raw[2] = f32::NAN;
    raw[3] = 1e9;
    let bad = task
        .process_action(&raw, &[0.0; 12], &mut a, &mut q)
        .unwrap();
    assert_eq!(bad, 1);
    assert_eq!(a[2], 0.0);
    assert_eq!(a[3], 100.0);
    assert!((q[0] - (0.1 + 0.25)).abs() < 1e-6);
    assert_eq!(q[2], -1.5);
    assert!(
        task.process_action(&raw[..5], &[0.0; 12], &mut a, &mut q)
            .is_err()
    );
    let mut rng = StdRng::seed_from_u64(2);
    // A1 (IsaacLab): default pose, zero velocities, xy within ±0.5, any yaw
    for _ in 0..50 {
        let s = task.sample_reset([4.0, -4.0, 0.0], &terrain, &mut rng);
        assert_eq!(s.joint_pos, A1_DEFAULT);
        assert_eq!(s.lin_vel, [0.0; 3]);
        assert!((s.base_xy[0] - 4.0).abs() <= 0.5 && (s.base_xy[1] + 4.0).abs() <= 0.5);
        let b = task.sample_body_randomization(&mut rng);
        assert!((-1.0..=3.0).contains(&b.added_base_mass));
        assert_eq!((b.static_friction, b.dynamic_friction), (0.8, 0.6));
    }
    // A1 has no pushes; ANYmal pushes every 10–15 s
    let mut env = TaskEnvState::new();
    task.reset_env(&mut env, &standing_state(), [0.0; 3], &mut rng);
    assert!((0..2000).all(|_| task.push_due(&mut env, &mut rng).is_none()));
    let spec = EnvConfig::default().resolve("anymal_c").unwrap();
    let task = Task::new(spec, a1_params()).unwrap();
    task.reset_env(&mut env, &standing_state(), [0.0; 3], &mut rng);
    let mut pushes = Vec::new();
    for i in 0..3000 {
        if let Some(v) = task.push_due(&mut env, &mut rng) {
            assert!(v[0].abs() <= 0.5 && v[1].abs() <= 0.5);
            pushes.push(i);
        }
    }
    assert!(pushes.len() >= 3 && pushes.len() <= 6, "{pushes:?}");
    assert!(
        pushes
            .windows(2)
            .all(|w| (499..=751).contains(&(w[1] - w[0]))),
        "{pushes:?}"
    );
    // ANYmal-style reset: joint positions scaled by U(0.5, 1.5), clamped to soft limits
    let s = task.sample_reset([0.0; 3], &terrain, &mut rng);
    let soft = task.soft_limits();
    assert!(
        s.joint_pos
            .iter()
            .zip(soft)
            .all(|(q, l)| *q >= l[0] && *q <= l[1])
    );
}

#[test]
fn episode_summary_tracks_errors_and_distance() {
    let (task, terrain) = flat_task("a1");
    let mut rng = StdRng::seed_from_u64(1);
    let mut env = TaskEnvState::new();
    let mut st = standing_state();
    task.reset_env(&mut env, &st, [1.0, 2.0, 0.0], &mut rng);
    env.command = Command {
        vx: 1.0,
        wz: 0.5,
        time_left: 100.0,
        ..Default::default()
    };
    st.base_lin_vel_w = [0.6, 0.0, 0.0];
    st.base_ang_vel_w = [0.0, 0.0, 0.2];
    for _ in 0..10 {
        task.evaluate(&mut env, &st, &[0.0; 12], &terrain);
    }
    st.base_pos = [4.0, 6.0, 0.3];
    let s = task.finish_episode(&env, &st);
    assert_eq!(s.length, 10);
    assert!((s.mean_lin_vel_error - 0.4).abs() < 1e-5);
    assert!((s.mean_yaw_rate_error - 0.3).abs() < 1e-5);
    assert!((s.distance - 5.0).abs() < 1e-5);
    assert!((s.command_xy_norm - 1.0).abs() < 1e-6);
    let total: f32 = s.terms.iter().sum();
    assert!((total - s.ret).abs() < 1e-5);
}
