//! The task's data: the physics snapshot ([`SimState`]), the per-env bookkeeping
//! ([`TaskEnvState`], [`Command`]), per-step and per-episode results ([`StepResult`],
//! [`EpisodeSummary`]) and the reset and randomisation draws ([`ResetSample`],
//! [`BodyRandomization`]).

use super::{MAX_PENALISED_BODIES, NUM_FEET, NUM_JOINTS, NUM_REWARD_TERMS, quat_rotate_inverse};

/// Snapshot of one robot after a control step, filled by the physics side.
///
/// Conventions: world frame z up; `base_quat` is `(w, x, y, z)` rotating base-frame vectors into
/// the world frame; velocities are of the base (root link) frame origin, in the world frame;
/// contact forces are norms in newtons, the **maximum over the substeps** of the control step
/// (stands in for IsaacLab's 3-substep contact history). Joint order is the robot's catalog order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimState {
    pub base_pos: [f32; 3],
    pub base_quat: [f32; 4],
    pub base_lin_vel_w: [f32; 3],
    pub base_ang_vel_w: [f32; 3],
    pub joint_pos: [f32; NUM_JOINTS],
    pub joint_vel: [f32; NUM_JOINTS],
    /// Torque applied by the actuators during the last substep (after clipping).
    pub joint_torque: [f32; NUM_JOINTS],
    /// Contact force norm on each foot.
    pub foot_force: [f32; NUM_FEET],
    /// Contact force norm on each penalised body (unused entries 0).
    pub penalised_force: [f32; MAX_PENALISED_BODIES],
    /// Contact force norm on the base / trunk (termination bodies).
    pub base_force: f32,
    /// World position of each foot's lowest point: the centre x, y and the minimum z of the
    /// foot colliders' bounding box (for `feet_clearance`).
    pub foot_sole: [[f32; 3]; NUM_FEET],
}

impl Default for SimState {
    fn default() -> Self {
        SimState {
            base_pos: [0.0; 3],
            base_quat: [1.0, 0.0, 0.0, 0.0],
            base_lin_vel_w: [0.0; 3],
            base_ang_vel_w: [0.0; 3],
            joint_pos: [0.0; NUM_JOINTS],
            joint_vel: [0.0; NUM_JOINTS],
            joint_torque: [0.0; NUM_JOINTS],
            foot_force: [0.0; NUM_FEET],
            penalised_force: [0.0; MAX_PENALISED_BODIES],
            base_force: 0.0,
            foot_sole: [[0.0; 3]; NUM_FEET],
        }
    }
}

impl SimState {
    /// True when every field is finite.
    pub fn is_finite(&self) -> bool {
        self.base_pos.iter().all(|v| v.is_finite())
            && self.base_quat.iter().all(|v| v.is_finite())
            && self.base_lin_vel_w.iter().all(|v| v.is_finite())
            && self.base_ang_vel_w.iter().all(|v| v.is_finite())
            && self.joint_pos.iter().all(|v| v.is_finite())
            && self.joint_vel.iter().all(|v| v.is_finite())
            && self.joint_torque.iter().all(|v| v.is_finite())
            && self.foot_force.iter().all(|v| v.is_finite())
            && self.penalised_force.iter().all(|v| v.is_finite())
            && self.base_force.is_finite()
            && self.foot_sole.iter().flatten().all(|v| v.is_finite())
    }

    /// Base linear velocity in the base frame.
    pub fn lin_vel_b(&self) -> [f32; 3] {
        quat_rotate_inverse(self.base_quat, self.base_lin_vel_w)
    }

    /// Base angular velocity in the base frame.
    pub fn ang_vel_b(&self) -> [f32; 3] {
        quat_rotate_inverse(self.base_quat, self.base_ang_vel_w)
    }
}

/// The velocity command of one env (IsaacLab `UniformVelocityCommand` state).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    /// Forward velocity (m/s, base frame).
    pub vx: f32,
    /// Lateral velocity (m/s, base frame).
    pub vy: f32,
    /// Yaw rate (rad/s); in heading mode recomputed every step from `heading`.
    pub wz: f32,
    /// Target heading (rad), world frame.
    pub heading: f32,
    /// Whether `wz` comes from the heading controller.
    pub heading_mode: bool,
    /// All-zero command.
    pub standing: bool,
    /// Seconds until the next resampling.
    pub time_left: f32,
}

impl Command {
    /// `(vx, vy, wz)` as seen by the policy.
    pub fn as_array(&self) -> [f32; 3] {
        [self.vx, self.vy, self.wz]
    }

    /// `‖(vx, vy)‖`.
    pub fn xy_norm(&self) -> f32 {
        (self.vx * self.vx + self.vy * self.vy).sqrt()
    }
}

/// Why an episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DoneReason {
    #[default]
    None,
    /// Base contact force above threshold (terminated).
    BaseContact,
    /// Fall guard: base tilt above `max_tilt_rad` (terminated).
    Tilt,
    /// Fall guard: base below `min_base_height` above the terrain (terminated).
    TooLow,
    /// Non-finite physics state (terminated; the vectorised env should count it and reset).
    NonFinite,
    /// Episode length reached (truncated, bootstrap).
    TimeOut,
}

/// Result of [`Task::evaluate`](super::Task::evaluate) for one env.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepResult {
    /// Sum of the weighted terms (already × dt).
    pub reward: f32,
    /// Weighted terms (× dt), [`RewardTerm`](super::RewardTerm) order.
    pub terms: [f32; NUM_REWARD_TERMS],
    /// MDP termination (no bootstrap).
    pub terminated: bool,
    /// Time-out (bootstrap from the value of the final state).
    pub truncated: bool,
    pub reason: DoneReason,
}

impl StepResult {
    /// `terminated || truncated`.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// Running sums of one episode.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpisodeStats {
    pub ret: f32,
    pub steps: u32,
    pub terms: [f32; NUM_REWARD_TERMS],
    /// Σ ‖v_xy(base) − cmd_xy‖ over steps.
    pub lin_vel_err_sum: f32,
    /// Σ |ω_z(base) − cmd_wz| over steps.
    pub yaw_rate_err_sum: f32,
}

/// Statistics of a finished episode.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpisodeSummary {
    /// Undiscounted return.
    pub ret: f32,
    /// Length in control steps.
    pub length: u32,
    /// Per-term sums (weighted, × dt), [`RewardTerm`](super::RewardTerm) order.
    pub terms: [f32; NUM_REWARD_TERMS],
    /// Mean ‖v_xy − cmd_xy‖ (m/s).
    pub mean_lin_vel_error: f32,
    /// Mean |ω_z − cmd_wz| (rad/s).
    pub mean_yaw_rate_error: f32,
    /// xy distance of the base from the env origin at the end (m), for the curriculum.
    pub distance: f32,
    /// ‖cmd_xy‖ at the end, for the curriculum.
    pub command_xy_norm: f32,
    pub reason: DoneReason,
}

/// Per-env task bookkeeping. Create with [`TaskEnvState::new`], reset with
/// [`Task::reset_env`](super::Task::reset_env).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TaskEnvState {
    pub command: Command,
    /// The action applied in the last step (observation `last_action`; IsaacLab `action`).
    pub last_action: [f32; NUM_JOINTS],
    /// The policy's mean action in the last step after the action filter (what `action_rate_l2`
    /// differences: the deployed policy's target path; equals `last_action` when the caller gives
    /// no means).
    pub last_mean_action: [f32; NUM_JOINTS],
    /// The mean action one step before `last_mean_action` (for `action_smoothness_l2`).
    pub prev_mean_action: [f32; NUM_JOINTS],
    /// Joint velocities at the previous step (for `dof_acc_l2`).
    pub last_joint_vel: [f32; NUM_JOINTS],
    /// Current air time per foot (s).
    pub air_time: [f32; NUM_FEET],
    /// Current contact time per foot (s).
    pub contact_time: [f32; NUM_FEET],
    /// Duration of the last completed air phase per foot (s).
    pub last_air_time: [f32; NUM_FEET],
    /// The last stride's yaw-rate errors, for `track_yaw_rate_mean_exp`.
    pub yaw_error_window: MovingMean,
    /// Env origin (tile origin) for the curriculum distance.
    pub origin: [f32; 3],
    /// Seconds until the next push (∞ when pushes are off).
    pub push_time_left: f32,
    /// Running episode sums.
    pub episode: EpisodeStats,
    /// Control steps the episode counts as already elapsed towards its time-out: a random part
    /// of the first episode when a run staggers time-outs (`l3p_sim::vecenv::VecEnv::stagger_time_outs`, rsl_rl's
    /// `init_at_random_ep_len`), else 0. The episode's statistics count only the steps taken.
    ///
    pub time_out_head_start: u32,
    /// Reason of the last `evaluate` that ended the episode.
    pub last_reason: DoneReason,
}

impl TaskEnvState {
    /// A zeroed state; call [`Task::reset_env`](super::Task::reset_env) before use.
    pub fn new() -> Self {
        TaskEnvState {
            push_time_left: f32::INFINITY,
            ..Default::default()
        }
    }
}

/// Initial state for a physics reset (IsaacLab `reset_base` + `reset_robot_joints`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ResetSample {
    /// Base x, y (world): origin + U(−d, d).
    pub base_xy: [f32; 2],
    /// Ground height to put the robot on: max(tile origin z, terrain height at `base_xy`). The
    /// physics adds the robot's initial base height above ground.
    pub ground_z: f32,
    /// Base yaw (rad).
    pub yaw: f32,
    /// Base linear velocity, world frame.
    pub lin_vel: [f32; 3],
    /// Base angular velocity, world frame.
    pub ang_vel: [f32; 3],
    /// Joint positions: default × U(lo, hi), clamped to the soft limits.
    pub joint_pos: [f32; NUM_JOINTS],
    /// Joint velocities (0).
    pub joint_vel: [f32; NUM_JOINTS],
}

/// Per-env physical randomisation (IsaacLab "startup" events).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BodyRandomization {
    pub static_friction: f32,
    /// Not above `static_friction`.
    pub dynamic_friction: f32,
    /// Mass added to the base (kg).
    pub added_base_mass: f32,
    /// Base centre-of-mass shift (m, base frame).
    pub base_com_offset: [f32; 3],
    /// Passive joint damping (N·m·s/rad).
    pub joint_damping: f32,
    /// Coulomb joint friction (N·m).
    pub joint_friction: f32,
    /// Motor torque scale.
    pub motor_strength: f32,
    /// PD gain scales.
    pub kp_scale: f32,
    pub kd_scale: f32,
    /// Action latency (s).
    pub latency_s: f32,
}

/// The longest [`MovingMean`] window, in control steps.
pub const MOVING_MEAN_MAX_STEPS: usize = 64;

/// The mean of the last `n` values pushed (fewer at the start): a window of exactly one stride
/// removes the stride's periodic part and keeps the drift.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovingMean {
    values: [f32; MOVING_MEAN_MAX_STEPS],
    pushed: usize,
    sum: f32,
}

impl Default for MovingMean {
    fn default() -> Self {
        MovingMean {
            values: [0.0; MOVING_MEAN_MAX_STEPS],
            pushed: 0,
            sum: 0.0,
        }
    }
}

impl MovingMean {
    /// Adds `x` and returns the mean over the last `window_s` (at least one step, at most
    /// [`MOVING_MEAN_MAX_STEPS`]) of steps of `dt`.
    pub fn push(&mut self, x: f32, window_s: f32, dt: f32) -> f32 {
        let n = ((window_s / dt).round() as usize).clamp(1, MOVING_MEAN_MAX_STEPS);
        let slot = self.pushed % n;
        if self.pushed >= n {
            self.sum -= self.values[slot];
        }
        self.values[slot] = x;
        self.sum += x;
        self.pushed += 1;
        self.sum / self.pushed.min(n) as f32
    }
}
