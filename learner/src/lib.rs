//! The PPO learner of l3p as a library: rollout storage, GAE, the PPO update (rsl_rl semantics) with
//! the L3P recovery losses, freezing for transfer, several robots per update, checkpoints.
//!
//! # Public API (what the learner daemon calls)
//! - [`PpoConfig`] (TOML section, rsl_rl defaults; [`Mode`] `mlp` | `l3p` | `mlp-transfer` |
//!   `l3p-transfer`), [`l3p_policy::PolicyConfig`] for the networks.
//! - [`init_model`]`(mode, policy_config, robots, init_from, heads, &device)` builds the model a mode
//!   starts from (fresh, or initialised/frozen from a checkpoint; [`TransferHeads`] says what robots
//!   new to the checkpoint start with under `l3p-transfer`).
//! - [`Ppo::new`]`(cfg, model, device)`; [`Ppo::update`]`(&RolloutBatch) -> UpdateMetrics`;
//!   [`Ppo::export`]`(robot)` (deployable policy blob for actors/deploy, format `l3p-export-v1`);
//!   [`Ppo::checkpoint_bytes`] / [`Ppo::from_checkpoint_bytes`] / [`Ppo::save`] / [`Ppo::load`]
//!   (resume with optimiser state, iteration, lr); [`Ppo::model`], [`Ppo::iteration`],
//!   [`Ppo::learning_rate`].
//! - Storage: [`RolloutBatch`] of [`RobotRollout`]s (`[T, N, …]` flat arrays, filled from
//!   `l3p_proto::RolloutChunk`s with [`RolloutBatch::from_chunks`] or by hand).
//! - [`UpdateMetrics`]: approx KL, clip fraction, explained variance, lr, entropy, mean std, every
//!   loss, `R_obs` reconstruction MSE, samples/s.
//! - [`bench`]: the `l3p bench learner` workload (synthetic data, timed update and inference).
//! - [`gather::Gather`]: the daemon's gather rule (who to wait for, stale chunks, timeouts, silent
//!   actors) as a pure, unit-tested state machine.
//! - [`uploader::RegistryUploader`]: the daemon's background registry uploads (retried with
//!   backoff; an outage never stops training).
//! - The daemon writes every metrics record also as TensorBoard scalars in the run's directory
//!   (rsl_rl's tag names) with `l3p_report::tensorboard::EventWriter`; charts and reports are
//!   `l3p-report`'s.
//!
//! Architecture invariant: no rapier; Zenoh is only used by the daemon module (not in this file set).

pub mod bench;
pub mod daemon;
pub mod gae;
pub mod gather;
mod links;
pub mod ppo;
pub mod storage;
pub mod uploader;

pub use gae::{compute_gae, explained_variance, normalize};
pub use ppo::{
    Mirror, Mode, Ppo, PpoConfig, Schedule, SmoothnessSpace, TransferHeads, UpdateMetrics,
    clip_global_grad_norm, param_ids,
};
pub use storage::{RobotRollout, RolloutBatch};

use burn::tensor::Device;
use l3p_policy::{HeadMap, PolicyConfig, PolicyError, PolicyModel, PolicyRobot};

/// Errors of the learner library.
#[derive(Debug, thiserror::Error)]
pub enum LearnerError {
    #[error("invalid learner config: {0}")]
    Config(String),
    #[error("bad rollout batch: {0}")]
    Batch(String),
    #[error("training diverged: {0}")]
    NonFinite(String),
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error(transparent)]
    Policy(#[from] PolicyError),
}

/// The model a training mode starts from.
///
/// - `mlp`, `l3p`: fresh (`init_from` must be `None`).
/// - `mlp-transfer`: an MLP checkpoint; each robot takes the heads of the same-named robot in the
///   checkpoint, or else those of the checkpoint's first robot (the prototype, e.g. A1) when the
///   dimensions match.
/// - `l3p-transfer`: the core of an L3P checkpoint (frozen later by [`Ppo::new`]); robots present in
///   the checkpoint keep their adapters (terrain transfer), new robots get fresh adapters, or with
///   [`TransferHeads::Prototype`] a copy of the prototype's.
///
/// With [`TransferHeads::Mapped`] (either transfer mode) a new robot's copy of the prototype's heads
/// has its entry of `maps` (by robot name, from the prototype's spaces to the robot's) folded in.
pub fn init_model(
    mode: Mode,
    mut config: PolicyConfig,
    robots: Vec<PolicyRobot>,
    init_from: Option<&std::path::Path>,
    heads: TransferHeads,
    maps: &[(String, HeadMap)],
    device: &Device,
) -> Result<PolicyModel, LearnerError> {
    config.arch = mode.arch();
    match (mode, init_from) {
        (Mode::Mlp | Mode::L3p, None) => Ok(PolicyModel::new(config, robots, device)?),
        (Mode::Mlp | Mode::L3p, Some(_)) => Err(LearnerError::Config(format!(
            "mode {} trains from scratch\nhint: use {}-transfer to start from a checkpoint",
            mode.as_str(),
            mode.arch()
        ))),
        (_, None) => Err(LearnerError::Config(format!(
            "mode {} needs a checkpoint to start from\nhint: pass the pretrained checkpoint",
            mode.as_str()
        ))),
        (_, Some(path)) => {
            let ck = l3p_policy::load_checkpoint(path, device)?;
            transfer_model(mode, ck.model, robots, heads, maps, device)
        }
    }
}

/// [`init_model`] for an already loaded source model.
pub fn transfer_model(
    mode: Mode,
    source: PolicyModel,
    robots: Vec<PolicyRobot>,
    heads: TransferHeads,
    maps: &[(String, HeadMap)],
    device: &Device,
) -> Result<PolicyModel, LearnerError> {
    if source.config.arch != mode.arch() {
        return Err(LearnerError::Config(format!(
            "mode {} needs a {} checkpoint, got {}",
            mode.as_str(),
            mode.arch(),
            source.config.arch
        )));
    }
    let mut fresh = PolicyModel::new(source.config.clone(), robots.clone(), device)?;
    let proto = source.net.robots.first().cloned();
    let proto_spec = source.robots.first().cloned();
    for (k, spec) in robots.iter().enumerate() {
        if let Ok(j) = source.robot_index(&spec.name) {
            let s = &source.robots[j];
            if s.obs_dim != spec.obs_dim || s.action_dim != spec.action_dim {
                return Err(LearnerError::Config(format!(
                    "robot {}: checkpoint has obs {} / action {}, now obs {} / action {}",
                    spec.name, s.obs_dim, s.action_dim, spec.obs_dim, spec.action_dim
                )));
            }
            fresh.net.robots[k] = source.net.robots[j].clone();
        } else if mode == Mode::MlpTransfer || heads != TransferHeads::Fresh {
            match (&proto, &proto_spec) {
                (Some(h), Some(s))
                    if s.obs_dim == spec.obs_dim && s.action_dim == spec.action_dim =>
                {
                    fresh.net.robots[k] = if heads == TransferHeads::Mapped {
                        let map = maps
                            .iter()
                            .find(|(name, _)| *name == spec.name)
                            .map(|(_, m)| m)
                            .ok_or_else(|| {
                                LearnerError::Config(format!(
                                    "robot {}: transfer_heads = \"mapped\" but no map from {}",
                                    spec.name, s.name
                                ))
                            })?;
                        h.clone().map_spaces(map)?
                    } else {
                        h.clone()
                    };
                }
                _ => {
                    return Err(LearnerError::Config(format!(
                        "robot {}: no robot with its dimensions in the {} checkpoint\nhint: {} from the prototype needs equal observation and action sizes",
                        spec.name,
                        source.config.arch,
                        mode.as_str()
                    )));
                }
            }
        }
    }
    fresh.net.core = source.net.core;
    Ok(fresh)
}
