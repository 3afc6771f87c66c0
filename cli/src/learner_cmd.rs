//! `l3p learner --config <toml>`: the learner daemon.

use std::path::PathBuf;

use clap::Args;
use l3p_learner::daemon::{self, LearnerOptions};

use crate::config::Config;
use crate::runtime;

#[derive(Debug, Args)]
pub struct LearnerArgs {
    /// Run config (TOML); see configs/reference.toml.
    #[arg(long)]
    pub config: PathBuf,
    /// Zenoh endpoint to listen on (e.g. tcp/0.0.0.0:7447); overrides [zenoh] listen.
    #[arg(long)]
    pub listen: Vec<String>,
    /// Zenoh endpoint to connect to; overrides [zenoh] connect.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Store checkpoints and deployable policies in the registry service too.
    #[arg(long)]
    pub registry: bool,
}

/// Learner options for a config.
pub fn learner_options(config: &Config, use_registry: bool) -> anyhow::Result<LearnerOptions> {
    let robots = runtime::configured_robots(config)?;
    Ok(LearnerOptions {
        run: config.run.name.clone(),
        run_dir: config.run.data_dir.join(&config.run.name),
        daemon: config.learner.clone(),
        ppo: config.ppo.clone(),
        policy: config.model.clone(),
        robots: robots
            .iter()
            .map(|r| runtime::policy_robot(config, r))
            .collect::<anyhow::Result<_>>()?,
        use_registry,
        steps_per_env: config.rollout.steps_per_env,
        obs_clip: config.env.obs_clip,
        mirrors: if config.ppo.symmetry_coef > 0.0 || config.ppo.symmetrize_export {
            robots
                .iter()
                .map(|r| Ok((r.name.to_string(), runtime::mirror(config, r)?)))
                .collect::<anyhow::Result<_>>()?
        } else {
            Vec::new()
        },
        transfer_maps: runtime::transfer_maps(config, &robots)?,
    })
}

pub fn run(args: LearnerArgs) -> anyhow::Result<()> {
    let mut config = Config::load(&args.config)?;
    if !args.listen.is_empty() {
        config.zenoh.listen = args.listen.clone();
    }
    if !args.connect.is_empty() {
        config.zenoh.connect = args.connect.clone();
    }
    let opts = learner_options(&config, args.registry)?;
    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        let session = l3p_net::open_session(&config.zenoh).await?;
        let summary = daemon::run(session, opts, cancel, None).await?;
        println!(
            "learner stopped at iteration {} ({} stale chunks dropped, {} rejected)",
            summary.iterations, summary.dropped_chunks, summary.rejected_chunks
        );
        Ok(())
    })
}
