//! The locomotion task: commands, observations, rewards, terminations, resets and randomisation
//! draws, as pure `f32` functions over a per-env physics snapshot. No physics, no allocation per step.
//!
//! # Public API (what the vectorised env calls)
//! - [`SimState`]: the snapshot the physics fills per env per control step (fixed arrays: 12 leg
//!   joints, 4 feet, up to 8 penalised bodies).
//! - [`RobotTaskParams`]: per-robot constants (default pose, joint limits, soft-limit factor, action
//!   scale) from the robot catalog.
//! - [`Task`]: `Task::new(spec: TaskSpec, robot: RobotTaskParams)`, then per env per control step:
//!   1. [`Task::process_action`]: raw policy output → clipped action + joint position targets
//!      `q* = default + scale · a`;
//!   2. physics runs `decimation` substeps and fills a [`SimState`];
//!   3. [`Task::evaluate`]: terminations, rewards (per term, weighted × dt), bookkeeping
//!      (air time, last action, last joint velocity, episode sums) → [`StepResult`];
//!   4. if `terminated || truncated`: [`Task::finish_episode`] → [`EpisodeSummary`] (and the
//!      curriculum update, see [`crate::terrain::Curriculum::update`]), then [`Task::sample_reset`]
//!      → physics reset → [`Task::reset_env`];
//!   5. [`Task::update_commands`]: resampling timer, heading → yaw-rate;
//!   6. [`Task::push_due`]: `Some([vx, vy])` when a push is due (set the base xy velocity);
//!   7. [`Task::observe`]: 48 (+187) observations with noise into `&mut [f32]`.
//!
//!   [`Task::sample_body_randomization`] draws friction / added mass / CoM shift once per env
//!   (IsaacLab applies these at startup).
//! - [`TaskEnvState`]: the per-env bookkeeping (command, last action, last joint velocity, feet air
//!   time, episode step and sums, push timer, origin) with [`TaskEnvState::new`].
//! - [`RewardTerm`] / [`NUM_REWARD_TERMS`]: the term order of every per-term array.
//! - Math helpers: [`quat_rotate_inverse`], [`projected_gravity`], [`yaw_of`], [`wrap_to_pi`],
//!   [`heading_yaw_rate`].
//!
//! Step order follows IsaacLab's `ManagerBasedRLEnv.step`: terminations and rewards are computed on
//! the post-physics state with the command the policy saw; resets; then commands; then
//! observations (of the reset state for reset envs).

use rand::Rng;
use thiserror::Error;

use crate::config::{COMMAND_OBS, GAIT_CLOCK_OBS, HEIGHT_SCAN_OBS, PROPRIO_OBS, TaskSpec};
pub use crate::config::{NUM_REWARD_TERMS, RewardTerm};
use crate::terrain::Terrain;

/// Actuated leg joints of every supported robot.
pub const NUM_JOINTS: usize = 12;
/// Feet of every supported robot.
pub const NUM_FEET: usize = 4;
/// Capacity for bodies whose contact is penalised (thighs, calves/shanks).
pub const MAX_PENALISED_BODIES: usize = 8;

/// Errors of the task.
#[derive(Debug, Error)]
pub enum TaskError {
    /// A buffer has the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    Length {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    /// Invalid per-robot parameters.
    #[error("invalid task parameters for robot `{robot}`: {reason}")]
    Robot { robot: String, reason: String },
}

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

// ---------------------------------------------------------------------------------------------
// Math

/// Rotates world vector `v` into the frame of unit quaternion `q = (w, x, y, z)`: `R(q)ᵀ v`.
#[inline]
pub fn quat_rotate_inverse(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let (w, x, y, z) = (q[0], -q[1], -q[2], -q[3]);
    // t = 2 (u × v), v' = v + w t + u × t, with u = (x, y, z) of the conjugate
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

/// Gravity direction `(0, 0, −1)` in the base frame of `q`.
#[inline]
pub fn projected_gravity(q: [f32; 4]) -> [f32; 3] {
    quat_rotate_inverse(q, [0.0, 0.0, -1.0])
}

/// Yaw (heading) of `q`: the angle of the rotated base x axis in the world xy plane
/// (IsaacLab `heading_w`).
#[inline]
pub fn yaw_of(q: [f32; 4]) -> f32 {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// Wraps an angle to `[−π, π)`.
#[inline]
pub fn wrap_to_pi(a: f32) -> f32 {
    use std::f32::consts::PI;
    let r = (a + PI).rem_euclid(2.0 * PI) - PI;
    if r.is_finite() { r } else { 0.0 }
}

/// Heading-mode yaw-rate command: `clip(stiffness · wrap(target − yaw), lo, hi)`.
#[inline]
pub fn heading_yaw_rate(target: f32, yaw: f32, stiffness: f32, range: [f32; 2]) -> f32 {
    (stiffness * wrap_to_pi(target - yaw)).clamp(range[0], range[1])
}

/// Quaternion `(w, x, y, z)` of a rotation by `yaw` about z.
pub fn quat_from_yaw(yaw: f32) -> [f32; 4] {
    let (s, c) = (0.5 * yaw).sin_cos();
    [c, 0.0, 0.0, s]
}

/// Quaternion of a rotation by `yaw` about z followed (in the body frame) by a small roll and pitch
/// (rad): `q_yaw ⊗ normalise(1, roll/2, pitch/2, 0)`, exact to first order in the tilt angles.
pub fn quat_from_yaw_and_tilt(yaw: f32, roll: f32, pitch: f32) -> [f32; 4] {
    let q = quat_from_yaw(yaw);
    let t = [1.0, 0.5 * roll, 0.5 * pitch, 0.0];
    let mut m = [
        q[0] * t[0] - q[1] * t[1] - q[2] * t[2] - q[3] * t[3],
        q[0] * t[1] + q[1] * t[0] + q[2] * t[3] - q[3] * t[2],
        q[0] * t[2] - q[1] * t[3] + q[2] * t[0] + q[3] * t[1],
        q[0] * t[3] + q[1] * t[2] - q[2] * t[1] + q[3] * t[0],
    ];
    let n = m.iter().map(|v| v * v).sum::<f32>().sqrt();
    m.iter_mut().for_each(|v| *v /= n);
    m
}

// ---------------------------------------------------------------------------------------------
// Per-robot parameters

/// Per-robot constants the task needs (from the robot catalog).
#[derive(Debug, Clone, PartialEq)]
pub struct RobotTaskParams {
    /// Robot name (for errors).
    pub name: String,
    /// Default joint positions (rad), catalog order.
    pub default_joint_pos: [f32; NUM_JOINTS],
    /// Hard joint position limits `[lo, hi]` (rad).
    pub joint_pos_limits: [[f32; 2]; NUM_JOINTS],
    /// Soft-limit factor (IsaacLab `soft_joint_pos_limit_factor`: 0.9 Unitree, 0.95 ANYmal).
    pub soft_limit_factor: f32,
    /// `q* = default + action_scale · a` (0.25 Unitree, 0.5 ANYmal, 0.2 Spot).
    pub action_scale: f32,
    /// How many entries of [`SimState::penalised_force`] are used.
    pub num_penalised_bodies: usize,
    /// Base height above the ground in the default pose with the feet on the ground (m): the
    /// target of `base_height_l2`.
    pub standing_height: f32,
}

impl RobotTaskParams {
    /// Soft limits: centre ± factor · half-range (IsaacLab `soft_joint_pos_limits`).
    pub fn soft_limits(&self) -> [[f32; 2]; NUM_JOINTS] {
        let mut out = [[0.0; 2]; NUM_JOINTS];
        for (o, l) in out.iter_mut().zip(&self.joint_pos_limits) {
            let mid = 0.5 * (l[0] + l[1]);
            let half = 0.5 * (l[1] - l[0]) * self.soft_limit_factor;
            *o = [mid - half, mid + half];
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// Commands

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

fn uniform<R: Rng + ?Sized>(rng: &mut R, r: [f32; 2]) -> f32 {
    if r[1] > r[0] {
        rng.random_range(r[0]..r[1])
    } else {
        r[0]
    }
}

fn sym<R: Rng + ?Sized>(rng: &mut R, half: f32) -> f32 {
    if half > 0.0 {
        rng.random_range(-half..half)
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------------------------
// Rewards

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

/// Result of [`Task::evaluate`] for one env.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepResult {
    /// Sum of the weighted terms (already × dt).
    pub reward: f32,
    /// Weighted terms (× dt), [`RewardTerm`] order.
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
    /// Per-term sums (weighted, × dt), [`RewardTerm`] order.
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

/// The action contract's filter (`io.action_filter_alpha`): the applied action after `previous`
/// for raw output `raw`, `previous + α (clip(raw) − previous)`. Training and the deploy controller
/// both call this.
pub fn filtered_action(previous: f32, raw: f32, clip: f32, alpha: f32) -> f32 {
    previous + alpha * (clip_action(raw, clip) - previous)
}

/// A raw action clipped to ±`clip`; non-finite becomes 0.
fn clip_action(a: f32, clip: f32) -> f32 {
    if a.is_finite() {
        a.clamp(-clip, clip)
    } else {
        0.0
    }
}

/// 1 when the feet move in diagonal pairs — FL with RR, FR with RL, the two pairs in opposite
/// phases (one pair on the ground, the other in the air) — else 0. A trot without a clock: the
/// policy needs no phase input, so the observation layout stays the deployable 48.
pub fn trot_contact(foot_force: &[f32; NUM_FEET], threshold: f32) -> f32 {
    let c = foot_force.map(|f| f > threshold);
    let diagonal_a = c[0] == c[3];
    let diagonal_b = c[1] == c[2];
    if diagonal_a && diagonal_b && c[0] != c[1] {
        1.0
    } else {
        0.0
    }
}

/// Phase φ ∈ [0, 1) of a `hz` gait clock after `steps` control steps of `dt` seconds since the
/// episode (or the deploy controller's policy mode) began. Counting steps, not accumulating time,
/// keeps training and deployment on the same phase however long either runs.
pub fn gait_clock_phase(steps: u64, hz: f32, dt: f32) -> f32 {
    let cycles = steps as f64 * hz as f64 * dt as f64;
    (cycles - cycles.floor()) as f32
}

/// The clock's observation: `[sin 2πφ, cos 2πφ]` (continuous across the period's wrap).
pub fn gait_clock_observation(phase: f32) -> [f32; 2] {
    let a = std::f32::consts::TAU * phase;
    [a.sin(), a.cos()]
}

/// The trot the clock asks for, per foot (FL, FR, RL, RR): `true` = stance. The diagonal pair
/// FL + RR stands in the first half of the period while FR + RL swing, then they swap.
pub fn gait_clock_stance(phase: f32) -> [bool; NUM_FEET] {
    let first_half = phase < 0.5;
    [first_half, !first_half, !first_half, first_half]
}

/// Target sole height of each foot at clock `phase`: `peak · sin(π · s)` for a foot the clock
/// swings, with s ∈ [0, 1) its progress through the swing half-cycle, and 0 for a stance foot.
pub fn gait_clock_swing_height(phase: f32, peak: f32) -> [f32; NUM_FEET] {
    let stance = gait_clock_stance(phase);
    let progress = 2.0 * phase.rem_euclid(0.5);
    let h = peak * (std::f32::consts::PI * progress).sin();
    stance.map(|s| if s { 0.0 } else { h })
}

/// Share of feet whose contact (force above `threshold`) matches [`gait_clock_stance`].
pub fn gait_clock_match(foot_force: &[f32; NUM_FEET], threshold: f32, phase: f32) -> f32 {
    let stance = gait_clock_stance(phase);
    let matching = foot_force
        .iter()
        .zip(stance)
        .filter(|(f, s)| (**f > threshold) == *s)
        .count();
    matching as f32 / NUM_FEET as f32
}

// ---------------------------------------------------------------------------------------------
// Per-env state

/// Per-env task bookkeeping. Create with [`TaskEnvState::new`], reset with [`Task::reset_env`].
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
    /// Env origin (tile origin) for the curriculum distance.
    pub origin: [f32; 3],
    /// Seconds until the next push (∞ when pushes are off).
    pub push_time_left: f32,
    /// Running episode sums.
    pub episode: EpisodeStats,
    /// Reason of the last `evaluate` that ended the episode.
    pub last_reason: DoneReason,
}

impl TaskEnvState {
    /// A zeroed state; call [`Task::reset_env`] before use.
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

// ---------------------------------------------------------------------------------------------
// The task

/// The locomotion task for one robot (shared by all envs; stateless per step).
#[derive(Debug, Clone)]
pub struct Task {
    pub spec: TaskSpec,
    pub robot: RobotTaskParams,
    soft_limits: [[f32; 2]; NUM_JOINTS],
    weights_dt: [f32; NUM_REWARD_TERMS],
}

impl Task {
    /// Builds the task; checks the robot parameters.
    pub fn new(spec: TaskSpec, robot: RobotTaskParams) -> Result<Task, TaskError> {
        let err = |reason: String| TaskError::Robot {
            robot: robot.name.clone(),
            reason,
        };
        if !robot.default_joint_pos.iter().all(|v| v.is_finite()) {
            return Err(err("non-finite default joint position".into()));
        }
        for (i, l) in robot.joint_pos_limits.iter().enumerate() {
            if !(l[0].is_finite() && l[1].is_finite() && l[0] <= l[1]) {
                return Err(err(format!(
                    "joint {i}: invalid limits [{}, {}]",
                    l[0], l[1]
                )));
            }
        }
        if !(robot.soft_limit_factor > 0.0 && robot.soft_limit_factor <= 1.0) {
            return Err(err(format!(
                "soft_limit_factor {} not in (0, 1]",
                robot.soft_limit_factor
            )));
        }
        if !(robot.action_scale.is_finite() && robot.action_scale > 0.0) {
            return Err(err(format!("action_scale {} not > 0", robot.action_scale)));
        }
        if robot.num_penalised_bodies > MAX_PENALISED_BODIES {
            return Err(err(format!(
                "{} penalised bodies, at most {MAX_PENALISED_BODIES}",
                robot.num_penalised_bodies
            )));
        }
        let w = spec.rewards.named();
        let mut weights_dt = [0.0; NUM_REWARD_TERMS];
        for (o, (_, v)) in weights_dt.iter_mut().zip(w) {
            *o = v * spec.step_dt;
        }
        let soft_limits = robot.soft_limits();
        Ok(Task {
            spec,
            robot,
            soft_limits,
            weights_dt,
        })
    }

    /// Observation length ([`crate::config::obs_dim_of`]).
    pub fn obs_dim(&self) -> usize {
        self.spec.obs_dim
    }

    /// Phase of the gait clock for `env` now (0 without a clock): after `episode.steps` steps.
    pub fn gait_phase(&self, env: &TaskEnvState) -> f32 {
        if self.spec.gait_clock_hz > 0.0 {
            gait_clock_phase(
                env.episode.steps as u64,
                self.spec.gait_clock_hz,
                self.spec.step_dt,
            )
        } else {
            0.0
        }
    }

    /// Policy step (s).
    pub fn dt(&self) -> f32 {
        self.spec.step_dt
    }

    /// Soft joint limits used by `dof_pos_limits` and the reset clamp.
    pub fn soft_limits(&self) -> &[[f32; 2]; NUM_JOINTS] {
        &self.soft_limits
    }

    /// Raw policy output → applied `action` and joint targets `q* = default + action_scale ·
    /// action`. Non-finite entries are replaced by 0 and the rest clipped to ±`action_clip`; the
    /// result is low-pass filtered against `previous` (the last applied action):
    /// `action = previous + α (clip(raw) − previous)` with α = `action_filter_alpha` (1 = no
    /// filter). Returns the number of non-finite entries replaced.
    pub fn process_action(
        &self,
        raw: &[f32],
        previous: &[f32; NUM_JOINTS],
        action: &mut [f32; NUM_JOINTS],
        targets: &mut [f32; NUM_JOINTS],
    ) -> Result<usize, TaskError> {
        if raw.len() != NUM_JOINTS {
            return Err(TaskError::Length {
                what: "action",
                expected: NUM_JOINTS,
                got: raw.len(),
            });
        }
        let c = self.spec.action_clip;
        let alpha = self.spec.action_filter_alpha;
        let mut bad = 0;
        for i in 0..NUM_JOINTS {
            bad += usize::from(!raw[i].is_finite());
            let a = filtered_action(previous[i], raw[i], c, alpha);
            action[i] = a;
            targets[i] = self.robot.default_joint_pos[i] + self.robot.action_scale * a;
        }
        Ok(bad)
    }

    /// Draws a fresh command (IsaacLab `_resample_command`).
    pub fn resample_command<R: Rng + ?Sized>(&self, cmd: &mut Command, rng: &mut R) {
        let c = &self.spec.commands;
        cmd.vx = uniform(rng, c.lin_vel_x);
        cmd.vy = uniform(rng, c.lin_vel_y);
        cmd.wz = uniform(rng, c.ang_vel_z);
        if c.heading_command {
            cmd.heading = uniform(rng, c.heading);
            cmd.heading_mode = rng.random::<f32>() <= c.rel_heading_envs;
        } else {
            cmd.heading_mode = false;
        }
        cmd.standing = rng.random::<f32>() <= c.rel_standing_envs;
        cmd.time_left = uniform(rng, c.resampling_time_s);
    }

    /// Heading → yaw rate and standing → zero (IsaacLab `_update_command`).
    pub fn apply_command_modes(&self, cmd: &mut Command, state: &SimState) {
        let c = &self.spec.commands;
        if cmd.heading_mode {
            cmd.wz = heading_yaw_rate(
                cmd.heading,
                yaw_of(state.base_quat),
                c.heading_stiffness,
                c.ang_vel_z,
            );
        }
        if cmd.standing {
            cmd.vx = 0.0;
            cmd.vy = 0.0;
            cmd.wz = 0.0;
        }
    }

    /// Once per control step after resets (IsaacLab `CommandTerm.compute(dt)`): counts down the
    /// resampling timer, resamples when it runs out, then applies heading / standing modes.
    pub fn update_commands<R: Rng + ?Sized>(
        &self,
        env: &mut TaskEnvState,
        state: &SimState,
        rng: &mut R,
    ) {
        env.command.time_left -= self.spec.step_dt;
        if env.command.time_left <= 0.0 {
            self.resample_command(&mut env.command, rng);
        }
        self.apply_command_modes(&mut env.command, state);
    }

    /// Resets the bookkeeping of an env after its physics reset to `state` (origin: its tile
    /// origin). Resamples the command and the push timer.
    pub fn reset_env<R: Rng + ?Sized>(
        &self,
        env: &mut TaskEnvState,
        state: &SimState,
        origin: [f32; 3],
        rng: &mut R,
    ) {
        *env = TaskEnvState::new();
        env.origin = origin;
        env.last_joint_vel = state.joint_vel;
        self.resample_command(&mut env.command, rng);
        self.apply_command_modes(&mut env.command, state);
        let rz = &self.spec.randomization;
        env.push_time_left = if rz.pushes {
            uniform(rng, rz.push_interval_s)
        } else {
            f32::INFINITY
        };
    }

    /// Initial state for a physics reset on the tile with spawn `origin`.
    pub fn sample_reset<R: Rng + ?Sized>(
        &self,
        origin: [f32; 3],
        terrain: &Terrain,
        rng: &mut R,
    ) -> ResetSample {
        let r = &self.spec.randomization;
        let base_xy = [
            origin[0] + sym(rng, r.reset_base_xy),
            origin[1] + sym(rng, r.reset_base_xy),
        ];
        let ground_z = origin[2].max(terrain.height_at(base_xy[0], base_xy[1]));
        let yaw = sym(rng, r.reset_yaw);
        let v = r.reset_base_velocity;
        let lin_vel = [sym(rng, v), sym(rng, v), sym(rng, v)];
        let ang_vel = [sym(rng, v), sym(rng, v), sym(rng, v)];
        let mut joint_pos = [0.0; NUM_JOINTS];
        for i in 0..NUM_JOINTS {
            let s = uniform(rng, r.reset_joint_pos_scale);
            let l = self.soft_limits[i];
            joint_pos[i] = (self.robot.default_joint_pos[i] * s).clamp(l[0], l[1]);
        }
        ResetSample {
            base_xy,
            ground_z,
            yaw,
            lin_vel,
            ang_vel,
            joint_pos,
            joint_vel: [0.0; NUM_JOINTS],
        }
    }

    /// Friction, added base mass, CoM shift and joint/actuator dynamics for one env (drawn at
    /// start-up and again at every reset).
    pub fn sample_body_randomization<R: Rng + ?Sized>(&self, rng: &mut R) -> BodyRandomization {
        let r = &self.spec.randomization;
        let static_friction = uniform(rng, r.static_friction);
        let dynamic_friction = uniform(rng, r.dynamic_friction).min(static_friction);
        let added_base_mass = uniform(rng, r.added_base_mass);
        let h = r.base_com_offset;
        let base_com_offset = [sym(rng, h[0]), sym(rng, h[1]), sym(rng, h[2])];
        BodyRandomization {
            static_friction,
            dynamic_friction,
            added_base_mass,
            base_com_offset,
            joint_damping: uniform(rng, r.joint_damping),
            joint_friction: uniform(rng, r.joint_friction),
            motor_strength: uniform(rng, r.motor_strength),
            kp_scale: uniform(rng, r.kp_scale),
            kd_scale: uniform(rng, r.kd_scale),
            latency_s: uniform(rng, r.latency_s),
        }
    }

    /// Counts down the push timer; `Some([vx, vy])` (world base xy velocity to set) when a push
    /// is due (IsaacLab `push_by_setting_velocity`, interval mode).
    pub fn push_due<R: Rng + ?Sized>(
        &self,
        env: &mut TaskEnvState,
        rng: &mut R,
    ) -> Option<[f32; 2]> {
        if !self.spec.randomization.pushes {
            return None;
        }
        let interval = self.spec.randomization.push_interval_s;
        env.push_time_left -= self.spec.step_dt;
        if env.push_time_left > 0.0 {
            return None;
        }
        env.push_time_left = uniform(rng, interval);
        let v = self.spec.randomization.push_velocity_xy;
        Some([sym(rng, v), sym(rng, v)])
    }

    /// Terminations, rewards and bookkeeping for one env after a control step in which `action`
    /// (the output of [`Task::process_action`]) was applied and the physics produced `state`.
    pub fn evaluate(
        &self,
        env: &mut TaskEnvState,
        state: &SimState,
        action: &[f32; NUM_JOINTS],
        terrain: &Terrain,
    ) -> StepResult {
        self.evaluate_with_mean(env, state, action, None, terrain)
    }

    /// [`Task::evaluate`] where `action_rate_l2` differences the policy's mean action (`mean`,
    /// clipped like actions) instead of the sampled one: the deployed, deterministic policy is
    /// the mean, so its smoothness is what is penalised, and exploration noise — an unavoidable
    /// 2σ² per joint per step — is not (with `only_positive_rewards` that noise floor alone zeroed
    /// early rewards at a useful weight).
    pub fn evaluate_with_mean(
        &self,
        env: &mut TaskEnvState,
        state: &SimState,
        action: &[f32; NUM_JOINTS],
        mean: Option<&[f32; NUM_JOINTS]>,
        terrain: &Terrain,
    ) -> StepResult {
        let c = self.spec.action_clip;
        let alpha = self.spec.action_filter_alpha;
        // The mean's path through the action filter, as the deployed policy's targets move (the
        // applied `action` is already filtered).
        let smooth: [f32; NUM_JOINTS] = match mean {
            Some(m) => {
                std::array::from_fn(|j| filtered_action(env.last_mean_action[j], m[j], c, alpha))
            }
            None => *action,
        };
        let mut out = StepResult::default();
        env.episode.steps += 1;
        if !state.is_finite() {
            out.terminated = true;
            out.reason = DoneReason::NonFinite;
            env.last_reason = out.reason;
            return out;
        }
        let dt = self.spec.step_dt;
        let p = &self.spec.reward_params;
        let cmd = env.command;
        let v = state.lin_vel_b();
        let w = state.ang_vel_b();
        let g = projected_gravity(state.base_quat);

        // --- feet air time (IsaacLab ContactSensor air-time bookkeeping at the control rate)
        let mut first_contact = [false; NUM_FEET];
        for f in 0..NUM_FEET {
            let contact = state.foot_force[f] > p.contact_threshold;
            if contact {
                if env.air_time[f] > 0.0 {
                    env.last_air_time[f] = env.air_time[f] + dt;
                    first_contact[f] = true;
                }
                env.air_time[f] = 0.0;
                env.contact_time[f] += dt;
            } else {
                env.air_time[f] += dt;
                env.contact_time[f] = 0.0;
            }
        }

        // --- raw term values
        let mut raw = [0.0f32; NUM_REWARD_TERMS];
        let inv_var = 1.0 / (p.tracking_std * p.tracking_std);
        let (ex, ey) = (cmd.vx - v[0], cmd.vy - v[1]);
        let lin_err_sq = ex * ex + ey * ey;
        let ang_err = cmd.wz - w[2];
        raw[RewardTerm::TrackLinVelXyExp as usize] = (-lin_err_sq * inv_var).exp();
        raw[RewardTerm::TrackLinVelXyCoarseExp as usize] =
            (-lin_err_sq / (p.coarse_tracking_std * p.coarse_tracking_std)).exp();
        raw[RewardTerm::TrackAngVelZExp as usize] = (-ang_err * ang_err * inv_var).exp();
        raw[RewardTerm::LinVelZL2 as usize] = v[2] * v[2];
        raw[RewardTerm::AngVelXyL2 as usize] = w[0] * w[0] + w[1] * w[1];
        let mut torque = 0.0;
        let mut acc = 0.0;
        let mut rate = 0.0;
        let mut second = 0.0;
        let mut limits = 0.0;
        for j in 0..NUM_JOINTS {
            torque += state.joint_torque[j] * state.joint_torque[j];
            let a = (state.joint_vel[j] - env.last_joint_vel[j]) / dt;
            acc += a * a;
            let d = smooth[j] - env.last_mean_action[j];
            rate += d * d;
            let d2 = smooth[j] - 2.0 * env.last_mean_action[j] + env.prev_mean_action[j];
            second += d2 * d2;
            let l = self.soft_limits[j];
            let q = state.joint_pos[j];
            limits += (l[0] - q).max(0.0) + (q - l[1]).max(0.0);
        }
        raw[RewardTerm::DofTorquesL2 as usize] = torque;
        raw[RewardTerm::DofAccL2 as usize] = acc;
        raw[RewardTerm::ActionRateL2 as usize] = rate;
        // Needs two earlier actions of this episode (steps counts this one).
        if env.episode.steps >= 3 {
            raw[RewardTerm::ActionSmoothnessL2 as usize] = second;
        }
        raw[RewardTerm::DofPosLimits as usize] = limits;
        if cmd.xy_norm() > p.air_time_min_command {
            let mut air = 0.0;
            for f in 0..NUM_FEET {
                if first_contact[f] {
                    air += env.last_air_time[f] - p.air_time_threshold;
                }
            }
            raw[RewardTerm::FeetAirTime as usize] = air;
        }
        let n_pen = self.robot.num_penalised_bodies;
        raw[RewardTerm::UndesiredContacts as usize] = state.penalised_force[..n_pen]
            .iter()
            .filter(|f| **f > p.contact_threshold)
            .count() as f32;
        raw[RewardTerm::FlatOrientationL2 as usize] = g[0] * g[0] + g[1] * g[1];
        let height = state.base_pos[2] - terrain.height_at(state.base_pos[0], state.base_pos[1]);
        let dh = height - p.base_height_fraction * self.robot.standing_height;
        raw[RewardTerm::BaseHeightL2 as usize] = dh * dh;
        if cmd.xy_norm() > p.air_time_min_command || cmd.wz.abs() > p.air_time_min_command {
            raw[RewardTerm::TrotContact as usize] =
                trot_contact(&state.foot_force, p.contact_threshold);
            if self.spec.gait_clock_hz > 0.0 {
                // The phase the next observation shows (`steps` already counts this step).
                let phase = self.gait_phase(env);
                raw[RewardTerm::GaitClock as usize] =
                    gait_clock_match(&state.foot_force, p.contact_threshold, phase);
                let peak = p.feet_clearance_fraction * self.robot.standing_height;
                let target = gait_clock_swing_height(phase, peak);
                raw[RewardTerm::FeetClearance as usize] = state
                    .foot_sole
                    .iter()
                    .zip(target)
                    .filter(|(_, h)| *h > 0.0)
                    .map(|(sole, h)| {
                        let clearance = sole[2] - terrain.height_at(sole[0], sole[1]);
                        (h - clearance).max(0.0).powi(2)
                    })
                    .sum();
            }
        }
        let mut deviation = 0.0;
        for j in (0..NUM_JOINTS).step_by(3) {
            // Hip abduction joints (canonical order: abduction, flexion, knee per leg).
            deviation += (state.joint_pos[j] - self.robot.default_joint_pos[j]).abs();
        }
        raw[RewardTerm::JointDeviationL1 as usize] = deviation;

        let mut total = 0.0;
        for k in 0..NUM_REWARD_TERMS {
            let r = raw[k] * self.weights_dt[k];
            out.terms[k] = r;
            total += r;
            env.episode.terms[k] += r;
        }
        if p.only_positive_rewards {
            total = total.max(0.0);
        }
        out.reward = total;
        env.episode.ret += total;
        env.episode.lin_vel_err_sum += lin_err_sq.sqrt();
        env.episode.yaw_rate_err_sum += ang_err.abs();
        env.last_action = *action;
        env.prev_mean_action = env.last_mean_action;
        env.last_mean_action = smooth;
        env.last_joint_vel = state.joint_vel;

        // --- terminations
        let t = &self.spec.termination;
        if state.base_force > t.base_contact_threshold {
            out.terminated = true;
            out.reason = DoneReason::BaseContact;
        } else if let Some(max_tilt) = t.max_tilt_rad
            && (-g[2]).clamp(-1.0, 1.0).acos() > max_tilt
        {
            out.terminated = true;
            out.reason = DoneReason::Tilt;
        } else if let Some(min_h) = t.min_base_height
            && state.base_pos[2] - terrain.height_at(state.base_pos[0], state.base_pos[1]) < min_h
        {
            out.terminated = true;
            out.reason = DoneReason::TooLow;
        } else if env.episode.steps >= self.spec.max_episode_steps {
            out.truncated = true;
            out.reason = DoneReason::TimeOut;
        }
        env.last_reason = out.reason;
        out
    }

    /// Statistics of the episode that just ended in `state` (call before the reset).
    pub fn finish_episode(&self, env: &TaskEnvState, state: &SimState) -> EpisodeSummary {
        let e = &env.episode;
        let n = e.steps.max(1) as f32;
        let (dx, dy) = (
            state.base_pos[0] - env.origin[0],
            state.base_pos[1] - env.origin[1],
        );
        let distance = (dx * dx + dy * dy).sqrt();
        EpisodeSummary {
            ret: e.ret,
            length: e.steps,
            terms: e.terms,
            mean_lin_vel_error: e.lin_vel_err_sum / n,
            mean_yaw_rate_error: e.yaw_rate_err_sum / n,
            distance: if distance.is_finite() { distance } else { 0.0 },
            command_xy_norm: env.command.xy_norm(),
            reason: env.last_reason,
        }
    }

    /// Writes the observation of one env into `out` (length [`Task::obs_dim`]):
    /// `[v_b (3), ω_b (3), g_b (3), cmd (3), q − q_default (12), q̇ (12), last action (12)]`
    /// then, with the height scan, 187 values `clip(base_z − h − 0.5 + noise, −1, 1)`, then, with
    /// the gait clock, `[sin 2πφ, cos 2πφ]` ([`Task::gait_phase`], noise-free); additive
    /// uniform noise per [`crate::config::NoiseConfig`]; every entry clipped to ±`obs_clip`.
    pub fn observe<R: Rng + ?Sized>(
        &self,
        env: &TaskEnvState,
        state: &SimState,
        terrain: &Terrain,
        rng: &mut R,
        out: &mut [f32],
    ) -> Result<(), TaskError> {
        if out.len() != self.spec.obs_dim {
            return Err(TaskError::Length {
                what: "observation buffer",
                expected: self.spec.obs_dim,
                got: out.len(),
            });
        }
        let nz = &self.spec.noise;
        let on = nz.enabled;
        let mut put = |i: usize, x: f32, n: f32, rng: &mut R| {
            out[i] = if on && n > 0.0 {
                x + rng.random_range(-n..n)
            } else {
                x
            };
        };
        let v = state.lin_vel_b();
        let w = state.ang_vel_b();
        let g = projected_gravity(state.base_quat);
        let c = env.command.as_array();
        for k in 0..3 {
            put(k, v[k], nz.lin_vel, rng);
            put(3 + k, w[k], nz.ang_vel, rng);
            put(6 + k, g[k], nz.gravity, rng);
            put(COMMAND_OBS.start + k, c[k], 0.0, rng);
        }
        for j in 0..NUM_JOINTS {
            put(
                12 + j,
                state.joint_pos[j] - self.robot.default_joint_pos[j],
                nz.joint_pos,
                rng,
            );
            put(24 + j, state.joint_vel[j], nz.joint_vel, rng);
            put(36 + j, env.last_action[j], 0.0, rng);
        }
        if self.spec.height_scan {
            let scan = &mut out[PROPRIO_OBS..PROPRIO_OBS + HEIGHT_SCAN_OBS];
            terrain.sample_scan(state.base_pos, yaw_of(state.base_quat), scan);
            for s in scan.iter_mut() {
                let x = if on && nz.height_scan > 0.0 {
                    *s + rng.random_range(-nz.height_scan..nz.height_scan)
                } else {
                    *s
                };
                *s = x.clamp(-1.0, 1.0);
            }
        }
        if self.spec.gait_clock_hz > 0.0 {
            let at = PROPRIO_OBS
                + if self.spec.height_scan {
                    HEIGHT_SCAN_OBS
                } else {
                    0
                };
            out[at..at + GAIT_CLOCK_OBS]
                .copy_from_slice(&gait_clock_observation(self.gait_phase(env)));
        }
        let clip = self.spec.obs_clip;
        for o in out.iter_mut() {
            // NaN (only from a non-finite state) becomes 0 so that it never reaches the network.
            *o = if o.is_nan() {
                0.0
            } else {
                o.clamp(-clip, clip)
            };
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
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
    fn coarse_tracking_kernel_matches_hand_computation() {
        let mut cfg = EnvConfig {
            recipe: crate::config::Recipe::Isaaclab,
            ..EnvConfig::default()
        };
        cfg.terrain.preset = TerrainPreset::Flat;
        cfg.rewards.track_lin_vel_xy_coarse_exp = Some(0.8);
        cfg.reward_params.coarse_tracking_std = 1.2;
        let spec = cfg.resolve("a1").unwrap();
        let terrain = Terrain::generate(&spec.terrain).unwrap();
        let task = Task::new(spec, a1_params()).unwrap();
        let mut env = TaskEnvState::new();
        let mut st = standing_state();
        let mut rng = StdRng::seed_from_u64(1);
        task.reset_env(&mut env, &st, [0.0; 3], &mut rng);
        env.command = Command {
            vx: 1.0,
            vy: 0.0,
            wz: 0.0,
            time_left: 10.0,
            ..Default::default()
        };
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
}
