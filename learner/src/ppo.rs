//! PPO as rsl_rl (`algorithms/ppo.py`), plus the L3P recovery losses, for one or several robots.
//!
//! Main types: [`PpoConfig`] (every hyperparameter, rsl_rl defaults), [`Mode`], [`Ppo`] (model +
//! Adam + learning rate + iteration; [`Ppo::update`]), [`UpdateMetrics`].
//!
//! One update ([`Ppo::update`]) reads top to bottom:
//! 1. `check_batch`: every robot's rollout against the model and the config;
//! 2. `prepare`: values `V(s_t)` and `V(s_T)` under the current critic, GAE with time-out
//!    bootstrapping ([`crate::gae`]), advantages normalised per robot over the whole batch (rsl_rl
//!    normalises over its batch; one robot = one batch), and one split of each robot's rollout into
//!    minibatches ([`RobotRollout::minibatches`](crate::storage::RobotRollout::minibatches)) reused
//!    by every epoch (rsl_rl; with `smoothness_coef` > 0 whole env segments, so that neighbours in
//!    time share a minibatch);
//! 3. `recon_error`: `R_obs` reconstruction error on observations not trained on yet (the fresh
//!    batch);
//! 4. `epochs × minibatches` of `minibatch_step`: the k-th minibatch of every robot through its
//!    adapters and the shared core; per robot `minibatch_loss` (the clipped surrogate, the clipped
//!    value loss, the entropy bonus, `λ (L_rec_obs + L_rec_act)`, with `symmetry_coef` > 0 the
//!    mirror loss on the same minibatch mirrored left-right ([`Mirror`]), with `smoothness_coef` > 0
//!    the temporal smoothness of the minibatch's own means at consecutive steps of an episode) and
//!    its parts; the KL to the behaviour policy adapts the learning rate *before* the step;
//!    back-propagation, the global gradient norm clipped, Adam; the parts summed into an
//!    `UpdateAccumulator`;
//! 5. `check_progress`: an update whose every step was non-finite counts towards an error.
//!
//! Files: `ppo/config.rs` holds the settings and modes, `ppo/ops.rs` the tensor-level losses and
//! gradient clipping; both re-exported here.

use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Int, Tensor, TensorData};
use l3p_policy::{
    ActorOut, PolicyModel, PolicyNet, gaussian_entropy, gaussian_log_prob, tensor_to_vec,
};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

use crate::LearnerError;
use crate::gae::{compute_gae, explained_variance, normalize};
use crate::storage::{MinibatchSplit, Minibatches, RolloutBatch};

mod config;
mod ops;

pub use config::{Mode, PpoConfig, Schedule, SmoothnessSpace, TransferHeads};
use ops::scalar;
pub use ops::{approx_kl, clip_global_grad_norm, param_ids, surrogate_loss, value_loss};

/// What one update did (means over all minibatches unless noted).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct UpdateMetrics {
    pub iteration: u64,
    pub samples: usize,
    pub approx_kl: f32,
    pub clip_fraction: f32,
    /// Of the critic's values at the start of the update against the GAE returns.
    pub explained_variance: f32,
    /// Learning rate after the update.
    pub learning_rate: f64,
    pub entropy: f32,
    pub mean_std: f32,
    pub surrogate_loss: f32,
    pub value_loss: f32,
    pub rec_obs_loss: f32,
    pub rec_act_loss: f32,
    /// Mirror-symmetry loss (0 when `symmetry_coef` is 0).
    pub symmetry_loss: f32,
    /// Temporal smoothness loss (0 when `smoothness_coef` is 0).
    pub smoothness_loss: f32,
    pub total_loss: f32,
    /// Global gradient norm before clipping (mean over minibatches).
    pub grad_norm: f32,
    /// Minibatch steps skipped because their loss or gradient was not finite (parameters and
    /// optimiser state untouched).
    pub skipped_steps: usize,
    /// MSE between observations and `R_obs` samples given `h`, on observations of this batch taken
    /// before any gradient step (NaN when there is no `R_obs`).
    pub recon_mse: f32,
    /// Variance of those observations (the MSE of predicting their mean), for scale.
    pub recon_baseline_mse: f32,
    pub mean_reward: f32,
    pub update_seconds: f32,
    pub samples_per_second: f32,
}

/// Per-robot data prepared for minibatching.
struct Prepared {
    robot: usize,
    advantages: Vec<f32>,
    returns: Vec<f32>,
    values: Vec<f32>,
    minibatches: Minibatches,
}

/// Left-right mirror maps of one robot's observation and action (`out[i] = sign[i] · in[index[i]]`;
/// built by `l3p_task::mirror::TaskMirror` from the robot's geometry).
#[derive(Debug, Clone, PartialEq)]
pub struct Mirror {
    pub obs_index: Vec<usize>,
    pub obs_sign: Vec<f32>,
    pub action_index: Vec<usize>,
    pub action_sign: Vec<f32>,
}

/// A [`Mirror`] on the device.
#[derive(Debug, Clone)]
struct MirrorTensors {
    obs_index: Tensor<1, Int>,
    obs_sign: Tensor<2>,
    action_index: Tensor<1, Int>,
    action_sign: Tensor<2>,
    /// The maps themselves, for a symmetrized export.
    host: Mirror,
}

impl MirrorTensors {
    fn observations(&self, obs: Tensor<2>) -> Tensor<2> {
        obs.select(1, self.obs_index.clone())
            .mul(self.obs_sign.clone())
    }

    fn actions(&self, actions: Tensor<2>) -> Tensor<2> {
        actions
            .select(1, self.action_index.clone())
            .mul(self.action_sign.clone())
    }
}

/// The PPO learner state.
pub struct Ppo {
    cfg: PpoConfig,
    model: PolicyModel,
    optim: ModuleOptimizer,
    device: Device,
    lr: f64,
    iteration: u64,
    rng: StdRng,
    /// Consecutive updates in which every minibatch step was skipped as non-finite.
    diverged_updates: u32,
    /// Per model robot, for the symmetry loss.
    mirrors: Vec<Option<MirrorTensors>>,
}

/// Updates in a row with no finite step before training stops.
pub const MAX_DIVERGED_UPDATES: u32 = 3;

impl std::fmt::Debug for Ppo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ppo")
            .field("cfg", &self.cfg)
            .field("lr", &self.lr)
            .field("iteration", &self.iteration)
            .finish_non_exhaustive()
    }
}

fn adam(cfg: &PpoConfig) -> ModuleOptimizer {
    AdamConfig::new().with_epsilon(cfg.adam_epsilon).init()
}

impl Ppo {
    /// A learner for `model` (built on an autodiff device, e.g. [`l3p_policy::train_device`]). In
    /// `l3p-transfer` the core is frozen here.
    pub fn new(cfg: PpoConfig, model: PolicyModel, device: Device) -> Result<Self, LearnerError> {
        cfg.validate()?;
        if model.config.arch != cfg.mode.arch() {
            return Err(LearnerError::Config(format!(
                "mode {} needs a {} model, got {}",
                cfg.mode.as_str(),
                cfg.mode.arch(),
                model.config.arch
            )));
        }
        let model = if cfg.mode == Mode::L3pTransfer {
            model.freeze_core()
        } else {
            model
        };
        let optim = adam(&cfg);
        let lr = cfg.learning_rate;
        let rng = StdRng::seed_from_u64(cfg.seed);
        let mirrors = vec![None; model.robots.len()];
        Ok(Self {
            cfg,
            mirrors,
            model,
            optim,
            device,
            lr,
            iteration: 0,
            diverged_updates: 0,
            rng,
        })
    }

    pub fn config(&self) -> &PpoConfig {
        &self.cfg
    }

    /// Sets `robot`'s mirror maps (needed for every robot when `symmetry_coef` > 0); checks that
    /// each is a permutation of the robot's dimensions with signs ±1.
    pub fn set_mirror(&mut self, robot: &str, mirror: &Mirror) -> Result<(), LearnerError> {
        let i = self.model.robot_index(robot)?;
        let spec = &self.model.robots[i];
        let check = |what: &str, index: &[usize], sign: &[f32], dim: usize| {
            let mut seen = vec![false; dim];
            let ok = index.len() == dim
                && sign.len() == dim
                && sign.iter().all(|s| *s == 1.0 || *s == -1.0)
                && index
                    .iter()
                    .all(|&j| j < dim && !std::mem::replace(&mut seen[j], true));
            if ok {
                Ok(())
            } else {
                Err(LearnerError::Config(format!(
                    "robot {robot}: the {what} mirror is not a signed permutation of {dim} entries"
                )))
            }
        };
        check(
            "observation",
            &mirror.obs_index,
            &mirror.obs_sign,
            spec.obs_dim,
        )?;
        check(
            "action",
            &mirror.action_index,
            &mirror.action_sign,
            spec.action_dim,
        )?;
        let index = |v: &[usize]| {
            let v: Vec<i64> = v.iter().map(|&j| j as i64).collect();
            let n = v.len();
            Tensor::<1, Int>::from_data(TensorData::new(v, [n]), &self.device)
        };
        self.mirrors[i] = Some(MirrorTensors {
            obs_index: index(&mirror.obs_index),
            obs_sign: self.tensor2(mirror.obs_sign.clone(), 1, spec.obs_dim),
            action_index: index(&mirror.action_index),
            action_sign: self.tensor2(mirror.action_sign.clone(), 1, spec.action_dim),
            host: mirror.clone(),
        });
        Ok(())
    }

    pub fn model(&self) -> &PolicyModel {
        &self.model
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    pub fn learning_rate(&self) -> f64 {
        self.lr
    }

    pub fn set_learning_rate(&mut self, lr: f64) {
        self.lr = lr;
    }

    /// Number of updates done (restored from checkpoints).
    pub fn iteration(&self) -> u64 {
        self.iteration
    }

    /// Checkpoint: model + Adam state + iteration + learning rate and mode.
    pub fn checkpoint_bytes(&self) -> Result<Vec<u8>, LearnerError> {
        let optim = self
            .optim
            .into_bytes()
            .map_err(|e| LearnerError::Checkpoint(format!("optimiser state: {e}")))?;
        let learner =
            serde_json::json!({ "learning_rate": self.lr, "mode": self.cfg.mode.as_str() });
        Ok(l3p_policy::checkpoint_to_bytes(
            &self.model,
            &optim,
            self.iteration,
            learner,
        )?)
    }

    /// Resume from [`checkpoint_bytes`](Self::checkpoint_bytes): model, optimiser state, iteration
    /// and learning rate.
    pub fn from_checkpoint_bytes(
        cfg: PpoConfig,
        bytes: &[u8],
        device: Device,
    ) -> Result<Self, LearnerError> {
        let ck = l3p_policy::checkpoint_from_bytes(bytes, &device)?;
        let mut ppo = Ppo::new(cfg, ck.model, device)?;
        if !ck.optimizer.is_empty() {
            ppo.optim = adam(&ppo.cfg)
                .from_bytes(burn::tensor::Bytes::from_bytes_vec(ck.optimizer))
                .map_err(|e| LearnerError::Checkpoint(format!("optimiser state: {e}")))?;
        }
        ppo.iteration = ck.iteration;
        if let Some(lr) = ck.learner.get("learning_rate").and_then(|v| v.as_f64()) {
            ppo.lr = lr;
        }
        Ok(ppo)
    }

    pub fn save(&self, path: &std::path::Path) -> Result<(), LearnerError> {
        let bytes = self.checkpoint_bytes()?;
        l3p_policy::write_atomic(path, &bytes)
            .map_err(|e| LearnerError::Checkpoint(format!("{}: {e}", path.display())))
    }

    pub fn load(
        cfg: PpoConfig,
        path: &std::path::Path,
        device: Device,
    ) -> Result<Self, LearnerError> {
        let bytes = std::fs::read(path)
            .map_err(|e| LearnerError::Checkpoint(format!("{}: {e}", path.display())))?;
        Self::from_checkpoint_bytes(cfg, &bytes, device)
    }

    /// Export one robot's deployable policy (safetensors + JSON config in one blob).
    pub fn export(&self, robot: &str) -> Result<(Vec<u8>, l3p_policy::ExportConfig), LearnerError> {
        Ok(l3p_policy::export_bytes(&self.model, robot)?)
    }

    /// The policy a run deploys for `robot` (its registry deploy artifacts): [`export`](Self::export),
    /// averaged with its left-right mirror image when `symmetrize_export` is set (an error without
    /// the robot's mirror maps). The actors keep rolling out the trained policy: PPO is on-policy.
    pub fn deploy_export(
        &self,
        robot: &str,
    ) -> Result<(Vec<u8>, l3p_policy::ExportConfig), LearnerError> {
        let (bytes, config) = self.export(robot)?;
        if !self.cfg.symmetrize_export {
            return Ok((bytes, config));
        }
        let i = self.model.robot_index(robot)?;
        let m = &self.mirrors[i]
            .as_ref()
            .ok_or_else(|| {
                LearnerError::Config(format!(
                    "ppo.symmetrize_export = true but robot {robot} has no mirror maps"
                ))
            })?
            .host;
        let symmetric = l3p_policy::DeployPolicy::from_bytes(&bytes)?.symmetrized(
            &m.obs_index,
            &m.obs_sign,
            &m.action_index,
            &m.action_sign,
        )?;
        Ok((symmetric.to_bytes()?, symmetric.config))
    }

    fn tensor2(&self, v: Vec<f32>, rows: usize, cols: usize) -> Tensor<2> {
        Tensor::from_data(TensorData::new(v, [rows, cols]), &self.device)
    }

    fn tensor1(&self, v: Vec<f32>) -> Tensor<1> {
        let n = v.len();
        Tensor::from_data(TensorData::new(v, [n]), &self.device)
    }

    /// Critic values for many observations, without autodiff.
    fn values(
        &self,
        net: &PolicyNet,
        robot: usize,
        obs: &[f32],
        obs_dim: usize,
    ) -> Result<Vec<f32>, LearnerError> {
        let n = obs.len() / obs_dim;
        let x = self.tensor2(obs.to_vec(), n, obs_dim).inner();
        Ok(tensor_to_vec(net.robots[robot].value(x))?)
    }

    /// One PPO update on `batch` (see the module docs for the order of operations).
    pub fn update(&mut self, batch: &RolloutBatch) -> Result<UpdateMetrics, LearnerError> {
        let start = Instant::now();
        let index = self.check_batch(batch)?;
        let net_eval = self.model.net.valid();
        let (prepared, explained_variance) = self.prepare(&net_eval, batch, &index)?;
        let (recon_mse, recon_baseline_mse) = self.recon_error(&net_eval, batch, &index)?;
        drop(net_eval);

        let mut acc = UpdateAccumulator::default();
        for _epoch in 0..self.cfg.num_learning_epochs {
            for k in 0..self.cfg.num_mini_batches {
                match self.minibatch_step(batch, &prepared, k)? {
                    Some((parts, grad_norm)) => acc.add(&parts, grad_norm),
                    None => acc.skipped += 1,
                }
            }
        }
        self.iteration += 1;
        self.check_progress(&acc)?;

        let mut std_sum = 0f32;
        let mut std_n = 0usize;
        for &i in &index {
            let s = tensor_to_vec(self.model.net.robots[i].std().detach())?;
            std_sum += s.iter().sum::<f32>();
            std_n += s.len();
        }
        let samples = batch.samples();
        let secs = start.elapsed().as_secs_f32();
        let reward_sum: f32 = batch
            .robots
            .iter()
            .map(|r| r.rewards.iter().sum::<f32>())
            .sum();
        let mean = acc.mean();
        Ok(UpdateMetrics {
            iteration: self.iteration,
            samples,
            approx_kl: mean.kl,
            clip_fraction: mean.clip_fraction,
            explained_variance,
            learning_rate: self.lr,
            entropy: mean.entropy,
            mean_std: std_sum / std_n.max(1) as f32,
            surrogate_loss: mean.surrogate,
            value_loss: mean.value,
            rec_obs_loss: mean.rec_obs,
            rec_act_loss: mean.rec_act,
            symmetry_loss: mean.symmetry,
            smoothness_loss: mean.smoothness,
            total_loss: mean.total,
            grad_norm: acc.grad_norm / acc.steps.max(1) as f32,
            skipped_steps: acc.skipped,
            recon_mse,
            recon_baseline_mse,
            mean_reward: reward_sum / samples.max(1) as f32,
            update_seconds: secs,
            samples_per_second: samples as f32 / secs.max(1e-9),
        })
    }

    /// Validates every robot's rollout against the model and the config; the model index of each.
    fn check_batch(&self, batch: &RolloutBatch) -> Result<Vec<usize>, LearnerError> {
        let cfg = &self.cfg;
        if batch.robots.is_empty() {
            return Err(LearnerError::Batch("empty batch".into()));
        }
        let mut index = Vec::with_capacity(batch.robots.len());
        for (k, r) in batch.robots.iter().enumerate() {
            r.validate()?;
            let i = self.model.robot_index(&r.robot)?;
            let spec = &self.model.robots[i];
            if spec.obs_dim != r.obs_dim || spec.action_dim != r.action_dim {
                return Err(LearnerError::Batch(format!(
                    "robot {}: batch has obs {} / action {}, model expects obs {} / action {}",
                    r.robot, r.obs_dim, r.action_dim, spec.obs_dim, spec.action_dim
                )));
            }
            if batch.robots[..k].iter().any(|o| o.robot == r.robot) {
                return Err(LearnerError::Batch(format!(
                    "robot {} appears twice in the batch",
                    r.robot
                )));
            }
            if r.samples() < cfg.num_mini_batches {
                return Err(LearnerError::Batch(format!(
                    "robot {}: {} samples cannot fill {} minibatches",
                    r.robot,
                    r.samples(),
                    cfg.num_mini_batches
                )));
            }
            if cfg.smoothness_coef > 0.0 && r.envs < cfg.num_mini_batches {
                return Err(LearnerError::Batch(format!(
                    "robot {}: {} envs cannot fill {} minibatches (with ppo.smoothness_coef a \
                     minibatch is whole env segments)",
                    r.robot, r.envs, cfg.num_mini_batches
                )));
            }
            if cfg.symmetry_coef > 0.0 && self.mirrors[i].is_none() {
                return Err(LearnerError::Config(format!(
                    "ppo.symmetry_coef = {} but robot {} has no mirror maps",
                    cfg.symmetry_coef, r.robot
                )));
            }
            index.push(i);
        }
        Ok(index)
    }

    /// Steps 1, 2 and the split of 4: values, GAE returns and normalised advantages of every
    /// robot, and its minibatches; the explained variance of the values over the whole batch.
    fn prepare(
        &mut self,
        net: &PolicyNet,
        batch: &RolloutBatch,
        index: &[usize],
    ) -> Result<(Vec<Prepared>, f32), LearnerError> {
        // With the smoothness loss a minibatch is whole env segments, so each sample's
        // neighbours in time share its forward pass.
        let split = if self.cfg.smoothness_coef > 0.0 {
            MinibatchSplit::EnvSegments
        } else {
            MinibatchSplit::Samples
        };
        let mut prepared = Vec::with_capacity(batch.robots.len());
        let (mut all_values, mut all_returns) = (Vec::new(), Vec::new());
        for (r, &i) in batch.robots.iter().zip(index) {
            let values = self.values(net, i, &r.observations, r.obs_dim)?;
            let last = self.values(net, i, &r.last_observations, r.obs_dim)?;
            let (mut advantages, returns) = compute_gae(
                &r.rewards,
                &values,
                &last,
                &r.terminated,
                &r.truncated,
                r.steps,
                r.envs,
                self.cfg.gamma,
                self.cfg.lam,
            );
            normalize(&mut advantages);
            all_values.extend_from_slice(&values);
            all_returns.extend_from_slice(&returns);
            let minibatches = r.minibatches(self.cfg.num_mini_batches, split, &mut self.rng);
            prepared.push(Prepared {
                robot: i,
                advantages,
                returns,
                values,
                minibatches,
            });
        }
        Ok((prepared, explained_variance(&all_values, &all_returns)))
    }

    /// One gradient step on minibatch `k` of every robot: the losses summed over robots weighted by
    /// their share of the minibatch, the global gradient norm clipped, the learning rate adapted to
    /// the KL, Adam. `None` when the loss or the gradient is not finite: the step is skipped with
    /// parameters, optimiser state and learning rate untouched.
    fn minibatch_step(
        &mut self,
        batch: &RolloutBatch,
        prepared: &[Prepared],
        k: usize,
    ) -> Result<Option<(LossParts, f32)>, LearnerError> {
        let total: usize = prepared.iter().map(|p| p.minibatches.size()).sum();
        let mut obs = vec![None; self.model.robots.len()];
        let mut inputs = Vec::with_capacity(prepared.len());
        for (p, r) in prepared.iter().zip(&batch.robots) {
            let idx = p.minibatches.get(k);
            let rows = r.minibatch_rows(idx);
            let pick = |src: &[f32]| idx.iter().map(|&j| src[j]).collect::<Vec<f32>>();
            let (n, ad) = (idx.len(), r.action_dim);
            obs[p.robot] = Some(self.tensor2(rows.observations, n, r.obs_dim));
            let targets = MinibatchTargets {
                actions: self.tensor2(rows.actions, n, ad),
                old_log_probs: self.tensor1(rows.log_probs),
                old_means: self.tensor2(rows.action_means, n, ad),
                old_stds: self.tensor2(rows.action_stds, n, ad),
                advantages: self.tensor1(pick(&p.advantages)),
                returns: self.tensor1(pick(&p.returns)),
                old_values: self.tensor1(pick(&p.values)),
            };
            let neighbours = (self.cfg.smoothness_coef > 0.0)
                .then(|| NeighbourRows::new(r, idx, self.cfg.smoothness_order))
                .filter(|n| !n.current.is_empty())
                .map(|n| n.tensors(&self.device));
            inputs.push((p.robot, n, targets, neighbours));
        }
        let outs = self.model.net.actors(obs.clone());
        // The same minibatch mirrored left-right, for the symmetry loss.
        let mirrored_outs =
            (self.cfg.symmetry_coef > 0.0 && !self.critic_warming_up()).then(|| {
                let mirrored = obs
                    .iter()
                    .zip(&self.mirrors)
                    .map(|(o, m)| match (o, m) {
                        (Some(o), Some(m)) => Some(m.observations(o.clone())),
                        _ => None,
                    })
                    .collect();
                self.model.net.actors(mirrored)
            });

        let mut loss_sum: Option<Tensor<1>> = None;
        let mut parts = LossParts::default();
        for (robot, n, targets, neighbours) in inputs {
            let missing = |what: &str| LearnerError::Batch(format!("missing {what}"));
            let out = outs[robot]
                .as_ref()
                .ok_or_else(|| missing("actor output"))?;
            let robot_obs = obs[robot].clone().ok_or_else(|| missing("observations"))?;
            let mirrored = match (&mirrored_outs, &self.mirrors[robot]) {
                (Some(o), Some(_)) => Some(
                    o[robot]
                        .as_ref()
                        .ok_or_else(|| missing("mirrored output"))?,
                ),
                _ => None,
            };
            let (loss, robot_parts) =
                self.minibatch_loss(robot, out, mirrored, robot_obs, targets, neighbours)?;
            let w = n as f32 / total as f32;
            parts.add_weighted(&robot_parts, w);
            let weighted = loss.mul_scalar(w);
            loss_sum = Some(match loss_sum {
                None => weighted,
                Some(t) => t.add(weighted),
            });
        }
        let loss = loss_sum.ok_or_else(|| LearnerError::Batch("no loss".into()))?;
        let grads = loss.backward();
        let mut grads = GradientsParams::from_grads(grads, &self.model.net);
        let norm = clip_global_grad_norm(&self.model.net, &mut grads, self.cfg.max_grad_norm)?;
        if !(norm.is_finite() && parts.kl.is_finite()) {
            return Ok(None);
        }
        if !self.critic_warming_up() {
            // While the actor stands still its KL is 0, which would raise the rate to its cap.
            self.lr = self.cfg.adapt_lr(self.lr, parts.kl);
        }
        let net = std::mem::replace(&mut self.model.net, placeholder_net());
        self.model.net = self.optim.step(self.lr, net, grads);
        Ok(Some((parts, norm)))
    }

    /// One robot's loss on one minibatch, as rsl_rl's `ppo.py` adds it up: the clipped surrogate,
    /// the (clipped) value loss and the entropy bonus; for L3P `λ (L_rec_obs + L_rec_act)`; with
    /// `symmetry_coef` > 0 the mirror loss; with `smoothness_coef` > 0 the temporal smoothness of the
    /// minibatch's own means at consecutive steps of an episode. Also the KL to the behaviour
    /// policy (no gradient) and the clipped fraction.
    fn minibatch_loss(
        &mut self,
        robot: usize,
        out: &ActorOut,
        mirrored: Option<&ActorOut>,
        obs: Tensor<2>,
        t: MinibatchTargets,
        neighbours: Option<NeighbourTensors>,
    ) -> Result<(Tensor<1>, LossParts), LearnerError> {
        let cfg = &self.cfg;
        let heads = &self.model.net.robots[robot];
        let warming_up = self.critic_warming_up();
        let mut parts = LossParts {
            kl: scalar(approx_kl(
                out.mean.clone().detach(),
                out.std.clone().detach(),
                t.old_means,
                t.old_stds,
            ))?,
            ..LossParts::default()
        };
        let logp = gaussian_log_prob(t.actions, out.mean.clone(), out.std.clone());
        let entropy = gaussian_entropy(out.std.clone());
        let ratio = logp.sub(t.old_log_probs).exp();
        let ratio_host = tensor_to_vec(ratio.clone().detach())?;
        let clipped = ratio_host
            .iter()
            .filter(|r| (**r - 1.0).abs() > cfg.clip_param)
            .count();
        parts.clip_fraction = clipped as f32 / ratio_host.len().max(1) as f32;
        let surrogate = surrogate_loss(ratio, t.advantages, cfg.clip_param);
        let value = heads.value(obs.clone()).squeeze_dim::<1>(1);
        let value_loss = value_loss(
            value,
            t.old_values,
            t.returns,
            cfg.clip_param,
            cfg.use_clipped_value_loss,
        );
        parts.surrogate = scalar(surrogate.clone().detach())?;
        parts.value = scalar(value_loss.clone().detach())?;
        parts.entropy = scalar(entropy.clone().detach())?;
        if warming_up {
            // Only the critic learns: no term that reaches the actor's parameters.
            let loss = value_loss.mul_scalar(cfg.value_loss_coef);
            parts.total = scalar(loss.clone().detach())?;
            return Ok((loss, parts));
        }
        let mut loss = surrogate
            .add(value_loss.mul_scalar(cfg.value_loss_coef))
            .sub(entropy.mul_scalar(cfg.entropy_coef));

        let lambda = self.model.config.recovery.lambda;
        if let (Some(r_obs), Some(h)) = (&heads.r_obs, &out.h) {
            let l = r_obs.loss(obs, h.clone(), &mut self.rng);
            parts.rec_obs = scalar(l.clone().detach())?;
            loss = loss.add(l.mul_scalar(lambda));
        }
        if let (Some(r_act), Some(z)) = (&heads.r_act, &out.z) {
            let z_hat = r_act.forward(out.mean.clone());
            let l = z_hat.sub(z.clone().detach()).square().mean();
            parts.rec_act = scalar(l.clone().detach())?;
            loss = loss.add(l.mul_scalar(lambda));
        }
        if let (Some(out_m), Some(m)) = (mirrored, &self.mirrors[robot]) {
            let l = out_m
                .mean
                .clone()
                .sub(m.actions(out.mean.clone()))
                .square()
                .mean();
            parts.symmetry = scalar(l.clone().detach())?;
            loss = loss.add(l.mul_scalar(cfg.symmetry_coef));
        }
        if let Some(n) = neighbours {
            // μ of each sample's neighbours in time, from this same forward pass.
            let at = |rows: &Tensor<1, Int>| out.mean.clone().select(0, rows.clone());
            let current = at(&n.current);
            let mut diff = at(&n.next).sub(current.clone());
            if let Some(prev) = &n.prev {
                diff = diff.sub(current.sub(at(prev)));
            }
            let scale = match cfg.smoothness_space {
                SmoothnessSpace::Action => 1.0,
                SmoothnessSpace::JointTarget => self.model.robots[robot].action_scale,
            };
            let l = diff.mul_scalar(scale).square().mean();
            parts.smoothness = scalar(l.clone().detach())?;
            loss = loss.add(l.mul_scalar(cfg.smoothness_coef));
        }
        parts.total = scalar(loss.clone().detach())?;
        Ok((loss, parts))
    }

    /// Whether this update trains only the critic (`critic_warmup_iterations`).
    fn critic_warming_up(&self) -> bool {
        self.iteration < self.cfg.critic_warmup_iterations
    }

    /// Counts updates in which every step was skipped; too many in a row is an error (the last
    /// good policy stays in the last checkpoint).
    fn check_progress(&mut self, acc: &UpdateAccumulator) -> Result<(), LearnerError> {
        if acc.steps > 0 {
            self.diverged_updates = 0;
            return Ok(());
        }
        self.diverged_updates += 1;
        tracing::warn!(
            iteration = self.iteration,
            skipped = acc.skipped,
            "every minibatch step had a non-finite loss or gradient; the policy is unchanged"
        );
        if self.diverged_updates >= MAX_DIVERGED_UPDATES {
            return Err(LearnerError::NonFinite(format!(
                "{MAX_DIVERGED_UPDATES} updates in a row had only non-finite losses or \
                 gradients (last at iteration {}); the last good policy is in the last \
                 checkpoint",
                self.iteration
            )));
        }
        Ok(())
    }

    /// `R_obs` sampled reconstruction MSE on up to `eval_samples` observations per robot, and the
    /// MSE of predicting their mean.
    fn recon_error(
        &mut self,
        net: &PolicyNet,
        batch: &RolloutBatch,
        index: &[usize],
    ) -> Result<(f32, f32), LearnerError> {
        let want = self.model.config.recovery.eval_samples;
        if want == 0 || net.core.is_none() {
            return Ok((f32::NAN, f32::NAN));
        }
        let (mut se, mut base, mut count) = (0f64, 0f64, 0usize);
        for (r, &i) in batch.robots.iter().zip(index) {
            let Some(r_obs) = &net.robots[i].r_obs else {
                continue;
            };
            let n = want.min(r.samples());
            let mut pick: Vec<usize> = (0..r.samples()).collect();
            pick.shuffle(&mut self.rng);
            pick.truncate(n);
            let d = r.obs_dim;
            let mut obs = Vec::with_capacity(n * d);
            for &j in &pick {
                obs.extend_from_slice(&r.observations[j * d..(j + 1) * d]);
            }
            let x = self.tensor2(obs.clone(), n, d).inner();
            let h = net.robots[i].encoder.forward(x);
            let rec = tensor_to_vec(r_obs.sample(h, &mut self.rng))?;
            let mut mean = vec![0f64; d];
            for row in obs.chunks_exact(d) {
                for (m, v) in mean.iter_mut().zip(row) {
                    *m += *v as f64 / n as f64;
                }
            }
            for (k, (a, b)) in obs.iter().zip(&rec).enumerate() {
                se += ((a - b) as f64).powi(2);
                base += (*a as f64 - mean[k % d]).powi(2);
            }
            count += n * d;
        }
        if count == 0 {
            return Ok((f32::NAN, f32::NAN));
        }
        Ok(((se / count as f64) as f32, (base / count as f64) as f32))
    }
}

/// One minibatch's loss terms (for several robots: weighted by their share of the minibatch).
#[derive(Debug, Default, Clone, PartialEq)]
struct LossParts {
    kl: f32,
    clip_fraction: f32,
    surrogate: f32,
    value: f32,
    entropy: f32,
    rec_obs: f32,
    rec_act: f32,
    symmetry: f32,
    smoothness: f32,
    total: f32,
}

impl LossParts {
    fn add_weighted(&mut self, o: &LossParts, w: f32) {
        self.kl += w * o.kl;
        self.clip_fraction += w * o.clip_fraction;
        self.surrogate += w * o.surrogate;
        self.value += w * o.value;
        self.entropy += w * o.entropy;
        self.rec_obs += w * o.rec_obs;
        self.rec_act += w * o.rec_act;
        self.symmetry += w * o.symmetry;
        self.smoothness += w * o.smoothness;
        self.total += w * o.total;
    }
}

/// The metrics of an update's steps: sums of the steps taken, and the count of skipped ones.
#[derive(Debug, Default)]
struct UpdateAccumulator {
    sums: LossParts,
    grad_norm: f32,
    steps: usize,
    /// Minibatch steps skipped for a non-finite loss or gradient.
    skipped: usize,
}

impl UpdateAccumulator {
    fn add(&mut self, parts: &LossParts, grad_norm: f32) {
        self.sums.add_weighted(parts, 1.0);
        self.grad_norm += grad_norm;
        self.steps += 1;
    }

    /// Mean loss terms over the steps taken (zeros when none was).
    fn mean(&self) -> LossParts {
        let mut mean = LossParts::default();
        mean.add_weighted(&self.sums, 1.0 / self.steps.max(1) as f32);
        mean
    }
}

/// One robot's minibatch targets as tensors: the behaviour policy's actions and distribution, and
/// the advantages, returns and values of [`Ppo::prepare`].
struct MinibatchTargets {
    actions: Tensor<2>,
    old_log_probs: Tensor<1>,
    old_means: Tensor<2>,
    old_stds: Tensor<2>,
    advantages: Tensor<1>,
    returns: Tensor<1>,
    old_values: Tensor<1>,
}

/// Rows of a minibatch that have their neighbours in time within it, for the smoothness loss:
/// `current[k]`, `next[k]` (and for order 2 `prev[k]`) are rows of the same episode at `t`, `t + 1`
/// (`t − 1`).
struct NeighbourRows {
    current: Vec<i64>,
    next: Vec<i64>,
    /// Order 2 only.
    prev: Option<Vec<i64>>,
}

/// [`NeighbourRows`] as index tensors.
struct NeighbourTensors {
    current: Tensor<1, Int>,
    next: Tensor<1, Int>,
    prev: Option<Tensor<1, Int>>,
}

impl NeighbourRows {
    /// `idx` is a minibatch of whole env segments in time order (step-major rollout: sample
    /// `t · envs + e`). A row has a next neighbour unless its episode ended there (terminated or
    /// truncated) or it is the segment's last step; for order 2 also a previous one unless its
    /// episode began there or it is the segment's first step.
    fn new(r: &crate::storage::RobotRollout, idx: &[usize], order: u8) -> Self {
        let done = |j: usize| r.terminated[j] || r.truncated[j];
        let (mut current, mut next) = (Vec::new(), Vec::new());
        let mut prev = (order == 2).then(Vec::new);
        for (row, pair) in idx.windows(2).enumerate() {
            let (j, j_next) = (pair[0], pair[1]);
            // Consecutive rows of one env's segment are `envs` samples apart.
            if j_next != j + r.envs || done(j) {
                continue;
            }
            if let Some(p) = prev.as_mut() {
                if row == 0 || idx[row - 1] + r.envs != j || done(idx[row - 1]) {
                    continue;
                }
                p.push(row as i64 - 1);
            }
            current.push(row as i64);
            next.push(row as i64 + 1);
        }
        NeighbourRows {
            current,
            next,
            prev,
        }
    }

    fn tensors(self, device: &Device) -> NeighbourTensors {
        let index = |v: Vec<i64>| {
            let n = v.len();
            Tensor::<1, Int>::from_data(TensorData::new(v, [n]), device)
        };
        NeighbourTensors {
            current: index(self.current),
            next: index(self.next),
            prev: self.prev.map(index),
        }
    }
}

/// A cheap stand-in while the real net is moved into the optimiser (an empty net: no core, no robots).
fn placeholder_net() -> PolicyNet {
    PolicyNet {
        core: None,
        robots: Vec::new(),
    }
}
