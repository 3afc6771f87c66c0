//! The rollout actor: one robot morphology, `N` simulated environments, local policy inference, and
//! the Zenoh side of collecting experience for the learner.
//!
//! Main types: [`RolloutEnv`] (what the actor needs from a vectorised environment; implemented for
//! `l3p_sim::vecenv::VecEnv`), [`Collector`] (fills a [`RolloutChunk`] with `steps` control steps under one
//! policy version), [`ActorOptions`] and [`run`] (the daemon loop), [`announce::AnnounceTracker`]
//! (which policy to collect with next: a pure, unit-tested state machine).
//!
//! Daemon loop: declare a liveliness token `l3p/<run>/actors/<robot>/<actor>`; wait for a policy
//! announce newer than the last version collected; fetch that version's weights by query and check
//! their sha256 against the announce; collect a chunk on a blocking thread; publish it with
//! `CongestionControl::Block` (Zenoh's default `Drop` silently loses large messages); publish episode
//! metrics; repeat. A restarted actor simply joins at the version currently announced.
//!
//! [`simrobot::run_sim_robot`] (`l3p sim-robot`) is the simulator standing in for a real robot on the
//! deploy controller's keys; it lives here, with the simulator, so that `l3p-deploy` links no rapier.

pub mod announce;
pub mod simrobot;

pub use simrobot::{SimRobotOptions, SimRobotSummary, run_sim_robot};

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use l3p_infer::{DeployPolicy, InferScratch};
use l3p_proto::{
    EpisodeStats, MetricsRecord, PolicyAnnounce, RolloutChunk, WeightsBlob, codec, keys,
};
use l3p_robot::catalog::RobotSpec;
use l3p_sim::vecenv::VecEnv;
use l3p_task::config::EnvConfig;
use l3p_task::gait::{GaitReport, TrackingSummary};
use l3p_task::task::DoneReason;
use rand::SeedableRng;
use rand::rngs::StdRng;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};
use zenoh::Session;

use announce::{AnnounceTracker, Next};

/// What the actor needs from a vectorised environment.
pub trait RolloutEnv: Send + 'static {
    fn num_envs(&self) -> usize;
    fn obs_dim(&self) -> usize;
    fn action_dim(&self) -> usize;
    /// Current observations `[num_envs, obs_dim]` (after the last step's resets).
    fn observations(&self) -> &[f32];
    /// Advance every env by one control step with `actions [num_envs, action_dim]`; write per-env
    /// rewards and end flags and append the episodes that finished.
    fn step(
        &mut self,
        actions: &[f32],
        rewards: &mut [f32],
        terminated: &mut [bool],
        truncated: &mut [bool],
        episodes: &mut Vec<EpisodeStats>,
    ) -> Result<(), ActorError>;
    /// Mean base height above the ground under it over the envs (m), where the env knows it.
    fn mean_base_height(&self) -> Option<f32> {
        None
    }
    /// The policy's mean actions behind the next `step`'s sampled actions (smoothness penalties
    /// use them, where the env supports it).
    fn set_action_means(&mut self, _means: &[f32]) {}
    /// Names of the reward terms each finished episode reports (`EpisodeStats::reward_terms`).
    fn reward_term_names(&self) -> Vec<String> {
        Vec::new()
    }
    /// Seconds spent per simulation stage since the last call (`physics`, `observations`,
    /// `rewards`, `resets`, `env_total`), then clears them; empty where the env does not time them.
    fn take_stage_seconds(&mut self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// Starts gait diagnostics, where the env can measure them.
    fn enable_gait_meter(&mut self) {}
    /// Gait diagnostics since [`RolloutEnv::enable_gait_meter`].
    fn gait_report(&self) -> Option<GaitReport> {
        None
    }
}

/// The rapier locomotion environment as a [`RolloutEnv`].
pub struct SimEnv {
    pub env: VecEnv,
    obs: Vec<f32>,
}

impl SimEnv {
    pub fn new(mut env: VecEnv) -> Self {
        let obs = env.reset_all().to_vec();
        Self { env, obs }
    }
}

/// Build the simulated environment of an actor.
pub fn sim_env(
    robot: &RobotSpec,
    config: &EnvConfig,
    envs: usize,
    threads: usize,
    seed: u64,
) -> Result<SimEnv, ActorError> {
    let env = VecEnv::new(robot, config, envs, threads, seed)
        .map_err(|e| ActorError::Env(e.to_string()))?;
    Ok(SimEnv::new(env))
}

impl RolloutEnv for SimEnv {
    fn num_envs(&self) -> usize {
        self.env.num_envs()
    }
    fn obs_dim(&self) -> usize {
        self.env.obs_dim()
    }
    fn action_dim(&self) -> usize {
        self.env.action_dim()
    }
    fn observations(&self) -> &[f32] {
        &self.obs
    }
    fn step(
        &mut self,
        actions: &[f32],
        rewards: &mut [f32],
        terminated: &mut [bool],
        truncated: &mut [bool],
        episodes: &mut Vec<EpisodeStats>,
    ) -> Result<(), ActorError> {
        let out = self
            .env
            .step(actions)
            .map_err(|e| ActorError::Env(e.to_string()))?;
        self.obs.copy_from_slice(out.obs);
        rewards.copy_from_slice(out.rewards);
        terminated.copy_from_slice(out.terminated);
        truncated.copy_from_slice(out.truncated);
        episodes.extend(out.episodes.iter().map(|e| EpisodeStats {
            episode_return: e.ret,
            length: e.length,
            terrain_level: e.terrain_level as f32,
            terrain_type: e.terrain_type.index() as u8,
            lin_vel_error: e.lin_vel_error,
            yaw_rate_error: e.yaw_rate_error,
            terminated: e.reason != DoneReason::TimeOut,
            reward_terms: e.terms.to_vec(),
        }));
        Ok(())
    }
    fn mean_base_height(&self) -> Option<f32> {
        let terrain = self.env.terrain();
        let n = self.env.num_envs();
        let sum: f32 = (0..n)
            .filter_map(|e| self.env.robot_state(e))
            .map(|s| s.base_pos[2] - terrain.height_at(s.base_pos[0], s.base_pos[1]))
            .sum();
        (n > 0).then(|| sum / n as f32)
    }
    fn set_action_means(&mut self, means: &[f32]) {
        // A length mismatch is a bug in the caller; the step then penalises the sampled actions.
        let _ = self.env.set_action_means(means);
    }
    fn reward_term_names(&self) -> Vec<String> {
        l3p_task::task::RewardTerm::ALL
            .iter()
            .map(|t| t.as_str().to_string())
            .collect()
    }
    fn take_stage_seconds(&mut self) -> Vec<(&'static str, f64)> {
        let t = self.env.timings();
        self.env.reset_timings();
        vec![
            ("physics", t.physics.as_secs_f64()),
            ("observations", t.observations.as_secs_f64()),
            ("rewards", t.rewards.as_secs_f64()),
            ("resets", t.resets.as_secs_f64()),
            ("env_total", t.total.as_secs_f64()),
        ]
    }
    fn enable_gait_meter(&mut self) {
        self.env.enable_gait_meter();
    }
    fn gait_report(&self) -> Option<GaitReport> {
        Some(self.env.gait_report())
    }
}

/// Fills rollout chunks from an environment with a policy; buffers are reused between chunks.
pub struct Collector<E: RolloutEnv> {
    pub env: E,
    rng: StdRng,
    scratch: InferScratch,
    means: Vec<f32>,
    /// Seconds of policy inference + action sampling in the last `collect`.
    pub inference_seconds: f64,
    /// The env's stage seconds during the last `collect` (see [`RolloutEnv::take_stage_seconds`]).
    pub stage_seconds: Vec<(&'static str, f64)>,
}

impl<E: RolloutEnv> Collector<E> {
    pub fn new(env: E, seed: u64) -> Self {
        Self {
            env,
            rng: StdRng::seed_from_u64(seed),
            scratch: InferScratch::default(),
            means: Vec::new(),
            inference_seconds: 0.0,
            stage_seconds: Vec::new(),
        }
    }

    /// Run `chunk.steps` control steps, sampling actions from `policy`, writing into `chunk` (whose
    /// shape must match the environment). Returns an error if the policy's dimensions do not match.
    pub fn collect(
        &mut self,
        policy: &DeployPolicy,
        chunk: &mut RolloutChunk,
    ) -> Result<(), ActorError> {
        let (n, od, ad) = (
            self.env.num_envs(),
            self.env.obs_dim(),
            self.env.action_dim(),
        );
        if policy.obs_dim() != od || policy.action_dim() != ad {
            return Err(ActorError::Dims(format!(
                "policy has obs {} / action {}, environment has obs {od} / action {ad}",
                policy.obs_dim(),
                policy.action_dim()
            )));
        }
        let start = Instant::now();
        chunk.episodes.clear();
        if chunk.reward_terms.is_empty() {
            chunk.reward_terms = self.env.reward_term_names();
        }
        let std = policy.std().to_vec();
        let _ = self.env.take_stage_seconds();
        let mut inference = std::time::Duration::ZERO;
        for t in 0..chunk.steps as usize {
            let infer_start = Instant::now();
            let obs_rows = t * n * od..(t + 1) * n * od;
            chunk.observations[obs_rows].copy_from_slice(self.env.observations());
            policy
                .act_into(self.env.observations(), &mut self.means, &mut self.scratch)
                .map_err(|e| ActorError::Policy(e.to_string()))?;
            let (actions, log_probs) = policy.sample(&self.means, &mut self.rng);
            inference += infer_start.elapsed();
            let act_rows = t * n * ad..(t + 1) * n * ad;
            chunk.actions[act_rows.clone()].copy_from_slice(&actions);
            chunk.action_means[act_rows.clone()].copy_from_slice(&self.means);
            for row in chunk.action_stds[act_rows].chunks_exact_mut(ad) {
                row.copy_from_slice(&std);
            }
            let rows = t * n..(t + 1) * n;
            chunk.log_probs[rows.clone()].copy_from_slice(&log_probs);
            self.env.set_action_means(&self.means);
            self.env.step(
                &actions,
                &mut chunk.rewards[rows.clone()],
                &mut chunk.terminated[rows.clone()],
                &mut chunk.truncated[rows],
                &mut chunk.episodes,
            )?;
        }
        chunk
            .last_observations
            .copy_from_slice(self.env.observations());
        chunk.collect_seconds = start.elapsed().as_secs_f32();
        self.inference_seconds = inference.as_secs_f64();
        self.stage_seconds = self.env.take_stage_seconds();
        chunk.stage_seconds.clear();
        chunk
            .stage_seconds
            .push(("inference".into(), self.inference_seconds as f32));
        chunk.stage_seconds.extend(
            self.stage_seconds
                .iter()
                .map(|(name, s)| (name.to_string(), *s as f32)),
        );
        Ok(())
    }
}

/// Errors of the actor.
#[derive(Debug, thiserror::Error)]
pub enum ActorError {
    #[error("environment: {0}")]
    Env(String),
    #[error("dimension mismatch: {0}")]
    Dims(String),
    #[error("policy: {0}")]
    Policy(String),
    #[error("weights for {robot} v{version}: {message}")]
    Weights {
        robot: String,
        version: u64,
        message: String,
    },
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("{0}")]
    Name(#[from] keys::KeyError),
}

fn zerr(e: impl std::fmt::Display) -> ActorError {
    ActorError::Zenoh(e.to_string())
}

/// Identity and sizes of one actor.
#[derive(Debug, Clone)]
pub struct ActorOptions {
    pub run: String,
    pub robot: String,
    pub actor_id: String,
    /// Control steps per env per chunk (rsl_rl's `num_steps_per_env`, 24).
    pub steps_per_env: usize,
    pub seed: u64,
    /// Stop after this many chunks (0: until cancelled). For tests and benchmarks.
    pub max_chunks: u64,
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

fn decode_announce(bytes: &[u8]) -> Option<PolicyAnnounce> {
    codec::decode_json::<PolicyAnnounce>(bytes)
        .map_err(|e| warn!("ignored announce: {e}"))
        .ok()
}

/// Fetch and verify the weights an announce names for `robot`.
pub async fn fetch_policy(
    session: &Session,
    announce: &PolicyAnnounce,
    robot: &str,
) -> Result<DeployPolicy, ActorError> {
    let fail = |message: String| ActorError::Weights {
        robot: robot.into(),
        version: announce.version,
        message,
    };
    let entry = announce
        .robots
        .iter()
        .find(|r| r.robot == robot)
        .ok_or_else(|| {
            fail(format!(
                "the learner does not train this robot (it trains {:?})",
                announce.robots.iter().map(|r| &r.robot).collect::<Vec<_>>()
            ))
        })?;
    // No consolidation: the first reply is handed over at once. Zenoh's default holds replies until
    // every matching queryable has answered, so a learner killed a moment ago (its queryable is
    // dropped only when its lease expires, up to 10 s on QUIC) would delay every fetch.
    let replies = session
        .get(keys::policy_weights(&announce.run, robot, announce.version))
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(Duration::from_secs(30))
        .await
        .map_err(zerr)?;
    let mut last_error = String::from("no reply (hint: is the learner running?)");
    while let Ok(reply) = replies.recv_async().await {
        match reply.result() {
            Ok(sample) => {
                let blob: WeightsBlob =
                    codec::decode(&sample.payload().to_bytes()).map_err(|e| fail(e.to_string()))?;
                let sha = l3p_proto::sha256_hex(&blob.bytes);
                if sha != entry.sha256 || sha != blob.sha256 {
                    return Err(fail(format!(
                        "sha256 mismatch: announce {}, blob says {}, bytes hash to {sha}",
                        entry.sha256, blob.sha256
                    )));
                }
                return DeployPolicy::from_bytes(&blob.bytes).map_err(|e| fail(e.to_string()));
            }
            Err(err) => {
                last_error = String::from_utf8_lossy(&err.payload().to_bytes()).into_owned()
            }
        }
    }
    Err(fail(last_error))
}

/// An actor's metrics for one chunk: collection speed, the transport split, the collector's stage
/// times, and the episodes' and reward terms' means.
fn chunk_metrics<E: RolloutEnv>(
    record: &mut MetricsRecord,
    ch: &RolloutChunk,
    col: &Collector<E>,
    fetch_seconds: f64,
    send_seconds: f64,
) {
    record.insert("collect_seconds", ch.collect_seconds as f64);
    record.insert(
        "steps_per_second",
        ch.samples() as f64 / (ch.collect_seconds as f64).max(1e-9),
    );
    record.insert("send_seconds", send_seconds);
    record.insert("fetch_seconds", fetch_seconds);
    record.insert("time/inference_seconds", col.inference_seconds);
    for (stage, seconds) in &col.stage_seconds {
        record.insert(&format!("time/{stage}_seconds"), *seconds);
    }
    record.insert_episode_means(&ch.episodes);
    record.insert_reward_term_means([(ch.reward_terms.as_slice(), ch.episodes.as_slice())]);
}

/// Run the actor daemon until cancelled (or `max_chunks`).
pub async fn run<E: RolloutEnv>(
    session: Session,
    opts: ActorOptions,
    env: E,
    cancel: CancellationToken,
) -> Result<u64, ActorError> {
    keys::validate_segment("run", &opts.run)?;
    keys::validate_segment("robot", &opts.robot)?;
    keys::validate_segment("actor", &opts.actor_id)?;
    let (n, od, ad) = (env.num_envs(), env.obs_dim(), env.action_dim());
    let _token = session
        .liveliness()
        .declare_token(keys::actor_liveliness(
            &opts.run,
            &opts.robot,
            &opts.actor_id,
        ))
        .await
        .map_err(zerr)?;
    let announces = session
        .declare_subscriber(keys::policy_announce(&opts.run))
        .await
        .map_err(zerr)?;
    let publisher = l3p_net::declare_rollout_publisher(
        &session,
        keys::rollout(&opts.run, &opts.robot, &opts.actor_id),
    )
    .await
    .map_err(zerr)?;
    let metrics_source = format!("actor-{}-{}", opts.robot, opts.actor_id);
    let metrics_key = keys::metrics(&opts.run, &metrics_source);

    let mut collector = Some(Collector::new(env, opts.seed));
    let mut chunk = Some(RolloutChunk::zeros(
        &opts.run,
        &opts.robot,
        &opts.actor_id,
        0,
        n,
        opts.steps_per_env,
        od,
        ad,
    ));
    // Policy held, keyed by (learner incarnation, version), and the announce that named it.
    let mut policy: Option<((u64, u64), DeployPolicy)> = None;
    let mut tracker = AnnounceTracker::default();
    let mut last_send_seconds = 0f64;
    let mut seq = 0u64;
    info!(robot = %opts.robot, actor = %opts.actor_id, envs = n, "actor ready, waiting for a policy");

    loop {
        if opts.max_chunks > 0 && seq >= opts.max_chunks {
            break;
        }
        // Which policy to collect with: `announce::AnnounceTracker` holds the rules.
        let mut newest = None;
        while let Ok(Some(sample)) = announces.try_recv() {
            newest = Some(sample);
        }
        let newest = newest.and_then(|s| decode_announce(&s.payload().to_bytes()));
        let announce = match tracker.next(newest) {
            Next::Collect(a) => a,
            Next::Wait => {
                let sample = tokio::select! {
                    _ = cancel.cancelled() => break,
                    sample = announces.recv_async() => match sample { Ok(s) => s, Err(_) => break },
                };
                match decode_announce(&sample.payload().to_bytes()).map(|a| tracker.arrived(a)) {
                    Some(Next::Collect(a)) => a,
                    _ => continue,
                }
            }
        };
        let fetch_start = Instant::now();
        let key = (announce.incarnation, announce.version);
        if policy.as_ref().is_none_or(|(k, _)| *k != key) {
            match fetch_policy(&session, &announce, &opts.robot).await {
                Ok(p) => {
                    policy = Some((key, p));
                    tracker.fetched(&announce);
                }
                Err(e) => {
                    warn!("{e}");
                    continue;
                }
            }
        }
        let fetch_seconds = fetch_start.elapsed().as_secs_f64();
        let Some(((_, version), current)) = policy.clone() else {
            continue;
        };
        let (Some(mut col), Some(mut ch)) = (collector.take(), chunk.take()) else {
            break;
        };
        ch.policy_version = version;
        ch.seq = seq;
        ch.transport_seconds = (fetch_seconds + last_send_seconds) as f32;
        let (col, ch, result) = tokio::task::spawn_blocking(move || {
            let r = col.collect(&current, &mut ch);
            (col, ch, r)
        })
        .await
        .map_err(|e| ActorError::Zenoh(format!("collector thread: {e}")))?;
        result?;
        let send_start = Instant::now();
        let bytes = codec::encode(&ch).map_err(zerr)?;
        publisher.put(bytes).await.map_err(zerr)?;
        let send_seconds = send_start.elapsed().as_secs_f64();
        last_send_seconds = send_seconds;

        let mut record = MetricsRecord::new(&opts.run, &metrics_source, version, unix_ms());
        chunk_metrics(&mut record, &ch, &col, fetch_seconds, send_seconds);
        if let Ok(json) = codec::encode_json(&record) {
            let _ = session.put(&metrics_key, json).await;
        }
        tracker.collected((announce.incarnation, version));
        seq += 1;
        collector = Some(col);
        chunk = Some(ch);
    }
    Ok(seq)
}

/// What `l3p eval` reports: means over finished episodes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalSummary {
    pub episodes: usize,
    pub episode_return: f32,
    pub episode_length: f32,
    pub terrain_level: f32,
    /// Mean terrain level of the last `num_envs` finished episodes: with the curriculum on, the
    /// level the policy has walked itself to by the end (the paper's "final level the policy
    /// could reach"); `terrain_level` averages over the whole climb.
    #[serde(default)]
    pub final_terrain_level: f32,
    pub lin_vel_error: f32,
    pub yaw_rate_error: f32,
    /// Share of episodes that ended by termination (fall, base contact) rather than time-out.
    pub fall_fraction: f32,
    /// Mean base height above the ground over all envs and steps (m; `None` if the env does not
    /// report it): a walking policy stays near the robot's standing height, a crawling one does not.
    pub mean_base_height: Option<f32>,
    /// Gait diagnostics (base height, swing shares, non-foot contacts, chatter, ...), where the
    /// env measures them.
    pub gait: Option<GaitReport>,
}

impl EvalSummary {
    /// The tracking half, for [`l3p_task::gait::WalkCriterion::failures`].
    pub fn tracking(&self) -> TrackingSummary {
        TrackingSummary {
            lin_vel_error: self.lin_vel_error,
            yaw_rate_error: self.yaw_rate_error,
            fall_fraction: self.fall_fraction,
        }
    }
}

/// Play `policy` deterministically (action means, no exploration noise) until `episodes` episodes
/// have finished or `max_steps` control steps have passed.
pub fn evaluate<E: RolloutEnv>(
    env: &mut E,
    policy: &DeployPolicy,
    episodes: usize,
    max_steps: usize,
) -> Result<EvalSummary, ActorError> {
    let (n, od, ad) = (env.num_envs(), env.obs_dim(), env.action_dim());
    if policy.obs_dim() != od || policy.action_dim() != ad {
        return Err(ActorError::Dims(format!(
            "policy has obs {} / action {}, environment has obs {od} / action {ad}",
            policy.obs_dim(),
            policy.action_dim()
        )));
    }
    let (mut rewards, mut terminated, mut truncated) =
        (vec![0.0; n], vec![false; n], vec![false; n]);
    let (mut means, mut scratch, mut finished) = (Vec::new(), InferScratch::default(), Vec::new());
    let (mut height_sum, mut height_steps) = (0.0f64, 0u32);
    env.enable_gait_meter();
    for _ in 0..max_steps {
        policy
            .act_into(env.observations(), &mut means, &mut scratch)
            .map_err(|e| ActorError::Policy(e.to_string()))?;
        env.step(
            &means,
            &mut rewards,
            &mut terminated,
            &mut truncated,
            &mut finished,
        )?;
        if let Some(h) = env.mean_base_height() {
            height_sum += h as f64;
            height_steps += 1;
        }
        if finished.len() >= episodes {
            break;
        }
    }
    let k = finished.len().max(1) as f32;
    let mean = |f: &dyn Fn(&EpisodeStats) -> f32| finished.iter().map(f).sum::<f32>() / k;
    Ok(EvalSummary {
        episodes: finished.len(),
        episode_return: mean(&|e| e.episode_return),
        episode_length: mean(&|e| e.length as f32),
        terrain_level: mean(&|e| e.terrain_level),
        final_terrain_level: {
            let last = &finished[finished.len().saturating_sub(n)..];
            last.iter().map(|e| e.terrain_level).sum::<f32>() / last.len().max(1) as f32
        },
        lin_vel_error: mean(&|e| e.lin_vel_error),
        yaw_rate_error: mean(&|e| e.yaw_rate_error),
        fall_fraction: mean(&|e| if e.terminated { 1.0 } else { 0.0 }),
        mean_base_height: (height_steps > 0).then(|| (height_sum / height_steps as f64) as f32),
        gait: env.gait_report(),
    })
}
