//! Checks that a decoded message is usable: array lengths match declared dimensions, values are
//! finite, names are valid key segments. Errors say which field and which index.

use crate::keys::{KeyError, validate_segment};
use crate::{RobotCommand, RobotState, RolloutChunk, WIRE_VERSION, WireMessage};

/// Why a decoded message was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidationError {
    #[error("{what}: wire version {got}, expected {expected}")]
    WrongVersion {
        what: &'static str,
        got: u32,
        expected: u32,
    },
    #[error("{what}: {field} must be positive")]
    ZeroDimension {
        what: &'static str,
        field: &'static str,
    },
    #[error("{what}: declared dimensions overflow")]
    Overflow { what: &'static str },
    #[error("{what}: field `{field}` has {got} values but the declared dimensions need {expected}")]
    Length {
        what: &'static str,
        field: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what}: field `{field}` holds {value} at index {index}{position}")]
    NonFinite {
        what: &'static str,
        field: &'static str,
        index: usize,
        value: f32,
        position: String,
    },
    #[error("{what}: field `{field}` holds {value} at index {index}: must be positive")]
    NonPositive {
        what: &'static str,
        field: &'static str,
        index: usize,
        value: f32,
    },
    #[error("{what}: field `{field}` holds {value} at index {index}: beyond ±{limit}")]
    OutOfRange {
        what: &'static str,
        field: &'static str,
        index: usize,
        value: f32,
        limit: f32,
    },
    #[error("{what}: field `{field}`: expected {expected}, got {got}")]
    Mismatch {
        what: &'static str,
        field: &'static str,
        expected: String,
        got: String,
    },
    #[error("{0}")]
    Name(#[from] KeyError),
}

fn check_version<T: WireMessage>(message: &T) -> Result<(), ValidationError> {
    if message.wire_version() != WIRE_VERSION {
        return Err(ValidationError::WrongVersion {
            what: T::NAME,
            got: message.wire_version(),
            expected: WIRE_VERSION,
        });
    }
    Ok(())
}

fn check_len(
    what: &'static str,
    field: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), ValidationError> {
    if got != expected {
        return Err(ValidationError::Length {
            what,
            field,
            expected,
            got,
        });
    }
    Ok(())
}

/// First non-finite value of `values`, reported with its `[step, env, dim]` position when `shape`
/// (`[num_envs, dim]`) is given.
fn check_finite(
    what: &'static str,
    field: &'static str,
    values: &[f32],
    shape: Option<(usize, usize)>,
) -> Result<(), ValidationError> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => {
            let position = match shape {
                Some((envs, dim)) if envs > 0 && dim > 0 => {
                    let (step, rest) = (index / (envs * dim), index % (envs * dim));
                    format!(" (step {step}, env {}, dim {})", rest / dim, rest % dim)
                }
                _ => String::new(),
            };
            Err(ValidationError::NonFinite {
                what,
                field,
                index,
                value: values[index],
                position,
            })
        }
    }
}

/// Largest magnitude a rollout chunk's actions, means, stds, rewards and log-probabilities may hold:
/// far above what a policy or task produces (actions act clipped to ±100 by default, a step's
/// reward is O(1)), far below where a loss overflows `f32` (a chunk of 3e38s made the gradient
/// NaN).
pub const MAX_ROLLOUT_MAGNITUDE: f32 = 1.0e4;

fn check_magnitude(
    what: &'static str,
    field: &'static str,
    values: &[f32],
    limit: f32,
) -> Result<(), ValidationError> {
    match values.iter().position(|v| v.abs() > limit) {
        None => Ok(()),
        Some(index) => Err(ValidationError::OutOfRange {
            what,
            field,
            index,
            value: values[index],
            limit,
        }),
    }
}

impl RolloutChunk {
    /// [`RolloutChunk::validate_dims`] plus a run's contract: `steps` steps per env (what the run's
    /// actors send), observations within ±`obs_clip` (the task clips them there) and every other
    /// value within ±[`MAX_ROLLOUT_MAGNITUDE`]. A chunk that passes cannot end a PPO update.
    pub fn validate_contract(
        &self,
        obs_dim: usize,
        action_dim: usize,
        steps: usize,
        obs_clip: f32,
    ) -> Result<(), ValidationError> {
        const W: &str = "rollout chunk";
        self.validate_dims(obs_dim, action_dim)?;
        if self.steps as usize != steps {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "steps",
                expected: steps.to_string(),
                got: self.steps.to_string(),
            });
        }
        check_magnitude(W, "observations", &self.observations, obs_clip)?;
        check_magnitude(W, "last_observations", &self.last_observations, obs_clip)?;
        for (field, values) in [
            ("actions", &self.actions),
            ("log_probs", &self.log_probs),
            ("action_means", &self.action_means),
            ("action_stds", &self.action_stds),
            ("rewards", &self.rewards),
        ] {
            check_magnitude(W, field, values, MAX_ROLLOUT_MAGNITUDE)?;
        }
        Ok(())
    }

    /// Check the chunk's version, names, declared dimensions against its arrays, and that every value
    /// is finite (and every std positive).
    pub fn validate(&self) -> Result<(), ValidationError> {
        const W: &str = "rollout chunk";
        check_version(self)?;
        validate_segment("run", &self.run)?;
        validate_segment("robot", &self.robot)?;
        validate_segment("actor", &self.actor_id)?;
        for (field, value) in [
            ("num_envs", self.num_envs),
            ("steps", self.steps),
            ("obs_dim", self.obs_dim),
            ("action_dim", self.action_dim),
        ] {
            if value == 0 {
                return Err(ValidationError::ZeroDimension { what: W, field });
            }
        }
        let (envs, steps) = (self.num_envs as usize, self.steps as usize);
        let (obs, act) = (self.obs_dim as usize, self.action_dim as usize);
        let overflow = || ValidationError::Overflow { what: W };
        let samples = steps.checked_mul(envs).ok_or_else(overflow)?;
        let obs_len = samples.checked_mul(obs).ok_or_else(overflow)?;
        let act_len = samples.checked_mul(act).ok_or_else(overflow)?;
        let last_len = envs.checked_mul(obs).ok_or_else(overflow)?;

        check_len(W, "observations", self.observations.len(), obs_len)?;
        check_len(W, "actions", self.actions.len(), act_len)?;
        check_len(W, "log_probs", self.log_probs.len(), samples)?;
        check_len(W, "action_means", self.action_means.len(), act_len)?;
        check_len(W, "action_stds", self.action_stds.len(), act_len)?;
        check_len(W, "rewards", self.rewards.len(), samples)?;
        check_len(W, "terminated", self.terminated.len(), samples)?;
        check_len(W, "truncated", self.truncated.len(), samples)?;
        check_len(
            W,
            "last_observations",
            self.last_observations.len(),
            last_len,
        )?;

        check_finite(W, "observations", &self.observations, Some((envs, obs)))?;
        check_finite(W, "actions", &self.actions, Some((envs, act)))?;
        check_finite(W, "log_probs", &self.log_probs, Some((envs, 1)))?;
        check_finite(W, "action_means", &self.action_means, Some((envs, act)))?;
        check_finite(W, "action_stds", &self.action_stds, Some((envs, act)))?;
        check_finite(W, "rewards", &self.rewards, Some((envs, 1)))?;
        check_finite(
            W,
            "last_observations",
            &self.last_observations,
            Some((1, obs)),
        )?;
        if let Some(index) = self.action_stds.iter().position(|&s| s <= 0.0) {
            return Err(ValidationError::NonPositive {
                what: W,
                field: "action_stds",
                index,
                value: self.action_stds[index],
            });
        }
        if self.stage_seconds.len() > crate::messages::MAX_STAGES {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "stage_seconds",
                expected: format!("at most {} stages", crate::messages::MAX_STAGES),
                got: self.stage_seconds.len().to_string(),
            });
        }
        if let Some((name, v)) = self
            .stage_seconds
            .iter()
            .find(|(n, v)| !valid_term_name(n) || !v.is_finite() || *v < 0.0)
        {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "stage_seconds",
                expected:
                    "names of 1-64 ASCII letters, digits or '_' with finite, non-negative seconds"
                        .into(),
                got: format!("{name:?} = {v}"),
            });
        }
        if self.reward_terms.len() > crate::messages::MAX_REWARD_TERMS {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "reward_terms",
                expected: format!("at most {} names", crate::messages::MAX_REWARD_TERMS),
                got: self.reward_terms.len().to_string(),
            });
        }
        if let Some(index) = self.reward_terms.iter().position(|n| !valid_term_name(n)) {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "reward_terms",
                expected: "names of 1-64 ASCII letters, digits or '_'".into(),
                got: format!("{:?} at index {index}", self.reward_terms[index]),
            });
        }
        for (index, episode) in self.episodes.iter().enumerate() {
            if !episode.reward_terms.is_empty()
                && episode.reward_terms.len() != self.reward_terms.len()
            {
                return Err(ValidationError::Mismatch {
                    what: W,
                    field: "episodes.reward_terms",
                    expected: format!("{} values (one per reward term)", self.reward_terms.len()),
                    got: format!("{} at episode {index}", episode.reward_terms.len()),
                });
            }
            if let Some(v) = episode.reward_terms.iter().find(|v| !v.is_finite()) {
                return Err(ValidationError::NonFinite {
                    what: W,
                    field: "episodes.reward_terms",
                    index,
                    value: *v,
                    position: String::new(),
                });
            }
            let values = [
                episode.episode_return,
                episode.terrain_level,
                episode.lin_vel_error,
                episode.yaw_rate_error,
            ];
            if let Some(v) = values.iter().find(|v| !v.is_finite()) {
                return Err(ValidationError::NonFinite {
                    what: W,
                    field: "episodes",
                    index,
                    value: *v,
                    position: String::new(),
                });
            }
        }
        for (field, value) in [
            ("collect_seconds", self.collect_seconds),
            ("transport_seconds", self.transport_seconds),
        ] {
            if !value.is_finite() || value < 0.0 {
                return Err(ValidationError::Mismatch {
                    what: W,
                    field,
                    expected: "a finite, non-negative duration".into(),
                    got: value.to_string(),
                });
            }
        }
        Ok(())
    }

    /// [`Self::validate`], plus the dimensions the receiver expects for this robot.
    pub fn validate_dims(&self, obs_dim: usize, action_dim: usize) -> Result<(), ValidationError> {
        self.validate()?;
        let mismatch = |field, expected: usize, got: u32| ValidationError::Mismatch {
            what: "rollout chunk",
            field,
            expected: expected.to_string(),
            got: got.to_string(),
        };
        if self.obs_dim as usize != obs_dim {
            return Err(mismatch("obs_dim", obs_dim, self.obs_dim));
        }
        if self.action_dim as usize != action_dim {
            return Err(mismatch("action_dim", action_dim, self.action_dim));
        }
        Ok(())
    }
}

impl RobotState {
    /// Check version, id, `num_joints` joint entries, finite values and a unit-length quaternion.
    pub fn validate(&self, num_joints: usize) -> Result<(), ValidationError> {
        const W: &str = "robot state";
        check_version(self)?;
        validate_segment("robot id", &self.robot_id)?;
        check_len(W, "joint_pos", self.joint_pos.len(), num_joints)?;
        check_len(W, "joint_vel", self.joint_vel.len(), num_joints)?;
        check_finite(W, "base_quat", &self.base_quat, None)?;
        check_finite(W, "base_lin_vel", &self.base_lin_vel, None)?;
        check_finite(W, "base_ang_vel", &self.base_ang_vel, None)?;
        check_finite(W, "joint_pos", &self.joint_pos, None)?;
        check_finite(W, "joint_vel", &self.joint_vel, None)?;
        check_finite(W, "command", &self.command, None)?;
        let norm = self.base_quat.iter().map(|q| q * q).sum::<f32>().sqrt();
        if (norm - 1.0).abs() > 1e-2 {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "base_quat",
                expected: "unit quaternion".into(),
                got: format!("norm {norm}"),
            });
        }
        Ok(())
    }
}

impl RobotCommand {
    /// Check version, id, `num_joints` entries per array, finite values and non-negative gains.
    pub fn validate(&self, num_joints: usize) -> Result<(), ValidationError> {
        const W: &str = "robot command";
        check_version(self)?;
        validate_segment("robot id", &self.robot_id)?;
        check_len(
            W,
            "joint_pos_target",
            self.joint_pos_target.len(),
            num_joints,
        )?;
        check_len(W, "kp", self.kp.len(), num_joints)?;
        check_len(W, "kd", self.kd.len(), num_joints)?;
        check_finite(W, "joint_pos_target", &self.joint_pos_target, None)?;
        check_finite(W, "kp", &self.kp, None)?;
        check_finite(W, "kd", &self.kd, None)?;
        if let Some(index) = self.kp.iter().chain(&self.kd).position(|&g| g < 0.0) {
            return Err(ValidationError::Mismatch {
                what: W,
                field: "kp/kd",
                expected: "non-negative gains".into(),
                got: format!("negative gain at index {index}"),
            });
        }
        Ok(())
    }
}

/// A reward-term or stage name: 1-64 ASCII letters, digits or `_`.
fn valid_term_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}
