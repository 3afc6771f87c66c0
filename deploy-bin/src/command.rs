//! `l3p deploy` / `l3p-deploy`: run a policy as the 50 Hz controller of a robot. [`DeployArgs`] and
//! [`run`] are the command; `l3p` adds its own network flags and full config in front of them,
//! `l3p-deploy` the same flags ([`NetFlags`]) reading only what the controller needs ([`DeployFile`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::{Args, Parser};
use l3p_deploy::{DeployOptions, SafetyConfig};
use l3p_net::{Exposure, ZenohSettings, open_session};
use l3p_proto::keys;
use l3p_registry_client::RegistryClient;
use l3p_robot::catalog::RobotSpec as Robot;
use serde::Deserialize;
use serde::de::IgnoredAny;

use crate::process;

/// What to deploy on which robot, and how.
#[derive(Debug, Clone, Args)]
pub struct DeployArgs {
    /// Robot model (from `l3p robots list`).
    #[arg(long)]
    pub robot: String,
    /// Robot instance id: the `<id>` of `l3p/robot/<id>/state|command`.
    #[arg(long)]
    pub robot_id: String,
    /// Deploy artifact `name@version|alias` from the registry (e.g. `a1-flat-a1@latest`), or an
    /// export file / directory.
    #[arg(long)]
    pub policy: String,
    /// Stop (through damping) after this many seconds; default: until Ctrl-C / SIGTERM.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Run over links that leave this machine without mutual TLS (a plain `tcp/` endpoint off
    /// loopback, multicast scouting). Refused without this flag: anyone who reaches such a link can
    /// command the robot. With it, every status carries a warning.
    #[arg(long)]
    pub insecure: bool,
    /// A zero yaw-rate command holds the heading the robot has when it becomes zero (yaw rate =
    /// clip(0.5 · heading error, ±1), the training task's heading mode, on the base's yaw); a
    /// non-zero yaw rate passes through. Without it a zero yaw rate is passed to the policy as is.
    #[arg(long)]
    pub heading_hold: bool,
}

/// `l3p-deploy`'s command line: `l3p deploy`'s flags, `-v` included.
#[derive(Debug, Parser)]
#[command(
    name = "l3p-deploy",
    version,
    about = "Run a policy as a 50 Hz controller for a robot (watchdog, damping, start-up ramp): \
             `l3p deploy` without the simulator, the learner, the registry store or the viewer."
)]
pub struct Cli {
    /// On failure, print the error's causes one per line with a stack backtrace (as does
    /// RUST_LIB_BACKTRACE=1).
    #[arg(short, long)]
    pub verbose: bool,
    #[command(flatten)]
    pub deploy: DeployArgs,
    #[command(flatten)]
    pub net: NetFlags,
}

/// How `l3p-deploy` joins the Zenoh network: the flags of `l3p`'s `NetArgs`.
#[derive(Debug, Clone, Args)]
pub struct NetFlags {
    /// Config file: its [zenoh] section (with [zenoh.tls]), [deploy] and [run] data_dir (added
    /// robots) are used; the other sections of an l3p config are accepted and not read.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Zenoh endpoint to connect to (repeatable); default tcp/127.0.0.1:7447 without --config.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
}

impl NetFlags {
    /// The `[deploy]` settings and the Zenoh settings, as `l3p`'s `NetArgs::load` gives them for
    /// the same flags and file.
    pub fn load(&self) -> anyhow::Result<(SafetyConfig, ZenohSettings)> {
        let file = match &self.config {
            Some(path) => DeployFile::load(path)?,
            None => DeployFile::default(),
        };
        let zenoh = zenoh_with_flags(
            file.zenoh,
            self.config.is_some(),
            &self.connect,
            &self.listen,
        );
        Ok((file.deploy, zenoh))
    }
}

/// The Zenoh settings of a config (`from_file`) or the defaults, with `--connect`/`--listen`
/// applied: without a file, a peer that connects to `tcp/127.0.0.1:7447` and listens nowhere; a
/// flag replaces the endpoints of its kind.
pub fn zenoh_with_flags(
    mut zenoh: ZenohSettings,
    from_file: bool,
    connect: &[String],
    listen: &[String],
) -> ZenohSettings {
    if !from_file {
        zenoh.multicast_scouting = false;
        zenoh.connect = vec!["tcp/127.0.0.1:7447".into()];
    }
    if !connect.is_empty() {
        zenoh.connect = connect.to_vec();
    }
    if !listen.is_empty() {
        zenoh.listen = listen.to_vec();
    }
    zenoh
}

/// What `l3p-deploy` reads of an l3p config file: `[zenoh]` and `[deploy]`, strictly, and `[run]
/// data_dir`. The other sections of `l3p`'s config (`[env]`, `[model]`, `[ppo]`, `[learner]`,
/// `[rollout]`, `[[actors]]`, the rest of `[run]`) are accepted unread, so one `deploy.toml` serves both binaries; any other key is
/// an error, as in `l3p`. Checking those sections needs their crates (the learner's among them),
/// which the lean binary does not link: `l3p config <file>` checks the whole file.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeployFile {
    pub zenoh: ZenohSettings,
    pub deploy: SafetyConfig,
    /// `[run]`: only `data_dir`, whose `robots/` holds added robots, as `l3p` reads it.
    pub run: RunSection,
    env: Option<IgnoredAny>,
    model: Option<IgnoredAny>,
    ppo: Option<IgnoredAny>,
    learner: Option<IgnoredAny>,
    rollout: Option<IgnoredAny>,
    actors: Option<IgnoredAny>,
}

/// What `l3p-deploy` reads of `[run]`: where the run's data lives (its other keys are `l3p`'s).
#[derive(Debug, Clone, Deserialize)]
#[serde(default)]
pub struct RunSection {
    /// The data directory; robots added with `l3p robots add` are in its `robots/`.
    pub data_dir: PathBuf,
}

impl Default for RunSection {
    /// `l3p`'s default `[run] data_dir`.
    fn default() -> Self {
        Self {
            data_dir: PathBuf::from("l3p-data"),
        }
    }
}

impl DeployFile {
    /// Load and strictly parse `path`, register the robots added under its `[run] data_dir` (as
    /// `l3p` does for every config it loads), and validate its `[deploy]` settings.
    pub fn load(path: &Path) -> Result<Self, l3p_proto::config::ConfigError> {
        let file: DeployFile = l3p_proto::config::load_toml(path)?;
        l3p_robot::added::load_added_robots(Some(&file.run.data_dir));
        file.deploy
            .validate()
            .map_err(|message| l3p_proto::config::ConfigError::Invalid {
                path: path.to_path_buf(),
                message,
            })?;
        Ok(file)
    }
}

/// Why the controller may not run over these links, or `Ok(Some(why))` when it may only because
/// `insecure` says so (see [`DeployArgs::insecure`]).
pub fn check_deploy_links(zenoh: &ZenohSettings, insecure: bool) -> anyhow::Result<Option<String>> {
    match zenoh.exposure()? {
        Exposure::Local | Exposure::Authenticated => Ok(None),
        Exposure::Unauthenticated(why) if insecure => Ok(Some(why)),
        Exposure::Unauthenticated(why) => anyhow::bail!(
            "refusing to command a robot over unauthenticated links: {why}\n\
             hint: give [zenoh.tls] ca, cert and key (a certificate with CN l3p-deploy, \
             deploy/certs/README.md) and use quic/ (or tls/) endpoints, keep every endpoint on loopback, or \
             pass --insecure on a network you trust"
        ),
    }
}

/// A seconds argument as a duration: a clear error, not a panic, for a negative or non-finite value.
pub fn seconds_arg(flag: &str, seconds: Option<f64>) -> anyhow::Result<Option<Duration>> {
    seconds
        .map(|s| {
            Duration::try_from_secs_f64(s)
                .map_err(|e| anyhow::anyhow!("{flag} {s}: {e} (seconds, finite and >= 0)"))
        })
        .transpose()
}

/// The command: refuse unauthenticated links (unless `--insecure`), load the policy (a file, else
/// the registry over Zenoh) for `args.robot`, run the controller until Ctrl-C/SIGTERM,
/// `--duration` or an operator's `stop`, and print its final status as JSON on stdout.
pub fn run(args: &DeployArgs, zenoh: ZenohSettings, safety: SafetyConfig) -> anyhow::Result<()> {
    let insecure = check_deploy_links(&zenoh, args.insecure)?;
    if let Some(why) = &insecure {
        tracing::warn!("--insecure: {why}; anyone who reaches these links can command the robot");
    }
    let robot = Robot::by_name(&args.robot)?;
    keys::validate_segment("robot id", &args.robot_id)?;
    safety.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let rt = process::tokio_runtime()?;
    rt.block_on(async {
        let session = open_session(&zenoh).await?;
        let path = Path::new(&args.policy);
        let loaded = if path.exists() {
            l3p_deploy::read_policy_file(path, robot)?
        } else {
            let client = RegistryClient::new(&session);
            l3p_deploy::fetch_policy(&client, &args.policy, robot).await?.1
        };
        if loaded.io_from_catalog {
            tracing::warn!(
                "{} carries no robot I/O contract (older export): using this build's {} catalog entry",
                loaded.reference,
                robot.name
            );
        }
        eprintln!(
            "deploying {} (sha256 {}) on {} as robot id {}",
            loaded.reference, loaded.sha256, robot.name, args.robot_id
        );
        let cancel = process::cancel_on_signal();
        let opts = DeployOptions {
            robot,
            robot_id: args.robot_id.clone(),
            safety,
            duration: seconds_arg("--duration", args.duration)?,
            status_every: Duration::from_secs(1),
            insecure,
            heading_hold: args.heading_hold,
        };
        let status = l3p_deploy::run_deploy(&session, loaded, opts, cancel).await?;
        println!("{}", serde_json::to_string(&status)?);
        let _ = session.close().await;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DeployFile, String> {
        l3p_proto::config::parse_toml(text, Path::new("deploy.toml")).map_err(|e| e.to_string())
    }

    #[test]
    fn the_file_reads_zenoh_and_deploy_and_accepts_the_other_sections_unread() {
        let file = parse(
            "[run]\nname = \"x\"\n[env]\nanything = 1\n[[actors]]\nrobot = \"a1\"\n\
             [deploy]\nstale_periods = 10.0\n[zenoh]\nmode = \"client\"\n",
        )
        .unwrap();
        assert_eq!(file.deploy.stale_periods, 10.0);
        assert_eq!(file.zenoh.mode, "client");
    }

    #[test]
    fn unknown_sections_and_keys_are_errors_that_name_them() {
        let e = parse("[deplyo]\nstale_periods = 10.0\n").unwrap_err();
        assert!(e.contains("deplyo") && e.contains("line 1"), "{e}");
        let e = parse("[deploy]\nstale_period = 10.0\n").unwrap_err();
        assert!(e.contains("stale_period"), "{e}");
    }

    #[test]
    fn without_a_file_it_connects_to_a_local_router_and_flags_replace_endpoints() {
        let z = zenoh_with_flags(ZenohSettings::default(), false, &[], &[]);
        assert_eq!(z.connect, ["tcp/127.0.0.1:7447"]);
        assert!(!z.multicast_scouting);
        let listen = vec!["tcp/127.0.0.1:7000".to_string()];
        let z = zenoh_with_flags(ZenohSettings::default(), true, &[], &listen);
        assert_eq!(z.listen, listen);
    }
}
