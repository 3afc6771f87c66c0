//! `l3p transfer --robot <name> --from <ref|checkpoint>`: fine-tune a pretrained policy on another
//! robot. From an L3P checkpoint the core is loaded and frozen and only the robot's encoder,
//! decoder and the critic train (`l3p-transfer`); from an MLP checkpoint everything trains
//! (`mlp-transfer`). The run's config (the base config with the robot, the mode and the source) is
//! written to `<data_dir>/<run>/transfer.toml` and trained as `l3p train` trains it; its registry
//! checkpoints name the source checkpoint as lineage (`from_checkpoint`) when it came from the
//! registry. Glue only: the transfer itself is `l3p_learner::init_model`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use l3p_learner::Mode;
use l3p_policy::Arch;
use l3p_registry::ArtifactKind;

use crate::config::{ActorSpec, Config};
use crate::train_cmd::{self, TrainArgs, TrainingFlags};

/// `l3p transfer` arguments.
#[derive(Debug, Args)]
pub struct TransferArgs {
    /// Target robot (built-in or added with `l3p robots add`).
    #[arg(long)]
    pub robot: String,
    /// Source policy: a checkpoint file or a registry checkpoint artifact (`a1-flat-checkpoint@3`,
    /// `...@latest`) in the data directory's registry.
    #[arg(long)]
    pub from: String,
    /// Base config (env, rewards, networks, PPO) of the fine-tuning run.
    #[arg(long, default_value = "configs/a1-flat.toml")]
    pub config: PathBuf,
    /// Run name (default `<robot>-transfer`).
    #[arg(long)]
    pub run: Option<String>,
    /// Iterations (default: the base config's max_iterations).
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Environments (default: the base config's first actor's).
    #[arg(long)]
    pub envs: Option<usize>,
    /// Data directory (default: the base config's).
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    #[command(flatten)]
    pub flags: TrainingFlags,
}

/// Builds the fine-tuning config, writes it to `<data_dir>/<run>/transfer.toml` and trains it.
pub fn run(args: TransferArgs) -> anyhow::Result<()> {
    let mut config = Config::load(&args.config)?;
    if let Some(dir) = &args.data_dir {
        config.run.data_dir = dir.clone();
        crate::robots_cmd::load_added_robots(Some(dir));
    }
    let robot = l3p_robot::catalog::RobotSpec::by_name(&args.robot)?;
    let run = args
        .run
        .clone()
        .unwrap_or_else(|| format!("{}-transfer", robot.name));
    l3p_proto::keys::validate_segment("run", &run)?;
    let run_dir = config.run.data_dir.join(&run);
    std::fs::create_dir_all(&run_dir).with_context(|| format!("creating {}", run_dir.display()))?;
    let (checkpoint, source_artifact) =
        source_checkpoint(&args.from, &config.run.data_dir, &run_dir)?;
    let source = l3p_policy::load_checkpoint(&checkpoint, &l3p_policy::cpu_device())
        .with_context(|| format!("loading {}", checkpoint.display()))?;
    let mode = match source.model.config.arch {
        Arch::L3p => Mode::L3pTransfer,
        Arch::Mlp => Mode::MlpTransfer,
    };
    let first = config.actors.first().cloned();
    config.run.name = run.clone();
    config.ppo.mode = mode;
    config.learner.init_from = Some(checkpoint.clone());
    config.learner.init_from_artifact = source_artifact.clone();
    if let Some(n) = args.iterations {
        config.learner.max_iterations = n;
    }
    config.actors = vec![ActorSpec {
        robot: robot.name.to_string(),
        envs: args.envs.or(first.as_ref().map(|a| a.envs)).unwrap_or(512),
        threads: first.as_ref().map_or(2, |a| a.threads),
    }];
    config.validate().map_err(|e| anyhow::anyhow!(e))?;
    let path = run_dir.join("transfer.toml");
    let text = format!(
        "# `l3p transfer --robot {} --from {}` (base config {}).\n{}",
        robot.name,
        args.from,
        args.config.display(),
        toml::to_string(&config)?
    );
    l3p_policy::write_atomic(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "transfer: {} policy of {} (robots: {}) → {} as {}; config {}",
        source.model.config.arch,
        source_artifact.as_deref().unwrap_or(&args.from),
        source
            .model
            .robots
            .iter()
            .map(|r| r.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        robot.name,
        mode.as_str(),
        path.display()
    );
    train_cmd::run(TrainArgs {
        config: path,
        run: None,
        iterations: None,
        envs: None,
        data_dir: None,
        flags: args.flags,
    })
}

/// The checkpoint file to start from and, when it came from the registry, its `name@version`.
fn source_checkpoint(
    from: &str,
    data_dir: &Path,
    run_dir: &Path,
) -> anyhow::Result<(PathBuf, Option<String>)> {
    let file = Path::new(from);
    if file.is_file() {
        return Ok((file.to_path_buf(), None));
    }
    let registry = l3p_registry::Registry::open(data_dir)
        .with_context(|| format!("opening the registry in {}", data_dir.display()))?;
    let (meta, bytes) = registry.get_blob(from).with_context(|| {
        format!(
            "{from}: neither a checkpoint file nor an artifact of the registry in {}",
            data_dir.display()
        )
    })?;
    if meta.kind != ArtifactKind::Checkpoint {
        anyhow::bail!(
            "{from} is a {} artifact; transfer starts from a checkpoint\nhint: `l3p registry list` shows the `<run>-checkpoint` artifacts",
            meta.kind
        );
    }
    let path = run_dir.join("source.ckpt");
    l3p_policy::write_atomic(&path, &bytes)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok((path, Some(format!("{}@{}", meta.name, meta.version))))
}
