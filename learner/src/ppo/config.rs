//! PPO's settings: [`PpoConfig`] (every hyperparameter, rsl_rl defaults, validated) and its
//! enums: the training [`Mode`], [`TransferHeads`], the learning-rate [`Schedule`] and the
//! [`SmoothnessSpace`].

use l3p_policy::Arch;
use serde::{Deserialize, Serialize};

use crate::LearnerError;

/// Training mode (paper baselines).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// MLP from scratch.
    Mlp,
    /// L3P, every module trained.
    #[default]
    L3p,
    /// MLP initialised from an MLP checkpoint, everything trained.
    MlpTransfer,
    /// L3P with the core loaded from a checkpoint and frozen: adapters and critics train.
    L3pTransfer,
}

impl Mode {
    pub fn arch(self) -> Arch {
        match self {
            Mode::Mlp | Mode::MlpTransfer => Arch::Mlp,
            Mode::L3p | Mode::L3pTransfer => Arch::L3p,
        }
    }
}

l3p_names::string_enum!(Mode {
    Mlp => "mlp",
    L3p => "l3p",
    MlpTransfer => "mlp-transfer",
    L3pTransfer => "l3p-transfer",
});

impl std::str::FromStr for Mode {
    type Err = LearnerError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::from_name(s).ok_or_else(|| {
            LearnerError::Config(format!("unknown mode {s}\nhint: one of {}", Self::names()))
        })
    }
}

/// What a robot that the checkpoint does not know starts with under `l3p-transfer` (under
/// `mlp-transfer` it always takes the prototype's network: a fresh one would be training from
/// scratch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum TransferHeads {
    /// Fresh adapters, std and critic around the frozen core: the paper's L3P-Transfer.
    #[default]
    Fresh,
    /// A copy of the checkpoint's first robot's (the prototype's) adapters, std, critic and
    /// recovery modules when the dimensions match — the same warm start `mlp-transfer` gets.
    Prototype,
    /// The prototype's copy with the robots' morphology folded in: joint observations and actions
    /// mapped leg by leg as equal foot displacements (`l3p_task::morphology`,
    /// `l3p_policy::HeadMap`), so the copy moves the new robot's feet as it moved the prototype's.
    /// Also applies to `mlp-transfer`.
    Mapped,
}

/// Learning-rate schedule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Schedule {
    /// rsl_rl `adaptive`: move the lr by `lr_factor` to keep the KL near `desired_kl`.
    #[default]
    Adaptive,
    Fixed,
}

/// What the smoothness loss measures its differences in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SmoothnessSpace {
    /// The policy's raw mean action: the same weight lets a robot with a larger action scale
    /// jitter its joint targets more (ANYmal's 0.5 against A1's 0.25).
    #[default]
    Action,
    /// Joint targets in rad (the mean action times the robot's `action_scale`): the quantity the
    /// walk criterion bounds, so one weight means the same on every robot.
    JointTarget,
}

/// PPO hyperparameters; defaults are rsl_rl's locomotion values (legged_gym / IsaacLab 2.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    pub mode: Mode,
    /// `l3p-transfer` only: how robots new to the checkpoint start.
    pub transfer_heads: TransferHeads,
    pub num_learning_epochs: usize,
    pub num_mini_batches: usize,
    pub clip_param: f32,
    pub gamma: f32,
    pub lam: f32,
    pub value_loss_coef: f32,
    pub use_clipped_value_loss: bool,
    pub entropy_coef: f32,
    pub learning_rate: f64,
    pub schedule: Schedule,
    pub desired_kl: f32,
    pub lr_min: f64,
    pub lr_max: f64,
    pub lr_factor: f64,
    pub max_grad_norm: f32,
    /// Adam ε; PyTorch's default 1e-8 (burn's default is 1e-5).
    pub adam_epsilon: f32,
    /// Seed of minibatch shuffling and diffusion noise.
    pub seed: u64,
    /// Weight of the mirror-symmetry loss `mean((μ(M_o o) − M_a μ(o))²)` (Yu et al. 2018): the
    /// policy's mean on a left-right mirrored observation should be the mirrored mean. 0 = off;
    /// every robot then needs a [`Mirror`] ([`Ppo::set_mirror`]).
    pub symmetry_coef: f32,
    /// Weight of the temporal smoothness loss `mean((μ(o_t) − μ(o_{t+1}))²)` (or the second
    /// difference, `smoothness_order`) over consecutive observations of one episode (CAPS, Mysore
    /// et al. 2021): the policy's mean may not jump between neighbouring states, which penalises
    /// the joint-target chatter differentiably instead of only through an action-rate reward.
    /// 0 = off. When on, minibatches are whole env segments (`envs ≥ num_mini_batches`).
    pub smoothness_coef: f32,
    /// Which difference the smoothness loss penalises: 1 = `μ(o_{t+1}) − μ(o_t)` (every change,
    /// the fast but smooth motion of a quick gait included), 2 = `μ(o_{t+1}) − 2μ(o_t) + μ(o_{t−1})`
    /// (only changes of the change: step-to-step jitter, not a smooth gait at any speed).
    pub smoothness_order: u8,
    /// Units of the smoothness loss's differences: the raw action, or joint targets in rad.
    pub smoothness_space: SmoothnessSpace,
    /// Updates at the start of a run that train only the critic (value loss; the actor, its std
    /// and the recovery modules untouched, the learning rate not adapted): a transferred actor
    /// that already walks is not pushed around by the advantages of a fresh critic. 0 = off.
    pub critic_warmup_iterations: u64,
    /// The deployable policy is the trained one averaged with its left-right mirror image,
    /// `½(π(o) + M_a π(M_o o))` (`l3p export --symmetrized`): exactly symmetric, so a zero yaw
    /// command does not turn it on a symmetric robot. The run's registry deploy artifacts are that
    /// policy ([`Ppo::deploy_export`](crate::Ppo::deploy_export)) and `l3p train --until-walks` checks (and writes to
    /// `walked/`) it; the actors roll out the trained one. The mirror loss (`symmetry_coef`) keeps
    /// the two halves close.
    pub symmetrize_export: bool,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            mode: Mode::L3p,
            transfer_heads: TransferHeads::Fresh,
            num_learning_epochs: 5,
            num_mini_batches: 4,
            clip_param: 0.2,
            gamma: 0.99,
            lam: 0.95,
            value_loss_coef: 1.0,
            use_clipped_value_loss: true,
            entropy_coef: 0.01,
            learning_rate: 1e-3,
            schedule: Schedule::Adaptive,
            desired_kl: 0.01,
            lr_min: 1e-5,
            lr_max: 1e-2,
            lr_factor: 1.5,
            max_grad_norm: 1.0,
            adam_epsilon: 1e-8,
            seed: 1,
            symmetry_coef: 0.0,
            smoothness_coef: 0.0,
            smoothness_order: 1,
            smoothness_space: SmoothnessSpace::Action,
            critic_warmup_iterations: 0,
            symmetrize_export: false,
        }
    }
}

impl PpoConfig {
    /// Range checks of every field; errors name the key and the value (`ppo.<key> = <value>`).
    pub fn validate(&self) -> Result<(), LearnerError> {
        let bad = |m: String| Err(LearnerError::Config(m));
        for (key, v) in [
            ("num_learning_epochs", self.num_learning_epochs),
            ("num_mini_batches", self.num_mini_batches),
        ] {
            if v == 0 {
                return bad(format!("ppo.{key} = 0: expected >= 1"));
            }
        }
        for (key, v) in [
            ("learning_rate", self.learning_rate),
            ("lr_min", self.lr_min),
            ("lr_max", self.lr_max),
            ("clip_param", self.clip_param as f64),
            ("max_grad_norm", self.max_grad_norm as f64),
            ("desired_kl", self.desired_kl as f64),
            ("adam_epsilon", self.adam_epsilon as f64),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("ppo.{key} = {v}: expected a finite number > 0"));
            }
        }
        for (key, v) in [
            ("value_loss_coef", self.value_loss_coef),
            ("entropy_coef", self.entropy_coef),
            ("symmetry_coef", self.symmetry_coef),
            ("smoothness_coef", self.smoothness_coef),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("ppo.{key} = {v}: expected a finite number >= 0"));
            }
        }
        for (key, v) in [("gamma", self.gamma), ("lam", self.lam)] {
            if !(0.0..=1.0).contains(&v) {
                return bad(format!("ppo.{key} = {v}: expected 0 <= {key} <= 1"));
            }
        }
        if !matches!(self.smoothness_order, 1 | 2) {
            return bad(format!(
                "ppo.smoothness_order = {}: expected 1 (first difference) or 2 (second)",
                self.smoothness_order
            ));
        }
        if self.lr_min > self.lr_max {
            return bad(format!(
                "ppo.lr_min = {} is above ppo.lr_max = {}",
                self.lr_min, self.lr_max
            ));
        }
        if !(self.lr_factor.is_finite() && self.lr_factor > 1.0) {
            return bad(format!("ppo.lr_factor = {}: expected > 1", self.lr_factor));
        }
        Ok(())
    }

    /// rsl_rl's adaptive rule: `kl > 2·target → lr / factor` (floored at `lr_min`),
    /// `0 < kl < target / 2 → lr · factor` (capped at `lr_max`).
    pub fn adapt_lr(&self, lr: f64, kl: f32) -> f64 {
        if self.schedule != Schedule::Adaptive || !kl.is_finite() {
            return lr;
        }
        let target = self.desired_kl;
        if kl > 2.0 * target {
            (lr / self.lr_factor).max(self.lr_min)
        } else if kl > 0.0 && kl < target / 2.0 {
            (lr * self.lr_factor).min(self.lr_max)
        } else {
            lr
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_names_are_its_serde_names_and_parse_back() {
        for mode in Mode::ALL {
            let json = serde_json::to_string(&mode).unwrap();
            assert_eq!(json, format!("\"{mode}\""));
            assert_eq!(serde_json::from_str::<Mode>(&json).unwrap(), mode);
            assert_eq!(mode.as_str().parse::<Mode>().unwrap(), mode);
        }
        let err = "ppo".parse::<Mode>().unwrap_err().to_string();
        assert!(
            err.contains("one of mlp, l3p, mlp-transfer or l3p-transfer"),
            "{err}"
        );
    }
}
