//! The `l3p bench learner` workload: one full PPO update (`epochs × minibatches`) on synthetic data
//! of rsl_rl's shape, and batched policy inference, timed. [`LearnerBenchConfig`] →
//! [`run_learner_bench`] → [`LearnerBenchReport`].

use std::time::Instant;

use l3p_policy::{
    Arch, DeployPolicy, InferScratch, PolicyConfig, PolicyRobot, export_bytes, train_device,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::{LearnerError, Mode, Ppo, PpoConfig, RobotRollout, RolloutBatch};

/// What to time.
#[derive(Debug, Clone)]
pub struct LearnerBenchConfig {
    pub mode: Mode,
    pub envs: usize,
    pub steps: usize,
    pub obs_dim: usize,
    pub action_dim: usize,
    /// Actor (MLP) and critic hidden sizes; L3P keeps its latent layout but uses these for the critic.
    pub hidden: Vec<usize>,
    /// Timed updates (after one warm-up update).
    pub updates: usize,
    pub seed: u64,
    /// rayon threads for burn's kernels (0: rayon's default).
    pub threads: usize,
    /// A training config's networks and PPO settings, timed as they are (`mode` and `hidden` are then
    /// ignored): what `l3p bench learner --config configs/a1-flat.toml` measures.
    pub from_config: Option<(PolicyConfig, PpoConfig)>,
}

impl Default for LearnerBenchConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Mlp,
            envs: 1024,
            steps: 24,
            obs_dim: 48,
            action_dim: 12,
            hidden: vec![512, 256, 128],
            updates: 2,
            seed: 1,
            threads: 2,
            from_config: None,
        }
    }
}

/// Measured throughput.
#[derive(Debug, Clone)]
pub struct LearnerBenchReport {
    pub samples_per_update: usize,
    /// Median seconds of one full update.
    pub update_seconds: f64,
    pub samples_per_second: f64,
    /// Observations per second of the actor mean through burn (flex, no autodiff), batch = envs.
    pub infer_burn_obs_per_second: f64,
    /// Same through the pure-Rust export path ([`DeployPolicy`]).
    pub infer_rust_obs_per_second: f64,
    pub actor_params: usize,
}

fn synthetic_batch(cfg: &LearnerBenchConfig, rng: &mut StdRng) -> RolloutBatch {
    let mut r = RobotRollout::zeros("bench", cfg.steps, cfg.envs, cfg.obs_dim, cfg.action_dim);
    for v in r
        .observations
        .iter_mut()
        .chain(r.last_observations.iter_mut())
        .chain(r.actions.iter_mut())
    {
        *v = rng.random_range(-1.0..1.0);
    }
    for v in r.action_means.iter_mut() {
        *v = rng.random_range(-0.1..0.1);
    }
    for (i, v) in r.log_probs.iter_mut().enumerate() {
        *v = -(cfg.action_dim as f32) * 1.4 - (i % 7) as f32 * 0.1;
    }
    for (i, v) in r.rewards.iter_mut().enumerate() {
        *v = rng.random_range(-1.0..1.0);
        r.truncated[i] = i % 997 == 0;
        r.terminated[i] = i % 613 == 0;
    }
    RolloutBatch { robots: vec![r] }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Run the benchmark inside a rayon pool of `cfg.threads` threads.
pub fn run_learner_bench(cfg: &LearnerBenchConfig) -> Result<LearnerBenchReport, LearnerError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads)
        .build()
        .map_err(|e| LearnerError::Config(format!("thread pool: {e}")))?;
    pool.install(|| bench_in_pool(cfg))
}

fn bench_in_pool(cfg: &LearnerBenchConfig) -> Result<LearnerBenchReport, LearnerError> {
    let device = train_device();
    // From-scratch modes only: a transfer mode needs a checkpoint to start from.
    let from_scratch = |m: Mode| {
        if m.arch() == Arch::Mlp {
            Mode::Mlp
        } else {
            Mode::L3p
        }
    };
    let mode = from_scratch(cfg.mode);
    let (policy, ppo_cfg) = match &cfg.from_config {
        Some((policy, ppo)) => (
            policy.clone(),
            PpoConfig {
                mode: from_scratch(ppo.mode),
                ..ppo.clone()
            },
        ),
        None => (
            PolicyConfig {
                arch: mode.arch(),
                mlp_hidden: cfg.hidden.clone(),
                critic_hidden: cfg.hidden.clone(),
                ..PolicyConfig::default()
            },
            PpoConfig {
                mode,
                ..Default::default()
            },
        ),
    };
    let spec = PolicyRobot::new("bench", cfg.obs_dim, cfg.action_dim);
    let actor_params = policy.actor_params(cfg.obs_dim, cfg.action_dim);
    let model = crate::init_model(
        ppo_cfg.mode,
        policy,
        vec![spec],
        None,
        crate::TransferHeads::Fresh,
        &[],
        &device,
    )?;
    let mut ppo = Ppo::new(ppo_cfg, model, device)?;
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let batch = synthetic_batch(cfg, &mut rng);
    ppo.update(&batch)?; // warm-up
    let mut times = Vec::new();
    for _ in 0..cfg.updates.max(1) {
        let t = Instant::now();
        ppo.update(&batch)?;
        times.push(t.elapsed().as_secs_f64());
    }
    let update_seconds = median(times);
    let samples = batch.samples();

    // Inference, batch = envs.
    let obs: Vec<f32> = batch.robots[0].observations[..cfg.envs * cfg.obs_dim].to_vec();
    let reps = 10;
    ppo.model().act_mean_host(0, &obs)?;
    let t = Instant::now();
    for _ in 0..reps {
        ppo.model().act_mean_host(0, &obs)?;
    }
    let burn_s = t.elapsed().as_secs_f64() / reps as f64;
    let (bytes, _) = export_bytes(ppo.model(), "bench")?;
    let deploy = DeployPolicy::from_bytes(&bytes)?;
    let (mut out, mut scratch) = (Vec::new(), InferScratch::default());
    deploy.act_into(&obs, &mut out, &mut scratch)?;
    let t = Instant::now();
    for _ in 0..reps {
        deploy.act_into(&obs, &mut out, &mut scratch)?;
    }
    let rust_s = t.elapsed().as_secs_f64() / reps as f64;
    Ok(LearnerBenchReport {
        samples_per_update: samples,
        update_seconds,
        samples_per_second: samples as f64 / update_seconds,
        infer_burn_obs_per_second: cfg.envs as f64 / burn_s,
        infer_rust_obs_per_second: cfg.envs as f64 / rust_s,
        actor_params,
    })
}
