//! `l3p config check <file>`: strict parse of a config file, printing the resolved values.

use std::path::PathBuf;

use clap::Args;

use crate::config::Config;

#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// Config file (TOML) to check.
    pub file: PathBuf,
}

pub fn run(args: ConfigArgs) -> anyhow::Result<()> {
    let config = Config::load(&args.file)?;
    println!("{}", toml::to_string_pretty(&config)?);
    Ok(())
}
