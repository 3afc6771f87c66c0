//! The multi-robot policy: [`PolicyNet`] (the burn module: one optional shared core `π_core` and one
//! [`RobotHeads`] per robot) wrapped by [`PolicyModel`] (the module plus its [`PolicyConfig`] and the
//! [`PolicyRobot`] of each robot, in the same order as `PolicyNet::robots`).
//!
//! Architecture `l3p`: `obs ─E_r→ h ─π_core→ z ─D_r→ mean`; architecture `mlp`: `obs ─MLP_r→ mean`
//! (the `encoder` field then holds the whole actor and `core`/`decoder` are `None`). Both have a
//! learned state-independent std per robot and a per-robot critic.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

use crate::PolicyError;
use crate::config::{Arch, PolicyConfig, PolicyRobot};
use crate::diffusion::{ObsDiffusion, ObsDiffusionConfig};
use crate::nets::{Mlp, MlpConfig};

/// Everything that belongs to one robot ("adapters" plus critic).
#[derive(Module, Debug)]
pub struct RobotHeads {
    /// `l3p`: `E_r` (`obs → d_h`); `mlp`: the whole actor (`obs → action`).
    pub encoder: Mlp,
    /// `l3p`: `D_r` (`d_z → action`).
    pub decoder: Option<Mlp>,
    /// Action standard deviation, one per action dimension (rsl_rl `std_type = "scalar"`).
    pub std: Param<Tensor<1>>,
    /// `V(obs)`.
    pub critic: Mlp,
    /// `l3p`: `R_obs`.
    pub r_obs: Option<ObsDiffusion>,
    /// `l3p`: `R_act` (`action → d_z`).
    pub r_act: Option<Mlp>,
}

/// The burn module of a [`PolicyModel`].
#[derive(Module, Debug)]
pub struct PolicyNet {
    /// Shared `π_core` (`d_h → d_z`), `l3p` only.
    pub core: Option<Mlp>,
    pub robots: Vec<RobotHeads>,
}

/// Actor outputs for one robot's batch.
#[derive(Debug, Clone)]
pub struct ActorOut {
    /// Action mean `[B, action]`.
    pub mean: Tensor<2>,
    /// Action std `[action]` (clamped to ≥ 1e-6 as rsl_rl 5).
    pub std: Tensor<1>,
    /// Latent observation `[B, d_h]` (`l3p` only).
    pub h: Option<Tensor<2>>,
    /// Latent action `[B, d_z]` (`l3p` only).
    pub z: Option<Tensor<2>>,
}

/// Minimum std used in the distribution.
pub const MIN_STD: f32 = 1e-6;

impl RobotHeads {
    /// Fresh heads for one robot.
    pub fn init(config: &PolicyConfig, spec: &PolicyRobot, device: &Device) -> Self {
        let std = Tensor::<1>::from_data(
            TensorData::new(vec![config.init_std; spec.action_dim], [spec.action_dim]),
            device,
        );
        let critic = MlpConfig::new(spec.obs_dim, &config.critic_hidden, 1).init(device);
        match config.arch {
            Arch::Mlp => Self {
                encoder: MlpConfig::new(spec.obs_dim, &config.mlp_hidden, spec.action_dim)
                    .init(device),
                decoder: None,
                std: Param::from_tensor(std),
                critic,
                r_obs: None,
                r_act: None,
            },
            Arch::L3p => Self {
                encoder: MlpConfig::new(spec.obs_dim, &config.encoder_hidden, config.d_h)
                    .init(device),
                decoder: Some(
                    MlpConfig::new(config.d_z, &config.decoder_hidden, spec.action_dim)
                        .init(device),
                ),
                std: Param::from_tensor(std),
                critic,
                r_obs: Some(
                    ObsDiffusionConfig {
                        obs_dim: spec.obs_dim,
                        cond_dim: config.d_h,
                        recovery: config.recovery.clone(),
                    }
                    .init(device),
                ),
                r_act: Some(
                    MlpConfig::new(spec.action_dim, &config.recovery.act_hidden, config.d_z)
                        .init(device),
                ),
            },
        }
    }

    /// # Shapes
    /// `[B, obs]` → `[B, 1]`
    pub fn value(&self, obs: Tensor<2>) -> Tensor<2> {
        self.critic.forward(obs)
    }

    /// # Shapes
    /// → `[action]`
    pub fn std(&self) -> Tensor<1> {
        self.std.val().clamp_min(MIN_STD)
    }
}

impl PolicyNet {
    /// Actor forward for several robots at once: each robot's observations go through its own
    /// encoder; in `l3p` the latents of all robots are concatenated and pass the shared core in one
    /// batch, then are split again for the decoders. `None` entries (robots without samples) give
    /// `None`.
    ///
    /// # Shapes
    /// `obs[r]: [B_r, obs_r]` → `mean[r]: [B_r, action_r]`
    pub fn actors(&self, obs: Vec<Option<Tensor<2>>>) -> Vec<Option<ActorOut>> {
        match &self.core {
            None => obs
                .into_iter()
                .zip(&self.robots)
                .map(|(o, heads)| {
                    o.map(|o| ActorOut {
                        mean: heads.encoder.forward(o),
                        std: heads.std(),
                        h: None,
                        z: None,
                    })
                })
                .collect(),
            Some(core) => {
                let hs: Vec<Option<Tensor<2>>> = obs
                    .into_iter()
                    .zip(&self.robots)
                    .map(|(o, heads)| o.map(|o| heads.encoder.forward(o)))
                    .collect();
                let sizes: Vec<usize> = hs.iter().flatten().map(|h| h.dims()[0]).collect();
                let present: Vec<Tensor<2>> = hs.iter().flatten().cloned().collect();
                if present.is_empty() {
                    return hs.into_iter().map(|_| None).collect();
                }
                let z_all = core.forward(Tensor::cat(present, 0));
                let mut zs = if sizes.len() == 1 {
                    vec![z_all]
                } else {
                    z_all.split_with_sizes(sizes, 0)
                }
                .into_iter();
                hs.into_iter()
                    .zip(&self.robots)
                    .map(|(h, heads)| {
                        let h = h?;
                        let z = zs.next()?;
                        let mean = match &heads.decoder {
                            Some(d) => d.forward(z.clone()),
                            None => z.clone(),
                        };
                        Some(ActorOut {
                            mean,
                            std: heads.std(),
                            h: Some(h),
                            z: Some(z),
                        })
                    })
                    .collect()
            }
        }
    }

    /// Actor forward for one robot.
    ///
    /// # Shapes
    /// `[B, obs_r]` → `mean [B, action_r]`
    pub fn actor(&self, robot: usize, obs: Tensor<2>) -> Option<ActorOut> {
        let mut input: Vec<Option<Tensor<2>>> = (0..self.robots.len()).map(|_| None).collect();
        *input.get_mut(robot)? = Some(obs);
        self.actors(input).into_iter().nth(robot).flatten()
    }
}

/// A [`PolicyNet`] with its configuration and robot list.
#[derive(Debug)]
pub struct PolicyModel {
    pub net: PolicyNet,
    pub config: PolicyConfig,
    pub robots: Vec<PolicyRobot>,
}

impl Clone for PolicyModel {
    fn clone(&self) -> Self {
        Self {
            net: self.net.clone(),
            config: self.config.clone(),
            robots: self.robots.clone(),
        }
    }
}

impl PolicyModel {
    /// A freshly initialised model for `robots` (names must be unique).
    pub fn new(
        config: PolicyConfig,
        robots: Vec<PolicyRobot>,
        device: &Device,
    ) -> Result<Self, PolicyError> {
        config.validate()?;
        for (i, r) in robots.iter().enumerate() {
            if r.obs_dim == 0 || r.action_dim == 0 {
                return Err(PolicyError::Config(format!(
                    "robot {}: obs_dim and action_dim must be positive",
                    r.name
                )));
            }
            if robots[..i].iter().any(|o| o.name == r.name) {
                return Err(PolicyError::Config(format!(
                    "robot {} listed twice",
                    r.name
                )));
            }
        }
        let core = match config.arch {
            Arch::L3p => {
                Some(MlpConfig::new(config.d_h, &config.core_hidden, config.d_z).init(device))
            }
            Arch::Mlp => None,
        };
        let heads = robots
            .iter()
            .map(|r| RobotHeads::init(&config, r, device))
            .collect();
        Ok(Self {
            net: PolicyNet {
                core,
                robots: heads,
            },
            config,
            robots,
        })
    }

    /// Index of a robot by name.
    pub fn robot_index(&self, name: &str) -> Result<usize, PolicyError> {
        self.robots
            .iter()
            .position(|r| r.name == name)
            .ok_or_else(|| PolicyError::UnknownRobot {
                robot: name.to_string(),
                known: self
                    .robots
                    .iter()
                    .map(|r| r.name.clone())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// Add fresh heads for a new robot (transfer to a new morphology). The core is untouched.
    pub fn add_robot(&mut self, spec: PolicyRobot, device: &Device) -> Result<usize, PolicyError> {
        if self.robots.iter().any(|r| r.name == spec.name) {
            return Err(PolicyError::Config(format!(
                "robot {} already in the model",
                spec.name
            )));
        }
        self.net
            .robots
            .push(RobotHeads::init(&self.config, &spec, device));
        self.robots.push(spec);
        Ok(self.robots.len() - 1)
    }

    /// Keep only the named robots (in the given order), e.g. to drop the pretraining robot.
    pub fn retain_robots(self, names: &[&str]) -> Result<Self, PolicyError> {
        let mut slots: Vec<Option<(RobotHeads, PolicyRobot)>> = self
            .net
            .robots
            .into_iter()
            .zip(self.robots)
            .map(Some)
            .collect();
        let mut heads = Vec::new();
        let mut specs = Vec::new();
        for name in names {
            let pos = slots
                .iter()
                .position(|s| s.as_ref().is_some_and(|(_, spec)| spec.name == *name))
                .ok_or_else(|| PolicyError::UnknownRobot {
                    robot: name.to_string(),
                    known: String::new(),
                })?;
            let (h, s) = slots[pos]
                .take()
                .ok_or_else(|| PolicyError::Config("unreachable".into()))?;
            heads.push(h);
            specs.push(s);
        }
        Ok(Self {
            net: PolicyNet {
                core: self.net.core,
                robots: heads,
            },
            config: self.config,
            robots: specs,
        })
    }

    /// Freeze the shared core: its parameters stop requiring gradients, so no optimiser step can
    /// move them (`l3p-transfer`). Gradients still flow *through* it to the encoders.
    pub fn freeze_core(mut self) -> Self {
        self.net.core = self.net.core.map(|c| c.no_grad());
        self
    }

    /// Number of parameters of each part, for printing.
    pub fn param_counts(&self) -> Vec<(String, usize)> {
        let mut out = Vec::new();
        if let Some(core) = &self.net.core {
            out.push(("core".to_string(), core.num_params()));
        }
        for (spec, h) in self.robots.iter().zip(&self.net.robots) {
            let n = &spec.name;
            let label = if h.decoder.is_some() {
                "encoder"
            } else {
                "actor"
            };
            out.push((format!("{n}.{label}"), h.encoder.num_params()));
            if let Some(d) = &h.decoder {
                out.push((format!("{n}.decoder"), d.num_params()));
            }
            out.push((format!("{n}.std"), h.std.num_params()));
            out.push((format!("{n}.critic"), h.critic.num_params()));
            if let Some(r) = &h.r_obs {
                out.push((format!("{n}.r_obs"), r.num_params()));
            }
            if let Some(r) = &h.r_act {
                out.push((format!("{n}.r_act"), r.num_params()));
            }
        }
        out
    }

    /// Human-readable parameter table (one line per part, then the total and each robot's actor).
    pub fn param_report(&self) -> String {
        let mut s = String::new();
        let counts = self.param_counts();
        for (name, n) in &counts {
            s.push_str(&format!("{name:<24} {n:>10}\n"));
        }
        s.push_str(&format!("{:<24} {:>10}\n", "total", self.net.num_params()));
        for spec in &self.robots {
            s.push_str(&format!(
                "{:<24} {:>10}\n",
                format!("{}.deployed-actor", spec.name),
                self.config.actor_params(spec.obs_dim, spec.action_dim)
            ));
        }
        s
    }

    /// Deterministic actions (the mean) for a batch of host observations of one robot, without
    /// autodiff. `obs` is row-major `[n, obs_dim]`.
    pub fn act_mean_host(&self, robot: usize, obs: &[f32]) -> Result<Vec<f32>, PolicyError> {
        let spec = self
            .robots
            .get(robot)
            .ok_or_else(|| PolicyError::UnknownRobot {
                robot: format!("#{robot}"),
                known: String::new(),
            })?;
        if !obs.len().is_multiple_of(spec.obs_dim) {
            return Err(PolicyError::Shape(format!(
                "robot {}: observation buffer of {} floats is not a multiple of obs_dim {}",
                spec.name,
                obs.len(),
                spec.obs_dim
            )));
        }
        let n = obs.len() / spec.obs_dim;
        let net = self.net.valid();
        let device = net.robots[robot].critic.layers[0].weight.val().device();
        let x = Tensor::<2>::from_data(TensorData::new(obs.to_vec(), [n, spec.obs_dim]), &device);
        let out = net
            .actor(robot, x)
            .ok_or_else(|| PolicyError::Shape("actor produced no output".into()))?;
        tensor_to_vec(out.mean)
    }
}

/// Copy a float tensor to a host vector.
pub fn tensor_to_vec<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>, PolicyError> {
    t.into_data()
        .try_into_vec::<f32>()
        .map_err(|e| PolicyError::Shape(format!("tensor read: {e:?}")))
}
