//! `l3p report <run> [<run>…]`: training curves as SVG and PNG (one run under its directory, several
//! overlaid), on terrain the level per terrain type (`terrain_level_by_type`, one line per type),
//! and the paper-style row per run.

use std::path::PathBuf;

use clap::Args;
use l3p_learner::daemon::metrics_path;
use l3p_report::{
    ReportRow, load_learner_records, png_bands, png_chart, series, smooth, svg_bands, svg_chart,
};

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Run name; several runs are overlaid (one line each) in one set of charts.
    #[arg(required = true, num_args = 1..)]
    pub runs: Vec<String>,
    /// Data directory holding the runs.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// Moving-average window (iterations) for smoothing and convergence.
    #[arg(long, default_value_t = 10)]
    pub window: usize,
    /// Where the charts go (default: `<data_dir>/<run>/report/`, or
    /// `<data_dir>/reports/<run>_vs_<run>…/` for several runs).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The charted metrics: key and axis label.
const CHARTS: [(&str, &str); 5] = [
    ("episode_return", "episode reward"),
    ("terrain_level", "terrain level"),
    ("lin_vel_error", "xy-velocity tracking error (m/s)"),
    ("yaw_rate_error", "yaw-rate tracking error (rad/s)"),
    ("episode_length", "episode length (steps)"),
];

pub fn run(args: ReportArgs) -> anyhow::Result<()> {
    let mut runs = Vec::with_capacity(args.runs.len());
    for run in &args.runs {
        l3p_proto::keys::validate_segment("run", run)?;
        let path = metrics_path(&args.data_dir.join(run));
        let records = load_learner_records(&path)
            .map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))?;
        if records.is_empty() {
            anyhow::bail!("{} holds no learner records yet", path.display());
        }
        runs.push((run.as_str(), records));
    }
    let out = match (&args.out, runs.as_slice()) {
        (Some(dir), _) => dir.clone(),
        (None, [(run, _)]) => args.data_dir.join(run).join("report"),
        (None, _) => args.data_dir.join("reports").join(args.runs.join("_vs_")),
    };
    std::fs::create_dir_all(&out)?;
    let title = args.runs.join(" vs ");
    for (key, label) in CHARTS {
        let raws: Vec<(&str, Vec<(f64, f64)>)> = runs
            .iter()
            .map(|(run, records)| (*run, series(records, key)))
            .filter(|(_, raw)| !raw.is_empty())
            .collect();
        let (svg, png) = match raws.as_slice() {
            [] => continue,
            [(_, raw)] => {
                let smoothed = smooth(raw, args.window);
                let title = format!("{title} — {label}");
                (
                    svg_chart(&title, label, raw, &smoothed),
                    png_chart(&title, label, raw, &smoothed),
                )
            }
            several => {
                let lines: Vec<(String, Vec<(f64, f64, f64, f64)>)> = several
                    .iter()
                    .map(|(run, raw)| {
                        let line = smooth(raw, args.window)
                            .into_iter()
                            .map(|(x, y)| (x, y, y, y))
                            .collect();
                        (run.to_string(), line)
                    })
                    .collect();
                let title = format!("{label} (smoothed over {} iterations)", args.window);
                (
                    svg_bands(&title, label, &lines),
                    png_bands(&title, label, &lines),
                )
            }
        };
        for (ext, bytes) in [("svg", svg.into_bytes()), ("png", png)] {
            let file = out.join(format!("{key}.{ext}"));
            std::fs::write(&file, bytes)?;
            println!("wrote {}", file.display());
        }
    }
    let by_type = terrain_level_by_type(&runs, args.window);
    if !by_type.is_empty() {
        let label = "terrain level";
        let title = format!(
            "{title} — terrain level by type (smoothed over {} iterations)",
            args.window
        );
        let svg = svg_bands(&title, label, &by_type);
        let png = png_bands(&title, label, &by_type);
        for (ext, bytes) in [("svg", svg.into_bytes()), ("png", png)] {
            let file = out.join(format!("terrain_level_by_type.{ext}"));
            std::fs::write(&file, bytes)?;
            println!("wrote {}", file.display());
        }
        println!();
        println!(
            "| run, terrain type | final level (mean of the last {} iterations) |",
            args.window
        );
        println!("|---|---|");
        for (name, line) in &by_type {
            if let Some(&(_, level, _, _)) = line.last() {
                println!("| {name} | {level:.2} |");
            }
        }
    }
    let it = |v: Option<u64>| v.map(|v| v.to_string()).unwrap_or_else(|| "—".into());
    println!();
    println!(
        "| run | iterations | level 85% | level 95% | reward 85% | reward 95% | final level | final reward | vel err | yaw err |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (run, records) in &runs {
        let row = ReportRow::from_records(records, args.window);
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {:.3} |",
            run,
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
    }
    Ok(())
}

/// One smoothed line per run and terrain type from the learner's `terrain_level/type<k>` metrics
/// (k indexes `TerrainType::ALL`), named by the type (and the run when there are several).
fn terrain_level_by_type(
    runs: &[(&str, Vec<l3p_proto::MetricsRecord>)],
    window: usize,
) -> Vec<(String, Vec<(f64, f64, f64, f64)>)> {
    let mut lines = Vec::new();
    for (run, records) in runs {
        for (k, kind) in l3p_task::terrain::TerrainType::ALL.iter().enumerate() {
            let raw = series(records, &format!("terrain_level/type{k}"));
            if raw.is_empty() {
                continue;
            }
            let name = match runs.len() {
                1 => kind.as_str().to_string(),
                _ => format!("{run} {}", kind.as_str()),
            };
            let line = smooth(&raw, window)
                .into_iter()
                .map(|(x, y)| (x, y, y, y))
                .collect();
            lines.push((name, line));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use l3p_proto::MetricsRecord;

    #[test]
    fn terrain_levels_chart_one_line_per_type_seen() {
        let records: Vec<MetricsRecord> = (0..4)
            .map(|i| {
                let mut r = MetricsRecord::new("rough", "learner", i, 0);
                r.insert("terrain_level/type1", 1.0 + i as f64);
                r.insert("terrain_level/type4", 0.5);
                r
            })
            .collect();
        let lines = terrain_level_by_type(&[("rough", records.clone())], 1);
        let names: Vec<_> = lines.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["pyramid_stairs", "random_rough"]);
        assert_eq!(lines[0].1.last().unwrap().1, 4.0);
        let two = terrain_level_by_type(&[("a", records.clone()), ("b", records)], 1);
        assert_eq!(two.len(), 4);
        assert_eq!(two[2].0, "b pyramid_stairs");
    }
}
