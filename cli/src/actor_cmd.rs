//! `l3p actor --config <toml> --robot <name>`: one rollout actor daemon.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use l3p_actor::ActorOptions;

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
    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        if args.exit_with_parent {
            cancel_when_stdin_closes(cancel.clone());
        }
        let session = l3p_net::open_session(&config.zenoh).await?;
        // Only asked for a robot neither the catalog nor the data directory has: a missing
        // registry should not hold the actor for the default two minutes.
        let registry = l3p_registry::RegistryClient::new(&session)
            .with_timeouts(Duration::from_secs(20), Duration::from_secs(60));
        let robot = resolve_robot(&registry, &args.robot, &config.run.data_dir).await?;
        let entry = config.actors.iter().find(|a| a.robot == robot.name);
        let envs = args.envs.or(entry.map(|a| a.envs)).unwrap_or(64);
        let threads = args.threads.or(entry.map(|a| a.threads)).unwrap_or(1);
        let actor_id = args
            .id
            .clone()
            .unwrap_or_else(|| format!("{}-{}", robot.name, std::process::id()));
        let seed =
            config.run.seed ^ (std::process::id() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut env = l3p_actor::sim_env(robot, &config.env, envs, threads, seed)?;
        if config.rollout.random_initial_episode_length {
            env.env.stagger_time_outs();
        }
        let opts = ActorOptions {
            run: config.run.name.clone(),
            robot: robot.name.to_string(),
            actor_id,
            steps_per_env: config.rollout.steps_per_env,
            seed,
            max_chunks: args.max_chunks,
        };
        let chunks = l3p_actor::run(session, opts, env, cancel).await?;
        println!("actor stopped after {chunks} chunks");
        Ok(())
    })
}

/// A catalog robot, one added under the run's data directory, or else one added on another
/// machine: its registry artifact (`l3p robots add` stores one) is fetched into
/// `<data_dir>/robots/` so that this actor simulates the same robot.
async fn resolve_robot(
    registry: &l3p_registry::RegistryClient,
    name: &str,
    data_dir: &std::path::Path,
) -> anyhow::Result<&'static l3p_robot::catalog::RobotSpec> {
    let unknown = match l3p_robot::catalog::RobotSpec::by_name(name) {
        Ok(robot) => return Ok(robot),
        Err(e) => e,
    };
    let key = l3p_robot::added::sanitize_name(name);
    let reference = format!("{}@latest", crate::robots_cmd::robot_artifact(&key));
    let fetched = registry.try_get_blob(&reference).await;
    match fetched {
        Ok(Some((meta, bytes))) => {
            let dir = data_dir.join("robots");
            let robot = crate::robots_cmd::install_robot_artifact(&bytes, &key, &dir)
                .with_context(|| format!("installing {}", meta.reference()))?;
            tracing::info!(robot = robot.name, artifact = %meta.reference(), dir = %dir.display(), "robot fetched from the registry");
            Ok(robot)
        }
        Ok(None) => Err(anyhow::anyhow!(
            "{unknown}\nhint: no registry artifact `{reference}` either; add the robot with `l3p robots add` where the registry's data lives"
        )),
        Err(e) => Err(anyhow::anyhow!(
            "{unknown}\nhint: asking the registry for `{reference}` failed: {e}"
        )),
    }
}
