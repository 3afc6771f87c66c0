//! `l3p actor --config <toml> --robot <name>`: one rollout actor daemon.

use std::path::PathBuf;

use clap::Args;
use l3p_actor::ActorOptions;
use l3p_registry::net;

use crate::config::Config;
use crate::runtime;

#[derive(Debug, Args)]
pub struct ActorArgs {
    /// Run config (TOML); see configs/reference.toml.
    #[arg(long)]
    pub config: PathBuf,
    /// Robot to simulate (see `l3p robots list`).
    #[arg(long)]
    pub robot: String,
    /// Parallel environments (default: the config's first actor entry for this robot, else 64).
    #[arg(long)]
    pub envs: Option<usize>,
    /// Simulator threads.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Actor id, unique within the run (default: robot-pid).
    #[arg(long)]
    pub id: Option<String>,
    /// Zenoh endpoint to connect to; overrides [zenoh] connect.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Stop after this many chunks (0: until stopped).
    #[arg(long, default_value_t = 0)]
    pub max_chunks: u64,
    /// Stop when standard input closes: `l3p train` starts its actors with a pipe on stdin, which
    /// the kernel closes when `l3p train` ends in any way (even SIGKILL), so no actor outlives it.
    #[arg(long)]
    pub exit_with_parent: bool,
}

/// Cancels `cancel` when stdin reaches end of file (or fails).
fn cancel_when_stdin_closes(cancel: tokio_util::sync::CancellationToken) {
    std::thread::spawn(move || {
        use std::io::Read;
        let mut stdin = std::io::stdin();
        let mut buf = [0u8; 256];
        while matches!(stdin.read(&mut buf), Ok(n) if n > 0) {}
        tracing::warn!("parent process gone (stdin closed): stopping");
        cancel.cancel();
    });
}

pub fn run(args: ActorArgs) -> anyhow::Result<()> {
    let mut config = Config::load(&args.config)?;
    if !args.connect.is_empty() {
        config.zenoh.connect = args.connect.clone();
        config.zenoh.listen.clear();
    }
    let robot = l3p_robots::catalog::RobotSpec::by_name(&args.robot)?;
    let entry = config.actors.iter().find(|a| a.robot == robot.name);
    let envs = args.envs.or(entry.map(|a| a.envs)).unwrap_or(64);
    let threads = args.threads.or(entry.map(|a| a.threads)).unwrap_or(1);
    let actor_id = args
        .id
        .clone()
        .unwrap_or_else(|| format!("{}-{}", robot.name, std::process::id()));
    let seed = config.run.seed ^ (std::process::id() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let env = l3p_actor::sim_env(robot, &config.env, envs, threads, seed)?;
    let opts = ActorOptions {
        run: config.run.name.clone(),
        robot: robot.name.to_string(),
        actor_id,
        steps_per_env: config.rollout.steps_per_env,
        seed,
        max_chunks: args.max_chunks,
    };
    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        if args.exit_with_parent {
            cancel_when_stdin_closes(cancel.clone());
        }
        let session = net::open_session(&config.zenoh).await?;
        let chunks = l3p_actor::run(session, opts, env, cancel).await?;
        println!("actor stopped after {chunks} chunks");
        Ok(())
    })
}
