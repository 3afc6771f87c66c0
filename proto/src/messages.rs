//! Message structs. Plain data with serde; constructors fill in [`WIRE_VERSION`].

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::{WIRE_VERSION, WireMessage};

/// Statistics of one finished episode, reported by the actor that ran it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeStats {
    /// Undiscounted sum of rewards.
    pub episode_return: f32,
    /// Length in control steps.
    pub length: u32,
    /// Terrain level at the end of the episode (after the curriculum update).
    pub terrain_level: f32,
    /// Terrain type index (column type) the episode ran on.
    pub terrain_type: u8,
    /// Mean |v_xy − cmd_xy| over the episode, m/s.
    pub lin_vel_error: f32,
    /// Mean |ω_z − cmd_yaw| over the episode, rad/s.
    pub yaw_rate_error: f32,
    /// `true` if the episode ended by termination (fall, base contact), `false` if by time-out.
    pub terminated: bool,
    /// Per reward term, the sum over the episode of its weighted value, in the order of the
    /// chunk's [`RolloutChunk::reward_terms`] (empty when the actor does not report terms).
    pub reward_terms: Vec<f32>,
}

/// Most reward terms a chunk may name.
pub const MAX_REWARD_TERMS: usize = 64;

/// One actor's rollout for one policy version: `steps` control steps of `num_envs` environments.
///
/// # Layout
/// Arrays are flat, row-major `[steps, num_envs, dim]`: `observations` and `action_means` /
/// `action_stds` / `actions` have `dim` = `obs_dim` / `action_dim`; `log_probs`, `rewards`,
/// `terminated`, `truncated` are `[steps, num_envs]`; `last_observations` is `[num_envs, obs_dim]`, the
/// observation after the last step, for bootstrapping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolloutChunk {
    pub wire_version: u32,
    pub run: String,
    pub robot: String,
    pub actor_id: String,
    /// Policy version that produced the actions (behaviour policy).
    pub policy_version: u64,
    /// Sequence number of this chunk from this actor, starting at 0.
    pub seq: u64,
    pub num_envs: u32,
    pub steps: u32,
    pub obs_dim: u32,
    pub action_dim: u32,
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    /// Behaviour log-probability of each action (summed over action dimensions).
    pub log_probs: Vec<f32>,
    pub action_means: Vec<f32>,
    pub action_stds: Vec<f32>,
    pub rewards: Vec<f32>,
    /// The episode ended by failure: no bootstrapping.
    pub terminated: Vec<bool>,
    /// The episode ended by time-out: bootstrapped with the value of the state.
    pub truncated: Vec<bool>,
    pub last_observations: Vec<f32>,
    /// Names of the reward terms in each episode's `reward_terms`.
    pub reward_terms: Vec<String>,
    /// Episodes that finished during this chunk.
    pub episodes: Vec<EpisodeStats>,
    /// Seconds the actor spent producing this chunk (simulation + inference).
    pub collect_seconds: f32,
    /// Seconds the actor spent on the wire for this chunk: fetching its policy's weights plus
    /// encoding and sending its previous chunk.
    pub transport_seconds: f32,
    /// Where `collect_seconds` went, by stage (`physics`, `inference`, `observations`, `rewards`,
    /// `resets`, ...; seconds, at most [`MAX_STAGES`] entries).
    pub stage_seconds: Vec<(String, f32)>,
}

/// Most entries of [`RolloutChunk::stage_seconds`].
pub const MAX_STAGES: usize = 16;
wire_message!(RolloutChunk, "rollout chunk");

impl RolloutChunk {
    /// An all-zero chunk of the given shape, ready to be filled.
    pub fn zeros(
        run: &str,
        robot: &str,
        actor_id: &str,
        policy_version: u64,
        num_envs: usize,
        steps: usize,
        obs_dim: usize,
        action_dim: usize,
    ) -> Self {
        let samples = num_envs * steps;
        Self {
            wire_version: WIRE_VERSION,
            run: run.into(),
            robot: robot.into(),
            actor_id: actor_id.into(),
            policy_version,
            seq: 0,
            num_envs: num_envs as u32,
            steps: steps as u32,
            obs_dim: obs_dim as u32,
            action_dim: action_dim as u32,
            observations: vec![0.0; samples * obs_dim],
            actions: vec![0.0; samples * action_dim],
            log_probs: vec![0.0; samples],
            action_means: vec![0.0; samples * action_dim],
            action_stds: vec![0.0; samples * action_dim],
            rewards: vec![0.0; samples],
            terminated: vec![false; samples],
            truncated: vec![false; samples],
            last_observations: vec![0.0; num_envs * obs_dim],
            reward_terms: Vec::new(),
            episodes: Vec::new(),
            collect_seconds: 0.0,
            transport_seconds: 0.0,
            stage_seconds: Vec::new(),
        }
    }

    /// Number of transitions (`steps × num_envs`).
    pub fn samples(&self) -> usize {
        self.steps as usize * self.num_envs as usize
    }
}

/// Per-robot entry of a [`PolicyAnnounce`]: where to fetch the weights and how to check them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotWeights {
    pub robot: String,
    /// Hex sha256 of the weights blob's `bytes`.
    pub sha256: String,
    pub size: u64,
    pub obs_dim: u32,
    pub action_dim: u32,
}

/// The learner announces a new policy version (JSON, small). Actors fetch weights by query.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PolicyAnnounce {
    pub wire_version: u32,
    pub run: String,
    pub version: u64,
    /// Identifies one learner process (its start time, ms): a restarted learner may announce a
    /// version an actor already collected for its predecessor, and must still get a chunk.
    pub incarnation: u64,
    /// Training mode (`mlp`, `l3p`, `mlp-transfer`, `l3p-transfer`).
    pub mode: String,
    pub robots: Vec<RobotWeights>,
    /// Maximum accepted policy lag: chunks older than `version − max_policy_lag` are dropped.
    pub max_policy_lag: u64,
}
wire_message!(PolicyAnnounce, "policy announce");

/// Serialized policy weights for one robot and version (binary). `format` names the encoding of
/// `bytes` (e.g. `l3p-export-v1`, safetensors + JSON config).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct WeightsBlob {
    pub wire_version: u32,
    pub run: String,
    pub robot: String,
    pub version: u64,
    pub format: String,
    pub sha256: String,
    #[serde(with = "serde_bytes")]
    pub bytes: Vec<u8>,
}
wire_message!(WeightsBlob, "weights blob");

/// A metrics record (JSON on the wire, one line in the run's metrics file). Non-finite values are
/// dropped by [`MetricsRecord::insert`] because JSON has no NaN.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricsRecord {
    pub wire_version: u32,
    pub run: String,
    /// Who produced it: `learner`, `actor-<robot>-<id>`, `deploy-<id>`, ...
    pub source: String,
    /// Learner iteration (policy version) this record belongs to.
    pub iteration: u64,
    /// Milliseconds since the Unix epoch.
    pub unix_ms: u64,
    pub values: BTreeMap<String, f64>,
}
wire_message!(MetricsRecord, "metrics record");

impl MetricsRecord {
    pub fn new(run: &str, source: &str, iteration: u64, unix_ms: u64) -> Self {
        Self {
            wire_version: WIRE_VERSION,
            run: run.into(),
            source: source.into(),
            iteration,
            unix_ms,
            values: BTreeMap::new(),
        }
    }

    /// Record the means of finished episodes: `episodes`, `episode_return`, `episode_length`,
    /// `terrain_level` (and `terrain_level/type<k>` per terrain type), `lin_vel_error`,
    /// `yaw_rate_error`, `fall_fraction`. Without episodes only `episodes = 0` is recorded.
    pub fn insert_episode_means<'a>(
        &mut self,
        episodes: impl IntoIterator<Item = &'a EpisodeStats>,
    ) {
        let episodes: Vec<&EpisodeStats> = episodes.into_iter().collect();
        self.insert("episodes", episodes.len() as f64);
        if episodes.is_empty() {
            return;
        }
        let n = episodes.len() as f64;
        let mean = |f: fn(&EpisodeStats) -> f64| episodes.iter().map(|e| f(e)).sum::<f64>() / n;
        self.insert("episode_return", mean(|e| e.episode_return as f64));
        self.insert("episode_length", mean(|e| e.length as f64));
        self.insert("terrain_level", mean(|e| e.terrain_level as f64));
        self.insert("lin_vel_error", mean(|e| e.lin_vel_error as f64));
        self.insert("yaw_rate_error", mean(|e| e.yaw_rate_error as f64));
        self.insert(
            "fall_fraction",
            mean(|e| if e.terminated { 1.0 } else { 0.0 }),
        );
        let mut by_type: BTreeMap<u8, (f64, f64)> = BTreeMap::new();
        for e in &episodes {
            let slot = by_type.entry(e.terrain_type).or_default();
            slot.0 += e.terrain_level as f64;
            slot.1 += 1.0;
        }
        for (kind, (sum, count)) in by_type {
            self.insert(&format!("terrain_level/type{kind}"), sum / count);
        }
    }

    /// Record `Episode_Reward/<term>` (IsaacLab's and rsl_rl's name): per reward term, the mean over
    /// finished episodes of the term's sum over the episode. `chunks` gives each chunk's term names
    /// and episodes; terms of the same name from several chunks (robots) are averaged together.
    pub fn insert_reward_term_means<'a>(
        &mut self,
        chunks: impl IntoIterator<Item = (&'a [String], &'a [EpisodeStats])>,
    ) {
        let mut sums: BTreeMap<&str, (f64, f64)> = BTreeMap::new();
        for (names, episodes) in chunks {
            for e in episodes {
                for (name, v) in names.iter().zip(&e.reward_terms) {
                    let slot = sums.entry(name.as_str()).or_default();
                    slot.0 += *v as f64;
                    slot.1 += 1.0;
                }
            }
        }
        for (name, (sum, count)) in sums {
            self.insert(&format!("Episode_Reward/{name}"), sum / count);
        }
    }

    /// Insert a value; non-finite values are skipped (returns `false`).
    pub fn insert(&mut self, key: &str, value: f64) -> bool {
        if value.is_finite() {
            self.values.insert(key.to_string(), value);
            true
        } else {
            false
        }
    }
}

/// Robot state published by the robot (or `l3p sim-robot`) at 50–200 Hz; the deploy controller keeps
/// only the latest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotState {
    pub wire_version: u32,
    pub robot_id: String,
    pub seq: u64,
    /// Sender's clock, nanoseconds since the Unix epoch.
    pub stamp_ns: u64,
    /// Base orientation quaternion (w, x, y, z), world frame, Z up.
    pub base_quat: [f32; 4],
    /// Base linear velocity in the base frame (estimated on hardware), m/s.
    pub base_lin_vel: [f32; 3],
    /// Base angular velocity in the base frame (IMU gyro), rad/s.
    pub base_ang_vel: [f32; 3],
    /// Joint positions in the robot's canonical joint order, rad.
    pub joint_pos: Vec<f32>,
    /// Joint velocities, rad/s.
    pub joint_vel: Vec<f32>,
    /// Velocity command (vx, vy, yaw rate) the operator gives the policy.
    pub command: [f32; 3],
}
wire_message!(RobotState, "robot state");

/// What the controller is doing; the robot applies `τ = kp (q* − q) − kd q̇` in every mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ControlMode {
    /// kp = kd = 0: the motors are limp.
    ZeroTorque,
    /// Interpolating from the measured pose to the default pose.
    Ramp,
    /// Targets come from the policy.
    Policy,
    /// kp = 0, kd > 0: safe stop after a fault.
    Damping,
}

/// Joint targets and gains sent by the deploy controller at 50 Hz.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotCommand {
    pub wire_version: u32,
    pub robot_id: String,
    pub seq: u64,
    pub stamp_ns: u64,
    pub mode: ControlMode,
    pub joint_pos_target: Vec<f32>,
    pub kp: Vec<f32>,
    pub kd: Vec<f32>,
}
wire_message!(RobotCommand, "robot command");

/// What an operator asks a running deploy controller to do (`l3p operate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum OperatorAction {
    /// Leave damping (after a fault or `Damp`): ramp to the default pose, then run the policy.
    /// Refused while the fault's cause persists.
    Resume,
    /// Go to damping now and stay there until `Resume`.
    Damp,
    /// Damp, then exit the controller.
    Stop,
}

/// An operator request on `l3p/robot/<id>/operator`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatorCommand {
    pub wire_version: u32,
    pub robot_id: String,
    pub action: OperatorAction,
    /// Sender's clock, nanoseconds since the Unix epoch (for logs).
    pub stamp_ns: u64,
}
wire_message!(OperatorCommand, "operator command");

/// The deploy controller's status, published as JSON on `l3p/robot/<id>/deploy/status` about once a
/// second and on every mode change (so that any Zenoh client can watch it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeployStatus {
    pub wire_version: u32,
    pub robot_id: String,
    pub robot: String,
    /// `name@version` of the policy being run.
    pub policy: String,
    pub mode: ControlMode,
    /// Why the controller is in damping (`None` otherwise).
    pub fault: Option<String>,
    /// Control ticks so far.
    pub ticks: u64,
    /// Commands published so far.
    pub commands: u64,
    /// Ticks that started later than one full period after their deadline.
    pub overruns: u64,
    /// State messages rejected (malformed, wrong robot id or joint count, NaN).
    pub rejected_states: u64,
    /// |actual − nominal| tick period, microseconds: median and 99th percentile so far.
    pub period_error_p50_us: f64,
    pub period_error_p99_us: f64,
    /// Policy inference (observation → action) latency, microseconds: median and 99th percentile.
    pub inference_p50_us: f64,
    pub inference_p99_us: f64,
    /// Set while the controller runs over links that anyone on the network can use (`l3p deploy
    /// --insecure`), saying which; absent otherwise, and in statuses of older controllers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warning: Option<String>,
}
wire_message!(DeployStatus, "deploy status");
