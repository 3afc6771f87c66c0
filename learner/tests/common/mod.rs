//! A point mass reaching a target, for learning tests: obs `[p.x, p.y, target.x, target.y]`,
//! action `a ∈ R²`, `p += STEP · clip(a, −1, 1)`, reward `−‖p − target‖` after the move, episodes of
//! `EPISODE` steps ending by time-out (`truncated`). The optimum moves each axis at full speed
//! toward the target; [`optimal_return`] evaluates it on the same episodes as [`eval_return`].
#![allow(dead_code)]

use l3p_learner::{RobotRollout, RolloutBatch};
use l3p_policy::PolicyModel;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

pub const OBS: usize = 4;
pub const ACT: usize = 2;
pub const STEP: f32 = 0.2;
pub const EPISODE: usize = 10;

pub struct PointMass {
    pub n: usize,
    pub pos: Vec<[f32; 2]>,
    pub target: Vec<[f32; 2]>,
    pub t: Vec<usize>,
    rng: StdRng,
}

impl PointMass {
    pub fn new(n: usize, seed: u64) -> Self {
        let mut env = Self {
            n,
            pos: vec![[0.0; 2]; n],
            target: vec![[0.0; 2]; n],
            t: vec![0; n],
            rng: StdRng::seed_from_u64(seed),
        };
        for i in 0..n {
            env.reset(i);
            // Spread episode phases like rsl_rl's init_at_random_ep_len.
            env.t[i] = i % EPISODE;
        }
        env
    }

    fn reset(&mut self, i: usize) {
        self.pos[i] = [
            self.rng.random_range(-1.0..1.0),
            self.rng.random_range(-1.0..1.0),
        ];
        self.target[i] = [
            self.rng.random_range(-1.0..1.0),
            self.rng.random_range(-1.0..1.0),
        ];
        self.t[i] = 0;
    }

    pub fn obs(&self, out: &mut [f32]) {
        for i in 0..self.n {
            out[i * OBS..(i + 1) * OBS].copy_from_slice(&[
                self.pos[i][0],
                self.pos[i][1],
                self.target[i][0],
                self.target[i][1],
            ]);
        }
    }

    /// Step env `i`; returns `(reward, truncated)` and resets a finished episode.
    pub fn step(&mut self, i: usize, a: &[f32]) -> (f32, bool) {
        for k in 0..2 {
            self.pos[i][k] += STEP * a[k].clamp(-1.0, 1.0);
        }
        let d = ((self.pos[i][0] - self.target[i][0]).powi(2)
            + (self.pos[i][1] - self.target[i][1]).powi(2))
        .sqrt();
        self.t[i] += 1;
        let done = self.t[i] >= EPISODE;
        if done {
            self.reset(i);
        }
        (-d, done)
    }
}

/// Collect `steps` steps of every env with the stochastic policy of `model` (robot 0).
pub fn collect(
    model: &PolicyModel,
    env: &mut PointMass,
    steps: usize,
    rng: &mut StdRng,
) -> RolloutBatch {
    let n = env.n;
    let mut r = RobotRollout::zeros(&model.robots[0].name, steps, n, OBS, ACT);
    let std = l3p_policy::tensor_to_vec(model.net.robots[0].std()).unwrap();
    let log_norm: f32 = std.iter().map(|s| s.ln()).sum::<f32>()
        + 0.5 * ACT as f32 * (2.0 * std::f32::consts::PI).ln();
    let mut obs = vec![0f32; n * OBS];
    for t in 0..steps {
        env.obs(&mut obs);
        let mean = model.act_mean_host(0, &obs).unwrap();
        for i in 0..n {
            let s = t * n + i;
            let mut quad = 0.0;
            let mut a = [0f32; ACT];
            for k in 0..ACT {
                let e: f32 = rng.sample(StandardNormal);
                a[k] = mean[i * ACT + k] + std[k] * e;
                quad += 0.5 * e * e;
                r.action_means[s * ACT + k] = mean[i * ACT + k];
                r.action_stds[s * ACT + k] = std[k];
            }
            r.actions[s * ACT..(s + 1) * ACT].copy_from_slice(&a);
            r.log_probs[s] = -quad - log_norm;
            r.observations[s * OBS..(s + 1) * OBS].copy_from_slice(&obs[i * OBS..(i + 1) * OBS]);
            let (rew, trunc) = env.step(i, &a);
            r.rewards[s] = rew;
            r.truncated[s] = trunc;
        }
    }
    env.obs(&mut r.last_observations);
    RolloutBatch { robots: vec![r] }
}

/// Mean undiscounted episode return of a deterministic controller on `episodes` fixed episodes.
pub fn episodes_return(episodes: usize, mut act: impl FnMut(&[f32]) -> Vec<f32>) -> f32 {
    let mut env = PointMass::new(episodes, 12345);
    for i in 0..episodes {
        env.t[i] = 0;
    }
    let mut obs = vec![0f32; episodes * OBS];
    let mut total = 0.0;
    for _ in 0..EPISODE {
        env.obs(&mut obs);
        let a = act(&obs);
        for i in 0..episodes {
            total += env.step(i, &a[i * ACT..(i + 1) * ACT]).0;
        }
    }
    total / episodes as f32
}

/// Return of the policy mean.
pub fn eval_return(model: &PolicyModel) -> f32 {
    episodes_return(200, |obs| model.act_mean_host(0, obs).unwrap())
}

/// Return of the optimal controller (full speed toward the target on each axis).
pub fn optimal_return() -> f32 {
    episodes_return(200, |obs| {
        obs.chunks_exact(OBS)
            .flat_map(|o| {
                [
                    ((o[2] - o[0]) / STEP).clamp(-1.0, 1.0),
                    ((o[3] - o[1]) / STEP).clamp(-1.0, 1.0),
                ]
            })
            .collect()
    })
}
