//! The robot I/O contract of a policy: [`robot_io`] builds it from the robot catalog and the env
//! config (training and `l3p export` call it), [`ObservationBuilder`] turns a wire [`RobotState`] into
//! the policy's observation exactly as the training task does (`l3p_robots::task::Task::observe` with
//! noise off — a test compares the two).

use l3p_policy::{IO_VERSION, ObsSegment, RobotIo};
use l3p_proto::RobotState;
use l3p_robots::catalog::RobotSpec;
use l3p_robots::config::{EnvConfig, GAIT_CLOCK_OBS, HEIGHT_SCAN_OBS};
use l3p_robots::task::{gait_clock_observation, gait_clock_phase, projected_gravity};

use crate::DeployError;

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
            env.height_scan = obs_dim != l3p_robots::config::PROPRIO_OBS;
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
pub fn sim_env_for_policy(
    base: &EnvConfig,
    policy: &l3p_policy::infer::ExportConfig,
    robot: &str,
) -> EnvConfig {
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
                l3p_robots::config::GainsOverride {
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
pub fn robot_io(robot: &RobotSpec, env: &EnvConfig) -> Result<RobotIo, DeployError> {
    let model = robot
        .model()
        .map_err(|e| DeployError::Robot(e.to_string()))?;
    let params = robot.task_params(&model);
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

/// How far outside its soft limits a measured joint may be (rad) before the state is not believed.
pub const JOINT_LIMIT_MARGIN: f32 = 0.5;
/// Fastest believable joint (rad/s): quadruped knee motors top out near 30.
pub const MAX_JOINT_SPEED: f32 = 100.0;
/// Fastest believable base linear (m/s) and angular (rad/s) velocity.
pub const MAX_BASE_SPEED: f32 = 20.0;
pub const MAX_BASE_RATE: f32 = 50.0;

/// Whether a decoded, finite state is physically believable for the robot of `io`: joints within
/// their soft limits ± [`JOINT_LIMIT_MARGIN`], speeds below the bounds above. A state that is not
/// (a broken sensor, a hostile publisher) is rejected like a malformed one; if only such states
/// arrive, the stale-state watchdog damps.
pub fn plausible_state(state: &RobotState, io: &RobotIo) -> Result<(), String> {
    for (j, (q, l)) in state
        .joint_pos
        .iter()
        .zip(&io.soft_joint_limits)
        .enumerate()
    {
        if *q < l[0] - JOINT_LIMIT_MARGIN || *q > l[1] + JOINT_LIMIT_MARGIN {
            return Err(format!(
                "joint {} at {q} rad, outside its limits [{}, {}] by more than {JOINT_LIMIT_MARGIN}",
                io.joint_names[j], l[0], l[1]
            ));
        }
    }
    if let Some((j, v)) = state
        .joint_vel
        .iter()
        .enumerate()
        .find(|(_, v)| v.abs() > MAX_JOINT_SPEED)
    {
        return Err(format!(
            "joint {} moving at {v} rad/s (more than {MAX_JOINT_SPEED})",
            io.joint_names[j]
        ));
    }
    let norm = |v: &[f32; 3]| v.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm(&state.base_lin_vel) > MAX_BASE_SPEED {
        return Err(format!(
            "base moving at {} m/s (more than {MAX_BASE_SPEED})",
            norm(&state.base_lin_vel)
        ));
    }
    if norm(&state.base_ang_vel) > MAX_BASE_RATE {
        return Err(format!(
            "base turning at {} rad/s (more than {MAX_BASE_RATE})",
            norm(&state.base_ang_vel)
        ));
    }
    Ok(())
}

/// The wire state of `robot_id` standing still and level at the default pose, zero command.
pub fn standing_state(io: &RobotIo, robot_id: &str) -> RobotState {
    RobotState {
        wire_version: l3p_proto::WIRE_VERSION,
        robot_id: robot_id.into(),
        seq: 0,
        stamp_ns: 0,
        base_quat: [1.0, 0.0, 0.0, 0.0],
        base_lin_vel: [0.0; 3],
        base_ang_vel: [0.0; 3],
        joint_pos: io.default_joint_pos.clone(),
        joint_vel: vec![0.0; io.joint_names.len()],
        command: [0.0; 3],
    }
}

/// Builds observations from wire states for one policy's layout. Only proprioceptive layouts are
/// deployable (no terrain sensing on the robot side yet).
#[derive(Debug, Clone)]
pub struct ObservationBuilder {
    segments: Vec<(Segment, usize, f32)>,
    default_joint_pos: Vec<f32>,
    obs_clip: f32,
    obs_dim: usize,
    gait_clock_hz: f32,
    control_dt: f32,
}

#[derive(Debug, Clone, Copy)]
enum Segment {
    LinVel,
    AngVel,
    Gravity,
    Command,
    JointPos,
    JointVel,
    LastAction,
    GaitClock,
}

impl ObservationBuilder {
    /// Checks that every segment is known and sized for the robot.
    pub fn new(io: &RobotIo) -> Result<Self, DeployError> {
        let joints = io.joint_names.len();
        let mut segments = Vec::new();
        for s in &io.obs_layout {
            let (kind, len) = match s.name.as_str() {
                "base_lin_vel" => (Segment::LinVel, 3),
                "base_ang_vel" => (Segment::AngVel, 3),
                "projected_gravity" => (Segment::Gravity, 3),
                "velocity_command" => (Segment::Command, 3),
                "joint_pos_rel" => (Segment::JointPos, joints),
                "joint_vel" => (Segment::JointVel, joints),
                "last_action" => (Segment::LastAction, joints),
                GAIT_CLOCK_SEGMENT => (Segment::GaitClock, GAIT_CLOCK_OBS),
                "height_scan" => {
                    return Err(DeployError::Policy(
                        "the policy observes a terrain height scan; deploy runs blind \
                         (proprioceptive) policies only\nhint: train with [env] height_scan = false"
                            .into(),
                    ));
                }
                other => {
                    return Err(DeployError::Policy(format!(
                        "unknown observation segment {other:?}"
                    )));
                }
            };
            if s.len != len {
                return Err(DeployError::Policy(format!(
                    "observation segment {} has length {}, expected {len}",
                    s.name, s.len
                )));
            }
            segments.push((kind, len, s.scale));
        }
        Ok(Self {
            segments,
            default_joint_pos: io.default_joint_pos.clone(),
            obs_clip: io.obs_clip,
            obs_dim: io.obs_layout.iter().map(|s| s.len).sum(),
            gait_clock_hz: io.gait_clock_hz,
            control_dt: io.control_dt,
        })
    }

    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Writes the observation of `state` (already validated: finite, right joint count), the
    /// previous action and, with a gait clock, its phase after `ticks` policy steps into `out`
    /// (`obs_dim` long).
    pub fn build(&self, state: &RobotState, last_action: &[f32], ticks: u64, out: &mut [f32]) {
        let gravity = projected_gravity(state.base_quat);
        let clock =
            gait_clock_observation(gait_clock_phase(ticks, self.gait_clock_hz, self.control_dt));
        let mut i = 0;
        for &(kind, len, scale) in &self.segments {
            for k in 0..len {
                let x = match kind {
                    Segment::LinVel => state.base_lin_vel[k],
                    Segment::AngVel => state.base_ang_vel[k],
                    Segment::Gravity => gravity[k],
                    Segment::Command => state.command[k],
                    Segment::JointPos => state.joint_pos[k] - self.default_joint_pos[k],
                    Segment::JointVel => state.joint_vel[k],
                    Segment::LastAction => last_action[k],
                    Segment::GaitClock => clock[k],
                };
                let v = scale * x;
                out[i] = if v.is_nan() {
                    0.0
                } else {
                    v.clamp(-self.obs_clip, self.obs_clip)
                };
                i += 1;
            }
        }
    }
}
