//! The locomotion task as pure maths: what a policy observes, how it is rewarded and judged, on
//! which ground, and the contracts and maps that carry it between robots.
//!
//! Main types: [`config::EnvConfig`] (`[env]`: rewards, randomisation, commands, terrain),
//! [`task::Task`] (observations, rewards, commands, terminations on a [`task::SimState`]
//! snapshot), [`terrain::Terrain`] (height grid, six types, curriculum), [`gait::GaitMeter`] →
//! [`gait::GaitReport`] and [`gait::WalkCriterion`], [`contract::robot_io`] (the policy's
//! [`l3p_infer::RobotIo`] contract), [`mirror::TaskMirror`] and [`morphology::TransferMap`].
//!
//! # Public API
//! - [`config::EnvConfig`]: the `[env]` table (`recipe = "l3p"` adds l3p's gait terms and actuator
//!   randomisation to IsaacLab's per-robot tables); [`config::TerrainConfig`] resolves to a
//!   [`terrain::TerrainSpec`].
//! - [`task::Task`]: `Task::new(spec, RobotTaskParams::of(&robot, &model))`, then per env per
//!   control step `observe`, `apply_action`, `rewards`, `done`; the simulator fills the
//!   [`task::SimState`] (`l3p_sim`), a real robot's wire state becomes the same observation
//!   (`l3p_deploy::observation::ObservationBuilder`, tested equal).
//! - [`gait::GaitMeter`] → [`gait::GaitReport`], [`gait::WalkCriterion`]: gait diagnostics and the
//!   walk criterion of `l3p eval` / `l3p bench walk`.
//! - [`contract::robot_io`]: the policy's robot I/O contract built beside `Task::observe`, whose
//!   observations it describes; [`contract::env_for_policy`] / [`contract::sim_env_for_policy`]: the env a
//!   policy's contract asks for.
//! - [`mirror::TaskMirror`]: the left-right observation and action maps of a robot's task, derived
//!   from its geometry (PPO's symmetry loss).
//! - [`morphology::TransferMap`]: the observation and action maps that carry a policy from one
//!   robot to another as equal foot displacements (the `mapped` transfer warm start).
//!
//! Architecture invariant: no simulator, burn, Zenoh or tokio here — the deploy controller
//! computes its observations with this crate and links no physics.

pub mod config;
pub mod contract;
pub mod gait;
pub mod mirror;
pub mod morphology;
pub mod task;
pub mod terrain;
