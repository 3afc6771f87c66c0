//! The robot I/O contract of a policy, next to the task that produces its observations
//! ([`crate::task::Task::observe`]): [`robot_io`] builds the contract ([`RobotIo`]: observation
//! layout, default pose, gains, limits, clips, period) from the robot catalog and the env config
//! (training and `l3p export` call it); [`env_for_policy`] and [`sim_env_for_policy`] go the other
//! way, from a policy's contract to the env it must be simulated in. The deploy controller builds
//! observations from the same layout (`l3p_deploy::ObservationBuilder`, tested equal to
//! `Task::observe`).

use l3p_infer::{ExportConfig, IO_VERSION, ObsSegment, RobotIo};

use crate::config::{EnvConfig, GAIT_CLOCK_OBS, GainsOverride, HEIGHT_SCAN_OBS, PROPRIO_OBS};
use crate::task::RobotTaskParams;
use l3p_robot::catalog::RobotSpec;
use l3p_robot::urdf::UrdfError;

/// Segment names of the proprioceptive observation, in training order (`Task::observe`).
pub const PROPRIO_SEGMENTS: [&str; 7] = [
    "base_lin_vel",
    "base_ang_vel",
    "projected_gravity",
    "velocity_command",
    "joint_pos_rel",
    "joint_vel",
    "last_action",
];

/// Name of the gait-clock observation segment.
pub const GAIT_CLOCK_SEGMENT: &str = "gait_clock";

/// `base` with what a policy's observation and action contract fix taken from the policy: the
/// height scan (from its observation length when it carries no `io`), the gait clock and the
/// action filter. Evaluating or serving a policy under another contract would feed it
/// observations it never saw.
pub fn env_for_policy(base: &EnvConfig, obs_dim: usize, io: Option<&RobotIo>) -> EnvConfig {
    let mut env = base.clone();
    match io {
        Some(io) => {
            env.height_scan = io.obs_layout.iter().any(|s| s.name == "height_scan");
            env.gait_clock_hz = io.gait_clock_hz;
            env.action_filter_alpha = io.action_filter_alpha;
        }
        None => {
            // Checkpoints from before `io` existed: 48 or 48 + 187, no clock, no filter.
            env.height_scan = obs_dim != PROPRIO_OBS;
            env.gait_clock_hz = 0.0;
            env.action_filter_alpha = 1.0;
        }
    }
    env
}

/// [`env_for_policy`] for simulating `robot` under a policy: when the policy was trained on this
/// robot, its PD gains too (`io.kp`/`io.kd` are the training gains × the centre of the kp/kd
/// randomisation, so the centre of `base`'s ranges is divided out). Without them a policy trained at
/// other gains than the catalog's (`[env.gains.<robot>]`) would be judged on a robot it never
/// drove. Another robot (zero-shot transfer) keeps its own gains.
pub fn sim_env_for_policy(base: &EnvConfig, policy: &ExportConfig, robot: &str) -> EnvConfig {
    let mut env = env_for_policy(base, policy.obs_dim, policy.io.as_ref());
    let same_robot = |a: &str| a.to_ascii_lowercase().replace('-', "_");
    if let Some(io) = &policy.io
        && same_robot(&policy.robot) == same_robot(robot)
        && !io.kp.is_empty()
        && !io.kd.is_empty()
    {
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        let randomization = env.randomization(robot);
        let mid = |r: [f32; 2]| 0.5 * (r[0] + r[1]);
        let (kp, kd) = (
            mean(&io.kp) / mid(randomization.kp_scale),
            mean(&io.kd) / mid(randomization.kd_scale),
        );
        if kp.is_finite() && kd.is_finite() && kp > 0.0 && kd >= 0.0 {
            env.gains.insert(
                robot.to_string(),
                GainsOverride {
                    kp: Some(kp),
                    kd: Some(kd),
                },
            );
        }
    }
    env
}

/// The I/O contract of `robot` trained under `env`: observation layout (IsaacLab's, unscaled),
/// training gains (the catalog's × the centre of `env`'s kp/kd scale ranges), default pose, soft
/// limits, clips, control period.
pub fn robot_io(robot: &RobotSpec, env: &EnvConfig) -> Result<RobotIo, UrdfError> {
    let model = robot.model()?;
    let params = RobotTaskParams::of(robot, &model);
    let n = robot.joint_names.len();
    let seg = |name: &str, len: usize, description: &str| ObsSegment {
        name: name.into(),
        len,
        scale: 1.0,
        description: description.into(),
    };
    let mut obs_layout = vec![
        seg(
            PROPRIO_SEGMENTS[0],
            3,
            "base linear velocity in the base frame (x forward, y left, z up), m/s",
        ),
        seg(
            PROPRIO_SEGMENTS[1],
            3,
            "base angular velocity in the base frame (IMU gyro), rad/s",
        ),
        seg(
            PROPRIO_SEGMENTS[2],
            3,
            "unit gravity vector in the base frame (0, 0, -1 when level), from the base quaternion",
        ),
        seg(
            PROPRIO_SEGMENTS[3],
            3,
            "commanded (vx m/s, vy m/s, yaw rate rad/s) in the base frame",
        ),
        seg(
            PROPRIO_SEGMENTS[4],
            n,
            "joint positions minus default_joint_pos, rad, joint_names order",
        ),
        seg(PROPRIO_SEGMENTS[5], n, "joint velocities, rad/s"),
        seg(
            PROPRIO_SEGMENTS[6],
            n,
            "the previous applied action: raw output clipped to ±action_clip, then low-pass \
             filtered with action_filter_alpha (0 at start)",
        ),
    ];
    if env.height_scan {
        obs_layout.push(seg(
            "height_scan",
            HEIGHT_SCAN_OBS,
            "clip(base_z − terrain_height − 0.5, −1, 1) on IsaacLab's 1.6 m × 1.0 m grid (0.1 m), yaw-aligned",
        ));
    }
    if env.gait_clock_hz > 0.0 {
        obs_layout.push(seg(
            GAIT_CLOCK_SEGMENT,
            GAIT_CLOCK_OBS,
            "[sin 2πφ, cos 2πφ] of the trot clock, φ = frac(ticks · gait_clock_hz · control_dt), \
             ticks = policy steps since the policy took over (0 at its first step)",
        ));
    }
    // The gains the policy was trained around: the catalog's (or `[env.gains.<robot>]`), scaled by
    // the centre of the config's kp/kd randomisation; deploy uses them.
    let randomization = env.randomization(robot.name);
    let gains = env.training_gains(robot);
    let mid = |r: [f32; 2]| 0.5 * (r[0] + r[1]);
    Ok(RobotIo {
        version: IO_VERSION,
        control_dt: env.sim_dt * env.decimation as f32,
        joint_names: robot.joint_names.iter().map(|s| s.to_string()).collect(),
        default_joint_pos: robot.default_pose.to_vec(),
        kp: vec![gains.kp * mid(randomization.kp_scale); n],
        kd: vec![gains.kd * mid(randomization.kd_scale); n],
        soft_joint_limits: params.soft_limits().to_vec(),
        effort_limit: robot.effort_limit.to_vec(),
        action_clip: env.action_clip,
        action_filter_alpha: env.action_filter_alpha,
        gait_clock_hz: env.gait_clock_hz,
        obs_clip: env.obs_clip,
        obs_layout,
    })
}
