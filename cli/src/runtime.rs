//! Shared glue of the daemon commands: [`NetArgs`] (the network flags of every command that joins
//! Zenoh), the tokio runtime, Ctrl-C → cancellation ([`Interrupted`]), and the policy's view of the
//! configured robots.

use std::path::PathBuf;

use clap::Args;
use l3p_net::ZenohSettings;
use l3p_robots::catalog::RobotSpec as Robot;
use tokio_util::sync::CancellationToken;

use crate::config::Config;

/// How a command joins the Zenoh network.
#[derive(Debug, Clone, Args)]
pub struct NetArgs {
    /// Config file: its [zenoh] section (with [zenoh.tls]) is used, and [deploy] by `l3p deploy`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Zenoh endpoint to connect to (repeatable); default tcp/127.0.0.1:7447 without --config.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
}

impl NetArgs {
    /// The run config (defaults without `--config`) and the Zenoh settings: the config's `[zenoh]`
    /// (with `[zenoh.tls]`), else a peer that connects to `tcp/127.0.0.1:7447` and listens nowhere;
    /// `--connect`/`--listen` replace its endpoints.
    pub fn load(&self) -> anyhow::Result<(Config, ZenohSettings)> {
        let config = match &self.config {
            Some(path) => Config::load(path)?,
            None => Config::default(),
        };
        let mut zenoh = config.zenoh.clone();
        if self.config.is_none() {
            zenoh.multicast_scouting = false;
            zenoh.connect = vec!["tcp/127.0.0.1:7447".into()];
        }
        if !self.connect.is_empty() {
            zenoh.connect = self.connect.clone();
        }
        if !self.listen.is_empty() {
            zenoh.listen = self.listen.clone();
        }
        Ok((config, zenoh))
    }
}

/// The command stopped because its user asked it to (Ctrl-C, SIGTERM) and left its work resumable:
/// an expected end, which `main` reports as its message and exit status 130 — never with the
/// backtrace that `RUST_BACKTRACE=1` adds to a failure.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// Whether `RUST_LIB_BACKTRACE` asks for error backtraces (set and not `0`, as std reads it).
/// `RUST_BACKTRACE` alone does not: it is for panics, and CI sets it for every command.
pub fn lib_backtrace_asked() -> bool {
    std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0")
}

/// A failed command's error as `main` prints it: `error: ` and the chain of causes on one line
/// (`context: cause: …`, hint lines as the messages hold them); `verbose` (`-v`, or
/// `RUST_LIB_BACKTRACE`) adds anyhow's full report — the causes one per line and the stack
/// backtrace when one was captured.
pub fn error_report(error: &anyhow::Error, verbose: bool) -> String {
    if verbose {
        format!("error: {error:?}")
    } else {
        format!("error: {error:#}")
    }
}

/// A multi-threaded tokio runtime for Zenoh and the daemon loops (heavy work runs on blocking threads).
pub fn tokio_runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?)
}

/// A token cancelled by the first Ctrl-C (SIGINT) or SIGTERM; a second Ctrl-C exits at once.
pub fn cancel_on_signal() -> CancellationToken {
    let cancel = CancellationToken::new();
    let token = cancel.clone();
    tokio::spawn(async move {
        let term = async {
            #[cfg(unix)]
            if let Ok(mut s) =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            {
                s.recv().await;
                return;
            }
            std::future::pending::<()>().await
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term => {}
        }
        tracing::info!("stopping (signal received; a second Ctrl-C exits immediately)");
        token.cancel();
        let _ = tokio::signal::ctrl_c().await;
        std::process::exit(130);
    });
    cancel
}

/// Observation size of the configured task.
pub fn obs_dim(config: &Config) -> usize {
    config.env.obs_dim()
}

/// Left-right mirror maps of `robot`'s task under this config (for `[ppo] symmetry_coef`).
pub fn mirror(config: &Config, robot: &Robot) -> anyhow::Result<l3p_learner::Mirror> {
    let model = robot.model()?;
    let m = l3p_robots::mirror::TaskMirror::new(
        &model,
        &robot.joint_names,
        &robot.default_pose,
        config.env.height_scan,
        config.env.gait_clock_hz > 0.0,
    )
    .map_err(|e| {
        anyhow::anyhow!(
            "{}: no mirror symmetry for ppo.symmetry_coef: {e}",
            robot.name
        )
    })?;
    Ok(l3p_learner::Mirror {
        obs_index: m.observation.index,
        obs_sign: m.observation.sign,
        action_index: m.action.index,
        action_sign: m.action.sign,
    })
}

/// `[ppo] transfer_heads = "mapped"`: the morphology map from the init checkpoint's prototype
/// (first) robot to each configured robot (empty otherwise).
pub fn transfer_maps(
    config: &Config,
    robots: &[&Robot],
) -> anyhow::Result<Vec<(String, l3p_policy::HeadMap)>> {
    let from = match (&config.learner.init_from, config.ppo.transfer_heads) {
        (Some(from), l3p_learner::TransferHeads::Mapped) => from,
        _ => return Ok(Vec::new()),
    };
    let source = l3p_policy::load_checkpoint(from, &l3p_policy::cpu_device())
        .map_err(|e| anyhow::anyhow!("loading {}: {e}", from.display()))?;
    let prototype = source
        .model
        .robots
        .first()
        .ok_or_else(|| anyhow::anyhow!("{}: a checkpoint without robots", from.display()))?;
    let prototype = Robot::by_name(&prototype.name).map_err(|e| {
        anyhow::anyhow!("transfer_heads = \"mapped\" needs the prototype's model: {e}")
    })?;
    robots
        .iter()
        .map(|r| {
            let m = l3p_robots::morphology::TransferMap::new(
                prototype,
                r,
                config.env.height_scan,
                config.env.gait_clock_hz > 0.0,
            )
            .map_err(|e| anyhow::anyhow!("mapping {} onto {}: {e}", prototype.name, r.name))?;
            Ok((
                r.name.to_string(),
                l3p_policy::HeadMap {
                    obs_dim: m.obs_dim,
                    observation: m.observation,
                    action_dim: l3p_robots::catalog::NUM_JOINTS,
                    action: m.action,
                    action_inverse: m.action_inverse,
                },
            ))
        })
        .collect()
}

/// The policy's description of a robot under this config, with the controller contract
/// ([`l3p_policy::RobotIo`]) that travels into checkpoints and deploy artifacts.
pub fn policy_robot(config: &Config, robot: &Robot) -> anyhow::Result<l3p_policy::PolicyRobot> {
    Ok(l3p_policy::PolicyRobot {
        name: robot.name.to_string(),
        obs_dim: obs_dim(config),
        action_dim: l3p_robots::catalog::NUM_JOINTS,
        action_scale: robot.action_scale,
        io: Some(l3p_robots::io::robot_io(robot, &config.env)?),
    })
}

/// Robots of the configured actors, each once, in first-seen order.
pub fn configured_robots(config: &Config) -> anyhow::Result<Vec<&'static Robot>> {
    let mut robots: Vec<&'static Robot> = Vec::new();
    for actor in &config.actors {
        let robot = Robot::by_name(&actor.robot)?;
        if !robots.iter().any(|r| r.name == robot.name) {
            robots.push(robot);
        }
    }
    if robots.is_empty() {
        anyhow::bail!("the config lists no [[actors]]\nhint: add e.g. [[actors]] robot = \"a1\"");
    }
    Ok(robots)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_prints_its_chain_and_hint_without_a_backtrace_unless_verbose() {
        let error = anyhow::anyhow!("leg joints without limits\nhint: add <limit/>")
            .context("adding lab_dog.urdf");
        let short = error_report(&error, false);
        assert_eq!(
            short,
            "error: adding lab_dog.urdf: leg joints without limits\nhint: add <limit/>"
        );
        let long = error_report(&error, true);
        assert!(
            long.starts_with("error: adding lab_dog.urdf") && long.contains("Caused by:"),
            "{long}"
        );
    }
}
