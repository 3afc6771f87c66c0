//! Shared glue of the daemon commands: [`NetArgs`] (the network flags of every command that joins
//! Zenoh), the tokio runtime, Ctrl-C → cancellation ([`Interrupted`]), the error report, and the
//! policy's view of the configured robots. The process glue (logging, runtime, signals, error
//! report) lives in `l3p_deploy_bin::process`, which the lean `l3p-deploy` binary shares, and is
//! re-exported here.

use std::path::PathBuf;

use clap::Args;
pub use l3p_deploy_bin::process::{
    Interrupted, cancel_on_signal, error_report, exit_code, init_logging, lib_backtrace_asked,
    tokio_runtime,
};
use l3p_net::ZenohSettings;
use l3p_robot::catalog::RobotSpec as Robot;

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
        let zenoh = l3p_deploy_bin::command::zenoh_with_flags(
            config.zenoh.clone(),
            self.config.is_some(),
            &self.connect,
            &self.listen,
        );
        Ok((config, zenoh))
    }
}

/// Observation size of the configured task.
pub fn obs_dim(config: &Config) -> usize {
    config.env.obs_dim()
}

/// Left-right mirror maps of `robot`'s task under this config (for `[ppo] symmetry_coef`).
pub fn mirror(config: &Config, robot: &Robot) -> anyhow::Result<l3p_learner::Mirror> {
    let model = robot.model()?;
    let m = l3p_task::mirror::TaskMirror::new(
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
            let m = l3p_task::morphology::TransferMap::new(
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
                    action_dim: l3p_robot::catalog::NUM_JOINTS,
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
        action_dim: l3p_robot::catalog::NUM_JOINTS,
        action_scale: robot.action_scale,
        io: Some(l3p_task::contract::robot_io(robot, &config.env)?),
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
