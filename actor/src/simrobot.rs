//! `l3p sim-robot` ([`run_sim_robot`]): the rapier simulator standing in for a real robot behind
//! its vendor-SDK bridge, on the same keys, so that the deploy path is testable without hardware.
//!
//! It steps physics in real time at the training rate (200 Hz), publishes [`RobotState`] at 200 or
//! 50 Hz on `l3p/robot/<id>/state`, and applies the latest [`RobotCommand`] from
//! `l3p/robot/<id>/command` as a joint PD (`τ = kp (q* − q) − kd q̇`, clipped like training). Like a
//! robot's low-level controller it owns a second watchdog: no command for `command_timeout_s` →
//! damping with the robot's training kd. Before the first command the joints are limp.

use std::time::{Duration, Instant};

use l3p_deploy::DeployError;
use l3p_deploy::controller::tilt_degrees;
use l3p_deploy::latest::{LatestSlot, now_unix_ns};
use l3p_deploy::pacer::Pacer;
use l3p_proto::{ControlMode, RobotCommand, RobotState, WIRE_VERSION, codec, keys};
use l3p_robot::catalog::{Gains, NUM_JOINTS, RobotSpec};
use l3p_robot::math::{Pose, Vec3};
use l3p_sim::actuator::Actuator;
use l3p_sim::world::{RobotBinding, SimConfig, SimWorld};
use l3p_task::task::SimState;
use serde::{Deserialize, Serialize};
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};
use zenoh::Wait;

#[derive(Debug, Clone)]
pub struct SimRobotOptions {
    pub robot: &'static RobotSpec,
    pub robot_id: String,
    /// State publication rate: 200 (every physics step) or 50.
    pub state_hz: u32,
    /// The operator's velocity command `(vx, vy, yaw rate)` sent in every state.
    pub command: [f32; 3],
    /// Stop after this long; `None`: until cancelled.
    pub duration: Option<Duration>,
    /// No command for this long → damping.
    pub command_timeout_s: f32,
}

/// What happened, printed as JSON when `l3p sim-robot` exits.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SimRobotSummary {
    pub robot: String,
    pub seconds: f64,
    pub states_published: u64,
    pub commands_received: u64,
    pub commands_rejected: u64,
    /// Physics steps spent under each mode of the applied command.
    pub steps_zero_torque: u64,
    pub steps_ramp: u64,
    pub steps_policy: u64,
    pub steps_damping: u64,
    /// Times the robot-side command watchdog fired.
    pub command_timeouts: u64,
    /// Seconds under policy commands.
    pub policy_seconds: f64,
    /// Lowest base height (m) and largest tilt (degrees) while under policy commands.
    pub policy_min_base_height: f32,
    pub policy_max_tilt_deg: f32,
    /// Mean base height (m) while under policy commands.
    pub policy_mean_base_height: f32,
    /// Base displacement (world x, y) while under policy commands, and mean forward speed.
    pub policy_displacement: [f32; 2],
    pub policy_mean_forward_velocity: f32,
    /// Nominal standing height of the robot (m), for scale.
    pub nominal_base_height: f32,
}

/// Runs the stand-in robot until cancelled or `opts.duration` has passed.
pub async fn run_sim_robot(
    session: &zenoh::Session,
    opts: SimRobotOptions,
    cancel: CancellationToken,
) -> Result<SimRobotSummary, DeployError> {
    keys::validate_segment("robot id", &opts.robot_id)
        .map_err(|e| DeployError::Config(e.to_string()))?;
    if !matches!(opts.state_hz, 50 | 200) {
        return Err(DeployError::Config(format!(
            "state rate {} Hz: expected 50 or 200",
            opts.state_hz
        )));
    }
    let zerr = |e: zenoh::Error| DeployError::Zenoh(e.to_string());
    let commands = LatestSlot::<RobotCommand>::subscribe(
        session,
        keys::robot_command(&opts.robot_id),
        &opts.robot_id,
        NUM_JOINTS,
        None,
    )
    .await?;
    let states = l3p_net::declare_control_publisher(session, keys::robot_state(&opts.robot_id))
        .await
        .map_err(zerr)?;

    let robot = opts.robot;
    let model = robot
        .model()
        .map_err(|e| DeployError::Robot(e.to_string()))?;
    let cfg = SimConfig::default();
    let mut sim = SimWorld::new(cfg);
    sim.add_flat_ground(0.0);
    let nominal = model.standing_height(&robot.model_order_pose(&model, &robot.default_pose));
    let limp = Actuator::from_spec(robot, Gains { kp: 0.0, kd: 0.0 });
    sim.add_robot(
        &model,
        &RobotBinding::from_spec(robot),
        limp,
        Pose::from_translation(Vec3::new(0.0, 0.0, nominal + 0.02)),
        &robot.default_pose,
    )
    .map_err(|e| DeployError::Robot(e.to_string()))?;
    info!(
        robot = robot.name,
        robot_id = %opts.robot_id,
        state_hz = opts.state_hz,
        "sim-robot up: joints limp until the first command"
    );

    let summary = tokio::task::spawn_blocking(move || {
        let physics_dt = Duration::from_secs_f32(cfg.dt);
        let publish_every = (200 / opts.state_hz) as u64;
        let mut pacer = Pacer::new(physics_dt);
        let start = Instant::now();
        let mut tally = Tally::new(robot.name, nominal);
        let mut state = SimState::default();
        let mut applied_seq = None;
        let mut timed_out = false;
        let mut seq = 0u64;
        let mut step = 0u64;
        let timeout = Duration::from_secs_f32(opts.command_timeout_s);
        while !cancel.is_cancelled() && opts.duration.is_none_or(|d| start.elapsed() < d) {
            let (now, _) = pacer.wait();
            let latest = commands.get();
            let mut mode = ControlMode::ZeroTorque;
            if let Some((cmd, at)) = latest {
                if now.saturating_duration_since(at) > timeout {
                    if !timed_out {
                        timed_out = true;
                        tally.summary.command_timeouts += 1;
                        warn!("no command for {:?}: damping", timeout);
                        let damp = Actuator::from_spec(
                            robot,
                            Gains {
                                kp: 0.0,
                                kd: robot.training_gains.kd,
                            },
                        );
                        sim.set_actuator(0, damp);
                    }
                    mode = ControlMode::Damping;
                } else {
                    timed_out = false;
                    mode = cmd.mode;
                    if applied_seq != Some(cmd.seq) {
                        applied_seq = Some(cmd.seq);
                        let mut act = limp;
                        act.kp.copy_from_slice(&cmd.kp);
                        act.kd.copy_from_slice(&cmd.kd);
                        sim.set_actuator(0, act);
                        let mut q = [0.0; NUM_JOINTS];
                        q.copy_from_slice(&cmd.joint_pos_target);
                        sim.set_targets(0, &q);
                    }
                }
            }
            sim.step();
            sim.read_state(0, &mut state);
            step += 1;
            tally.step(mode, &state, cfg.dt);
            if step.is_multiple_of(publish_every) {
                seq += 1;
                match codec::encode(&state_message(&opts, seq, &state)) {
                    Ok(bytes) => {
                        if states.put(bytes).wait().is_ok() {
                            tally.summary.states_published += 1;
                        }
                    }
                    Err(e) => warn!("cannot encode state: {e}"),
                }
            }
        }
        let mut summary = tally.finish(start.elapsed().as_secs_f64());
        summary.commands_received = commands.accepted();
        summary.commands_rejected = commands.rejected();
        summary
    })
    .await
    .map_err(|e| DeployError::Config(format!("sim-robot thread: {e}")))?;
    Ok(summary)
}

/// The state message a sim-robot publishes (`seq` counts messages, not physics steps).
fn state_message(opts: &SimRobotOptions, seq: u64, state: &SimState) -> RobotState {
    RobotState {
        wire_version: WIRE_VERSION,
        robot_id: opts.robot_id.clone(),
        seq,
        stamp_ns: now_unix_ns(),
        base_quat: state.base_quat,
        base_lin_vel: state.lin_vel_b(),
        base_ang_vel: state.ang_vel_b(),
        joint_pos: state.joint_pos.to_vec(),
        joint_vel: state.joint_vel.to_vec(),
        command: opts.command,
    }
}

/// The summary, counted physics step by physics step.
struct Tally {
    summary: SimRobotSummary,
    /// Base position when the policy first took control.
    policy_start: Option<[f32; 3]>,
    height_sum: f64,
}

impl Tally {
    /// For `robot`, whose nominal standing height is `nominal_base_height`.
    fn new(robot: &str, nominal_base_height: f32) -> Self {
        Tally {
            summary: SimRobotSummary {
                robot: robot.into(),
                // Lowered by every policy step; `finish` makes it 0 if none came.
                policy_min_base_height: f32::INFINITY,
                nominal_base_height,
                ..Default::default()
            },
            policy_start: None,
            height_sum: 0.0,
        }
    }

    /// One physics step of `dt` seconds in `mode`, ending in `state`.
    fn step(&mut self, mode: ControlMode, state: &SimState, dt: f32) {
        let summary = &mut self.summary;
        match mode {
            ControlMode::ZeroTorque => summary.steps_zero_torque += 1,
            ControlMode::Ramp => summary.steps_ramp += 1,
            ControlMode::Policy => summary.steps_policy += 1,
            ControlMode::Damping => summary.steps_damping += 1,
        }
        if mode == ControlMode::Policy {
            let start_pos = *self.policy_start.get_or_insert(state.base_pos);
            summary.policy_seconds += dt as f64;
            self.height_sum += state.base_pos[2] as f64;
            summary.policy_min_base_height = summary.policy_min_base_height.min(state.base_pos[2]);
            summary.policy_max_tilt_deg = summary
                .policy_max_tilt_deg
                .max(tilt_degrees(state.base_quat));
            summary.policy_displacement = [
                state.base_pos[0] - start_pos[0],
                state.base_pos[1] - start_pos[1],
            ];
        }
    }

    /// The summary after `seconds` of wall-clock: the policy's means (or a zero minimum height
    /// when the policy never ran).
    fn finish(self, seconds: f64) -> SimRobotSummary {
        let mut summary = self.summary;
        summary.seconds = seconds;
        if summary.policy_seconds > 0.0 {
            summary.policy_mean_forward_velocity =
                summary.policy_displacement[0] / summary.policy_seconds as f32;
            summary.policy_mean_base_height =
                (self.height_sum / summary.steps_policy.max(1) as f64) as f32;
        } else {
            summary.policy_min_base_height = 0.0;
        }
        summary
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f32, z: f32) -> SimState {
        let mut state = SimState::default();
        state.base_pos = [x, 0.0, z];
        state
    }

    #[test]
    fn the_tally_counts_modes_and_measures_only_the_policy_steps() {
        let mut tally = Tally::new("a1", 0.3);
        tally.step(ControlMode::ZeroTorque, &at(5.0, 0.1), 0.005);
        tally.step(ControlMode::Ramp, &at(5.0, 0.2), 0.005);
        // Two seconds of policy: 1 m forward, heights 0.30 and 0.26.
        tally.step(ControlMode::Policy, &at(1.0, 0.30), 1.0);
        tally.step(ControlMode::Policy, &at(2.0, 0.26), 1.0);
        tally.step(ControlMode::Damping, &at(9.0, 0.05), 0.005);
        let s = tally.finish(3.0);
        assert_eq!(
            (
                s.steps_zero_torque,
                s.steps_ramp,
                s.steps_policy,
                s.steps_damping
            ),
            (1, 1, 2, 1)
        );
        assert_eq!(s.policy_seconds, 2.0);
        assert_eq!(
            s.policy_displacement,
            [1.0, 0.0],
            "from where the policy took over"
        );
        assert_eq!(s.policy_mean_forward_velocity, 0.5);
        assert!((s.policy_mean_base_height - 0.28).abs() < 1e-6);
        assert_eq!(
            s.policy_min_base_height, 0.26,
            "the damping step's 0.05 is not the policy's"
        );
        assert_eq!(s.seconds, 3.0);
    }

    #[test]
    fn without_policy_steps_the_minimum_height_is_zero_not_infinite() {
        let mut tally = Tally::new("a1", 0.3);
        tally.step(ControlMode::ZeroTorque, &at(0.0, 0.3), 0.005);
        let s = tally.finish(1.0);
        assert_eq!(s.policy_min_base_height, 0.0);
        assert_eq!(s.policy_mean_forward_velocity, 0.0);
    }
}
