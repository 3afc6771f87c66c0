//! Model configuration: [`PolicyConfig`] (architecture, latent sizes, hidden sizes, initial std) with
//! its [`RecoveryConfig`] (diffusion steps, noise schedule, λ). TOML with serde, strict
//! (`deny_unknown_fields`), every field defaulted.

use serde::{Deserialize, Serialize};

use crate::PolicyError;

/// Which actor architecture a model uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Arch {
    /// End-to-end MLP actor per robot (`obs → mlp_hidden → action`), the baseline.
    Mlp,
    /// L3P: per-robot encoder `E_r`, shared core `π_core`, per-robot decoder `D_r`, recovery modules.
    #[default]
    L3p,
}

impl std::fmt::Display for Arch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Arch::Mlp => "mlp",
            Arch::L3p => "l3p",
        })
    }
}

/// Sizes of every network of a model. Defaults follow the paper (`d_h` 64, `d_z` 16) and rsl_rl
/// (`[512, 256, 128]` ELU critic and MLP actor, initial std 1.0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    pub arch: Arch,
    /// Latent observation size `h = E_r(obs)`.
    pub d_h: usize,
    /// Latent action size `z = π_core(h)`.
    pub d_z: usize,
    /// Hidden layers of the per-robot encoder `E_r` (`obs → … → d_h`).
    pub encoder_hidden: Vec<usize>,
    /// Hidden layers of the shared core `π_core` (`d_h → … → d_z`).
    pub core_hidden: Vec<usize>,
    /// Hidden layers of the per-robot decoder `D_r` (`d_z → … → action`).
    pub decoder_hidden: Vec<usize>,
    /// Hidden layers of the MLP baseline actor (`obs → … → action`).
    pub mlp_hidden: Vec<usize>,
    /// Hidden layers of the per-robot critic (`obs → … → 1`), both architectures.
    pub critic_hidden: Vec<usize>,
    /// Initial action standard deviation (state independent, learned).
    pub init_std: f32,
    pub recovery: RecoveryConfig,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        Self {
            arch: Arch::L3p,
            d_h: 64,
            d_z: 16,
            encoder_hidden: vec![512],
            core_hidden: vec![256, 128],
            decoder_hidden: vec![128],
            mlp_hidden: vec![512, 256, 128],
            critic_hidden: vec![512, 256, 128],
            init_std: 1.0,
            recovery: RecoveryConfig::default(),
        }
    }
}

/// Recovery modules `R_obs` (conditional DDPM) and `R_act` (action → latent action), and the weight
/// λ of their losses in `L = L_ppo + λ (L_rec_obs + L_rec_act)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecoveryConfig {
    /// λ. The paper does not give a value; 0.1 keeps the reconstruction terms below the PPO loss.
    pub lambda: f32,
    /// Number of diffusion steps `T` of `R_obs`.
    pub diffusion_steps: usize,
    /// Linear β schedule start and end (DDPM, Ho et al. 2020, scaled for small `T`).
    pub beta_start: f32,
    pub beta_end: f32,
    /// Size of the sinusoidal diffusion-step embedding.
    pub time_embed_dim: usize,
    /// Hidden layers of the noise-prediction network (`[x_t, emb(t), h] → … → ε`).
    pub obs_hidden: Vec<usize>,
    /// Hidden layers of `R_act` (`action → … → d_z`).
    pub act_hidden: Vec<usize>,
    /// Observations sampled for the reconstruction metric after each update (0 disables it).
    pub eval_samples: usize,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            lambda: 0.1,
            diffusion_steps: 50,
            beta_start: 1e-4,
            beta_end: 0.2,
            time_embed_dim: 32,
            obs_hidden: vec![256, 256],
            act_hidden: vec![64],
            eval_samples: 256,
        }
    }
}

impl PolicyConfig {
    /// Reject sizes that cannot build a network.
    pub fn validate(&self) -> Result<(), PolicyError> {
        let bad = |what: &str| Err(PolicyError::Config(what.to_string()));
        if self.d_h == 0 || self.d_z == 0 {
            return bad("d_h and d_z must be positive");
        }
        let all = [
            &self.encoder_hidden,
            &self.core_hidden,
            &self.decoder_hidden,
            &self.mlp_hidden,
            &self.critic_hidden,
            &self.recovery.obs_hidden,
            &self.recovery.act_hidden,
        ];
        if all.iter().any(|h| h.contains(&0)) {
            return bad("hidden layer sizes must be positive");
        }
        if !(self.init_std.is_finite() && self.init_std > 0.0) {
            return bad("init_std must be a positive finite number");
        }
        let r = &self.recovery;
        if r.diffusion_steps == 0 || r.time_embed_dim == 0 || !r.time_embed_dim.is_multiple_of(2) {
            return bad("diffusion_steps must be positive and time_embed_dim positive and even");
        }
        if !(r.beta_start > 0.0 && r.beta_end >= r.beta_start && r.beta_end < 1.0) {
            return bad("need 0 < beta_start <= beta_end < 1");
        }
        if !(r.lambda.is_finite() && r.lambda >= 0.0) {
            return bad("lambda must be finite and >= 0");
        }
        Ok(())
    }

    /// Number of actor parameters (what the deployed policy holds, std included) for one robot when
    /// it is the only robot, from the sizes alone.
    pub fn actor_params(&self, obs_dim: usize, action_dim: usize) -> usize {
        match self.arch {
            Arch::Mlp => mlp_params(obs_dim, &self.mlp_hidden, action_dim) + action_dim,
            Arch::L3p => {
                mlp_params(obs_dim, &self.encoder_hidden, self.d_h)
                    + mlp_params(self.d_h, &self.core_hidden, self.d_z)
                    + mlp_params(self.d_z, &self.decoder_hidden, action_dim)
                    + action_dim
            }
        }
    }

    /// The MLP-baseline hidden sizes with the same actor parameter budget as this config's L3P actor:
    /// `mlp_hidden` scaled by one common factor (found by bisection) so that the counts match to
    /// within the width granularity of one unit.
    pub fn matched_mlp_hidden(&self, obs_dim: usize, action_dim: usize) -> Vec<usize> {
        let l3p = PolicyConfig {
            arch: Arch::L3p,
            ..self.clone()
        };
        let target = l3p.actor_params(obs_dim, action_dim);
        let scaled = |f: f64| -> Vec<usize> {
            self.mlp_hidden
                .iter()
                .map(|&w| ((w as f64 * f).round() as usize).max(1))
                .collect()
        };
        let count = |f: f64| mlp_params(obs_dim, &scaled(f), action_dim) + action_dim;
        let (mut lo, mut hi) = (1e-3_f64, 64.0_f64);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if count(mid) < target {
                lo = mid
            } else {
                hi = mid
            }
        }
        let (a, b) = (scaled(lo), scaled(hi));
        let ca = mlp_params(obs_dim, &a, action_dim) + action_dim;
        let cb = mlp_params(obs_dim, &b, action_dim) + action_dim;
        if target.abs_diff(ca) <= target.abs_diff(cb) {
            a
        } else {
            b
        }
    }
}

/// Parameters of a fully connected net `input → hidden… → output` with biases.
pub fn mlp_params(input: usize, hidden: &[usize], output: usize) -> usize {
    let mut sizes = Vec::with_capacity(hidden.len() + 2);
    sizes.push(input);
    sizes.extend_from_slice(hidden);
    sizes.push(output);
    sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
}

/// One robot a model serves: its name and dimensions, and the scale the deploy side applies to the
/// raw action (`q* = default + action_scale · a`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyRobot {
    pub name: String,
    pub obs_dim: usize,
    pub action_dim: usize,
    #[serde(default = "default_action_scale")]
    pub action_scale: f32,
    /// What a controller needs besides the weights; carried into checkpoints and exports. `None` in
    /// checkpoints written before it existed (the deploy side then rebuilds it from the catalog).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub io: Option<RobotIo>,
}

/// The robot-side contract of a policy (IsaacLab bakes the same into its exported graph; unitree's
/// deploy configs carry it in YAML): observation layout, joint order, default pose, gains, limits.
/// All per-joint vectors are in the policy's joint order (`joint_names`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotIo {
    /// Version of this contract. 1 (files without the field): no action filter. 2: adds
    /// `action_filter_alpha`; a version-1 file reads as α = 1, which is what it meant. 3: adds
    /// `gait_clock_hz` and the `gait_clock` observation segment; older files read as no clock.
    #[serde(default = "io_version_1")]
    pub version: u32,
    /// Policy period (s); 0.02 = 50 Hz.
    pub control_dt: f32,
    pub joint_names: Vec<String>,
    /// Joint positions (rad) that action 0 maps to: `q* = default + action_scale · clip(a)`.
    pub default_joint_pos: Vec<f32>,
    /// PD gains the policy was trained with: `τ = kp (q* − q) − kd q̇`.
    pub kp: Vec<f32>,
    pub kd: Vec<f32>,
    /// Soft joint position limits `[lo, hi]` (rad); joint targets are clipped into them.
    pub soft_joint_limits: Vec<[f32; 2]>,
    /// Continuous torque limit per joint (N·m).
    pub effort_limit: Vec<f32>,
    /// Raw policy outputs are clipped to ±`action_clip` (non-finite outputs are a fault).
    pub action_clip: f32,
    /// Low-pass filter of the applied action each control period:
    /// `a = a_prev + α (clip(raw) − a_prev)`, `a` starting at 0; `a` is both the joint-target
    /// action and the `last_action` observation. 1 = no filter.
    #[serde(default = "no_action_filter")]
    pub action_filter_alpha: f32,
    /// Frequency (Hz) of the trot clock the policy observes (segment `gait_clock`:
    /// `[sin 2πφ, cos 2πφ]`, φ = frac(ticks · gait_clock_hz · control_dt), ticks = policy steps
    /// since the policy took over, 0 at its first step). 0 = no clock.
    #[serde(default)]
    pub gait_clock_hz: f32,
    /// Every observation entry is clipped to ±`obs_clip` after scaling.
    pub obs_clip: f32,
    /// Observation segments in order; their lengths sum to `obs_dim`.
    pub obs_layout: Vec<ObsSegment>,
}

/// One contiguous block of the observation vector: `obs[i] = scale · quantity[i]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObsSegment {
    pub name: String,
    pub len: usize,
    pub scale: f32,
    /// Units, frame and definition.
    pub description: String,
}

/// The `io` contract version this build writes and the newest it reads.
pub const IO_VERSION: u32 = 3;

fn io_version_1() -> u32 {
    1
}

fn no_action_filter() -> f32 {
    1.0
}

impl RobotIo {
    /// Checks the version and lengths against the policy's dimensions; errors name the field.
    pub fn check(&self, obs_dim: usize, action_dim: usize) -> Result<(), String> {
        if self.version == 0 || self.version > IO_VERSION {
            return Err(format!(
                "io.version {} is not supported (this build reads 1 to {IO_VERSION}; \
                 re-export the policy with this version of l3p, or update l3p)",
                self.version
            ));
        }
        if !(self.action_filter_alpha > 0.0 && self.action_filter_alpha <= 1.0) {
            return Err(format!(
                "io.action_filter_alpha {} is not in (0, 1]",
                self.action_filter_alpha
            ));
        }
        if !(self.gait_clock_hz.is_finite() && self.gait_clock_hz >= 0.0) {
            return Err(format!(
                "io.gait_clock_hz {} is not a finite value >= 0",
                self.gait_clock_hz
            ));
        }
        let clock_segment = self.obs_layout.iter().any(|s| s.name == "gait_clock");
        if clock_segment != (self.gait_clock_hz > 0.0) {
            return Err(format!(
                "io.gait_clock_hz is {} but the observation layout {} a gait_clock segment",
                self.gait_clock_hz,
                if clock_segment { "has" } else { "has no" }
            ));
        }
        let per_joint: [(&str, usize); 6] = [
            ("joint_names", self.joint_names.len()),
            ("default_joint_pos", self.default_joint_pos.len()),
            ("kp", self.kp.len()),
            ("kd", self.kd.len()),
            ("soft_joint_limits", self.soft_joint_limits.len()),
            ("effort_limit", self.effort_limit.len()),
        ];
        for (name, len) in per_joint {
            if len != action_dim {
                return Err(format!(
                    "io.{name} has {len} entries, action_dim is {action_dim}"
                ));
            }
        }
        let total: usize = self.obs_layout.iter().map(|s| s.len).sum();
        if total != obs_dim {
            return Err(format!(
                "io.obs_layout sums to {total}, obs_dim is {obs_dim}"
            ));
        }
        let finite = self
            .default_joint_pos
            .iter()
            .chain(&self.kp)
            .chain(&self.kd)
            .chain(&self.effort_limit)
            .chain(self.soft_joint_limits.iter().flatten())
            .chain(self.obs_layout.iter().map(|s| &s.scale))
            .chain([&self.control_dt, &self.action_clip, &self.obs_clip])
            .all(|v| v.is_finite());
        if !finite {
            return Err("io holds a non-finite number".into());
        }
        if self.soft_joint_limits.iter().any(|l| l[0] > l[1]) {
            return Err("io.soft_joint_limits has lo > hi".into());
        }
        if self.control_dt <= 0.0 {
            return Err(format!("io.control_dt {} is not > 0", self.control_dt));
        }
        Ok(())
    }
}

fn default_action_scale() -> f32 {
    0.25
}

impl PolicyRobot {
    pub fn new(name: &str, obs_dim: usize, action_dim: usize) -> Self {
        Self {
            name: name.to_string(),
            obs_dim,
            action_dim,
            action_scale: default_action_scale(),
            io: None,
        }
    }
}
