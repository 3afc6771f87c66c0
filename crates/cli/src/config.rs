//! The top-level TOML config: one section per subsystem, each owned by its crate. Parsing is strict
//! (`deny_unknown_fields` everywhere), so a misspelt key is an error that names the key and the file.
//! `configs/reference.toml` documents every key and is parsed by a test.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Everything `l3p train`, `l3p learner` and `l3p actor` read from one file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub run: RunConfig,
    pub zenoh: l3p_registry::net::ZenohSettings,
    /// Rollout actors started by `l3p train` (local mode); daemon-mode actors name their robot on the
    /// command line instead.
    pub actors: Vec<ActorSpec>,
}

impl Config {
    /// Load and strictly parse a config file.
    pub fn load(path: &Path) -> Result<Self, l3p_proto::config::ConfigError> {
        l3p_proto::config::load_toml(path)
    }
}

/// Run identity and where its data lives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunConfig {
    /// Run name: a single key segment (letters, digits, `-`, `_`).
    pub name: String,
    /// Root of all run data; the run writes under `<data_dir>/<name>/`, the registry at
    /// `<data_dir>/registry.db`.
    pub data_dir: PathBuf,
    /// Seed for every random stream of the run (envs, initialisation, minibatch shuffling).
    pub seed: u64,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self { name: "default".into(), data_dir: PathBuf::from("l3p-data"), seed: 1 }
    }
}

/// One actor process of local mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActorSpec {
    /// Robot name from `l3p robots list`.
    pub robot: String,
    /// Parallel environments simulated by this actor.
    #[serde(default = "default_envs")]
    pub envs: usize,
    /// Worker threads for the simulator.
    #[serde(default = "default_threads")]
    pub threads: usize,
}

fn default_envs() -> usize {
    64
}

fn default_threads() -> usize {
    1
}
