//! The deploy side of the robot I/O contract ([`RobotIo`], built by `l3p_task::contract::robot_io`):
//! [`ObservationBuilder`] turns a wire [`RobotState`] into the policy's observation exactly as the
//! training task does (`l3p_task::task::Task::observe` with noise off — a test compares the two),
//! [`plausible_state`] decides which states to believe, [`standing_state`] is the robot at rest.

use l3p_infer::RobotIo;
use l3p_proto::RobotState;
use l3p_task::config::GAIT_CLOCK_OBS;
use l3p_task::contract::GAIT_CLOCK_SEGMENT;
use l3p_task::task::{gait_clock_observation, gait_clock_phase, projected_gravity};

use crate::DeployError;

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
        self.build_with_command(state, state.command, last_action, ticks, out);
    }

    /// [`Self::build`] with `command` in place of the state's (a heading hold's output).
    pub fn build_with_command(
        &self,
        state: &RobotState,
        command: [f32; 3],
        last_action: &[f32],
        ticks: u64,
        out: &mut [f32],
    ) {
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
                    Segment::Command => command[k],
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
