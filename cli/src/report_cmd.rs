//! `l3p report <run>`: training curves as SVG under the run directory and the paper-style row.

use std::path::PathBuf;

use clap::Args;
use l3p_learner::daemon::metrics_path;
use l3p_learner::report::{ReportRow, load_learner_records, series, smooth, svg_chart};

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Run name.
    pub run: String,
    /// Data directory holding the run.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// Moving-average window (iterations) for smoothing and convergence.
    #[arg(long, default_value_t = 10)]
    pub window: usize,
}

pub fn run(args: ReportArgs) -> anyhow::Result<()> {
    l3p_proto::keys::validate_segment("run", &args.run)?;
    let run_dir = args.data_dir.join(&args.run);
    let path = metrics_path(&run_dir);
    let records = load_learner_records(&path)
        .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
    if records.is_empty() {
        anyhow::bail!("{} holds no learner records yet", path.display());
    }
    let out = run_dir.join("report");
    std::fs::create_dir_all(&out)?;
    for (key, label) in [
        ("episode_return", "episode reward"),
        ("terrain_level", "terrain level"),
        ("lin_vel_error", "xy-velocity tracking error (m/s)"),
        ("yaw_rate_error", "yaw-rate tracking error (rad/s)"),
        ("episode_length", "episode length (steps)"),
    ] {
        let raw = series(&records, key);
        if raw.is_empty() {
            continue;
        }
        let svg = svg_chart(
            &format!("{} — {label}", args.run),
            label,
            &raw,
            &smooth(&raw, args.window),
        );
        let file = out.join(format!("{key}.svg"));
        std::fs::write(&file, svg)?;
        println!("wrote {}", file.display());
    }
    let row = ReportRow::from_records(&records, args.window);
    let it = |v: Option<u64>| v.map(|v| v.to_string()).unwrap_or_else(|| "—".into());
    println!();
    println!(
        "| run | iterations | level 85% | level 95% | reward 85% | reward 95% | final level | final reward | vel err | yaw err |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    println!(
        "| {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {:.3} |",
        args.run,
        row.iterations,
        it(row.level_85),
        it(row.level_95),
        it(row.reward_85),
        it(row.reward_95),
        row.final_level,
        row.final_reward,
        row.lin_vel_error,
        row.yaw_rate_error
    );
    Ok(())
}
