//! `l3p train <config>`: local mode. Registry service and learner run in this process, one actor
//! process per `[[actors]]` entry; all joined by a Zenoh session bound to loopback, data under
//! `<data_dir>/<run>/`. A dead actor is restarted; Ctrl-C stops everything after a final checkpoint.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use l3p_learner::daemon;
use l3p_registry::net::{self, ZenohSettings};
use tracing::{info, warn};

use crate::config::Config;
use crate::{learner_cmd, runtime};

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Run config (TOML), e.g. configs/a1-flat.toml.
    pub config: PathBuf,
    /// Override the run name ([run] name).
    #[arg(long)]
    pub run: Option<String>,
    /// Override the number of iterations ([learner] max_iterations).
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Override the environments of every actor.
    #[arg(long)]
    pub envs: Option<usize>,
    /// Override the data directory ([run] data_dir).
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    /// No progress bar (log lines instead).
    #[arg(long)]
    pub quiet: bool,
}

struct ActorProcess {
    args: Vec<String>,
    child: Child,
    restarts: u32,
}

fn spawn_actor(args: &[String]) -> anyhow::Result<Child> {
    let exe = std::env::current_exe()?;
    Ok(Command::new(exe).args(args).stdin(Stdio::null()).spawn()?)
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    let mut config = Config::load(&args.config)?;
    if let Some(run) = &args.run {
        config.run.name = run.clone();
    }
    if let Some(n) = args.iterations {
        config.learner.max_iterations = n;
    }
    if let Some(dir) = &args.data_dir {
        config.run.data_dir = dir.clone();
    }
    if let Some(envs) = args.envs {
        config.actors.iter_mut().for_each(|a| a.envs = envs);
    }
    l3p_proto::keys::validate_segment("run", &config.run.name)?;
    let opts = learner_cmd::learner_options(&config, true)?;
    // Zenoh's usual port when it is free, so `l3p metrics --follow` in another terminal finds the run;
    // the endpoint is also written to <run_dir>/endpoint.
    let port = match std::net::TcpListener::bind(("127.0.0.1", 7447)) {
        Ok(_) => 7447,
        Err(_) => net::free_loopback_port()?,
    };
    std::fs::create_dir_all(&opts.run_dir)?;
    std::fs::write(
        opts.run_dir.join("endpoint"),
        format!("tcp/127.0.0.1:{port}\n"),
    )?;
    // Actors read the same config, with the overrides applied.
    // Actors connect to this process; it alone listens.
    config.zenoh = ZenohSettings::loopback(None, &[port]);
    let resolved = opts.run_dir.join("config.toml");
    std::fs::write(&resolved, toml::to_string_pretty(&config)?)?;
    config.zenoh = ZenohSettings::loopback(Some(port), &[]);

    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        let session = net::open_session(&config.zenoh).await?;
        let registry = Arc::new(l3p_registry::Registry::open(&config.run.data_dir)?);
        let registry_session = session.clone();
        // Not a child of `cancel`: the learner's final checkpoint still goes to the registry.
        let registry_cancel = tokio_util::sync::CancellationToken::new();
        let registry_task = tokio::spawn({
            let cancel = registry_cancel.clone();
            async move { l3p_registry::serve(&registry_session, registry, cancel).await }
        });

        let mut actors = Vec::new();
        for (i, actor) in config.actors.iter().enumerate() {
            let args: Vec<String> = vec![
                "actor".into(),
                "--config".into(),
                resolved.display().to_string(),
                "--robot".into(),
                actor.robot.clone(),
                "--envs".into(),
                actor.envs.to_string(),
                "--threads".into(),
                actor.threads.to_string(),
                "--id".into(),
                format!("{}-{i}", actor.robot),
                "--connect".into(),
                format!("tcp/127.0.0.1:{port}"),
            ];
            let child = spawn_actor(&args)?;
            actors.push(ActorProcess { args, child, restarts: 0 });
        }
        info!(run = %config.run.name, actors = actors.len(), port, "local mode started");

        let (progress_tx, mut progress_rx) = tokio::sync::mpsc::unbounded_channel();
        let learner = tokio::spawn(daemon::run(session.clone(), opts, cancel.clone(), Some(progress_tx)));

        let bar = if args.quiet {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::new(config.learner.max_iterations.max(1));
            bar.set_style(ProgressStyle::with_template(
                "{elapsed_precise} [{bar:30}] it {pos}/{len} {msg}",
            )?);
            bar
        };
        let mut watchdog = tokio::time::interval(Duration::from_secs(1));
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                report = progress_rx.recv() => match report {
                    None => break,
                    Some(r) => {
                        let v = |k: &str| r.metrics.values.get(k).copied().unwrap_or(f64::NAN);
                        let msg = format!(
                            "{:.0} samples/s | reward {:.2} | len {:.0} | level {:.2} | vel err {:.2}",
                            v("samples_per_second"), v("episode_return"), v("episode_length"),
                            v("terrain_level"), v("lin_vel_error"),
                        );
                        bar.set_position(r.iteration);
                        if args.quiet { info!(iteration = r.iteration, "{msg}"); } else { bar.set_message(msg); }
                    }
                },
                _ = watchdog.tick() => {
                    for actor in &mut actors {
                        if actor.restarts > 5 {
                            continue;
                        }
                        if let Ok(Some(status)) = actor.child.try_wait() {
                            if actor.restarts == 5 {
                                warn!("actor {} exited ({status}) 5 times; not restarting it", actor.args[4]);
                                actor.restarts += 1;
                                continue;
                            }
                            warn!("actor {} exited ({status}); restarting", actor.args[4]);
                            actor.restarts += 1;
                            actor.child = spawn_actor(&actor.args)?;
                        }
                    }
                }
            }
        }
        bar.finish();
        let summary = learner.await??;
        for actor in &mut actors {
            let _ = actor.child.kill();
            let _ = actor.child.wait();
        }
        registry_cancel.cancel();
        let _ = registry_task.await;
        println!(
            "run {} stopped at iteration {} ({} stale chunks dropped, {} rejected); data in {}",
            config.run.name,
            summary.iterations,
            summary.dropped_chunks,
            summary.rejected_chunks,
            config.run.data_dir.join(&config.run.name).display()
        );
        Ok(())
    })
}
