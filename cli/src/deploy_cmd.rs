//! `l3p deploy`, `l3p sim-robot`, `l3p operate` and `l3p export`: running a policy on a robot (or
//! the simulator standing in for one), talking to the running controller, and exporting weights for
//! other runtimes. The work lives in `l3p_deploy`; `l3p deploy` itself is `l3p_deploy_bin`'s
//! command, which the lean `l3p-deploy` binary runs too.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, ValueEnum};
use l3p_actor::SimRobotOptions;
use l3p_deploy_bin::seconds_arg;
use l3p_net::open_session;
use l3p_policy::{ExportConfig, cpu_device};
use l3p_proto::OperatorAction;
use l3p_registry::RegistryClient;
use l3p_robot::catalog::RobotSpec as Robot;

use crate::runtime::{self, NetArgs};

/// `l3p deploy`: the command's own arguments (shared with the lean `l3p-deploy` binary) and `l3p`'s
/// network flags. (No argument group of its own: its name would clash with the inner
/// `DeployArgs`'s.)
#[derive(Debug, Args)]
#[group(skip)]
pub struct DeployArgs {
    #[command(flatten)]
    pub deploy: l3p_deploy_bin::DeployArgs,
    #[command(flatten)]
    pub net: NetArgs,
}

/// `l3p deploy`: the full config file is loaded and checked (as every `l3p` command does), then the
/// command runs as `l3p-deploy` runs it ([`l3p_deploy_bin::run`]).
pub fn deploy(args: DeployArgs) -> anyhow::Result<()> {
    let (config, zenoh) = args.net.load()?;
    l3p_deploy_bin::run(&args.deploy, zenoh, config.deploy)
}

#[derive(Debug, Args)]
pub struct SimRobotArgs {
    /// Robot model to simulate.
    #[arg(long)]
    pub robot: String,
    /// Robot instance id for the keys.
    #[arg(long)]
    pub robot_id: String,
    /// State publication rate (Hz): 200 or 50.
    #[arg(long, default_value_t = 200)]
    pub state_hz: u32,
    /// Operator velocity command sent with every state: vx,vy,yaw_rate.
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 1,
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub command: Vec<f32>,
    /// Stop after this many seconds; default: until Ctrl-C / SIGTERM.
    #[arg(long)]
    pub duration: Option<f64>,
    /// The robot-side watchdog: no command for this long → damping.
    #[arg(long, default_value_t = 0.1)]
    pub command_timeout: f32,
    #[command(flatten)]
    pub net: NetArgs,
}

pub fn sim_robot(args: SimRobotArgs) -> anyhow::Result<()> {
    let (_, zenoh) = args.net.load()?;
    let robot = Robot::by_name(&args.robot)?;
    let command: [f32; 3] = args.command.as_slice().try_into().map_err(|_| {
        anyhow::anyhow!(
            "--command takes three numbers vx,vy,yaw_rate, got {:?}",
            args.command
        )
    })?;
    if !(args.command_timeout.is_finite() && args.command_timeout > 0.0) {
        anyhow::bail!("--command-timeout must be > 0 seconds");
    }
    let rt = runtime::tokio_runtime()?;
    rt.block_on(async {
        let session = open_session(&zenoh).await?;
        let cancel = runtime::cancel_on_signal();
        let opts = SimRobotOptions {
            robot,
            robot_id: args.robot_id.clone(),
            state_hz: args.state_hz,
            command,
            duration: seconds_arg("--duration", args.duration)?,
            command_timeout_s: args.command_timeout,
        };
        let summary = l3p_actor::run_sim_robot(&session, opts, cancel).await?;
        println!("{}", serde_json::to_string(&summary)?);
        let _ = session.close().await;
        Ok(())
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OperateAction {
    /// Leave damping: ramp to the default pose, then run the policy.
    Resume,
    /// Damp now and stay damped.
    Damp,
    /// Damp, then stop the controller.
    Stop,
}

#[derive(Debug, Args)]
pub struct OperateArgs {
    /// Robot instance id of the running `l3p deploy`.
    #[arg(long)]
    pub robot_id: String,
    pub action: OperateAction,
    /// Give up waiting for the controller's confirmation after this many seconds.
    #[arg(long, default_value_t = 3.0)]
    pub timeout: f64,
    #[command(flatten)]
    pub net: NetArgs,
}

/// Sends the request until the controller's status shows it took effect (pub/sub is
/// fire-and-forget, and every request is idempotent), then prints the status.
pub fn operate(args: OperateArgs) -> anyhow::Result<()> {
    let (_, zenoh) = args.net.load()?;
    let action = match args.action {
        OperateAction::Resume => OperatorAction::Resume,
        OperateAction::Damp => OperatorAction::Damp,
        OperateAction::Stop => OperatorAction::Stop,
    };
    let timeout = seconds_arg("--timeout", Some(args.timeout))?.unwrap_or_default();
    runtime::tokio_runtime()?.block_on(async {
        let session = open_session(&zenoh).await?;
        let result = l3p_deploy::operate(&session, &args.robot_id, action, timeout).await;
        let _ = session.close().await;
        let status = result?;
        if let Some(warning) = &status.warning {
            eprintln!("warning: controller {}: {warning}", args.robot_id);
        }
        println!("{}", serde_json::to_string(&status)?);
        Ok(())
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// safetensors weights + JSON config (PyTorch / numpy loadable).
    Safetensors,
    /// ONNX model (`obs` → `actions`, the action mean; onnxruntime, TensorRT) + JSON config.
    Onnx,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    /// What to export: a registry ref (`name@version|alias`: a deploy artifact or a checkpoint), a
    /// checkpoint file (`latest.ckpt`), or an export file/directory.
    pub source: String,
    #[arg(long, value_enum, default_value = "safetensors")]
    pub format: ExportFormat,
    /// Output directory: policy.safetensors (or policy.onnx) + policy.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Robot to export (needed when a checkpoint serves several robots).
    #[arg(long)]
    pub robot: Option<String>,
    /// Read the registry at `<dir>/registry.db` directly instead of asking a service.
    #[arg(long, visible_alias = "data-dir")]
    pub data: Option<PathBuf>,
    /// Export `½(π(o) + M_a π(M_o o))`, the policy averaged with its left-right mirror image: exactly
    /// symmetric at every state, one MLP of twice the width under the same contract (`l3p eval
    /// --symmetrized` plays it without exporting).
    #[arg(long)]
    pub symmetrized: bool,
    #[command(flatten)]
    pub net: NetArgs,
}

pub fn export(args: ExportArgs) -> anyhow::Result<()> {
    let (config, zenoh) = args.net.load()?;
    let path = Path::new(&args.source);
    let bytes = if path.exists() {
        crate::eval_cmd::read_export_bytes(path)?
    } else if let Some(data) = &args.data {
        l3p_registry::Registry::open(data)?
            .get_blob(&args.source)?
            .1
    } else {
        let rt = runtime::tokio_runtime()?;
        rt.block_on(async {
            let session = open_session(&zenoh).await?;
            let blob = RegistryClient::new(&session).get_blob(&args.source).await;
            let _ = session.close().await;
            anyhow::Ok(blob?.1)
        })?
    };
    // Only checkpoints without an `io` get one here: they predate the clock and the filter.
    let env_for = |obs_dim: usize| l3p_task::contract::env_for_policy(&config.env, obs_dim, None);
    let (export, export_config) = if l3p_policy::is_checkpoint(&bytes) {
        let mut ckpt = l3p_policy::checkpoint_from_bytes(&bytes, &cpu_device())?;
        let names: Vec<String> = ckpt.model.robots.iter().map(|r| r.name.clone()).collect();
        let name = match (&args.robot, names.as_slice()) {
            (Some(r), _) => Robot::by_name(r)?.name.to_string(),
            (None, [only]) => only.clone(),
            (None, _) => {
                anyhow::bail!("the checkpoint serves {names:?}\nhint: choose one with --robot")
            }
        };
        let idx = names
            .iter()
            .position(|n| *n == name)
            .ok_or_else(|| anyhow::anyhow!("the checkpoint has no {name} (it has {names:?})"))?;
        let spec = &mut ckpt.model.robots[idx];
        if spec.io.is_none() {
            spec.io = Some(l3p_task::contract::robot_io(
                Robot::by_name(&name)?,
                &env_for(spec.obs_dim),
            )?);
        }
        l3p_policy::export_bytes(&ckpt.model, &name)?
    } else {
        let policy = l3p_policy::DeployPolicy::from_bytes(&bytes)?;
        let mut cfg: ExportConfig = policy.config.clone();
        if let Some(r) = &args.robot
            && Robot::by_name(r)?.name != cfg.robot
        {
            anyhow::bail!("{} is a policy for {}, not {r}", args.source, cfg.robot);
        }
        if cfg.io.is_none() {
            cfg.io = Some(l3p_task::contract::robot_io(
                Robot::by_name(&cfg.robot)?,
                &env_for(cfg.obs_dim),
            )?);
            (l3p_policy::replace_export_config(&bytes, &cfg)?, cfg)
        } else {
            (bytes, cfg)
        }
    };
    let (export, export_config) = if args.symmetrized {
        let policy = l3p_policy::DeployPolicy::from_bytes(&export)?;
        let robot = l3p_robot::catalog::RobotSpec::by_name(&policy.config.robot)?;
        let symmetric = crate::eval_cmd::symmetrized_policy(&policy, robot)?;
        (symmetric.to_bytes()?, symmetric.config)
    } else {
        (export, export_config)
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let (st, export) = match args.format {
        ExportFormat::Safetensors => (args.output.join("policy.safetensors"), export),
        ExportFormat::Onnx => (
            args.output.join("policy.onnx"),
            l3p_policy::DeployPolicy::from_bytes(&export)?.to_onnx()?,
        ),
    };
    let json = args.output.join("policy.json");
    std::fs::write(&st, &export).with_context(|| format!("writing {}", st.display()))?;
    std::fs::write(&json, serde_json::to_vec_pretty(&export_config)?)
        .with_context(|| format!("writing {}", json.display()))?;
    println!(
        "exported {} policy for {} ({} → {}): {} and {}",
        export_config.arch,
        export_config.robot,
        export_config.obs_dim,
        export_config.action_dim,
        st.display(),
        json.display()
    );
    Ok(())
}
