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
//! Files: this one holds [`Task`] and its per-robot parameters; `task/state.rs` the data types,
//! `task/frames.rs` the quaternion and heading math, `task/clock.rs` the gait clock, `task/tests.rs`
//! the unit tests. Everything is re-exported here, so paths stay `task::…`.
//!
//! Step order follows IsaacLab's `ManagerBasedRLEnv.step`: terminations and rewards are computed on
//! the post-physics state with the command the policy saw; resets; then commands; then
//! observations (of the reset state for reset envs).

use rand::Rng;
use thiserror::Error;

use crate::config::{COMMAND_OBS, GAIT_CLOCK_OBS, HEIGHT_SCAN_OBS, PROPRIO_OBS, TaskSpec};
pub use crate::config::{NUM_REWARD_TERMS, RewardTerm};
use crate::terrain::Terrain;
use l3p_robot::catalog::{Family, RobotSpec};
use l3p_robot::model::RobotModel;

pub use l3p_robot::catalog::NUM_JOINTS;
/// Feet of every supported robot.
pub const NUM_FEET: usize = 4;
pub use l3p_robot::catalog::MAX_PENALISED_BODIES;

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

mod clock;
mod frames;
mod state;

pub use clock::{
    gait_clock_match, gait_clock_observation, gait_clock_phase, gait_clock_stance,
    gait_clock_swing_height, trot_contact,
};
pub use frames::{
    heading_yaw_rate, projected_gravity, quat_from_yaw, quat_from_yaw_and_tilt,
    quat_rotate_inverse, wrap_to_pi, yaw_of,
};
pub use state::{
    BodyRandomization, Command, DoneReason, EpisodeStats, EpisodeSummary, MovingMean, ResetSample,
    SimState, StepResult, TaskEnvState,
};

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
    /// The task's per-robot constants: default pose, URDF joint limits (±π where the URDF has none),
    /// soft-limit factor (0.95 ANYmal, 0.9 otherwise, as IsaacLab), action scale. Training and
    /// deployment both build it here (`RobotTaskParams::of`) so that they clip to the same soft limits.
    pub fn of(spec: &RobotSpec, model: &RobotModel) -> RobotTaskParams {
        let mut limits = [[-std::f32::consts::PI, std::f32::consts::PI]; NUM_JOINTS];
        for (k, name) in spec.joint_names.iter().enumerate() {
            if let Some(b) = model.body_of_joint(name)
                && let Some((lo, hi)) = model.bodies[b].joint.as_ref().and_then(|j| j.limits)
            {
                limits[k] = [lo, hi];
            }
        }
        RobotTaskParams {
            name: spec.name.to_string(),
            default_joint_pos: spec.default_pose,
            joint_pos_limits: limits,
            soft_limit_factor: if spec.family == Family::Anymal {
                0.95
            } else {
                0.9
            },
            action_scale: spec.action_scale,
            num_penalised_bodies: spec.penalised_links.len().min(MAX_PENALISED_BODIES),
            standing_height: model
                .standing_height(&spec.model_order_pose(model, &spec.default_pose)),
        }
    }

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
            let phase = gait_clock_phase(
                env.episode.steps as u64,
                self.spec.gait_clock_hz,
                self.spec.step_dt,
            ) + self.spec.gait_clock_start;
            phase - phase.floor()
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

    /// With `commands.heading_hold`, a fresh command in heading mode keeps the heading the robot
    /// has now instead of its random draw (`l3p eval --heading-hold`: walk straight on, corrected).
    fn hold_heading(&self, cmd: &mut Command, state: &SimState) {
        if self.spec.commands.heading_hold && cmd.heading_mode {
            cmd.heading = yaw_of(state.base_quat);
        }
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
            self.hold_heading(&mut env.command, state);
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
        self.hold_heading(&mut env.command, state);
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
        let yaw_std = p.yaw_tracking_std.unwrap_or(p.tracking_std);
        raw[RewardTerm::TrackAngVelZExp as usize] =
            (-ang_err * ang_err / (yaw_std * yaw_std)).exp();
        raw[RewardTerm::TrackAngVelZCoarseExp as usize] =
            (-ang_err * ang_err / (p.coarse_tracking_std * p.coarse_tracking_std)).exp();
        let mean = env.yaw_error_window.push(ang_err, p.yaw_mean_window_s, dt);
        raw[RewardTerm::TrackYawRateMeanExp as usize] =
            (-mean * mean / (p.yaw_mean_std * p.yaw_mean_std)).exp();
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
                        let ground =
                            terrain.max_height_within(sole[0], sole[1], p.feet_clearance_radius);
                        let clearance = sole[2] - ground;
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
        } else if env.episode.steps + env.time_out_head_start >= self.spec.max_episode_steps {
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
mod tests;
