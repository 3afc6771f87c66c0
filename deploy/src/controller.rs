//! The safety state machine of the deploy loop, free of I/O and clocks so that it can be tested
//! tick by tick: [`Controller::tick`] takes the time, the latest robot state and the policy, and
//! returns the [`RobotCommand`] to publish.
//!
//! ```text
//!  start ──► ZeroTorque ──(first fresh state + zero_torque_s)──► Ramp ──(ramp_s)──► Policy
//!                 │                                               │                 │
//!                 └──────────── fault (stale state, tilt, NaN/inf action, operator) ┘
//!                                               ▼
//!                                            Damping ──(operator Resume, cause cleared)──► Ramp
//! ```
//!
//! Safety does not depend on the policy: targets are clipped to the soft joint limits in every mode;
//! damping (kp = 0, kd > 0) is latched and left only on an explicit operator `Resume`.

use l3p_infer::RobotIo;
use l3p_proto::{ControlMode, OperatorAction, RobotCommand, RobotState, WIRE_VERSION};
use l3p_task::task::{filtered_action, projected_gravity};
use serde::{Deserialize, Serialize};

use crate::heading::HeadingHold;
use crate::observation::ObservationBuilder;

/// Safety settings (`[deploy]` in the config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// A state older than this many control periods is stale → damping.
    pub stale_periods: f32,
    /// Base tilt (angle between base z and world z) beyond which → damping, degrees.
    pub max_tilt_deg: f32,
    /// Time spent limp after the first state arrives, seconds.
    pub zero_torque_s: f32,
    /// Time to interpolate from the measured pose to the default pose, seconds.
    pub ramp_s: f32,
    /// Damping gain in damping mode = this × the policy's training kd.
    pub damping_kd_scale: f32,
    /// On stop (operator `Stop`, SIGTERM, Ctrl-C) keep sending damping this long before exiting.
    pub stop_damping_s: f32,
    /// Stay limp after start-up until an operator `Resume` (for physical robots: a controller
    /// restarted by its service manager must not stand the robot up unattended).
    pub wait_for_operator: bool,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            stale_periods: 3.0,
            max_tilt_deg: 60.0,
            zero_torque_s: 0.5,
            ramp_s: 2.0,
            damping_kd_scale: 1.0,
            stop_damping_s: 1.0,
            wait_for_operator: false,
        }
    }
}

impl SafetyConfig {
    /// Checks ranges; errors name the key.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("stale_periods", self.stale_periods),
            ("max_tilt_deg", self.max_tilt_deg),
            ("damping_kd_scale", self.damping_kd_scale),
        ];
        for (k, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("deploy.{k} = {v}: expected a number > 0"));
            }
        }
        for (k, v) in [
            ("zero_torque_s", self.zero_torque_s),
            ("ramp_s", self.ramp_s),
            ("stop_damping_s", self.stop_damping_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("deploy.{k} = {v}: expected a number >= 0"));
            }
        }
        if self.max_tilt_deg > 180.0 {
            return Err(format!(
                "deploy.max_tilt_deg = {}: expected at most 180",
                self.max_tilt_deg
            ));
        }
        Ok(())
    }
}

/// Angle between the base's z axis and world z (degrees) for base orientation `quat` (w, x, y, z).
pub fn tilt_degrees(quat: [f32; 4]) -> f32 {
    let g = projected_gravity(quat);
    (-g[2]).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Why the controller went to damping.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The latest state is older than `stale_periods` periods.
    StaleState { age_s: f64 },
    /// The policy produced a non-finite action.
    NonFiniteAction,
    /// The base tilted past `max_tilt_deg`.
    Tilt { degrees: f32 },
    /// The operator asked for damping.
    Operator,
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fault::StaleState { age_s } => {
                write!(f, "stale robot state ({:.0} ms old)", age_s * 1e3)
            }
            Fault::NonFiniteAction => write!(f, "the policy produced a non-finite action"),
            Fault::Tilt { degrees } => write!(f, "base tilted {degrees:.0}°"),
            Fault::Operator => write!(f, "operator requested damping"),
        }
    }
}

/// The latest state and when it was received (controller clock, seconds).
#[derive(Debug, Clone, Copy)]
pub struct Latest<'a> {
    pub state: &'a RobotState,
    pub received_at: f64,
}

/// What one tick did.
#[derive(Debug, Clone)]
pub struct TickOutput {
    pub command: RobotCommand,
    /// Set on the tick that entered damping.
    pub new_fault: Option<Fault>,
    /// The policy ran on this tick.
    pub inferred: bool,
}

/// The policy as the controller sees it: observation in, raw action out.
pub trait PolicyFn {
    fn act(&mut self, obs: &[f32], action: &mut [f32]);
}

/// A loaded export with its inference buffers (allocation-free after the first tick).
pub struct ExportedPolicy {
    pub policy: l3p_infer::DeployPolicy,
    out: Vec<f32>,
    scratch: l3p_infer::InferScratch,
}

impl ExportedPolicy {
    pub fn new(policy: l3p_infer::DeployPolicy) -> Self {
        Self {
            policy,
            out: Vec::new(),
            scratch: l3p_infer::InferScratch::default(),
        }
    }
}

impl PolicyFn for ExportedPolicy {
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        // Dimensions were checked when the artifact was loaded; a failure here is reported as a
        // non-finite action so that the watchdog damps.
        match self.policy.act_into(obs, &mut self.out, &mut self.scratch) {
            Ok(()) if self.out.len() == action.len() => action.copy_from_slice(&self.out),
            _ => action.iter_mut().for_each(|a| *a = f32::NAN),
        }
    }
}

/// The deploy state machine for one robot.
#[derive(Debug, Clone)]
pub struct Controller {
    robot_id: String,
    io: RobotIo,
    action_scale: f32,
    safety: SafetyConfig,
    observations: ObservationBuilder,
    mode: ControlMode,
    fault: Option<Fault>,
    /// When the current mode began (ZeroTorque: when the first fresh state arrived).
    mode_since: Option<f64>,
    ramp_from: Vec<f32>,
    /// Start-up may leave zero-torque (always, unless `wait_for_operator`).
    armed: bool,
    last_action: Vec<f32>,
    /// Policy steps since policy mode began (the gait clock's time base, as `episode.steps` is
    /// in training).
    policy_ticks: u64,
    last_target: Vec<f32>,
    /// `Some`: a zero yaw-rate command holds the heading (`l3p deploy --heading-hold`).
    heading_hold: Option<HeadingHold>,
    obs: Vec<f32>,
    action: Vec<f32>,
    damping_kd: Vec<f32>,
    seq: u64,
}

impl Controller {
    pub fn new(
        robot_id: &str,
        io: RobotIo,
        action_scale: f32,
        safety: SafetyConfig,
    ) -> Result<Self, crate::DeployError> {
        safety.validate().map_err(crate::DeployError::Config)?;
        let observations = ObservationBuilder::new(&io)?;
        let n = io.joint_names.len();
        Ok(Self {
            robot_id: robot_id.to_string(),
            obs: vec![0.0; observations.obs_dim()],
            observations,
            action_scale,
            mode: ControlMode::ZeroTorque,
            fault: None,
            mode_since: None,
            ramp_from: io.default_joint_pos.clone(),
            armed: !safety.wait_for_operator,
            last_action: vec![0.0; n],
            policy_ticks: 0,
            last_target: io.default_joint_pos.clone(),
            heading_hold: None,
            action: vec![0.0; n],
            damping_kd: io
                .kd
                .iter()
                .map(|kd| kd * safety.damping_kd_scale)
                .collect(),
            safety,
            io,
            seq: 0,
        })
    }

    /// A zero yaw-rate command holds the heading the robot has when it becomes zero
    /// ([`HeadingHold`]), instead of asking the policy for a zero yaw rate.
    pub fn with_heading_hold(mut self) -> Self {
        self.heading_hold = Some(HeadingHold::default());
        self
    }

    pub fn mode(&self) -> ControlMode {
        self.mode
    }

    pub fn fault(&self) -> Option<&Fault> {
        self.fault.as_ref()
    }

    /// The observation built on the last policy tick.
    pub fn last_observation(&self) -> &[f32] {
        &self.obs
    }

    fn period(&self) -> f64 {
        self.io.control_dt as f64
    }

    fn is_stale(&self, now: f64, latest: Option<Latest<'_>>) -> Option<Fault> {
        let limit = self.safety.stale_periods as f64 * self.period();
        latest.and_then(|l| {
            let age_s = now - l.received_at;
            (age_s > limit).then_some(Fault::StaleState { age_s })
        })
    }

    fn tilt_fault(&self, state: &RobotState) -> Option<Fault> {
        let degrees = tilt_degrees(state.base_quat);
        (degrees > self.safety.max_tilt_deg).then_some(Fault::Tilt { degrees })
    }

    /// Applies an operator request. Returns an error message when `Resume` is refused.
    pub fn operator(
        &mut self,
        action: OperatorAction,
        now: f64,
        latest: Option<Latest<'_>>,
    ) -> Result<(), String> {
        match action {
            OperatorAction::Damp | OperatorAction::Stop => {
                if self.mode != ControlMode::Damping {
                    self.enter_damping(Fault::Operator, now);
                }
                Ok(())
            }
            OperatorAction::Resume if self.mode == ControlMode::ZeroTorque && !self.armed => {
                if latest.is_none() || self.is_stale(now, latest).is_some() {
                    return Err("cannot start: no fresh robot state".into());
                }
                self.armed = true;
                Ok(())
            }
            OperatorAction::Resume => {
                if self.mode != ControlMode::Damping {
                    return Err(format!("not in damping (mode {:?})", self.mode));
                }
                let Some(l) = latest else {
                    return Err("no robot state received".into());
                };
                if let Some(f) = self.is_stale(now, latest) {
                    return Err(format!("cannot resume: {f}"));
                }
                if let Some(f) = self.tilt_fault(l.state) {
                    return Err(format!("cannot resume: {f}"));
                }
                self.start_ramp(l.state, now);
                self.fault = None;
                Ok(())
            }
        }
    }

    fn enter_damping(&mut self, fault: Fault, now: f64) {
        self.mode = ControlMode::Damping;
        self.fault = Some(fault);
        self.mode_since = Some(now);
    }

    fn start_ramp(&mut self, state: &RobotState, now: f64) {
        self.mode = ControlMode::Ramp;
        self.mode_since = Some(now);
        self.ramp_from.clone_from(&state.joint_pos);
    }

    /// One control tick at time `now` (seconds, monotonic) with the latest valid state, if any.
    pub fn tick(
        &mut self,
        now: f64,
        latest: Option<Latest<'_>>,
        policy: &mut dyn PolicyFn,
    ) -> TickOutput {
        let mut new_fault = None;
        let mut inferred = false;
        // Watchdogs first: they do not depend on the policy.
        if self.mode != ControlMode::Damping {
            let fault = self.is_stale(now, latest).or_else(|| {
                matches!(self.mode, ControlMode::Ramp | ControlMode::Policy)
                    .then(|| latest.and_then(|l| self.tilt_fault(l.state)))
                    .flatten()
            });
            if let Some(f) = fault {
                self.enter_damping(f.clone(), now);
                new_fault = Some(f);
            }
        }
        // Mode transitions driven by time.
        match self.mode {
            ControlMode::ZeroTorque => match (self.mode_since, latest) {
                (None, Some(_)) => self.mode_since = Some(now),
                (Some(since), Some(l))
                    if self.armed && now - since >= self.safety.zero_torque_s as f64 =>
                {
                    self.start_ramp(l.state, now);
                }
                _ => {}
            },
            ControlMode::Ramp => {
                if let Some(since) = self.mode_since
                    && now - since >= self.safety.ramp_s as f64
                {
                    self.mode = ControlMode::Policy;
                    self.mode_since = Some(now);
                    self.last_action.iter_mut().for_each(|a| *a = 0.0);
                    self.policy_ticks = 0;
                    if let Some(hold) = &mut self.heading_hold {
                        hold.reset();
                    }
                }
            }
            ControlMode::Policy | ControlMode::Damping => {}
        }
        let n = self.io.joint_names.len();
        let measured = latest.map(|l| l.state.joint_pos.as_slice());
        let (mut target, kp, kd) = match self.mode {
            ControlMode::ZeroTorque => (
                measured.map_or_else(|| self.last_target.clone(), <[f32]>::to_vec),
                vec![0.0; n],
                vec![0.0; n],
            ),
            ControlMode::Damping => (
                measured.map_or_else(|| self.last_target.clone(), <[f32]>::to_vec),
                vec![0.0; n],
                self.damping_kd.clone(),
            ),
            ControlMode::Ramp => {
                let since = self.mode_since.unwrap_or(now);
                let s = if self.safety.ramp_s > 0.0 {
                    ((now - since) / self.safety.ramp_s as f64).clamp(0.0, 1.0) as f32
                } else {
                    1.0
                };
                let target = self
                    .ramp_from
                    .iter()
                    .zip(&self.io.default_joint_pos)
                    .map(|(from, to)| from + s * (to - from))
                    .collect();
                (target, self.io.kp.clone(), self.io.kd.clone())
            }
            ControlMode::Policy => {
                // Policy mode implies a fresh state (stale → damping above).
                let state = latest.map(|l| l.state);
                match state {
                    Some(state) => {
                        let command = match &mut self.heading_hold {
                            Some(hold) => hold.command(state.command, state.base_quat),
                            None => state.command,
                        };
                        self.observations.build_with_command(
                            state,
                            command,
                            &self.last_action,
                            self.policy_ticks,
                            &mut self.obs,
                        );
                        self.policy_ticks += 1;
                        policy.act(&self.obs, &mut self.action);
                        inferred = true;
                        if self.action.iter().all(|a| a.is_finite()) {
                            // The training task's action path (`Task::process_action`):
                            // clip, then the contract's low-pass filter.
                            let clip = self.io.action_clip;
                            let alpha = self.io.action_filter_alpha;
                            for (a, prev) in self.action.iter_mut().zip(&self.last_action) {
                                *a = filtered_action(*prev, *a, clip, alpha);
                            }
                            self.last_action.clone_from(&self.action);
                            let target = self
                                .io
                                .default_joint_pos
                                .iter()
                                .zip(&self.action)
                                .map(|(d, a)| d + self.action_scale * a)
                                .collect();
                            (target, self.io.kp.clone(), self.io.kd.clone())
                        } else {
                            self.enter_damping(Fault::NonFiniteAction, now);
                            new_fault = Some(Fault::NonFiniteAction);
                            (
                                state.joint_pos.clone(),
                                vec![0.0; n],
                                self.damping_kd.clone(),
                            )
                        }
                    }
                    None => {
                        self.enter_damping(
                            Fault::StaleState {
                                age_s: f64::INFINITY,
                            },
                            now,
                        );
                        (
                            self.last_target.clone(),
                            vec![0.0; n],
                            self.damping_kd.clone(),
                        )
                    }
                }
            }
        };
        for (t, l) in target.iter_mut().zip(&self.io.soft_joint_limits) {
            *t = if t.is_finite() {
                t.clamp(l[0], l[1])
            } else {
                0.5 * (l[0] + l[1])
            };
        }
        self.last_target.clone_from(&target);
        self.seq += 1;
        TickOutput {
            command: RobotCommand {
                wire_version: WIRE_VERSION,
                robot_id: self.robot_id.clone(),
                seq: self.seq,
                stamp_ns: 0,
                mode: self.mode,
                joint_pos_target: target,
                kp,
                kd,
            },
            new_fault,
            inferred,
        }
    }
}
