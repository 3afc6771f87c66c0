//! Left-right mirror maps: derived from each catalog robot's geometry, reflections (involutions),
//! and a mirrored state's observation is the mirrored observation.

use l3p_robot::catalog::RobotSpec;
use l3p_task::config::{EnvConfig, TerrainPreset};
use l3p_task::mirror::{SignedPermutation, TaskMirror, observation_mirror};
use l3p_task::task::{
    Command, RobotTaskParams, SimState, Task, TaskEnvState, gait_clock_observation,
    quat_from_yaw_and_tilt,
};
use l3p_task::terrain::Terrain;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn mirror_of(robot: &RobotSpec, height_scan: bool, gait_clock: bool) -> TaskMirror {
    TaskMirror::new(
        &robot.model().unwrap(),
        &robot.joint_names,
        &robot.default_pose,
        height_scan,
        gait_clock,
    )
    .unwrap_or_else(|e| panic!("{}: {e}", robot.name))
}

#[test]
fn every_catalog_robot_mirrors_leg_for_leg_with_abduction_flipped() {
    for robot in RobotSpec::all() {
        let m = mirror_of(robot, true, true);
        assert!(m.action.is_involution(), "{}", robot.name);
        assert!(m.observation.is_involution(), "{}", robot.name);
        assert_eq!(m.observation.len(), 48 + 187 + 2);
        // Canonical order FL, FR, RL, RR × (abduction, flexion, knee): FL ↔ FR, RL ↔ RR.
        let want: Vec<usize> = [3, 4, 5, 0, 1, 2, 9, 10, 11, 6, 7, 8].to_vec();
        assert_eq!(m.action.index, want, "{}", robot.name);
        for (j, s) in m.action.sign.iter().enumerate() {
            let expected = if j % 3 == 0 { -1.0 } else { 1.0 };
            assert_eq!(*s, expected, "{} joint {j}", robot.name);
        }
    }
}

#[test]
fn an_asymmetric_default_pose_is_refused_with_the_joint_named() {
    let robot = RobotSpec::by_name("a1").unwrap();
    let mut pose = robot.default_pose;
    pose[0] = 0.3; // FL abduction 0.3, FR still −0.1
    let err = TaskMirror::new(
        &robot.model().unwrap(),
        &robot.joint_names,
        &pose,
        false,
        false,
    )
    .unwrap_err();
    assert!(err.contains("FL_hip_joint"), "{err}");
}

#[test]
fn the_clock_moves_half_a_period_and_the_scan_reverses_its_rows() {
    let joints = SignedPermutation {
        index: (0..12).collect(),
        sign: vec![1.0; 12],
    };
    let m = observation_mirror(&joints, true, true);
    let mut obs = vec![0.0; m.len()];
    let clock = gait_clock_observation(0.1);
    obs[235] = clock[0];
    obs[236] = clock[1];
    // Scan row 0 (y = −0.5 m, the right side) gets 1, the rest 0.
    obs[48..48 + 17].iter_mut().for_each(|v| *v = 1.0);
    let mut out = vec![0.0; m.len()];
    m.apply(&obs, &mut out);
    let half_later = gait_clock_observation(0.6);
    assert!((out[235] - half_later[0]).abs() < 1e-6 && (out[236] - half_later[1]).abs() < 1e-6);
    assert!(out[48 + 10 * 17..48 + 11 * 17].iter().all(|v| *v == 1.0));
    assert!(out[48..48 + 10 * 17].iter().all(|v| *v == 0.0));
}

/// The reflection `y → −y` of a simulated state.
fn mirror_state(s: &SimState, joints: &SignedPermutation) -> SimState {
    let q = s.base_quat;
    let mut m = *s;
    m.base_pos = [s.base_pos[0], -s.base_pos[1], s.base_pos[2]];
    m.base_quat = [q[0], -q[1], q[2], -q[3]];
    m.base_lin_vel_w = [
        s.base_lin_vel_w[0],
        -s.base_lin_vel_w[1],
        s.base_lin_vel_w[2],
    ];
    m.base_ang_vel_w = [
        -s.base_ang_vel_w[0],
        s.base_ang_vel_w[1],
        -s.base_ang_vel_w[2],
    ];
    joints.apply(&s.joint_pos, &mut m.joint_pos);
    joints.apply(&s.joint_vel, &mut m.joint_vel);
    m.foot_force = [
        s.foot_force[1],
        s.foot_force[0],
        s.foot_force[3],
        s.foot_force[2],
    ];
    m.foot_sole = [1, 0, 3, 2].map(|f| {
        let p = s.foot_sole[f];
        [p[0], -p[1], p[2]]
    });
    m
}

#[test]
fn a_mirrored_state_is_observed_as_the_mirrored_observation() {
    let robot = RobotSpec::by_name("a1").unwrap();
    let mut env = EnvConfig::default();
    env.terrain.preset = TerrainPreset::Flat;
    env.height_scan = false;
    let spec = env.resolve("a1").unwrap();
    let terrain = Terrain::generate(&spec.terrain).unwrap();
    let mut task = Task::new(spec, RobotTaskParams::of(robot, &robot.model().unwrap())).unwrap();
    task.spec.noise.enabled = false;
    let mirror = mirror_of(robot, false, false);
    let mut rng = StdRng::seed_from_u64(5);
    for _ in 0..20 {
        let mut s = SimState::default();
        let yaw = rng.random_range(-3.0..3.0);
        let tilt = [
            rng.random_range(-0.2f32..0.2),
            rng.random_range(-0.2f32..0.2),
        ];
        s.base_quat = quat_from_yaw_and_tilt(yaw, tilt[0], tilt[1]);
        s.base_pos = [
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
            0.3,
        ];
        for k in 0..3 {
            s.base_lin_vel_w[k] = rng.random_range(-1.0..1.0);
            s.base_ang_vel_w[k] = rng.random_range(-2.0..2.0);
        }
        for j in 0..12 {
            s.joint_pos[j] = robot.default_pose[j] + rng.random_range(-0.4..0.4);
            s.joint_vel[j] = rng.random_range(-8.0..8.0);
        }
        let mut e = TaskEnvState::new();
        e.command = Command {
            vx: rng.random_range(-1.0..1.0),
            vy: rng.random_range(-1.0..1.0),
            wz: rng.random_range(-1.0..1.0),
            ..Default::default()
        };
        for a in &mut e.last_action {
            *a = rng.random_range(-1.0..1.0);
        }
        let mut me = e;
        me.command.vy = -e.command.vy;
        me.command.wz = -e.command.wz;
        mirror.action.apply(&e.last_action, &mut me.last_action);
        let ms = mirror_state(&s, &mirror.action);

        let mut obs = vec![0.0; 48];
        let mut obs_of_mirrored = vec![0.0; 48];
        task.observe(&e, &s, &terrain, &mut rng, &mut obs).unwrap();
        task.observe(&me, &ms, &terrain, &mut rng, &mut obs_of_mirrored)
            .unwrap();
        let mut mirrored_obs = vec![0.0; 48];
        mirror.observation.apply(&obs, &mut mirrored_obs);
        for (i, (a, b)) in mirrored_obs.iter().zip(&obs_of_mirrored).enumerate() {
            assert!(
                (a - b).abs() < 1e-5,
                "obs[{i}]: mirrored {a} vs of mirrored {b}"
            );
        }
    }
}
