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
    }
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
