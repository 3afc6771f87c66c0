//! `l3p` — the command-line entry point. Argument parsing and glue only: every command calls into a
//! library crate (see ARCHITECTURE.md).

use clap::{Parser, Subcommand};

mod logging;

/// Train, transfer and deploy latent-to-latent locomotion policies (L3P) for legged robots.
#[derive(Debug, Parser)]
#[command(name = "l3p", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// List the built-in robots or check a robot / URDF file (load, stand under PD).
    Robots(l3p_cli::robots_cmd::RobotsArgs),
    /// Benchmarks (`bench sim`: simulator throughput).
    Bench(l3p_cli::bench_cmd::BenchArgs),
    /// Check a TOML config file: parse it strictly and print the resolved values.
    Config(l3p_cli::config_cmd::ConfigArgs),
}

fn main() -> anyhow::Result<()> {
    logging::init();
    let cli = Cli::parse();
    match cli.command {
        Command::Config(args) => l3p_cli::config_cmd::run(args),
        Command::Robots(args) => l3p_cli::robots_cmd::run(args),
        Command::Bench(args) => l3p_cli::bench_cmd::run(args),
    }
}
