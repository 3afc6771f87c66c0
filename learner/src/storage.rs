//! Rollout storage: [`RobotRollout`] holds one robot's `[T, N, …]` rollout as flat row-major f32/bool
//! arrays (the layout of `l3p_proto::RolloutChunk`), [`RolloutBatch`] the rollouts of every robot for
//! one update. Buffers are reused: [`RobotRollout::clear`] keeps capacity and
//! [`RobotRollout::append_chunk`] concatenates several actors' chunks of one robot along the env axis.
//! [`RobotRollout::minibatches`] splits a rollout into [`Minibatches`] and
//! [`RobotRollout::minibatch_rows`] copies one minibatch's rows out ([`MinibatchRows`]).

use l3p_proto::RolloutChunk;
use rand::Rng;
use rand::seq::SliceRandom;

use crate::LearnerError;

/// One robot's rollout: `steps` (T) control steps of `envs` (N) environments.
///
/// # Layout
/// `observations [T, N, obs_dim]`, `actions`, `action_means`, `action_stds` `[T, N, action_dim]`;
/// `log_probs`, `rewards`, `terminated`, `truncated` `[T, N]`; `last_observations [N, obs_dim]` (the
/// observation after the last step, for bootstrapping). `log_probs`, means and stds are those of the
/// behaviour policy that produced the actions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RobotRollout {
    pub robot: String,
    pub steps: usize,
    pub envs: usize,
    pub obs_dim: usize,
    pub action_dim: usize,
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub log_probs: Vec<f32>,
    pub action_means: Vec<f32>,
    pub action_stds: Vec<f32>,
    pub rewards: Vec<f32>,
    /// Episode ended by failure: no bootstrapping.
    pub terminated: Vec<bool>,
    /// Episode ended by time-out: bootstrapped (`r += γ V(s_t)`, as rsl_rl).
    pub truncated: Vec<bool>,
    pub last_observations: Vec<f32>,
}

impl RobotRollout {
    /// An all-zero rollout of the given shape.
    pub fn zeros(
        robot: &str,
        steps: usize,
        envs: usize,
        obs_dim: usize,
        action_dim: usize,
    ) -> Self {
        let s = steps * envs;
        Self {
            robot: robot.to_string(),
            steps,
            envs,
            obs_dim,
            action_dim,
            observations: vec![0.0; s * obs_dim],
            actions: vec![0.0; s * action_dim],
            log_probs: vec![0.0; s],
            action_means: vec![0.0; s * action_dim],
            action_stds: vec![1.0; s * action_dim],
            rewards: vec![0.0; s],
            terminated: vec![false; s],
            truncated: vec![false; s],
            last_observations: vec![0.0; envs * obs_dim],
        }
    }

    /// Number of transitions `T × N`.
    pub fn samples(&self) -> usize {
        self.steps * self.envs
    }

    /// Empty the buffers, keeping their capacity.
    pub fn clear(&mut self) {
        self.envs = 0;
        self.steps = 0;
        for v in [
            &mut self.observations,
            &mut self.actions,
            &mut self.log_probs,
            &mut self.action_means,
            &mut self.action_stds,
            &mut self.rewards,
            &mut self.last_observations,
        ] {
            v.clear();
        }
        self.terminated.clear();
        self.truncated.clear();
    }

    /// Copy a wire chunk.
    pub fn from_chunk(chunk: &RolloutChunk) -> Result<Self, LearnerError> {
        let mut r = RobotRollout {
            robot: chunk.robot.clone(),
            ..Default::default()
        };
        r.append_chunk(chunk)?;
        Ok(r)
    }

    /// Append a chunk of the same robot as more environments (`N += chunk.num_envs`); all chunks must
    /// have the same `steps` and dimensions. The `[T, N, …]` layout is rebuilt step by step.
    pub fn append_chunk(&mut self, c: &RolloutChunk) -> Result<(), LearnerError> {
        let (t, n2) = (c.steps as usize, c.num_envs as usize);
        let (od, ad) = (c.obs_dim as usize, c.action_dim as usize);
        let mut incoming = RobotRollout {
            robot: c.robot.clone(),
            steps: t,
            envs: n2,
            obs_dim: od,
            action_dim: ad,
            observations: c.observations.clone(),
            actions: c.actions.clone(),
            log_probs: c.log_probs.clone(),
            action_means: c.action_means.clone(),
            action_stds: c.action_stds.clone(),
            rewards: c.rewards.clone(),
            terminated: c.terminated.clone(),
            truncated: c.truncated.clone(),
            last_observations: c.last_observations.clone(),
        };
        incoming.validate()?;
        if self.envs == 0 {
            let robot = std::mem::take(&mut self.robot);
            *self = incoming;
            if !robot.is_empty() {
                self.robot = robot;
            }
            return Ok(());
        }
        if c.robot != self.robot || t != self.steps || od != self.obs_dim || ad != self.action_dim {
            return Err(LearnerError::Batch(format!(
                "chunk of robot {} ({t} steps, obs {od}, action {ad}) does not match rollout of {} ({} steps, obs {}, action {})",
                c.robot, self.robot, self.steps, self.obs_dim, self.action_dim
            )));
        }
        let n1 = self.envs;
        fn merge<T: Copy>(a: &mut Vec<T>, b: &[T], t: usize, w1: usize, w2: usize) {
            let old = std::mem::take(a);
            a.reserve(old.len() + b.len());
            for s in 0..t {
                a.extend_from_slice(&old[s * w1..(s + 1) * w1]);
                a.extend_from_slice(&b[s * w2..(s + 1) * w2]);
            }
        }
        merge(
            &mut self.observations,
            &incoming.observations,
            t,
            n1 * od,
            n2 * od,
        );
        merge(&mut self.actions, &incoming.actions, t, n1 * ad, n2 * ad);
        merge(
            &mut self.action_means,
            &incoming.action_means,
            t,
            n1 * ad,
            n2 * ad,
        );
        merge(
            &mut self.action_stds,
            &incoming.action_stds,
            t,
            n1 * ad,
            n2 * ad,
        );
        merge(&mut self.log_probs, &incoming.log_probs, t, n1, n2);
        merge(&mut self.rewards, &incoming.rewards, t, n1, n2);
        merge(&mut self.terminated, &incoming.terminated, t, n1, n2);
        merge(&mut self.truncated, &incoming.truncated, t, n1, n2);
        self.last_observations
            .append(&mut incoming.last_observations);
        self.envs = n1 + n2;
        Ok(())
    }

    /// Check lengths against the shape and that every float is finite.
    pub fn validate(&self) -> Result<(), LearnerError> {
        let s = self.samples();
        let err = |m: String| Err(LearnerError::Batch(format!("robot {}: {m}", self.robot)));
        if s == 0 {
            return err("empty rollout".into());
        }
        let checks: [(&str, usize, usize); 9] = [
            ("observations", self.observations.len(), s * self.obs_dim),
            ("actions", self.actions.len(), s * self.action_dim),
            ("action_means", self.action_means.len(), s * self.action_dim),
            ("action_stds", self.action_stds.len(), s * self.action_dim),
            ("log_probs", self.log_probs.len(), s),
            ("rewards", self.rewards.len(), s),
            ("terminated", self.terminated.len(), s),
            ("truncated", self.truncated.len(), s),
            (
                "last_observations",
                self.last_observations.len(),
                self.envs * self.obs_dim,
            ),
        ];
        for (name, got, want) in checks {
            if got != want {
                return err(format!(
                    "{name} has {got} values, expected {want} for [T={}, N={}]",
                    self.steps, self.envs
                ));
            }
        }
        let floats: [(&str, &[f32]); 7] = [
            ("observations", &self.observations),
            ("actions", &self.actions),
            ("action_means", &self.action_means),
            ("action_stds", &self.action_stds),
            ("log_probs", &self.log_probs),
            ("rewards", &self.rewards),
            ("last_observations", &self.last_observations),
        ];
        for (name, v) in floats {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return err(format!("{name}[{i}] is not finite"));
            }
        }
        if let Some(i) = self.action_stds.iter().position(|x| *x <= 0.0) {
            return err(format!("action_stds[{i}] is not positive"));
        }
        Ok(())
    }
}

/// How [`RobotRollout::minibatches`] draws its minibatches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MinibatchSplit {
    /// Samples shuffled one by one (rsl_rl's feed-forward PPO).
    Samples,
    /// Whole env segments (every step of a shuffled set of envs, in time order; rsl_rl's recurrent
    /// split), so that a sample's neighbours in time share its minibatch.
    EnvSegments,
}

/// A rollout's samples (step-major indices `t · N + e`) in `count` equal minibatches. One split
/// serves every epoch of an update, as in rsl_rl; samples beyond `count · size` are left out.
#[derive(Debug, Clone, PartialEq)]
pub struct Minibatches {
    order: Vec<usize>,
    size: usize,
    count: usize,
}

impl Minibatches {
    /// Number of minibatches.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Samples per minibatch.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The sample indices of minibatch `k` (< `count`).
    pub fn get(&self, k: usize) -> &[usize] {
        &self.order[k * self.size..(k + 1) * self.size]
    }
}

/// Host copies of one minibatch's rows of a [`RobotRollout`], row-major like the rollout.
#[derive(Debug, Clone, PartialEq)]
pub struct MinibatchRows {
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub log_probs: Vec<f32>,
    pub action_means: Vec<f32>,
    pub action_stds: Vec<f32>,
}

impl RobotRollout {
    /// Splits the rollout into `count` minibatches (`count` ≤ samples, and ≤ envs for
    /// [`MinibatchSplit::EnvSegments`]: checked by the caller).
    pub fn minibatches(
        &self,
        count: usize,
        split: MinibatchSplit,
        rng: &mut impl Rng,
    ) -> Minibatches {
        let (order, size) = match split {
            MinibatchSplit::EnvSegments => {
                let mut envs: Vec<usize> = (0..self.envs).collect();
                envs.shuffle(rng);
                let order = envs
                    .iter()
                    .flat_map(|&e| (0..self.steps).map(move |t| t * self.envs + e))
                    .collect();
                (order, (self.envs / count) * self.steps)
            }
            MinibatchSplit::Samples => {
                let mut order: Vec<usize> = (0..self.samples()).collect();
                order.shuffle(rng);
                (order, self.samples() / count)
            }
        };
        Minibatches { order, size, count }
    }

    /// Copies the rows `idx` (sample indices) out of the rollout.
    pub fn minibatch_rows(&self, idx: &[usize]) -> MinibatchRows {
        let rows = |src: &[f32], width: usize| {
            let mut v = Vec::with_capacity(idx.len() * width);
            for &j in idx {
                v.extend_from_slice(&src[j * width..(j + 1) * width]);
            }
            v
        };
        MinibatchRows {
            observations: rows(&self.observations, self.obs_dim),
            actions: rows(&self.actions, self.action_dim),
            log_probs: rows(&self.log_probs, 1),
            action_means: rows(&self.action_means, self.action_dim),
            action_stds: rows(&self.action_stds, self.action_dim),
        }
    }
}

/// The data of one PPO update: one rollout per robot (robots absent from the batch are not updated
/// except through the shared core).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RolloutBatch {
    pub robots: Vec<RobotRollout>,
}

impl RolloutBatch {
    pub fn samples(&self) -> usize {
        self.robots.iter().map(|r| r.samples()).sum()
    }

    /// Group wire chunks by robot (several actors of one robot are concatenated along envs).
    pub fn from_chunks<'a>(
        chunks: impl IntoIterator<Item = &'a RolloutChunk>,
    ) -> Result<Self, LearnerError> {
        let mut batch = RolloutBatch::default();
        for c in chunks {
            match batch.robots.iter_mut().find(|r| r.robot == c.robot) {
                Some(r) => r.append_chunk(c)?,
                None => batch.robots.push(RobotRollout::from_chunk(c)?),
            }
        }
        Ok(batch)
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    use super::*;

    /// A rollout whose every value encodes its sample index `t · N + e`.
    fn numbered(steps: usize, envs: usize) -> RobotRollout {
        let mut r = RobotRollout::zeros("a1", steps, envs, 2, 1);
        for j in 0..r.samples() {
            r.observations[2 * j] = j as f32;
            r.observations[2 * j + 1] = -(j as f32);
            r.actions[j] = j as f32;
            r.log_probs[j] = j as f32;
        }
        r
    }

    #[test]
    fn env_segment_minibatches_hold_whole_envs_in_time_order() {
        let r = numbered(5, 8);
        let mb = r.minibatches(
            4,
            MinibatchSplit::EnvSegments,
            &mut StdRng::seed_from_u64(1),
        );
        assert_eq!((mb.count(), mb.size()), (4, 10));
        let mut seen = Vec::new();
        for k in 0..mb.count() {
            let idx = mb.get(k);
            for segment in idx.chunks(5) {
                let env = segment[0] % 8;
                let expected: Vec<usize> = (0..5).map(|t| t * 8 + env).collect();
                assert_eq!(segment, expected.as_slice());
            }
            seen.extend_from_slice(idx);
        }
        seen.sort_unstable();
        assert_eq!(seen, (0..40).collect::<Vec<_>>());
    }

    #[test]
    fn sample_minibatches_are_a_permutation_and_rows_follow_indices() {
        let r = numbered(3, 4);
        let mb = r.minibatches(3, MinibatchSplit::Samples, &mut StdRng::seed_from_u64(2));
        let mut all: Vec<usize> = (0..3).flat_map(|k| mb.get(k).to_vec()).collect();
        assert_ne!(all, (0..12).collect::<Vec<_>>(), "not shuffled");
        all.sort_unstable();
        assert_eq!(all, (0..12).collect::<Vec<_>>());
        let idx = mb.get(1);
        let rows = r.minibatch_rows(idx);
        for (k, &j) in idx.iter().enumerate() {
            assert_eq!(rows.observations[2 * k..2 * k + 2], [j as f32, -(j as f32)]);
            assert_eq!(rows.actions[k], j as f32);
            assert_eq!(rows.log_probs[k], j as f32);
        }
    }

    #[test]
    fn a_split_that_does_not_divide_leaves_the_remainder_out() {
        let r = numbered(2, 5);
        let mb = r.minibatches(
            2,
            MinibatchSplit::EnvSegments,
            &mut StdRng::seed_from_u64(3),
        );
        assert_eq!(mb.size(), 4);
        let mb = r.minibatches(3, MinibatchSplit::Samples, &mut StdRng::seed_from_u64(3));
        assert_eq!(mb.size(), 3);
    }
}
