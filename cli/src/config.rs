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
    pub zenoh: l3p_net::ZenohSettings,
    /// Simulation and locomotion task (terrain, commands, rewards, noise, randomisation).
    pub env: l3p_task::config::EnvConfig,
    /// Networks: architecture (`mlp` | `l3p`), latent sizes, hidden sizes, recovery modules.
    pub model: l3p_policy::PolicyConfig,
    /// PPO hyperparameters and training mode.
    pub ppo: l3p_learner::PpoConfig,
    /// How the learner daemon gathers data, checkpoints and stops.
    pub learner: l3p_learner::daemon::DaemonConfig,
    /// What each actor collects per policy version.
    pub rollout: RolloutConfig,
    /// Safety settings of `l3p deploy` (watchdog, start-up ramp, damping).
    pub deploy: l3p_deploy::SafetyConfig,
    /// Rollout actors started by `l3p train` (local mode); daemon-mode actors name their robot on the
    /// command line instead.
    pub actors: Vec<ActorSpec>,
}

impl Config {
    /// Load, strictly parse and [`validate`](Config::validate) a config file: a value that would
    /// hang or fail a process later is an error here, before anything starts.
    pub fn load(path: &Path) -> Result<Self, l3p_proto::config::ConfigError> {
        let config: Config = l3p_proto::config::load_toml(path)?;
        // Robots added under the run's data directory (`l3p robots add`) are known to every
        // process that reads this config, actors included.
        crate::robots_cmd::load_added_robots(Some(&config.run.data_dir));
        config
            .validate()
            .map_err(|message| l3p_proto::config::ConfigError::Invalid {
                path: path.to_path_buf(),
                message,
            })?;
        Ok(config)
    }

    /// Every check that needs no process: sizes ≥ 1, finite positive rates, ranges, the env
    /// resolved for each actor's robot, and a batch that the minibatches can split. Errors name the
    /// key, the value and what is allowed.
    pub fn validate(&self) -> Result<(), String> {
        for (i, actor) in self.actors.iter().enumerate() {
            let key = |field: &str| format!("actors[{i}].{field}");
            if actor.envs == 0 {
                return Err(format!("{} = 0: expected >= 1", key("envs")));
            }
            if actor.threads == 0 {
                return Err(format!("{} = 0: expected >= 1", key("threads")));
            }
            l3p_robot::catalog::RobotSpec::by_name(&actor.robot)
                .map_err(|e| format!("{}: {e}", key("robot")))?;
            self.env
                .resolve(&actor.robot)
                .map_err(|e| format!("env (for {}): {e}", actor.robot))?;
        }
        if self.rollout.steps_per_env == 0 {
            return Err("rollout.steps_per_env = 0: expected >= 1".into());
        }
        let ppo = &self.ppo;
        ppo.validate().map_err(|e| e.to_string())?;
        let envs: usize = self.actors.iter().map(|a| a.envs).sum();
        let batch = envs * self.rollout.steps_per_env;
        if !self.actors.is_empty() && batch < ppo.num_mini_batches {
            return Err(format!(
                "ppo.num_mini_batches = {}: more than the {batch} samples per update \
                 (actors' envs × rollout.steps_per_env)",
                ppo.num_mini_batches
            ));
        }
        self.model.validate().map_err(|e| format!("model: {e}"))?;
        let l = &self.learner;
        if !(l.gather_timeout_s.is_finite() && l.gather_timeout_s > 0.0) {
            return Err(format!(
                "learner.gather_timeout_s = {}: expected a finite number > 0",
                l.gather_timeout_s
            ));
        }
        for (key, v) in [
            ("checkpoint_every", l.checkpoint_every),
            ("registry_checkpoint_every", l.registry_checkpoint_every),
        ] {
            if v == 0 {
                return Err(format!("learner.{key} = 0: expected >= 1"));
            }
        }
        self.deploy.validate()?;
        Ok(())
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
        Self {
            name: "default".into(),
            data_dir: PathBuf::from("l3p-data"),
            seed: 1,
        }
    }
}

/// Rollout collection shared by every actor of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RolloutConfig {
    /// Control steps per environment per policy version (rsl_rl's `num_steps_per_env`).
    pub steps_per_env: usize,
    /// Give each environment's first episode a random head start towards its time-out (rsl_rl's
    /// `init_at_random_ep_len`), so episodes that do not fall end spread over time instead of in
    /// waves one episode length apart. Off by default: the shipped recipes were measured without.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub random_initial_episode_length: bool,
}

impl Default for RolloutConfig {
    fn default() -> Self {
        Self {
            steps_per_env: 24,
            random_initial_episode_length: false,
        }
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
