//! The rapier simulator for the locomotion task.
//!
//! Main types: [`world::SimWorld`] (a multibody world of several robots on one ground),
//! [`actuator::Actuator`] (PD with torque–speed clipping), [`vecenv::VecEnv`] (N environments over
//! worker threads: physics + `l3p_task::task::Task`), [`bench::StandReport`] and the standing check,
//! and [`describe::describe`] (a user's URDF as an added robot, checked standing).
//!
//! # Public API
//! - [`world::SimWorld`]: `new(SimConfig)`, `add_flat_ground`, `add_heightfield_ground`,
//!   `add_robot(model, binding, actuator, pose, q) -> index`, `set_targets`, `step` (one physics
//!   step, PD inside), `clear_contact_maxima`, `read_state(i, &mut SimState)`, `reset_robot`,
//!   `push_base`, `set_friction`, `set_base_randomization`, `set_joint_dynamics`.
//!   [`actuator::Actuator`] / [`actuator::dc_motor_clip`].
//! - [`vecenv::VecEnv`]: `VecEnv::new(&spec, &EnvConfig, num_envs, threads, seed)?`, `obs_dim()`,
//!   `action_dim()`, `reset_all() -> &[f32]` (`[N * obs_dim]`), `step(&actions)? -> StepOutput {
//!   obs, rewards, terminated, truncated, episodes: &[EpisodeInfo] }`, `timings() -> StageTimings`
//!   (physics, observations, rewards, resets), `nan_resets()`, `curriculum()` (mean level, per
//!   type), `robot_state(e)`. Observations of reset envs are those of the new episode (legged_gym
//!   order).
//! - [`describe::describe`] → `l3p_robot::added::Inference` (inferred legs, standing pose, gains,
//!   checked standing on its feet in simulation; `l3p robots add`).
//! - [`bench::run_sim_bench`], [`bench::stand_check`]: the work behind `l3p bench sim` and
//!   `l3p robots check`.
//!
//! Architecture invariant: this crate knows nothing of burn, Zenoh or tokio.

pub mod actuator;
pub mod bench;
pub mod describe;
pub mod vecenv;
pub mod world;
