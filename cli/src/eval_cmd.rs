//! `l3p eval --policy <ref> --robot a1 --terrain flat --episodes N`: play a policy without learning.

use std::path::{Path, PathBuf};

use clap::Args;
use l3p_policy::DeployPolicy;
use l3p_robots::config::TerrainPreset;

use crate::config::Config;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A deployable policy: an export file/directory, or a registry ref `name@version|alias` (e.g.
    /// `a1-flat-a1@latest`) read from the local registry under --data-dir.
    #[arg(long)]
    pub policy: String,
    /// Robot to simulate.
    #[arg(long)]
    pub robot: String,
    /// Terrain preset: flat, simple-rough, curriculum, paper.
    #[arg(long, default_value = "flat")]
    pub terrain: String,
    /// Finished episodes to average over.
    #[arg(long, default_value_t = 64)]
    pub episodes: usize,
    /// Parallel environments.
    #[arg(long, default_value_t = 32)]
    pub envs: usize,
    /// Config whose [env] section to use (defaults otherwise); its height_scan must match the policy.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Forward-velocity command range, e.g. `0.5,1.0` (sets vy and yaw commands to zero).
    #[arg(long, value_delimiter = ',', num_args = 1, value_name = "MIN,MAX")]
    pub lin_vel_x: Option<Vec<f32>>,
    /// Data directory holding the registry.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// Seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

/// Load a deployable policy from a path or from the local registry.
pub fn load_policy(reference: &str, data_dir: &Path) -> anyhow::Result<DeployPolicy> {
    let path = Path::new(reference);
    if path.exists() {
        return Ok(DeployPolicy::load(path)?);
    }
    let registry = l3p_registry::Registry::open(data_dir)?;
    let (meta, bytes) = registry.get_blob(reference)?;
    if meta.kind != l3p_registry::ArtifactKind::Deploy {
        anyhow::bail!(
            "{reference} is a {:?} artifact, not a deployable policy",
            meta.kind
        );
    }
    Ok(DeployPolicy::from_bytes(&bytes)?)
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let mut config = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    let policy = load_policy(&args.policy, &args.data_dir)?;
    config.env.terrain.preset = match args.terrain.as_str() {
        "flat" => TerrainPreset::Flat,
        "simple-rough" => TerrainPreset::SimpleRough,
        "curriculum" => TerrainPreset::Curriculum,
        "paper" => TerrainPreset::Paper,
        other => {
            anyhow::bail!("unknown terrain {other}\nhint: flat, simple-rough, curriculum or paper")
        }
    };
    // A blind policy (48 observations) runs without the height scan.
    config.env.height_scan = policy.obs_dim() != l3p_robots::config::PROPRIO_OBS;
    if let Some(range) = &args.lin_vel_x {
        if range.len() != 2 || range[0] > range[1] {
            anyhow::bail!("--lin-vel-x takes MIN,MAX with MIN <= MAX, got {range:?}");
        }
        config.env.commands.lin_vel_x = [range[0], range[1]];
        config.env.commands.lin_vel_y = [0.0, 0.0];
        config.env.commands.ang_vel_z = [0.0, 0.0];
        config.env.commands.heading_command = false;
        config.env.commands.rel_standing_envs = 0.0;
    }
    let robot = l3p_robots::catalog::RobotSpec::by_name(&args.robot)?;
    let mut env = l3p_actor::sim_env(robot, &config.env, args.envs, 1, args.seed)?;
    let max_steps = 1000 * (args.episodes / args.envs.max(1) + 2);
    let s = l3p_actor::evaluate(&mut env, &policy, args.episodes, max_steps)?;
    println!(
        "policy {} on {} ({} terrain), {} episodes",
        args.policy, robot.name, args.terrain, s.episodes
    );
    println!("  xy-velocity tracking error  {:.3} m/s", s.lin_vel_error);
    println!(
        "  yaw-rate tracking error     {:.3} rad/s",
        s.yaw_rate_error
    );
    println!("  episode reward              {:.3}", s.episode_return);
    println!(
        "  episode length              {:.1} steps",
        s.episode_length
    );
    println!("  terrain level               {:.2}", s.terrain_level);
    println!(
        "  falls                       {:.1}%",
        100.0 * s.fall_fraction
    );
    if let Some(h) = s.mean_base_height {
        let standing = robot.nominal_standing_height()?;
        println!(
            "  base height above ground    {h:.3} m ({:.0}% of the {standing:.3} m standing height)",
            100.0 * h / standing
        );
    }
    Ok(())
}
