//! `l3p bench ...`: throughput benchmarks. `bench sim` steps the vectorised env with random actions
//! (all task work included) and prints control steps per second and stage timings.

use clap::{Args, Subcommand, ValueEnum};
use l3p_robot::catalog::RobotSpec;
use l3p_sim::bench::run_sim_bench;
use l3p_task::config::{EnvConfig, TerrainConfig, TerrainPreset};

/// `l3p bench ...`
#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub command: BenchCommand,
}

/// Benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Simulator throughput: N envs, random actions, physics + observations + rewards + resets.
    Sim(SimBenchArgs),
    /// Learner throughput: one full PPO update (the config's epochs × minibatches; rsl_rl's 5 × 4
    /// without one) on synthetic data, and policy inference for a batch of `envs` observations.
    Learner(LearnerBenchArgs),
    /// Deploy loop at 50 Hz: tick-period error and inference latency of `l3p deploy` driving an
    /// in-process `sim-robot` over loopback Zenoh, against a bare deadline loop (no work) as the
    /// baseline measured in the same run.
    Deploy(DeployBenchArgs),
    /// End-to-end training throughput: `l3p train <config>` for a few iterations in a scratch data
    /// directory, then samples/s and the split of an iteration (physics, inference, observations,
    /// rewards, resets, transport, update), medians after a warm-up.
    Train(TrainBenchArgs),
}

/// `l3p bench train` arguments.
#[derive(Debug, Args)]
pub struct TrainBenchArgs {
    /// The training config to measure.
    #[arg(default_value = "configs/a1-flat.toml")]
    pub config: std::path::PathBuf,
    /// Iterations to run (the first `warmup` are not counted).
    #[arg(long, default_value_t = 20)]
    pub iterations: u64,
    #[arg(long, default_value_t = 5)]
    pub warmup: u64,
}

/// `l3p bench deploy` arguments.
#[derive(Debug, Args)]
pub struct DeployBenchArgs {
    /// Export file or directory (e.g. docs/a1-flat-session1/policy).
    #[arg(long)]
    pub policy: std::path::PathBuf,
    #[arg(long, default_value = "a1")]
    pub robot: String,
    /// Seconds of each measurement (baseline, then deploy).
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Forward command given to the sim-robot (m/s).
    #[arg(long, default_value_t = 0.5)]
    pub vx: f32,
}

/// `l3p bench learner` arguments.
#[derive(Debug, Args)]
pub struct LearnerBenchArgs {
    /// Parallel envs (batch = envs × steps).
    #[arg(long, default_value_t = 1024)]
    pub envs: usize,
    /// Steps per env per update.
    #[arg(long, default_value_t = 24)]
    pub steps: usize,
    /// Observation size.
    #[arg(long, default_value_t = 48)]
    pub obs: usize,
    /// Action size.
    #[arg(long, default_value_t = 12)]
    pub actions: usize,
    /// Actor and critic hidden sizes, comma separated.
    #[arg(long, default_value = "512,256,128", value_delimiter = ',')]
    pub hidden: Vec<usize>,
    /// Threads for the tensor kernels.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Architecture: mlp (rsl_rl's ActorCritic) or l3p.
    #[arg(long, default_value = "mlp")]
    pub mode: String,
    /// Timed updates (median reported, after one warm-up).
    #[arg(long, default_value_t = 2)]
    pub updates: usize,
    /// Time this training config's networks and PPO settings instead of --mode/--hidden; the
    /// observation and action sizes, envs and steps come from its env and first actor.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
}

/// Terrain choices for the benchmark.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum BenchTerrain {
    /// Flat ground, 48-dim observations.
    Flat,
    /// Half flat, half small random rough.
    SimpleRough,
    /// IsaacLab 2.1 rough terrain with curriculum, 235-dim observations.
    Curriculum,
    /// The paper's larger difficulty ranges.
    Paper,
}

/// `l3p bench sim` arguments.
#[derive(Debug, Args)]
pub struct SimBenchArgs {
    /// Robot name.
    #[arg(long, default_value = "a1")]
    pub robot: String,
    /// Number of envs.
    #[arg(long, default_value_t = 64)]
    pub envs: usize,
    /// Terrain preset.
    #[arg(long, value_enum, default_value_t = BenchTerrain::Curriculum)]
    pub terrain: BenchTerrain,
    /// Wall-clock seconds to run.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stairs and boxes as meshes with vertical risers (`[env.terrain] vertical_faces`).
    #[arg(long)]
    pub vertical_faces: bool,
}

/// Runs a `bench` subcommand.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.command {
        BenchCommand::Sim(a) => sim(a),
        BenchCommand::Learner(a) => learner(a),
        BenchCommand::Deploy(a) => deploy(a),
        BenchCommand::Train(a) => train(a),
    }
}

fn train(a: TrainBenchArgs) -> anyhow::Result<()> {
    if a.iterations <= a.warmup {
        anyhow::bail!(
            "--iterations {} must exceed --warmup {}",
            a.iterations,
            a.warmup
        );
    }
    let scratch = std::env::temp_dir().join(format!("l3p-bench-train-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    let result = bench_train_in(&a, &scratch);
    let _ = std::fs::remove_dir_all(&scratch);
    result
}

fn bench_train_in(a: &TrainBenchArgs, scratch: &std::path::Path) -> anyhow::Result<()> {
    crate::train_cmd::run(crate::train_cmd::TrainArgs {
        config: a.config.clone(),
        run: Some("bench".into()),
        iterations: Some(a.iterations),
        envs: None,
        data_dir: Some(scratch.to_path_buf()),
        flags: crate::train_cmd::TrainingFlags {
            quiet: true,
            until_walks: false,
            sim2sim: false,
            eval_every: 25,
            screen_every: 0,
            rerun: None,
            rerun_every: 50,
        },
    })?;
    let text = std::fs::read_to_string(l3p_learner::daemon::metrics_path(&scratch.join("bench")))?;
    let records: Vec<l3p_proto::MetricsRecord> = text
        .lines()
        .filter_map(|l| l3p_proto::codec::decode_json(l.as_bytes()).ok())
        .filter(|r: &l3p_proto::MetricsRecord| r.iteration > a.warmup)
        .collect();
    if records.is_empty() {
        anyhow::bail!("no iterations after the warm-up were recorded");
    }
    let median = |key: &str| -> f64 {
        let mut v: Vec<f64> = records
            .iter()
            .filter_map(|r| r.values.get(key).copied())
            .collect();
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            f64::NAN
        } else {
            v[v.len() / 2]
        }
    };
    let iteration = median("iteration_seconds");
    println!(
        "bench train: {} ({} iterations after {} warm-up, medians)",
        a.config.display(),
        records.len(),
        a.warmup
    );
    println!(
        "  end to end        {:>9.0} samples/s  ({:.0} samples in {:.3} s per iteration)",
        median("samples_per_second"),
        median("samples"),
        iteration
    );
    let rows = [
        ("collect (actor)", median("collect_seconds")),
        ("  physics", median("time/physics_seconds")),
        ("  inference", median("time/inference_seconds")),
        ("  observations", median("time/observations_seconds")),
        ("  rewards", median("time/rewards_seconds")),
        ("  resets", median("time/resets_seconds")),
        ("update (learner)", median("update_seconds")),
        ("transport share", median("transport_share") * iteration),
    ];
    for (name, s) in rows {
        println!("  {name:<18}{s:>9.3} s  {:>5.1}%", 100.0 * s / iteration);
    }
    Ok(())
}

fn learner(a: LearnerBenchArgs) -> anyhow::Result<()> {
    let mut cfg = l3p_learner::bench::LearnerBenchConfig {
        mode: a.mode.parse()?,
        envs: a.envs,
        steps: a.steps,
        obs_dim: a.obs,
        action_dim: a.actions,
        hidden: a.hidden.clone(),
        updates: a.updates,
        seed: 1,
        threads: a.threads,
        from_config: None,
    };
    let mut what = format!("mode {} hidden {:?}", a.mode, a.hidden);
    let mut ppo = l3p_learner::PpoConfig::default();
    if let Some(path) = &a.config {
        let config = crate::config::Config::load(path)?;
        let actor = config
            .actors
            .first()
            .ok_or_else(|| anyhow::anyhow!("{} has no [[actors]]", path.display()))?;
        let spec = l3p_robot::catalog::RobotSpec::by_name(&actor.robot)?;
        cfg.obs_dim = config.env.obs_dim();
        cfg.action_dim = spec.joint_names.len();
        cfg.envs = actor.envs;
        cfg.steps = config.rollout.steps_per_env;
        cfg.mode = config.ppo.mode;
        ppo = config.ppo.clone();
        cfg.from_config = Some((config.model.clone(), config.ppo.clone()));
        what = format!("{} ({})", path.display(), config.ppo.mode.as_str());
    }
    let r = l3p_learner::bench::run_learner_bench(&cfg)?;
    println!(
        "bench learner: {what} obs {} envs {} x {} steps threads {} (actor params {})",
        cfg.obs_dim, cfg.envs, cfg.steps, a.threads, r.actor_params
    );
    println!(
        "  update ({} epochs x {} minibatches): {:.3} s, {:.0} samples/s",
        ppo.num_learning_epochs, ppo.num_mini_batches, r.update_seconds, r.samples_per_second
    );
    println!(
        "  inference, batch {}: burn {:.0} obs/s, pure-Rust export {:.0} obs/s",
        cfg.envs, r.infer_burn_obs_per_second, r.infer_rust_obs_per_second
    );
    Ok(())
}

fn deploy(a: DeployBenchArgs) -> anyhow::Result<()> {
    use l3p_deploy::pacer::Pacer;
    use l3p_deploy::stats::Percentiles;
    use l3p_net::{ZenohSettings, free_loopback_port, open_session};
    use std::time::{Duration, Instant};

    let robot = RobotSpec::by_name(&a.robot)?;
    let loaded = l3p_deploy::read_policy_file(&a.policy, robot)?;
    let period = Duration::from_secs_f32(loaded.io.control_dt);
    let seconds = Duration::from_secs_f64(a.seconds);

    // Baseline: the same deadline loop doing nothing.
    let mut pacer = Pacer::new(period);
    let mut base = Percentiles::new(usize::MAX / 2);
    let start = Instant::now();
    while start.elapsed() < seconds {
        if let (_, Some(dt)) = pacer.wait() {
            base.push((dt.as_secs_f64() - period.as_secs_f64()).abs() as f32 * 1e6);
        }
    }
    let (b50, b99) = base.p50_p99();

    let rt = crate::runtime::tokio_runtime()?;
    let status = rt.block_on(async {
        let port = free_loopback_port()?;
        let robot_session = open_session(&ZenohSettings::loopback(Some(port), &[])).await?;
        let deploy_session = open_session(&ZenohSettings::loopback(None, &[port])).await?;
        let cancel = tokio_util::sync::CancellationToken::new();
        let sim = tokio::spawn({
            let cancel = cancel.clone();
            async move {
                let opts = l3p_actor::SimRobotOptions {
                    robot,
                    robot_id: "bench".into(),
                    state_hz: 200,
                    command: [a.vx, 0.0, 0.0],
                    duration: None,
                    command_timeout_s: 0.1,
                };
                l3p_actor::run_sim_robot(&robot_session, opts, cancel).await
            }
        });
        let opts = l3p_deploy::DeployOptions {
            robot,
            robot_id: "bench".into(),
            safety: l3p_deploy::SafetyConfig::default(),
            duration: Some(seconds),
            status_every: Duration::from_secs(1),
            insecure: None,
            heading_hold: false,
        };
        let status = l3p_deploy::run_deploy(
            &deploy_session,
            loaded,
            opts,
            tokio_util::sync::CancellationToken::new(),
        )
        .await?;
        cancel.cancel();
        let summary = sim.await??;
        anyhow::Ok((status, summary))
    })?;
    let (status, summary) = status;
    println!(
        "bench deploy: robot {} policy {} {} Hz, {:.0} s each",
        robot.name,
        a.policy.display(),
        1.0 / period.as_secs_f64(),
        a.seconds
    );
    println!("  baseline deadline loop (no work): period error p50 {b50:.1} us, p99 {b99:.1} us");
    println!(
        "  deploy loop: period error p50 {:.1} us, p99 {:.1} us ({:.2}x / {:.2}x baseline); overruns {}",
        status.period_error_p50_us,
        status.period_error_p99_us,
        status.period_error_p50_us / b50.max(1.0),
        status.period_error_p99_us / b99.max(1.0),
        status.overruns
    );
    println!(
        "  inference (observation -> action, 1 obs): p50 {:.1} us, p99 {:.1} us",
        status.inference_p50_us, status.inference_p99_us
    );
    println!(
        "  sim-robot: {:.1} s under the policy, {:.2} m/s forward, min base height {:.2} m, max tilt {:.0} deg",
        summary.policy_seconds,
        summary.policy_mean_forward_velocity,
        summary.policy_min_base_height,
        summary.policy_max_tilt_deg
    );
    Ok(())
}

fn sim(a: SimBenchArgs) -> anyhow::Result<()> {
    let spec = RobotSpec::by_name(&a.robot)?;
    let preset = match a.terrain {
        BenchTerrain::Flat => TerrainPreset::Flat,
        BenchTerrain::SimpleRough => TerrainPreset::SimpleRough,
        BenchTerrain::Curriculum => TerrainPreset::Curriculum,
        BenchTerrain::Paper => TerrainPreset::Paper,
    };
    let cfg = EnvConfig {
        terrain: TerrainConfig {
            vertical_faces: a.vertical_faces,
            ..TerrainConfig::with_preset(preset)
        },
        height_scan: preset != TerrainPreset::Flat,
        ..EnvConfig::default()
    };
    let r = run_sim_bench(spec, &cfg, a.envs, a.threads, a.seconds, a.seed)?;
    let per_step = |d: std::time::Duration| d.as_secs_f64() * 1e6 / r.steps.max(1) as f64;
    let t = r.timings;
    println!(
        "bench sim: robot {} terrain {:?} envs {} threads {} seconds {:.1}",
        spec.name,
        a.terrain,
        r.envs,
        r.threads,
        r.wall.as_secs_f64()
    );
    println!(
        "control steps/s: {:.0}  (physics steps/s {:.0}, {} vec steps)",
        r.control_steps_per_s, r.physics_steps_per_s, r.steps
    );
    println!(
        "per vec step [us]: total {:.0} | per worker: physics {:.0}, observations {:.0}, rewards {:.0}, resets {:.0}",
        per_step(t.total),
        per_step(t.physics),
        per_step(t.observations),
        per_step(t.rewards),
        per_step(t.resets)
    );
    println!(
        "episodes finished {}, nan resets {}, mean terrain level {:.2}",
        r.episodes, r.nan_resets, r.mean_terrain_level
    );
    Ok(())
}
