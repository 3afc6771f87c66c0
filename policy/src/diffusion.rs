//! `R_obs`, the diffusion recovery module: a conditional DDPM (Ho et al. 2020) that reconstructs a
//! robot's observation from noise given its latent `h`.
//!
//! Main types: [`DdpmSchedule`] (linear β schedule and the derived ᾱ), [`ObsDiffusion`] (the
//! noise-prediction network `ε_θ([x_t, emb(t), h])` with [`ObsDiffusion::loss`], the DDPM training
//! objective, and [`ObsDiffusion::sample`], the ancestral sampler). Random numbers (steps, noise) come
//! from a caller-supplied RNG so training and tests are reproducible. Gradients of the loss reach the
//! encoder through `h`.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand_distr::StandardNormal;

use crate::config::RecoveryConfig;
use crate::nets::{Mlp, MlpConfig};

/// Linear β schedule and its products.
#[derive(Debug, Clone, PartialEq)]
pub struct DdpmSchedule {
    pub betas: Vec<f32>,
    pub alphas: Vec<f32>,
    /// ᾱ_t = Π_{s ≤ t} α_s.
    pub alpha_bars: Vec<f32>,
}

impl DdpmSchedule {
    pub fn linear(steps: usize, beta_start: f32, beta_end: f32) -> Self {
        let betas: Vec<f32> = (0..steps)
            .map(|t| {
                let f = if steps > 1 {
                    t as f32 / (steps - 1) as f32
                } else {
                    0.0
                };
                beta_start + f * (beta_end - beta_start)
            })
            .collect();
        let alphas: Vec<f32> = betas.iter().map(|b| 1.0 - b).collect();
        let mut alpha_bars = Vec::with_capacity(steps);
        let mut acc = 1.0f64;
        for a in &alphas {
            acc *= *a as f64;
            alpha_bars.push(acc as f32);
        }
        Self {
            betas,
            alphas,
            alpha_bars,
        }
    }

    pub fn steps(&self) -> usize {
        self.betas.len()
    }
}

/// Sinusoidal embedding of diffusion step `t` (Vaswani et al.), `dim` values written into `out`.
pub fn step_embedding(t: usize, dim: usize, out: &mut [f32]) {
    let half = dim / 2;
    for i in 0..half {
        let freq = (-(10000f32.ln()) * i as f32 / half as f32).exp();
        let arg = t as f32 * freq;
        out[i] = arg.sin();
        out[half + i] = arg.cos();
    }
}

/// Conditional noise-prediction network of `R_obs`.
#[derive(Module, Debug)]
pub struct ObsDiffusion {
    pub net: Mlp,
    pub obs_dim: usize,
    pub cond_dim: usize,
    pub embed_dim: usize,
    pub steps: usize,
    pub beta_start: f32,
    pub beta_end: f32,
}

/// Builds an [`ObsDiffusion`] for one robot.
#[derive(Debug, Clone)]
pub struct ObsDiffusionConfig {
    pub obs_dim: usize,
    pub cond_dim: usize,
    pub recovery: RecoveryConfig,
}

impl ObsDiffusionConfig {
    pub fn init(&self, device: &Device) -> ObsDiffusion {
        let r = &self.recovery;
        let input = self.obs_dim + r.time_embed_dim + self.cond_dim;
        ObsDiffusion {
            net: MlpConfig::new(input, &r.obs_hidden, self.obs_dim).init(device),
            obs_dim: self.obs_dim,
            cond_dim: self.cond_dim,
            embed_dim: r.time_embed_dim,
            steps: r.diffusion_steps,
            beta_start: r.beta_start,
            beta_end: r.beta_end,
        }
    }
}

impl ObsDiffusion {
    pub fn schedule(&self) -> DdpmSchedule {
        DdpmSchedule::linear(self.steps, self.beta_start, self.beta_end)
    }

    /// Predicted noise.
    ///
    /// # Shapes
    /// `x_t [B, obs]`, `emb [B, embed]`, `h [B, cond]` → `[B, obs]`
    pub fn forward(&self, x_t: Tensor<2>, emb: Tensor<2>, h: Tensor<2>) -> Tensor<2> {
        self.net.forward(Tensor::cat(vec![x_t, emb, h], 1))
    }

    /// DDPM objective: draw `t ~ U{0..T-1}` and `ε ~ N(0, I)` per sample, form
    /// `x_t = √ᾱ_t x_0 + √(1-ᾱ_t) ε`, and return `mean ‖ε − ε_θ(x_t, t, h)‖²` (mean over batch and
    /// dimensions).
    ///
    /// # Shapes
    /// `x0 [B, obs]` (no gradient needed), `h [B, cond]` → scalar `[1]`
    pub fn loss<R: Rng>(&self, x0: Tensor<2>, h: Tensor<2>, rng: &mut R) -> Tensor<1> {
        let device = x0.device();
        let [batch, obs] = x0.dims();
        let sched = self.schedule();
        let mut a = vec![0f32; batch];
        let mut b = vec![0f32; batch];
        let mut emb = vec![0f32; batch * self.embed_dim];
        for i in 0..batch {
            let t = rng.random_range(0..sched.steps());
            a[i] = sched.alpha_bars[t].sqrt();
            b[i] = (1.0 - sched.alpha_bars[t]).sqrt();
            step_embedding(
                t,
                self.embed_dim,
                &mut emb[i * self.embed_dim..(i + 1) * self.embed_dim],
            );
        }
        let noise: Vec<f32> = (0..batch * obs)
            .map(|_| rng.sample(StandardNormal))
            .collect();
        let noise = Tensor::<2>::from_data(TensorData::new(noise, [batch, obs]), &device);
        let a = Tensor::<2>::from_data(TensorData::new(a, [batch, 1]), &device);
        let b = Tensor::<2>::from_data(TensorData::new(b, [batch, 1]), &device);
        let emb = Tensor::<2>::from_data(TensorData::new(emb, [batch, self.embed_dim]), &device);
        let x_t = x0.mul(a).add(noise.clone().mul(b));
        let pred = self.forward(x_t, emb, h);
        pred.sub(noise).square().mean()
    }

    /// Ancestral DDPM sampling: start from `x_T ~ N(0, I)` and apply
    /// `x_{t-1} = (x_t − β_t/√(1-ᾱ_t) ε_θ) / √α_t + σ_t z` with `σ_t² = β̃_t`, the posterior variance.
    /// Call it on an inference copy (`module.valid()`) with a detached `h`.
    ///
    /// # Shapes
    /// `h [B, cond]` → `[B, obs]`
    pub fn sample<R: Rng>(&self, h: Tensor<2>, rng: &mut R) -> Tensor<2> {
        let device = h.device();
        let [batch, _] = h.dims();
        let sched = self.schedule();
        let obs = self.obs_dim;
        let gauss = |rng: &mut R| -> Tensor<2> {
            let v: Vec<f32> = (0..batch * obs)
                .map(|_| rng.sample(StandardNormal))
                .collect();
            Tensor::from_data(TensorData::new(v, [batch, obs]), &device)
        };
        let mut x = gauss(rng);
        let mut emb = vec![0f32; batch * self.embed_dim];
        for t in (0..sched.steps()).rev() {
            for i in 0..batch {
                step_embedding(
                    t,
                    self.embed_dim,
                    &mut emb[i * self.embed_dim..(i + 1) * self.embed_dim],
                );
            }
            let e = Tensor::<2>::from_data(
                TensorData::new(emb.clone(), [batch, self.embed_dim]),
                &device,
            );
            let eps = self.forward(x.clone(), e, h.clone());
            let beta = sched.betas[t];
            let alpha = sched.alphas[t];
            let ab = sched.alpha_bars[t];
            let mean = x
                .sub(eps.mul_scalar(beta / (1.0 - ab).sqrt()))
                .div_scalar(alpha.sqrt());
            x = if t > 0 {
                let ab_prev = sched.alpha_bars[t - 1];
                let var = beta * (1.0 - ab_prev) / (1.0 - ab);
                mean.add(gauss(rng).mul_scalar(var.sqrt()))
            } else {
                mean
            };
        }
        x
    }
}
