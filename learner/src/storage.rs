//! Rollout storage: [`RobotRollout`] holds one robot's `[T, N, …]` rollout as flat row-major f32/bool
//! arrays (the layout of `l3p_proto::RolloutChunk`), [`RolloutBatch`] the rollouts of every robot for
//! one update. Buffers are reused: [`RobotRollout::clear`] keeps capacity and
//! [`RobotRollout::append_chunk`] concatenates several actors' chunks of one robot along the env axis.

use l3p_proto::RolloutChunk;

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
