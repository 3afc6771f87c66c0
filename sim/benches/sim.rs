//! `cargo bench -p l3p-sim --bench sim [-- ROBOT ENVS THREADS SECONDS TERRAIN]`: the same
//! measurement as `l3p bench sim` without building the CLI. Prints control steps/s and stage timings,
//! and the ratio to flat ground measured in the same run (baseline).

use l3p_robot::catalog::RobotSpec;
use l3p_sim::bench::run_sim_bench;
use l3p_task::config::{EnvConfig, TerrainConfig, TerrainPreset};

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let robot = args.first().map(String::as_str).unwrap_or("a1");
    let envs: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(64);
    let threads: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2);
    let seconds: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5.0);
    let Ok(spec) = RobotSpec::by_name(robot) else {
        eprintln!("unknown robot {robot}");
        return;
    };
    let mut flat_cps = None;
    for preset in [TerrainPreset::Flat, TerrainPreset::Curriculum] {
        let cfg = EnvConfig {
            terrain: TerrainConfig::with_preset(preset),
            height_scan: preset != TerrainPreset::Flat,
            ..EnvConfig::default()
        };
        match run_sim_bench(spec, &cfg, envs, threads, seconds, 0) {
            Ok(r) => {
                let per = |d: std::time::Duration| d.as_secs_f64() * 1e6 / r.steps.max(1) as f64;
                let ratio = flat_cps
                    .map(|f: f64| r.control_steps_per_s / f)
                    .unwrap_or(1.0);
                println!(
                    "{robot} {preset:?} envs {envs} threads {threads}: {:.0} control steps/s (x{ratio:.2} vs flat) | us/step physics {:.0} obs {:.0} rewards {:.0} resets {:.0} total {:.0} | nan resets {}",
                    r.control_steps_per_s,
                    per(r.timings.physics),
                    per(r.timings.observations),
                    per(r.timings.rewards),
                    per(r.timings.resets),
                    per(r.timings.total),
                    r.nan_resets
                );
                if preset == TerrainPreset::Flat {
                    flat_cps = Some(r.control_steps_per_s);
                }
            }
            Err(e) => eprintln!("bench failed: {e}"),
        }
    }
}
