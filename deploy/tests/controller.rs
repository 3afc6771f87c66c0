//! The deploy controller tick by tick (no I/O, injected clock): observations equal training's, the
//! start-up sequence, every watchdog path, latched damping and the soft-limit clip; and artifact
//! checks refuse what does not fit the robot.

use l3p_deploy::controller::{Latest, PolicyFn};
use l3p_deploy::observation::standing_state;
use l3p_deploy::{Controller, Fault, ObservationBuilder, SafetyConfig, load_policy};
use l3p_policy::RobotIo;
use l3p_proto::{ControlMode, OperatorAction, RobotState};
use l3p_robot::catalog::RobotSpec;
use l3p_task::config::{EnvConfig, GainsOverride, TerrainPreset};
use l3p_task::contract::robot_io;
use l3p_task::task::{
    RobotTaskParams, Task, TaskEnvState, quat_from_yaw_and_tilt, quat_rotate_inverse,
};
use l3p_task::terrain::Terrain;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const DT: f64 = 0.02;

fn a1() -> &'static RobotSpec {
    RobotSpec::by_name("a1").unwrap()
}

fn flat_env() -> EnvConfig {
    let mut env = EnvConfig::default();
    env.height_scan = false;
    env.terrain.preset = TerrainPreset::Flat;
    env
}

fn a1_io() -> RobotIo {
    robot_io(a1(), &flat_env()).unwrap()
}

fn standing(io: &RobotIo) -> RobotState {
    RobotState {
        seq: 1,
        command: [0.5, 0.0, 0.0],
        ..standing_state(io, "dog")
    }
}

/// One tick at `t` with `state` received at `received_at`.
fn tick_at(
    c: &mut Controller,
    t: f64,
    state: &RobotState,
    received_at: f64,
    policy: &mut dyn PolicyFn,
) -> l3p_deploy::controller::TickOutput {
    c.tick(t, Some(Latest { state, received_at }), policy)
}

/// A policy returning a fixed action (or NaN), counting its calls.
struct Fixed {
    action: f32,
    calls: usize,
}

impl PolicyFn for Fixed {
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        assert_eq!(obs.len(), 48);
        self.calls += 1;
        action.iter_mut().for_each(|a| *a = self.action);
    }
}

#[test]
fn observation_matches_the_training_task() {
    observation_matches_with_clock(0.0);
}

#[test]
fn observation_with_a_gait_clock_matches_the_training_task() {
    observation_matches_with_clock(2.0);
}

fn observation_matches_with_clock(gait_clock_hz: f32) {
    let mut env = flat_env();
    env.gait_clock_hz = gait_clock_hz;
    let robot = a1();
    let spec = env.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let mut task = Task::new(spec, RobotTaskParams::of(robot, &robot.model().unwrap())).unwrap();
    task.spec.noise.enabled = false;
    let io = robot_io(robot, &env).unwrap();
    let builder = ObservationBuilder::new(&io).unwrap();
    let dim = builder.obs_dim();
    assert_eq!(dim, task.obs_dim());
    let mut rng = StdRng::seed_from_u64(3);
    for _ in 0..20 {
        let mut sim = l3p_task::task::SimState::default();
        let yaw = rng.random_range(-3.0..3.0);
        // Some roll and pitch too.
        let (r, p) = (
            rng.random_range(-0.3f32..0.3),
            rng.random_range(-0.3f32..0.3),
        );
        sim.base_quat = quat_from_yaw_and_tilt(yaw, r, p);
        for k in 0..3 {
            sim.base_lin_vel_w[k] = rng.random_range(-1.0..1.0);
            sim.base_ang_vel_w[k] = rng.random_range(-2.0..2.0);
        }
        for j in 0..12 {
            sim.joint_pos[j] = io.default_joint_pos[j] + rng.random_range(-0.5..0.5);
            sim.joint_vel[j] = rng.random_range(-10.0..10.0);
        }
        let mut env_state = TaskEnvState::new();
        env_state.command.vx = rng.random_range(-1.0..1.0);
        env_state.command.vy = rng.random_range(-1.0..1.0);
        env_state.command.wz = rng.random_range(-1.0..1.0);
        for a in &mut env_state.last_action {
            *a = rng.random_range(-2.0..2.0);
        }
        // Training counts the clock in episode steps, the controller in policy ticks.
        let ticks: u32 = rng.random_range(0..5000);
        env_state.episode.steps = ticks;
        let mut expected = vec![0.0; dim];
        task.observe(&env_state, &sim, &terrain, &mut rng, &mut expected)
            .unwrap();

        // What a robot bridge sends: velocities in the base frame.
        let wire = RobotState {
            base_quat: sim.base_quat,
            base_lin_vel: quat_rotate_inverse(sim.base_quat, sim.base_lin_vel_w),
            base_ang_vel: quat_rotate_inverse(sim.base_quat, sim.base_ang_vel_w),
            joint_pos: sim.joint_pos.to_vec(),
            joint_vel: sim.joint_vel.to_vec(),
            command: env_state.command.as_array(),
            ..standing(&io)
        };
        let mut got = vec![0.0; dim];
        builder.build(&wire, &env_state.last_action, ticks as u64, &mut got);
        for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
            assert!((g - e).abs() < 1e-5, "obs[{i}]: deploy {g} vs training {e}");
        }
    }
}

/// A policy flipping between ±`amplitude` every call: the worst chatter.
struct Flipping {
    amplitude: f32,
}

impl PolicyFn for Flipping {
    fn act(&mut self, _obs: &[f32], action: &mut [f32]) {
        self.amplitude = -self.amplitude;
        action.iter_mut().for_each(|a| *a = self.amplitude);
    }
}

#[test]
fn policy_targets_follow_the_training_action_filter() {
    let mut env = flat_env();
    env.action_filter_alpha = 0.4;
    let io = robot_io(a1(), &env).unwrap();
    assert_eq!(io.action_filter_alpha, 0.4);
    let spec = env.resolve("a1").unwrap();
    let robot = a1();
    let task = Task::new(spec, RobotTaskParams::of(robot, &robot.model().unwrap())).unwrap();
    let mut c = Controller::new("dog", io.clone(), 0.25, SafetyConfig::default()).unwrap();
    let mut policy = Flipping { amplitude: -0.6 };
    let state = standing(&io);
    let mut targets = Vec::new();
    let mut t = 0.0;
    while targets.len() < 6 {
        t += DT;
        let out = tick_at(&mut c, t, &state, t - 0.005, &mut policy);
        if out.command.mode == ControlMode::Policy {
            targets.push(out.command.joint_pos_target);
        }
    }
    // The training task fed the same raw outputs (first call +0.6 after the flip, then ±).
    let (mut previous, mut action, mut expected) = ([0.0; 12], [0.0; 12], [0.0; 12]);
    let mut amplitude = -0.6f32;
    for got in &targets {
        amplitude = -amplitude;
        task.process_action(&[amplitude; 12], &previous, &mut action, &mut expected)
            .unwrap();
        previous = action;
        for j in 0..12 {
            assert!(
                (got[j] - expected[j]).abs() < 1e-5,
                "joint {j}: {} vs {}",
                got[j],
                expected[j]
            );
        }
    }
    // Filtered: the target change is far below the unfiltered 2 × 0.6 × 0.25 = 0.3 rad flip.
    let change = (targets[5][1] - targets[4][1]).abs();
    assert!(change < 0.2, "target change {change}");
}

#[test]
fn a_contract_from_a_newer_l3p_is_refused_and_older_ones_read_as_unfiltered_and_clockless() {
    let io = a1_io();
    let mut json = serde_json::to_value(&io).unwrap();
    assert_eq!(json["version"], 3);
    json["version"] = 4.into();
    let newer: RobotIo = serde_json::from_value(json.clone()).unwrap();
    let err = newer.check(48, 12).unwrap_err();
    assert!(err.contains("io.version 4"), "{err}");
    let map = json.as_object_mut().unwrap();
    map.insert("version".into(), 2.into());
    map.remove("gait_clock_hz");
    let v2: RobotIo = serde_json::from_value(json.clone()).unwrap();
    assert_eq!((v2.version, v2.gait_clock_hz), (2, 0.0));
    v2.check(48, 12).unwrap();
    let map = json.as_object_mut().unwrap();
    map.remove("version");
    map.remove("action_filter_alpha");
    let old: RobotIo = serde_json::from_value(json).unwrap();
    assert_eq!((old.version, old.action_filter_alpha), (1, 1.0));
    old.check(48, 12).unwrap();
}

#[test]
fn a_clock_without_its_observation_segment_is_refused() {
    let mut env = flat_env();
    env.gait_clock_hz = 2.0;
    let io = robot_io(a1(), &env).unwrap();
    io.check(50, 12).unwrap();
    let mut no_segment = io.clone();
    no_segment.obs_layout.retain(|s| s.name != "gait_clock");
    let err = no_segment.check(48, 12).unwrap_err();
    assert!(err.contains("gait_clock"), "{err}");
    let mut no_clock = io;
    no_clock.gait_clock_hz = 0.0;
    assert!(no_clock.check(50, 12).is_err());
}

/// Records the gait-clock entries (the last two) of every observation.
struct ClockReader {
    seen: Vec<[f32; 2]>,
}

impl PolicyFn for ClockReader {
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        self.seen.push([obs[obs.len() - 2], obs[obs.len() - 1]]);
        action.iter_mut().for_each(|a| *a = 0.0);
    }
}

#[test]
fn the_gait_clock_starts_at_phase_zero_when_the_policy_takes_over_and_advances_per_tick() {
    let mut env = flat_env();
    env.gait_clock_hz = 2.0;
    let io = robot_io(a1(), &env).unwrap();
    let mut c = Controller::new("dog", io.clone(), 0.25, SafetyConfig::default()).unwrap();
    let mut policy = ClockReader { seen: Vec::new() };
    let state = standing(&io);
    let mut t = 0.0;
    while policy.seen.len() < 26 {
        t += DT;
        tick_at(&mut c, t, &state, t - 0.005, &mut policy);
    }
    // 2 Hz at 50 Hz: 25 ticks per period, a quarter period = 6.25 ticks.
    let tau = std::f32::consts::TAU;
    for (k, seen) in policy.seen.iter().enumerate() {
        let phase = (k as f32 * 2.0 * 0.02).fract();
        let want = [(tau * phase).sin(), (tau * phase).cos()];
        assert!(
            (seen[0] - want[0]).abs() < 1e-4 && (seen[1] - want[1]).abs() < 1e-4,
            "tick {k}: {seen:?} vs {want:?}"
        );
    }
    assert!((policy.seen[0][1] - 1.0).abs() < 1e-6);
    assert!((policy.seen[25][1] - 1.0).abs() < 1e-4, "one period later");
}

/// A policy recording the velocity command it observes (entries 9..12 of the 48).
struct CommandReader {
    seen: Vec<[f32; 3]>,
}

impl PolicyFn for CommandReader {
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        self.seen.push([obs[9], obs[10], obs[11]]);
        action.iter_mut().for_each(|a| *a = 0.0);
    }
}

#[test]
fn heading_hold_turns_a_zero_yaw_command_into_the_way_back_to_the_held_heading() {
    let io = a1_io();
    let mut state = standing(&io);
    let run = |hold: bool, state: &mut RobotState| {
        let c = Controller::new("dog", io.clone(), 0.25, SafetyConfig::default()).unwrap();
        let mut c = if hold { c.with_heading_hold() } else { c };
        let mut policy = CommandReader { seen: Vec::new() };
        let mut t = 0.0;
        state.base_quat = quat_from_yaw_and_tilt(0.3, 0.0, 0.0);
        while policy.seen.is_empty() {
            t += DT;
            tick_at(&mut c, t, state, t - 0.005, &mut policy);
        }
        // the base has yawed 0.2 rad left of where the policy took over
        state.base_quat = quat_from_yaw_and_tilt(0.5, 0.0, 0.0);
        t += DT;
        tick_at(&mut c, t, state, t - 0.005, &mut policy);
        policy.seen
    };
    let held = run(true, &mut state);
    assert_eq!(held[0], [0.5, 0.0, 0.0]);
    assert!((held[1][2] + 0.1).abs() < 1e-5, "{:?}", held[1]);
    assert_eq!(held[1][0], 0.5);
    // without the hold the policy sees the operator's command as sent
    let plain = run(false, &mut state);
    assert_eq!(plain[1], [0.5, 0.0, 0.0]);
}

#[test]
fn startup_goes_zero_torque_then_ramp_then_policy() {
    let io = a1_io();
    let safety = SafetyConfig::default();
    let mut c = Controller::new("dog", io.clone(), 0.25, safety.clone()).unwrap();
    let mut policy = Fixed {
        action: 0.4,
        calls: 0,
    };
    // No state yet: limp commands, no inference.
    let out = c.tick(0.0, None, &mut policy);
    assert_eq!(out.command.mode, ControlMode::ZeroTorque);
    assert!(
        out.command
            .kp
            .iter()
            .chain(&out.command.kd)
            .all(|g| *g == 0.0)
    );

    let mut lying = standing(&io);
    lying.joint_pos = io
        .soft_joint_limits
        .iter()
        .map(|l| 0.8 * l[1] + 0.2 * l[0])
        .collect();
    let mut t = 0.0;
    let mut modes = Vec::new();
    let mut first_ramp_target = None;
    let mut last_ramp_target = None;
    while t < 3.0 {
        t += DT;
        let latest = Latest {
            state: &lying,
            received_at: t - 0.005,
        };
        let out = c.tick(t, Some(latest), &mut policy);
        if out.command.mode == ControlMode::Ramp {
            first_ramp_target.get_or_insert(out.command.joint_pos_target.clone());
            last_ramp_target = Some(out.command.joint_pos_target.clone());
            assert_eq!(out.command.kp, io.kp);
        }
        if modes.last() != Some(&out.command.mode) {
            modes.push(out.command.mode);
        }
    }
    assert_eq!(
        modes,
        [
            ControlMode::ZeroTorque,
            ControlMode::Ramp,
            ControlMode::Policy
        ]
    );
    // The ramp starts at the measured pose and ends at the default pose.
    let first = first_ramp_target.unwrap();
    let last = last_ramp_target.unwrap();
    for j in 0..12 {
        assert!((first[j] - lying.joint_pos[j]).abs() < 0.05, "joint {j}");
        assert!(
            (last[j] - io.default_joint_pos[j]).abs() < 0.05,
            "joint {j}"
        );
    }
    assert!(policy.calls > 0);
}

/// A controller already in policy mode at `t`.
fn in_policy(io: &RobotIo, policy: &mut Fixed) -> (Controller, f64) {
    let mut c = Controller::new("dog", io.clone(), 0.25, SafetyConfig::default()).unwrap();
    let state = standing(io);
    let mut t = 0.0;
    while c.mode() != ControlMode::Policy {
        t += DT;
        tick_at(&mut c, t, &state, t, policy);
        assert!(t < 10.0, "never reached policy mode");
    }
    (c, t)
}

#[test]
fn policy_targets_are_scaled_and_clipped_to_soft_limits() {
    let io = a1_io();
    let mut policy = Fixed {
        action: 0.4,
        calls: 0,
    };
    let (mut c, t) = in_policy(&io, &mut policy);
    let state = standing(&io);
    let out = tick_at(&mut c, t + DT, &state, t + DT, &mut policy);
    assert_eq!(out.command.mode, ControlMode::Policy);
    for j in 0..12 {
        let want = (io.default_joint_pos[j] + 0.25 * 0.4)
            .clamp(io.soft_joint_limits[j][0], io.soft_joint_limits[j][1]);
        assert!((out.command.joint_pos_target[j] - want).abs() < 1e-6);
    }
    // The last action is fed back into the next observation.
    let obs = c.last_observation();
    assert!(obs[36..48].iter().all(|a| (*a - 0.4).abs() < 1e-6));
    // A huge action is clipped to ±action_clip, then to the soft limits.
    policy.action = 1e9;
    let out = tick_at(&mut c, t + 2.0 * DT, &state, t + 2.0 * DT, &mut policy);
    assert_eq!(out.command.mode, ControlMode::Policy);
    for j in 0..12 {
        let [lo, hi] = io.soft_joint_limits[j];
        let q = out.command.joint_pos_target[j];
        assert!(q >= lo && q <= hi, "joint {j}: {q} outside [{lo}, {hi}]");
    }
}

#[test]
fn stale_state_damps_within_three_periods_and_stays_damped() {
    let io = a1_io();
    let mut policy = Fixed {
        action: 0.0,
        calls: 0,
    };
    let (mut c, t0) = in_policy(&io, &mut policy);
    let state = standing(&io);
    let last_state_at = t0;
    let mut policy_ticks_after = 0;
    let mut t = t0;
    let damped_at = loop {
        t += DT;
        let out = tick_at(&mut c, t, &state, last_state_at, &mut policy);
        match out.command.mode {
            ControlMode::Policy => policy_ticks_after += 1,
            ControlMode::Damping => {
                assert!(matches!(out.new_fault, Some(Fault::StaleState { .. })));
                assert!(out.command.kp.iter().all(|k| *k == 0.0));
                assert!(out.command.kd.iter().all(|k| *k > 0.0));
                break t;
            }
            m => panic!("unexpected mode {m:?}"),
        }
    };
    assert!(
        policy_ticks_after <= 3,
        "{policy_ticks_after} policy ticks on a stale state"
    );
    assert!(damped_at - last_state_at <= 4.0 * DT + 1e-9);
    // Fresh states again: still damping (latched) until the operator resumes.
    for k in 1..20 {
        let now = damped_at + k as f64 * DT;
        let out = tick_at(&mut c, now, &state, now, &mut policy);
        assert_eq!(out.command.mode, ControlMode::Damping);
    }
    let now = damped_at + 20.0 * DT;
    let fresh = Latest {
        state: &state,
        received_at: now,
    };
    c.operator(OperatorAction::Resume, now, Some(fresh))
        .unwrap();
    assert_eq!(c.mode(), ControlMode::Ramp);
    assert!(c.fault().is_none());
}

#[test]
fn resume_is_refused_while_the_cause_persists() {
    let io = a1_io();
    let mut policy = Fixed {
        action: 0.0,
        calls: 0,
    };
    let (mut c, t) = in_policy(&io, &mut policy);
    let state = standing(&io);
    c.operator(OperatorAction::Damp, t, None).unwrap();
    assert_eq!(c.mode(), ControlMode::Damping);
    assert_eq!(c.fault(), Some(&Fault::Operator));
    // Stale: refused.
    let old = Latest {
        state: &state,
        received_at: t - 1.0,
    };
    assert!(c.operator(OperatorAction::Resume, t, Some(old)).is_err());
    // Tilted 90°: refused.
    let mut fallen = state.clone();
    let s = std::f32::consts::FRAC_1_SQRT_2;
    fallen.base_quat = [s, s, 0.0, 0.0];
    let tilted = Latest {
        state: &fallen,
        received_at: t,
    };
    assert!(c.operator(OperatorAction::Resume, t, Some(tilted)).is_err());
    assert_eq!(c.mode(), ControlMode::Damping);
}

#[test]
fn non_finite_action_and_tilt_damp() {
    let io = a1_io();
    let mut policy = Fixed {
        action: 0.0,
        calls: 0,
    };
    let (mut c, t) = in_policy(&io, &mut policy);
    let state = standing(&io);
    policy.action = f32::NAN;
    let out = tick_at(&mut c, t + DT, &state, t + DT, &mut policy);
    assert_eq!(out.command.mode, ControlMode::Damping);
    assert_eq!(out.new_fault, Some(Fault::NonFiniteAction));
    assert!(out.command.joint_pos_target.iter().all(|q| q.is_finite()));

    policy.action = f32::INFINITY;
    let (mut c, t) = in_policy(
        &io,
        &mut Fixed {
            action: 0.0,
            calls: 0,
        },
    );
    let out = tick_at(&mut c, t + DT, &state, t + DT, &mut policy);
    assert_eq!(out.new_fault, Some(Fault::NonFiniteAction));

    let (mut c, t) = in_policy(
        &io,
        &mut Fixed {
            action: 0.0,
            calls: 0,
        },
    );
    let mut tilted = state.clone();
    let a: f32 = 70f32.to_radians() / 2.0;
    tilted.base_quat = [a.cos(), a.sin(), 0.0, 0.0];
    let out = tick_at(&mut c, t + DT, &tilted, t + DT, &mut policy);
    assert!(matches!(out.new_fault, Some(Fault::Tilt { degrees }) if (degrees - 70.0).abs() < 0.5));
}

#[test]
fn bad_safety_settings_are_errors() {
    let mut s = SafetyConfig::default();
    s.stale_periods = 0.0;
    let e = Controller::new("dog", a1_io(), 0.25, s).unwrap_err();
    assert!(e.to_string().contains("stale_periods"), "{e}");
}

fn export_for(robot: &str) -> Vec<u8> {
    use l3p_policy::{PolicyConfig, PolicyModel, PolicyRobot};
    let r = RobotSpec::by_name(robot).unwrap();
    let mut cfg = PolicyConfig::default();
    cfg.encoder_hidden = vec![16];
    cfg.core_hidden = vec![16];
    cfg.decoder_hidden = vec![16];
    cfg.critic_hidden = vec![16];
    let spec = PolicyRobot {
        name: robot.into(),
        obs_dim: 48,
        action_dim: 12,
        action_scale: r.action_scale,
        io: Some(robot_io(r, &flat_env()).unwrap()),
    };
    let model = PolicyModel::new(cfg, vec![spec], &l3p_policy::cpu_device()).unwrap();
    l3p_policy::export_bytes(&model, robot).unwrap().0
}

#[test]
fn artifacts_for_another_robot_or_with_a_bad_hash_are_refused() {
    let go1 = export_for("go1");
    let e = load_policy("x@1", &go1, None, a1()).unwrap_err();
    assert!(e.to_string().contains("policy for go1"), "{e}");
    let e = load_policy("x@1", &go1, Some("00"), RobotSpec::by_name("go1").unwrap()).unwrap_err();
    assert!(e.to_string().contains("sha256"), "{e}");
    let ok = load_policy("x@1", &go1, None, RobotSpec::by_name("go1").unwrap()).unwrap();
    assert!(!ok.io_from_catalog);
    assert_eq!(ok.io.joint_names.len(), 12);
    let e = load_policy("x@1", b"not a policy", None, a1()).unwrap_err();
    assert!(e.to_string().contains("safetensors"), "{e}");
}

#[test]
fn wait_for_operator_keeps_the_robot_limp_until_resume() {
    let io = a1_io();
    let safety = SafetyConfig {
        wait_for_operator: true,
        ..SafetyConfig::default()
    };
    let mut c = Controller::new("dog", io.clone(), 0.25, safety).unwrap();
    let mut policy = Fixed {
        action: 0.0,
        calls: 0,
    };
    let state = standing(&io);
    let mut t = 0.0;
    for _ in 0..200 {
        t += DT;
        let fresh = Latest {
            state: &state,
            received_at: t,
        };
        assert_eq!(
            c.tick(t, Some(fresh), &mut policy).command.mode,
            ControlMode::ZeroTorque
        );
    }
    let fresh = Latest {
        state: &state,
        received_at: t,
    };
    c.operator(OperatorAction::Resume, t, Some(fresh)).unwrap();
    let mut modes = Vec::new();
    for _ in 0..200 {
        t += DT;
        let fresh = Latest {
            state: &state,
            received_at: t,
        };
        let m = c.tick(t, Some(fresh), &mut policy).command.mode;
        if modes.last() != Some(&m) {
            modes.push(m);
        }
    }
    // Limp for longer than zero_torque_s already: straight into the ramp.
    assert_eq!(modes, [ControlMode::Ramp, ControlMode::Policy]);
}

/// Finite but absurd states (joint velocity 1e30, joint position 1e6 — these drove the simulated
/// robot to 42° of tilt before) are not believed; a real standing state is.
#[test]
fn physically_absurd_states_are_not_believed() {
    use l3p_deploy::observation::plausible_state;
    let io = a1_io();
    let ok = standing(&io);
    plausible_state(&ok, &io).unwrap();
    let mut fast = ok.clone();
    fast.joint_vel[4] = 1e30;
    let e = plausible_state(&fast, &io).unwrap_err();
    assert!(e.contains("FR_thigh_joint") && e.contains("rad/s"), "{e}");
    let mut far = ok.clone();
    far.joint_pos[2] = 1e6;
    let e = plausible_state(&far, &io).unwrap_err();
    assert!(
        e.contains("FL_calf_joint") && e.contains("outside its limits"),
        "{e}"
    );
    let mut spinning = ok.clone();
    spinning.base_ang_vel = [0.0, 0.0, 1e9];
    assert!(
        plausible_state(&spinning, &io)
            .unwrap_err()
            .contains("turning")
    );
    let mut flying = ok;
    flying.base_lin_vel = [1e4, 0.0, 0.0];
    assert!(plausible_state(&flying, &io).unwrap_err().contains("m/s"));
}

#[test]
fn the_contract_carries_the_gains_the_policy_was_trained_around() {
    let robot = a1();
    let io = a1_io();
    assert!(
        io.kp
            .iter()
            .all(|k| (k - robot.training_gains.kp).abs() < 1e-4)
    );
    assert!(
        io.kd
            .iter()
            .all(|k| (k - robot.training_gains.kd).abs() < 1e-5)
    );
    // A config that trains stiffer (kp ≈ 40, kd ≈ 1 for A1's 25 / 0.5) deploys stiffer.
    let mut env = flat_env();
    env.randomization.kp_scale = Some([1.36, 1.84]);
    env.randomization.kd_scale = Some([1.7, 2.3]);
    let io = robot_io(robot, &env).unwrap();
    assert!(
        io.kp
            .iter()
            .all(|k| (k - 1.6 * robot.training_gains.kp).abs() < 1e-3)
    );
    assert!(
        io.kd
            .iter()
            .all(|k| (k - 2.0 * robot.training_gains.kd).abs() < 1e-4)
    );
    // Per-robot gains (`[env.gains.a1]`) replace the catalog's, and the randomisation scales them.
    env.gains.insert(
        "a1".into(),
        GainsOverride {
            kp: Some(60.0),
            kd: Some(1.2),
        },
    );
    env.randomization.kp_scale = Some([0.85, 1.15]);
    env.randomization.kd_scale = Some([0.9, 1.3]);
    let io = robot_io(robot, &env).unwrap();
    assert!(io.kp.iter().all(|k| (k - 60.0).abs() < 1e-3), "{:?}", io.kp);
    assert!(io.kd.iter().all(|k| (k - 1.32).abs() < 1e-4), "{:?}", io.kd);
}

/// Simulating a policy on its own robot uses the gains it was trained and is deployed with (its
/// `io`), whatever the config at hand says; another robot keeps its own.
#[test]
fn a_policy_is_simulated_at_its_own_gains_on_its_own_robot_only() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/a1-flat-session31/policy");
    let policy = l3p_policy::export::read_export_json(&dir).unwrap();
    let io = policy.io.as_ref().unwrap();
    assert_eq!(
        io.kp[0].round(),
        60.0,
        "trained at kp 60, not the catalog's"
    );
    let mut env = flat_env();
    env.randomization.kp_scale = Some([0.8, 1.0]); // centre 0.9: io / 0.9 × 0.9 = io again
    let sim = l3p_task::contract::sim_env_for_policy(&env, &policy, "a1");
    let gains = sim.training_gains(a1());
    assert!((gains.kp * 0.9 - io.kp[0]).abs() < 1e-3, "{gains:?}");
    assert!((gains.kd - io.kd[0]).abs() < 1e-4, "{gains:?}");
    assert_eq!(sim.gait_clock_hz, io.gait_clock_hz);
    let go1 = RobotSpec::by_name("go1").unwrap();
    let other = l3p_task::contract::sim_env_for_policy(&env, &policy, "go1");
    assert_eq!(other.training_gains(go1), go1.training_gains);
}
