//! `l3p bench ...`: throughput benchmarks. `bench sim` steps the vectorised env with random actions
//! (all task work included) and prints control steps per second and stage timings.

use clap::{Args, Subcommand, ValueEnum};
use l3p_robots::bench::run_sim_bench;
use l3p_robots::catalog::RobotSpec;
use l3p_robots::config::{EnvConfig, TerrainConfig, TerrainPreset};

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
    /// Learner throughput: one full PPO update (5 epochs × 4 minibatches) on synthetic data, and
    /// policy inference for a batch of `envs` observations.
    Learner(LearnerBenchArgs),
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
}

/// Runs a `bench` subcommand.
pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.command {
        BenchCommand::Sim(a) => sim(a),
        BenchCommand::Learner(a) => learner(a),
    }
}

fn learner(a: LearnerBenchArgs) -> anyhow::Result<()> {
    let cfg = l3p_learner::bench::LearnerBenchConfig {
        mode: a.mode.parse()?,
        envs: a.envs,
        steps: a.steps,
        obs_dim: a.obs,
        action_dim: a.actions,
        hidden: a.hidden.clone(),
        updates: a.updates,
        seed: 1,
        threads: a.threads,
    };
    let r = l3p_learner::bench::run_learner_bench(&cfg)?;
    println!(
        "bench learner: mode {} obs {} hidden {:?} envs {} x {} steps threads {} (actor params {})",
        a.mode, a.obs, a.hidden, a.envs, a.steps, a.threads, r.actor_params
    );
    println!(
        "  update (5 epochs x 4 minibatches): {:.3} s, {:.0} samples/s",
        r.update_seconds, r.samples_per_second
    );
    println!(
        "  inference, batch {}: burn {:.0} obs/s, pure-Rust export {:.0} obs/s",
        a.envs, r.infer_burn_obs_per_second, r.infer_rust_obs_per_second
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
        terrain: TerrainConfig::with_preset(preset),
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
