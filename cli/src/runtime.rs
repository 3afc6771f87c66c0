//! Shared glue of the daemon commands: the tokio runtime, Ctrl-C → cancellation, and the policy's
//! view of the configured robots.

use l3p_robots::catalog::RobotSpec as Robot;
use tokio_util::sync::CancellationToken;

use crate::config::Config;

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

/// The policy's description of a robot under this config, with the controller contract
/// ([`l3p_policy::RobotIo`]) that travels into checkpoints and deploy artifacts.
pub fn policy_robot(config: &Config, robot: &Robot) -> anyhow::Result<l3p_policy::RobotSpec> {
    Ok(l3p_policy::RobotSpec {
        name: robot.name.to_string(),
        obs_dim: obs_dim(config),
        action_dim: l3p_robots::catalog::NUM_JOINTS,
        action_scale: robot.action_scale,
        io: Some(l3p_deploy::robot_io(robot, &config.env)?),
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
