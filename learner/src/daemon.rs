//! The learner daemon: synchronous-with-tolerance PPO over Zenoh (DESIGN §2).
//!
//! Main types: [`DaemonConfig`] (the `[learner]` config section), [`LearnerOptions`], [`run`] (the
//! daemon loop), [`IterationReport`] (what a progress display receives), [`Event`] (everything the
//! loop reacts to).
//!
//! One iteration: announce policy version `k` (JSON on `keys::policy_announce`, repeated every 500 ms
//! so late actors catch up) and serve its weights (`keys::policy_weights`, verified by sha256); gather
//! chunks for `k` from every live actor (liveliness tokens) or until `gather_timeout_s` passes; drop
//! chunks older than `k − max_policy_lag` (counted); run the PPO update on a blocking thread; publish
//! metrics; checkpoint every `checkpoint_every` iterations (and on shutdown) so that a restarted
//! learner resumes at the same iteration with its optimiser state.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use l3p_policy::{PolicyConfig, PolicyRobot};
use l3p_proto::{
    MetricsRecord, PolicyAnnounce, RobotWeights, RolloutChunk, WIRE_VERSION, WeightsBlob, codec,
    keys,
};
use serde::{Deserialize, Serialize};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tracing::{debug, info, warn};
use zenoh::Session;

use crate::gather::{ChunkFate, Gather, Ready, actor_key};
use crate::links::{
    ChunkContract, Published, spawn_chunk_intake, spawn_liveliness_watch, spawn_weights_server,
};
use crate::uploader::{RegistryUploader, Upload};
use crate::{LearnerError, Mirror, Mode, Ppo, PpoConfig, RolloutBatch, UpdateMetrics};

/// `[learner]` config section: how the daemon gathers data and keeps state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// Chunks produced by a policy more than this many versions old are dropped (and counted).
    pub max_policy_lag: u64,
    /// Start the update with what has arrived after this many seconds, even if a live actor is silent.
    pub gather_timeout_s: f64,
    /// Live actors needed before the first update starts.
    pub min_actors: usize,
    /// Write a checkpoint every this many iterations (and always on shutdown).
    pub checkpoint_every: u64,
    /// Of those, store one in the registry (with the `<run>-<robot>` deploy artifacts) every this
    /// many iterations, and always on shutdown: registry versions are permanent and a checkpoint is
    /// ~5 MB, so the registry keeps a sparser history than the local `latest.ckpt`.
    pub registry_checkpoint_every: u64,
    /// Stop after this many iterations (0: run until stopped).
    pub max_iterations: u64,
    /// Checkpoint to initialise from in the transfer modes.
    pub init_from: Option<PathBuf>,
    /// Registry reference (`name@version`) of `init_from`, when it came from the registry: the
    /// run's registry checkpoints name it as lineage (`from_checkpoint`).
    pub init_from_artifact: Option<String>,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            max_policy_lag: 0,
            gather_timeout_s: 120.0,
            min_actors: 1,
            checkpoint_every: 25,
            registry_checkpoint_every: 100,
            max_iterations: 1500,
            init_from: None,
            init_from_artifact: None,
        }
    }
}

/// Everything the learner daemon needs, assembled by the binary from the config file.
#[derive(Debug, Clone)]
pub struct LearnerOptions {
    pub run: String,
    /// `<data_dir>/<run>`: metrics file and local checkpoints live here.
    pub run_dir: PathBuf,
    pub daemon: DaemonConfig,
    pub ppo: PpoConfig,
    pub policy: PolicyConfig,
    /// Robots this run trains, with their observation and action sizes.
    pub robots: Vec<PolicyRobot>,
    /// Write checkpoints and deployable policies to the registry as well (and resume from it when
    /// the run directory has no checkpoint).
    pub use_registry: bool,
    /// The run's chunk contract: steps per env (`[rollout] steps_per_env`) and the observation
    /// clip (`[env] obs_clip`); a chunk outside it is rejected on arrival.
    pub steps_per_env: usize,
    pub obs_clip: f32,
    /// Left-right mirror maps per robot name, for `[ppo] symmetry_coef`.
    pub mirrors: Vec<(String, Mirror)>,
    /// Maps from the checkpoint's prototype robot to each new robot, for
    /// `[ppo] transfer_heads = "mapped"`.
    pub transfer_maps: Vec<(String, l3p_policy::HeadMap)>,
}

/// How long a stopping learner waits for queued registry uploads.
const FINAL_UPLOAD_DEADLINE: Duration = Duration::from_secs(60);

/// Registry name of a run's checkpoints.
pub fn checkpoint_artifact(run: &str) -> String {
    format!("{run}-checkpoint")
}

/// Registry name of a run's deployable policy for one robot.
pub fn deploy_artifact(run: &str, robot: &str) -> String {
    format!("{run}-{robot}")
}

/// What the loop reacts to.
#[derive(Debug)]
pub enum Event {
    /// A decoded, validated chunk.
    Chunk(Box<RolloutChunk>),
    /// A chunk that failed to decode or validate (already logged).
    Rejected,
    /// An actor's liveliness token appeared (`robot/actor`).
    ActorUp(String),
    /// An actor's liveliness token disappeared.
    ActorDown(String),
}

/// Sent to a progress display after every update.
#[derive(Debug, Clone)]
pub struct IterationReport {
    pub iteration: u64,
    pub max_iterations: u64,
    pub metrics: MetricsRecord,
}

/// How the daemon ended.
#[derive(Debug, Clone)]
pub struct LearnerSummary {
    pub iterations: u64,
    pub dropped_chunks: u64,
    pub rejected_chunks: u64,
}

/// Errors that stop the learner daemon (bad input never does: it is logged and counted).
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Learner(#[from] LearnerError),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("registry: {0}")]
    Registry(#[from] l3p_registry_client::RegistryError),
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

pub(crate) fn zerr(e: impl std::fmt::Display) -> DaemonError {
    DaemonError::Zenoh(e.to_string())
}

/// Local checkpoint file of a run.
pub fn checkpoint_path(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoints").join("latest.ckpt")
}

/// Metrics file of a run (one JSON record per line).
pub fn metrics_path(run_dir: &Path) -> PathBuf {
    run_dir.join("metrics.jsonl")
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// Build the PPO state: resume from the run's checkpoint when there is one, else start per mode.
fn start_ppo(opts: &LearnerOptions, from_registry: Option<Vec<u8>>) -> Result<Ppo, LearnerError> {
    let mut ppo = load_or_init_ppo(opts, from_registry)?;
    for (robot, mirror) in &opts.mirrors {
        if ppo.model().robot_index(robot).is_ok() {
            ppo.set_mirror(robot, mirror)?;
        }
    }
    Ok(ppo)
}

fn load_or_init_ppo(
    opts: &LearnerOptions,
    from_registry: Option<Vec<u8>>,
) -> Result<Ppo, LearnerError> {
    let device = l3p_policy::train_device();
    let path = checkpoint_path(&opts.run_dir);
    if path.exists() {
        let ppo = Ppo::load(opts.ppo.clone(), &path, device)?;
        info!(iteration = ppo.iteration(), path = %path.display(), "resumed from checkpoint");
        return Ok(ppo);
    }
    if let Some(bytes) = from_registry {
        let ppo = Ppo::from_checkpoint_bytes(opts.ppo.clone(), &bytes, device)?;
        info!(
            iteration = ppo.iteration(),
            "resumed from the registry's latest checkpoint"
        );
        return Ok(ppo);
    }
    let init_from = match opts.ppo.mode {
        Mode::Mlp | Mode::L3p => None,
        _ => opts.daemon.init_from.as_deref(),
    };
    // Fresh weights (and any fresh transfer heads) come from the backend's RNG: seeding it makes
    // an arm's initial policy a function of its seed, not of OS entropy.
    device.seed(opts.ppo.seed);
    let model = crate::init_model(
        opts.ppo.mode,
        opts.policy.clone(),
        opts.robots.clone(),
        init_from,
        opts.ppo.transfer_heads,
        &opts.transfer_maps,
        &device,
    )?;
    info!(mode = opts.ppo.mode.as_str(), "{}", model.param_report());
    Ppo::new(opts.ppo.clone(), model, device)
}

/// Encode each robot's weights for `version` and make them the ones served.
fn publish_weights(
    ppo: &Ppo,
    run: &str,
    robots: &[PolicyRobot],
    published: &RwLock<Published>,
) -> Result<Vec<RobotWeights>, DaemonError> {
    let version = ppo.iteration();
    let mut blobs = HashMap::new();
    let mut entries = Vec::new();
    for spec in robots {
        let (bytes, config) = ppo.export(&spec.name)?;
        let sha256 = l3p_registry_client::sha256_hex(&bytes);
        entries.push(RobotWeights {
            robot: spec.name.clone(),
            sha256: sha256.clone(),
            size: bytes.len() as u64,
            obs_dim: config.obs_dim as u32,
            action_dim: config.action_dim as u32,
        });
        let blob = WeightsBlob {
            wire_version: WIRE_VERSION,
            run: run.to_string(),
            robot: spec.name.clone(),
            version,
            format: l3p_policy::EXPORT_FORMAT.to_string(),
            sha256,
            bytes,
        };
        let encoded = codec::encode(&blob).map_err(|e| DaemonError::Zenoh(e.to_string()))?;
        blobs.insert(spec.name.clone(), encoded);
    }
    if let Ok(mut p) = published.write() {
        *p = Published { version, blobs };
    }
    Ok(entries)
}

/// Write the checkpoint to the run directory (atomically) and, with a registry, queue it there too
/// along with each robot's deployable policy (`<run>-<robot>`, alias `latest`). The local file is
/// the source of truth; the registry upload happens in the background and never fails this.
fn save_checkpoint(
    ppo: &Ppo,
    opts: &LearnerOptions,
    registry: Option<&RegistryUploader>,
    record: &MetricsRecord,
) -> Result<(), DaemonError> {
    use l3p_registry_client::{ArtifactKind, LineageRole, PutRequest};
    let bytes = ppo.checkpoint_bytes()?;
    let path = checkpoint_path(&opts.run_dir);
    l3p_policy::write_atomic(&path, &bytes).map_err(|source| DaemonError::Io { path, source })?;
    let Some(uploader) = registry else {
        return Ok(());
    };
    let summary = |mut req: PutRequest| {
        for key in [
            "episode_return",
            "terrain_level",
            "lin_vel_error",
            "yaw_rate_error",
        ] {
            if let Some(v) = record.values.get(key) {
                req = req.metric(key, *v);
            }
        }
        req.metric("iteration", ppo.iteration() as f64)
            .producer(&format!("learner/{}", opts.run))
            .config(serde_json::json!({ "mode": opts.ppo.mode.as_str(), "policy": opts.policy }))
    };
    let mut checkpoint = summary(PutRequest::new(
        &checkpoint_artifact(&opts.run),
        ArtifactKind::Checkpoint,
        bytes,
    ));
    if let Some(source) = &opts.daemon.init_from_artifact {
        checkpoint = checkpoint.lineage(LineageRole::FromCheckpoint, source);
    }
    let mut deploys = Vec::with_capacity(opts.robots.len());
    for spec in &opts.robots {
        let (export, config) = ppo.deploy_export(&spec.name)?;
        let req = PutRequest::new(
            &deploy_artifact(&opts.run, &spec.name),
            ArtifactKind::Deploy,
            export,
        )
        .robot(&spec.name)
        .dim("obs_dim", config.obs_dim as u64)
        .dim("action_dim", config.action_dim as u64);
        deploys.push(summary(req));
    }
    uploader.submit(Upload {
        iteration: ppo.iteration(),
        checkpoint,
        deploys,
    });
    Ok(())
}

/// Append one metrics record to the run's file and publish it on Zenoh.
async fn emit_metrics(
    session: &Session,
    file: &Path,
    record: &MetricsRecord,
) -> Result<(), DaemonError> {
    use std::io::Write;
    let json = codec::encode_json(record).map_err(zerr)?;
    let io = |source| DaemonError::Io {
        path: file.to_path_buf(),
        source,
    };
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(file)
        .map_err(io)?;
    f.write_all(&json)
        .and_then(|_| f.write_all(b"\n"))
        .map_err(io)?;
    session
        .put(keys::metrics(&record.run, &record.source), json)
        .await
        .map_err(zerr)?;
    Ok(())
}

fn update_metrics(record: &mut MetricsRecord, m: &UpdateMetrics) {
    for (key, value) in [
        ("approx_kl", m.approx_kl as f64),
        ("clip_fraction", m.clip_fraction as f64),
        ("explained_variance", m.explained_variance as f64),
        ("learning_rate", m.learning_rate),
        ("entropy", m.entropy as f64),
        ("mean_std", m.mean_std as f64),
        ("surrogate_loss", m.surrogate_loss as f64),
        ("value_loss", m.value_loss as f64),
        ("rec_obs_loss", m.rec_obs_loss as f64),
        ("rec_act_loss", m.rec_act_loss as f64),
        ("symmetry_loss", m.symmetry_loss as f64),
        ("smoothness_loss", m.smoothness_loss as f64),
        ("recon_mse", m.recon_mse as f64),
        ("recon_baseline_mse", m.recon_baseline_mse as f64),
        ("grad_norm", m.grad_norm as f64),
        ("skipped_steps", m.skipped_steps as f64),
        ("mean_step_reward", m.mean_reward as f64),
        ("update_seconds", m.update_seconds as f64),
        ("samples", m.samples as f64),
    ] {
        record.insert(key, value);
    }
}

/// Run the learner daemon until `max_iterations`, cancellation, or a fatal error. `progress`
/// receives a report after each update.
///
/// This is the Zenoh wiring: the gather rule is `Gather`, and what leaves the learner after an
/// update (weights, announce, metrics, checkpoints) is `Outputs`.
pub async fn run(
    session: Session,
    opts: LearnerOptions,
    cancel: CancellationToken,
    progress: Option<mpsc::UnboundedSender<IterationReport>>,
) -> Result<LearnerSummary, DaemonError> {
    keys::validate_segment("run", &opts.run).map_err(|e| DaemonError::Zenoh(e.to_string()))?;
    std::fs::create_dir_all(&opts.run_dir).map_err(|source| DaemonError::Io {
        path: opts.run_dir.clone(),
        source,
    })?;
    let registry = opts
        .use_registry
        .then(|| l3p_registry_client::RegistryClient::new(&session));
    let from_registry = match &registry {
        Some(client) if !checkpoint_path(&opts.run_dir).exists() => client
            .try_get_blob(&format!("{}@latest", checkpoint_artifact(&opts.run)))
            .await?
            .map(|(_, bytes)| bytes),
        _ => None,
    };
    let mut ppo = start_ppo(&opts, from_registry)?;
    let mut out = Outputs::new(&session, &opts, &ppo, registry, progress)?;
    let serve =
        spawn_weights_server(&session, &opts.run, out.published.clone(), cancel.clone()).await?;

    // Events: rollout chunks and actor liveliness, funnelled into one bounded channel. When the loop
    // is busy updating, the channel fills and Zenoh's Block congestion control pushes back on actors.
    let (tx, mut events) = mpsc::channel::<Event>(256);
    let decode_seconds = Arc::new(std::sync::Mutex::new(0f64));
    let contract = ChunkContract::of(&opts);
    let chunk_task =
        spawn_chunk_intake(&session, contract, tx.clone(), decode_seconds.clone()).await?;
    let live_task = spawn_liveliness_watch(&session, &opts.run, tx).await?;

    // Seconds on this process's monotonic clock, for the gather rule.
    let clock = Instant::now();
    let now_s = || clock.elapsed().as_secs_f64();
    let mut gather = Gather::new(
        opts.daemon.max_policy_lag,
        opts.daemon.min_actors,
        opts.daemon.gather_timeout_s,
        now_s(),
    );
    let mut rejected = 0u64;
    let max_iterations = opts.daemon.max_iterations;
    let mut tick = tokio::time::interval(Duration::from_millis(500));

    let outcome: Result<(), DaemonError> = loop {
        if max_iterations > 0 && ppo.iteration() >= max_iterations {
            info!(iteration = ppo.iteration(), "reached max_iterations");
            break Ok(());
        }
        let version = ppo.iteration();
        tokio::select! {
            _ = cancel.cancelled() => break Ok(()),
            _ = tick.tick() => out.announce(version).await?,
            event = events.recv() => match event {
                None => break Err(DaemonError::Zenoh("subscriptions closed".into())),
                Some(event) => route_event(&mut gather, &mut rejected, event, version, now_s()),
            },
        }

        let now = now_s();
        let Some(ready) = gather.ready(now, ppo.iteration() == 0) else {
            continue;
        };
        let waited = gather.waited_s(now);
        if ready == Ready::TimedOut {
            warn!(
                waited_s = waited,
                have = gather.pending(),
                live = gather.live(),
                "gather timeout: updating with what arrived"
            );
        }
        let (chunks, newly_silent) = gather.take(ready, now);
        for actor in newly_silent {
            warn!(%actor, ?ready, "silent: not waited for until it sends a chunk");
        }

        // Update on a blocking thread; the subscription tasks keep buffering meanwhile.
        let iteration_start = Instant::now();
        let (returned, result) = tokio::task::spawn_blocking(move || {
            let result =
                RolloutBatch::from_chunks(chunks.iter()).and_then(|batch| ppo.update(&batch));
            (ppo, result.map(|m| (m, chunks)))
        })
        .await
        .map_err(|e| DaemonError::Zenoh(format!("update thread: {e}")))?;
        ppo = returned;
        let (update, chunks) = match result {
            Ok(ok) => ok,
            Err(e) => break Err(e.into()),
        };
        let weights_seconds = out.publish(&ppo).await?;
        let iteration_seconds = waited + iteration_start.elapsed().as_secs_f64();
        // The next gather (its wait and its timeout) starts now that the policy is out, not when
        // this update began: counting the update in both made `iteration_seconds` (and so
        // samples/s and `l3p bench train`) count every update twice.
        gather.restart(now_s());
        let decode = decode_seconds
            .lock()
            .map(|mut d| std::mem::take(&mut *d))
            .unwrap_or(0.0);
        let counters = LoopCounters {
            actors: gather.live(),
            dropped_chunks: gather.dropped(),
            rejected_chunks: rejected,
            silent_actors: gather.silent(),
            gather_wait_seconds: waited,
            registry: out.uploader.as_ref().map(|u| {
                let stats = u.stats();
                [stats.backlog(), stats.failed_attempts(), stats.dropped()]
            }),
        };
        let timing = (iteration_seconds, decode + weights_seconds);
        out.record_iteration(&ppo, &update, &chunks, timing, &counters)
            .await?;
    };

    out.finish(&ppo).await?;
    cancel.cancel();
    chunk_task.abort();
    live_task.abort();
    let _ = serve.await;
    outcome?;
    Ok(LearnerSummary {
        iterations: ppo.iteration(),
        dropped_chunks: gather.dropped(),
        rejected_chunks: rejected,
    })
}

/// A chunk or a liveliness change, handed to the gather rule; a rejected chunk is counted.
fn route_event(gather: &mut Gather, rejected: &mut u64, event: Event, version: u64, now_s: f64) {
    match event {
        Event::ActorUp(id) => {
            info!(actor = %id, "actor joined");
            gather.actor_up(id);
        }
        Event::ActorDown(id) => {
            info!(actor = %id, "actor left");
            gather.actor_down(&id);
        }
        Event::Chunk(chunk) => {
            let (actor, chunk_version) = (actor_key(&chunk), chunk.policy_version);
            match gather.chunk(*chunk, version, now_s) {
                ChunkFate::Stale => debug!(%actor, chunk_version, version, "dropped stale chunk"),
                ChunkFate::ReplacedOlder => {
                    debug!(%actor, "replaced an older chunk of the same actor")
                }
                ChunkFate::Accepted => {}
            }
        }
        Event::Rejected => *rejected += 1,
    }
}

/// Everything that leaves the learner: the served weights and their announce, the metrics file,
/// TensorBoard events and Zenoh metrics, checkpoints (local and registry) and progress reports.
struct Outputs<'a> {
    session: &'a Session,
    opts: &'a LearnerOptions,
    announce_key: String,
    /// Distinguishes this learner process from an earlier one of the same run (for actors).
    incarnation: u64,
    published: Arc<RwLock<Published>>,
    /// What the current announce lists (one entry per robot).
    weights: Vec<RobotWeights>,
    metrics_file: PathBuf,
    tensorboard: Option<l3p_report::tensorboard::EventWriter>,
    uploader: Option<RegistryUploader>,
    checkpoints: CheckpointSchedule,
    progress: Option<mpsc::UnboundedSender<IterationReport>>,
}

impl<'a> Outputs<'a> {
    /// Publishes `ppo`'s weights (served from now on) and opens the metrics outputs.
    fn new(
        session: &'a Session,
        opts: &'a LearnerOptions,
        ppo: &Ppo,
        registry: Option<l3p_registry_client::RegistryClient>,
        progress: Option<mpsc::UnboundedSender<IterationReport>>,
    ) -> Result<Self, DaemonError> {
        // TensorBoard scalars beside metrics.jsonl; a failure to write them costs the curves,
        // never the run.
        let tensorboard = match l3p_report::tensorboard::EventWriter::create(&opts.run_dir) {
            Ok(w) => Some(w),
            Err(e) => {
                warn!(dir = %opts.run_dir.display(), "no TensorBoard events for this run: {e}");
                None
            }
        };
        let published = Arc::new(RwLock::new(Published::default()));
        let weights = publish_weights(ppo, &opts.run, &opts.robots, &published)?;
        Ok(Outputs {
            session,
            opts,
            announce_key: keys::policy_announce(&opts.run),
            incarnation: unix_ms(),
            published,
            weights,
            metrics_file: metrics_path(&opts.run_dir),
            tensorboard,
            uploader: registry.map(RegistryUploader::spawn),
            checkpoints: CheckpointSchedule::new(&opts.daemon, ppo.iteration()),
            progress,
        })
    }

    /// Announces `version` with the current weights; a failed put is logged, not fatal.
    async fn announce(&self, version: u64) -> Result<(), DaemonError> {
        let message = PolicyAnnounce {
            wire_version: WIRE_VERSION,
            run: self.opts.run.clone(),
            version,
            incarnation: self.incarnation,
            mode: self.opts.ppo.mode.as_str().to_string(),
            robots: self.weights.clone(),
            max_policy_lag: self.opts.daemon.max_policy_lag,
        };
        let json = codec::encode_json(&message).map_err(zerr)?;
        if let Err(e) = self.session.put(&self.announce_key, json).await {
            warn!("cannot announce policy {version}: {e}");
        }
        Ok(())
    }

    /// Serves and announces the updated policy; returns the seconds spent encoding its weights.
    async fn publish(&mut self, ppo: &Ppo) -> Result<f64, DaemonError> {
        let start = Instant::now();
        self.weights = publish_weights(ppo, &self.opts.run, &self.opts.robots, &self.published)?;
        let seconds = start.elapsed().as_secs_f64();
        self.announce(ppo.iteration()).await?;
        Ok(seconds)
    }

    /// After an update: the iteration's metrics record (file, Zenoh, TensorBoard), a checkpoint
    /// when one is due, and a progress report. `timing` is (iteration seconds, learner transport
    /// seconds).
    async fn record_iteration(
        &mut self,
        ppo: &Ppo,
        update: &UpdateMetrics,
        chunks: &[RolloutChunk],
        timing: (f64, f64),
        counters: &LoopCounters,
    ) -> Result<(), DaemonError> {
        let version = ppo.iteration();
        let (iteration_seconds, transport_seconds) = timing;
        let record = iteration_record(
            &self.opts.run,
            version,
            update,
            chunks,
            iteration_seconds,
            transport_seconds,
            counters,
        );
        emit_metrics(self.session, &self.metrics_file, &record).await?;
        if let Some(w) = &mut self.tensorboard
            && let Err(e) = w.write(&record)
        {
            warn!(path = %w.path().display(), "TensorBoard events stopped: {e}");
            self.tensorboard = None;
        }
        if let Some(to_registry) = self.checkpoints.due(version, self.uploader.is_some()) {
            let target = self.uploader.as_ref().filter(|_| to_registry);
            save_checkpoint(ppo, self.opts, target, &record)?;
            self.checkpoints.written(version, to_registry);
        }
        if let Some(progress) = &self.progress {
            let _ = progress.send(IterationReport {
                iteration: version,
                max_iterations: self.opts.daemon.max_iterations,
                metrics: record,
            });
        }
        Ok(())
    }

    /// At shutdown, whatever stopped the loop: the final checkpoint, and the queued registry
    /// uploads given [`FINAL_UPLOAD_DEADLINE`].
    async fn finish(self, ppo: &Ppo) -> Result<(), DaemonError> {
        let opts = self.opts;
        let file_exists = checkpoint_path(&opts.run_dir).exists();
        let has_registry = self.uploader.is_some();
        if self
            .checkpoints
            .final_due(ppo.iteration(), file_exists, has_registry)
        {
            let record = MetricsRecord::new(&opts.run, "learner", ppo.iteration(), unix_ms());
            save_checkpoint(ppo, opts, self.uploader.as_ref(), &record)?;
            info!(iteration = ppo.iteration(), "final checkpoint written");
        }
        if let Some(uploader) = self.uploader {
            let left = uploader.finish(FINAL_UPLOAD_DEADLINE).await;
            if left > 0 {
                warn!(
                    left,
                    checkpoint = %checkpoint_path(&opts.run_dir).display(),
                    "registry unreachable: uploads not stored; the local checkpoint has the state"
                );
            }
        }
        Ok(())
    }
}

/// When to write checkpoints: every `checkpoint_every` iterations locally, every
/// `registry_checkpoint_every` of those also to the registry, and on shutdown whatever is not yet
/// written.
#[derive(Debug, Clone, PartialEq)]
struct CheckpointSchedule {
    every: u64,
    registry_every: u64,
    last: u64,
    last_registry: u64,
}

impl CheckpointSchedule {
    /// Starting at `iteration` (a resumed run's checkpoint counts as written).
    fn new(cfg: &DaemonConfig, iteration: u64) -> Self {
        CheckpointSchedule {
            every: cfg.checkpoint_every.max(1),
            registry_every: cfg.registry_checkpoint_every.max(1),
            last: iteration,
            last_registry: iteration,
        }
    }

    /// After the update that made `version`: `Some(to_registry)` when a checkpoint is due.
    fn due(&self, version: u64, has_registry: bool) -> Option<bool> {
        (version - self.last >= self.every)
            .then(|| has_registry && version - self.last_registry >= self.registry_every)
    }

    /// Records a checkpoint written at `version`.
    fn written(&mut self, version: u64, to_registry: bool) {
        self.last = version;
        if to_registry {
            self.last_registry = version;
        }
    }

    /// At shutdown: whether `version` still needs its checkpoint (locally or in the registry).
    fn final_due(&self, version: u64, file_exists: bool, has_registry: bool) -> bool {
        version != self.last || !file_exists || (has_registry && version != self.last_registry)
    }
}

/// Loop-level counts that go into every iteration's metrics.
struct LoopCounters {
    actors: usize,
    dropped_chunks: u64,
    rejected_chunks: u64,
    silent_actors: usize,
    /// How long the gather waited for chunks (from the policy's publication to the update).
    gather_wait_seconds: f64,
    /// The registry uploader's backlog, failed attempts and dropped uploads, if it runs.
    registry: Option<[u64; 3]>,
}

/// One iteration's metrics: the update's, the episodes' means, the slowest actor's split of its
/// collection time, reward terms, timing, throughput and the loop's counters. `learner_transport`
/// is the learner's side of transport (decoding chunks, encoding weights); the slowest actor's
/// side (fetching weights, sending its chunk) is added from the chunks.
fn iteration_record(
    run: &str,
    version: u64,
    update: &UpdateMetrics,
    chunks: &[RolloutChunk],
    iteration_seconds: f64,
    learner_transport: f64,
    counters: &LoopCounters,
) -> MetricsRecord {
    let slowest =
        |f: fn(&RolloutChunk) -> f32| chunks.iter().map(|c| f(c) as f64).fold(0.0, f64::max);
    let mut record = MetricsRecord::new(run, "learner", version, unix_ms());
    update_metrics(&mut record, update);
    record.insert_episode_means(chunks.iter().flat_map(|c| c.episodes.iter()));
    let mut stages: std::collections::BTreeMap<&str, f32> = Default::default();
    for c in chunks {
        for (name, s) in &c.stage_seconds {
            let slot = stages.entry(name.as_str()).or_default();
            *slot = slot.max(*s);
        }
    }
    for (name, s) in stages {
        record.insert(&format!("time/{name}_seconds"), s as f64);
    }
    record.insert_reward_term_means(
        chunks
            .iter()
            .map(|c| (c.reward_terms.as_slice(), c.episodes.as_slice())),
    );
    record.insert("iteration_seconds", iteration_seconds);
    record.insert("collect_seconds", slowest(|c| c.collect_seconds));
    record.insert(
        "samples_per_second",
        update.samples as f64 / iteration_seconds.max(1e-9),
    );
    record.insert("actors", counters.actors as f64);
    record.insert("dropped_chunks", counters.dropped_chunks as f64);
    record.insert("rejected_chunks", counters.rejected_chunks as f64);
    record.insert("silent_actors", counters.silent_actors as f64);
    record.insert("gather_wait_seconds", counters.gather_wait_seconds);
    if let Some([backlog, failed, dropped]) = counters.registry {
        record.insert("registry_backlog", backlog as f64);
        record.insert("registry_failed_attempts", failed as f64);
        record.insert("registry_dropped_uploads", dropped as f64);
    }
    let transport = learner_transport + slowest(|c| c.transport_seconds);
    record.insert("transport_seconds", transport);
    record.insert("transport_share", transport / iteration_seconds.max(1e-9));
    record
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkpoints_follow_both_intervals_and_shutdown_writes_what_is_missing() {
        let cfg = DaemonConfig {
            checkpoint_every: 25,
            registry_checkpoint_every: 100,
            ..DaemonConfig::default()
        };
        let mut s = CheckpointSchedule::new(&cfg, 0);
        assert_eq!(s.due(24, true), None);
        assert_eq!(s.due(25, true), Some(false), "local only");
        s.written(25, false);
        assert_eq!(s.due(49, true), None);
        s.written(50, false);
        s.written(75, false);
        assert_eq!(s.due(100, true), Some(true), "also to the registry");
        assert_eq!(s.due(100, false), Some(false), "no registry in this run");
        s.written(100, true);
        assert!(!s.final_due(100, true, true), "everything written");
        assert!(s.final_due(100, false, true), "the local file is gone");
        assert!(s.final_due(101, true, false), "one update since");
        s.written(125, false);
        assert!(!s.final_due(125, true, false));
        assert!(s.final_due(125, true, true), "the registry has only 100");

        // A resumed run counts its checkpoint as written; an interval of 0 means every iteration.
        let resumed = CheckpointSchedule::new(&cfg, 300);
        assert_eq!(resumed.due(301, true), None);
        let every = CheckpointSchedule::new(
            &DaemonConfig {
                checkpoint_every: 0,
                ..cfg
            },
            0,
        );
        assert_eq!(every.due(1, false), Some(false));
    }
}
