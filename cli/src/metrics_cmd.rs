//! `l3p metrics --run <run> [--follow] [--json]`: a run's metrics, from its file or live from Zenoh.

use std::io::BufRead;
use std::path::PathBuf;

use clap::Args;
use l3p_proto::{MetricsRecord, codec, keys};

use crate::runtime::{self, NetArgs};

#[derive(Debug, Args)]
pub struct MetricsArgs {
    /// Run name.
    #[arg(long)]
    pub run: String,
    /// Subscribe to live metrics on Zenoh instead of reading the run's metrics file.
    #[arg(long)]
    pub follow: bool,
    /// Print each record as one JSON line.
    #[arg(long)]
    pub json: bool,
    /// Data directory of the run (for the file, and the endpoint of a local-mode run).
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// With --follow: how to reach the run. Without --config and --connect, the local-mode run's
    /// endpoint file (`<data-dir>/<run>/endpoint`), else `tcp/127.0.0.1:7447`.
    #[command(flatten)]
    pub net: NetArgs,
}

const COLUMNS: [(&str, &str); 7] = [
    ("episode_return", "reward"),
    ("episode_length", "length"),
    ("terrain_level", "level"),
    ("lin_vel_error", "vel_err"),
    ("yaw_rate_error", "yaw_err"),
    ("approx_kl", "kl"),
    ("samples_per_second", "samples/s"),
];

fn print_record(record: &MetricsRecord, json: bool) -> anyhow::Result<()> {
    if json {
        println!("{}", String::from_utf8(codec::encode_json(record)?)?);
        return Ok(());
    }
    let mut line = format!("{:<24} it {:>5}", record.source, record.iteration);
    for (key, label) in COLUMNS {
        if let Some(v) = record.values.get(key) {
            line.push_str(&format!("  {label} {v:.3}"));
        }
    }
    println!("{line}");
    Ok(())
}

pub fn run(args: MetricsArgs) -> anyhow::Result<()> {
    keys::validate_segment("run", &args.run)?;
    let run_dir = args.data_dir.join(&args.run);
    if !args.follow {
        let path = l3p_learner::daemon::metrics_path(&run_dir);
        let file = std::fs::File::open(&path).map_err(|e| {
            anyhow::anyhow!(
                "cannot read {}: {e}\nhint: use --follow for a run on another machine",
                path.display()
            )
        })?;
        for (n, line) in std::io::BufReader::new(file).lines().enumerate() {
            match codec::decode_json::<MetricsRecord>(line?.as_bytes()) {
                Ok(record) => print_record(&record, args.json)?,
                Err(e) => tracing::warn!("{}:{}: skipped: {e}", path.display(), n + 1),
            }
        }
        return Ok(());
    }
    let (_, mut settings) = args.net.load()?;
    if args.net.config.is_none()
        && args.net.connect.is_empty()
        && let Ok(endpoint) = std::fs::read_to_string(run_dir.join("endpoint"))
    {
        settings.connect = vec![endpoint.trim().to_string()];
    }
    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        let session = l3p_net::open_session(&settings).await?;
        let subscriber = session
            .declare_subscriber(keys::metrics_all(&args.run))
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                sample = subscriber.recv_async() => {
                    let Ok(sample) = sample else { break };
                    match codec::decode_json::<MetricsRecord>(&sample.payload().to_bytes()) {
                        Ok(record) => print_record(&record, args.json)?,
                        Err(e) => tracing::warn!(key = %sample.key_expr(), "skipped: {e}"),
                    }
                }
            }
        }
        Ok(())
    })
}
