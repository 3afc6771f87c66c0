//! `l3p` — the command-line entry point. Argument parsing and glue only: every command calls into a
//! library crate (see ARCHITECTURE.md).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Train, transfer and deploy latent-to-latent locomotion policies (L3P) for legged robots.
#[derive(Debug, Parser)]
#[command(name = "l3p", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// On failure, print the error's causes one per line with a stack backtrace (as does
    /// RUST_LIB_BACKTRACE=1).
    #[arg(short, long, global = true)]
    verbose: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Train locally: registry, learner and actors on loopback Zenoh, data under ./l3p-data/<run>/.
    Train(l3p_cli::train_cmd::TrainArgs),
    /// Fine-tune a pretrained policy on another robot: L3P's core frozen, the robot's adapters train.
    Transfer(l3p_cli::transfer_cmd::TransferArgs),
    /// Run the learner daemon (PPO over Zenoh).
    Learner(l3p_cli::learner_cmd::LearnerArgs),
    /// Run a rollout actor daemon for one robot.
    Actor(l3p_cli::actor_cmd::ActorArgs),
    /// Show a run's metrics (from its file, or live with --follow).
    Metrics(l3p_cli::metrics_cmd::MetricsArgs),
    /// Play a policy without learning and print tracking errors, reward and falls.
    Eval(l3p_cli::eval_cmd::EvalArgs),
    /// Watch a policy: simulate it and log to Rerun (--save run.rrd, --connect, --spawn).
    Play(l3p_cli::play_cmd::PlayArgs),
    /// Draw a run's training curves (SVG) and print the convergence row.
    Report(l3p_cli::report_cmd::ReportArgs),
    /// List the robots, check one (load, stand under PD) or add your own from a URDF.
    Robots(l3p_cli::robots_cmd::RobotsArgs),
    /// Benchmarks: `bench sim` (simulator throughput), `bench learner` (PPO update throughput).
    Bench(l3p_cli::bench_cmd::BenchArgs),
    /// The artifact registry: serve it, or list/show/pull/put/tag/history/lineage.
    Registry(l3p_cli::registry_cmd::RegistryArgs),
    /// Run a policy as a 50 Hz controller for a robot (watchdog, damping, start-up ramp).
    Deploy(l3p_cli::deploy_cmd::DeployArgs),
    /// Run a Zenoh router (the library router `zenohd` runs) for processes on several machines.
    Router(l3p_cli::router_cmd::RouterArgs),
    /// Play a policy in MuJoCo, a second simulator, through its export contract: gait diagnostics
    /// and the walk verdict (needs Python 3 with numpy and mujoco).
    Sim2sim(l3p_cli::sim2sim_cmd::Sim2SimArgs),
    /// Run the simulator as a stand-in robot on the deploy keys.
    SimRobot(l3p_cli::deploy_cmd::SimRobotArgs),
    /// Send an operator request to a running `l3p deploy`: resume, damp or stop.
    Operate(l3p_cli::deploy_cmd::OperateArgs),
    /// Export a policy (checkpoint or deploy artifact) as safetensors or ONNX + JSON config.
    Export(l3p_cli::deploy_cmd::ExportArgs),
    /// Check a TOML config file: parse it strictly and print the resolved values.
    Config(l3p_cli::config_cmd::ConfigArgs),
    /// The paper's transfer experiment: plan, run (resumably), status, report.
    Experiment(l3p_cli::experiment_cmd::ExperimentArgs),
}

fn main() -> ExitCode {
    keep_large_allocations_on_the_heap();
    l3p_cli::runtime::init_logging();
    let cli = Cli::parse();
    let verbose = cli.verbose || l3p_cli::runtime::lib_backtrace_asked();
    if cli.verbose {
        // SAFETY: nothing has started another thread yet (logging set-up starts none), so no
        // concurrent reader of the environment exists; anyhow reads it when it captures a backtrace.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("RUST_LIB_BACKTRACE", "1");
        }
    }
    // Robots added with `l3p robots add` ($L3P_ROBOTS_DIR, else ./l3p-data/robots).
    l3p_cli::robots_cmd::load_added_robots(None);
    l3p_cli::runtime::exit_code(run(cli.command), verbose)
}

fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Train(args) => l3p_cli::train_cmd::run(args),
        Command::Transfer(args) => l3p_cli::transfer_cmd::run(args),
        Command::Learner(args) => l3p_cli::learner_cmd::run(args),
        Command::Actor(args) => l3p_cli::actor_cmd::run(args),
        Command::Metrics(args) => l3p_cli::metrics_cmd::run(args),
        Command::Eval(args) => l3p_cli::eval_cmd::run(args),
        Command::Sim2sim(args) => l3p_cli::sim2sim_cmd::run(args),
        Command::Play(args) => l3p_cli::play_cmd::run(args),
        Command::Report(args) => l3p_cli::report_cmd::run(args),
        Command::Config(args) => l3p_cli::config_cmd::run(args),
        Command::Registry(args) => l3p_cli::registry_cmd::run(args),
        Command::Robots(args) => l3p_cli::robots_cmd::run(args),
        Command::Bench(args) => l3p_cli::bench_cmd::run(args),
        Command::Experiment(args) => l3p_cli::experiment_cmd::run(args),
        Command::Deploy(args) => l3p_cli::deploy_cmd::deploy(args),
        Command::Router(args) => l3p_cli::router_cmd::run(args),
        Command::SimRobot(args) => l3p_cli::deploy_cmd::sim_robot(args),
        Command::Operate(args) => l3p_cli::deploy_cmd::operate(args),
        Command::Export(args) => l3p_cli::deploy_cmd::export(args),
    }
}

/// glibc serves allocations above its mmap threshold (128 KiB, adapting upwards) with fresh `mmap`s
/// and returns them on `free`, so every PPO minibatch's tensors (0.2–25 MB) page-faulted in anew:
/// 10% of an update's time went to the kernel, and the learner update ran ×1.2–1.3 faster with the
/// threshold raised (BENCHMARKS.md). 32 MiB is glibc's largest allowed threshold on 64-bit; the
/// trim threshold keeps freed heap memory for reuse instead of returning it at once.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn keep_large_allocations_on_the_heap() {
    const M_TRIM_THRESHOLD: i32 = -1;
    const M_MMAP_THRESHOLD: i32 = -3;
    unsafe extern "C" {
        fn mallopt(param: i32, value: i32) -> i32;
    }
    // An explicit GLIBC_TUNABLES setting wins.
    if std::env::var_os("GLIBC_TUNABLES").is_some() {
        return;
    }
    // SAFETY: `mallopt` only sets allocator parameters; it is called before any other thread runs.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 32 << 20);
        mallopt(M_TRIM_THRESHOLD, 256 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_large_allocations_on_the_heap() {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every command that reads a data directory takes `--data-dir` (export and registry call it
    /// `--data`, and accept both).
    #[test]
    fn data_dir_is_accepted_everywhere() {
        let parse = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("l3p").chain(args.iter().copied()))
                .unwrap_or_else(|e| panic!("{args:?}: {e}"))
        };
        let cli = parse(&[
            "export",
            "run-a1@latest",
            "--output",
            "out",
            "--data-dir",
            "d",
        ]);
        let Command::Export(export) = cli.command else {
            panic!("not export");
        };
        assert_eq!(export.data.as_deref(), Some(std::path::Path::new("d")));
        for args in [
            &["registry", "list", "--data-dir", "d"][..],
            &["registry", "serve", "--data-dir", "d"][..],
            &["export", "x@1", "--output", "o", "--data", "d"][..],
        ] {
            parse(args);
        }
    }
}
