//! Robots, physics and the locomotion task.
//!
//! Main types: robot descriptions and metadata (`catalog`), the tolerant URDF loader (`urdf`), the
//! rapier simulation (`sim`), the terrain generator and curriculum (`terrain`), the locomotion task —
//! observations, rewards, commands, terminations (`task`) — and the vectorised environment (`vecenv`).
//!
//! # Public API (physics side)
//! - [`catalog::RobotSpec`]: `RobotSpec::by_name("a1")?`, `RobotSpec::all()`; fields `joint_names`
//!   (canonical order FL, FR, RL, RR × hip abduction, hip flexion, knee), `default_pose`,
//!   `training_gains`, `stand_gains`, `effort_limit`, `saturation_effort`, `velocity_limit`,
//!   `action_scale`, `base_link`, `foot_links`, `penalised_links`, `termination_links`;
//!   `spec.model()` parses the embedded URDF, `spec.nominal_standing_height()`.
//! - [`urdf::load_urdf_file`] / [`urdf::load_urdf_str`] → [`model::RobotModel`] (bodies after fixed-joint
//!   merging; `total_mass()`, `num_actuated()`, `joint_names()`, `standing_height(q)`), errors
//!   [`urdf::UrdfError`] with file, element and line. From a file, collision meshes found beside it
//!   (STL, OBJ) are convex hulls ([`mesh`]); [`urdf::load_urdf_file_with_hulls`] returns them as
//!   [`mesh::MeshHull`]s and [`urdf::load_urdf_str_with_hulls`] builds the same model from the text
//!   (an added robot's description records them).
//! - [`sim::SimWorld`]: `new(SimConfig)`, `add_flat_ground`, `add_heightfield_ground`, `add_robot(model,
//!   binding, actuator, pose, q) -> index`, `set_targets`, `step` (one physics step, PD inside),
//!   `clear_contact_maxima`, `read_state(i, &mut task::SimState)`, `reset_robot`, `push_base`,
//!   `set_friction`, `set_base_randomization`, `set_joint_dynamics`. [`actuator::Actuator`] / [`actuator::dc_motor_clip`].
//! - [`vecenv::VecEnv`]: `VecEnv::new(&spec, &EnvConfig, num_envs, threads, seed)?`, `obs_dim()`,
//!   `action_dim()`, `reset_all() -> &[f32]` (`[N * obs_dim]`), `step(&actions)? -> StepOutput { obs,
//!   rewards, terminated, truncated, episodes: &[EpisodeInfo] }`, `timings() -> StageTimings`
//!   (physics, observations, rewards, resets), `nan_resets()`, `curriculum()` (mean level, per type),
//!   `robot_state(e)`. Observations of reset envs are those of the new episode (legged_gym order).
//! - [`gait::GaitMeter`] → [`gait::GaitReport`], [`gait::WalkCriterion`]: gait diagnostics and the
//!   walk criterion of `l3p eval` / `l3p bench walk`.
//! - [`mirror::TaskMirror`]: the left-right observation and action maps of a robot's task, derived
//!   from its geometry (PPO's symmetry loss).
//! - [`morphology::TransferMap`]: the observation and action maps that carry a policy from one
//!   robot to another as equal foot displacements (the `mapped` transfer warm start).
//! - [`added::describe`] → [`added::RobotDescription`] (a user's URDF as a robot: inferred legs,
//!   standing pose, gains; the TOML of `l3p robots add`), [`added::register`] / [`added::load_dir`]
//!   make it a [`catalog::RobotSpec`] that `RobotSpec::by_name` finds.
//! - [`bench::run_sim_bench`], [`bench::stand_check`]: the work behind `l3p bench sim` and
//!   `l3p robots check`.
//!
//! - [`io::robot_io`] and [`io::ObservationBuilder`]: the policy's robot I/O contract
//!   ([`l3p_infer::RobotIo`]) and a wire robot state turned into the observation exactly as
//!   [`task::Task::observe`] makes it (a test compares the two), for exports and the deploy controller.
//!
//! Without the default feature `sim` the crate has no rapier: catalog, models, task, terrain, gait
//! metrics, `io` and added robots (registered from their descriptions) remain; `sim`, `vecenv`,
//! `bench` and `added::describe` need it.
//!
//! Architecture invariant: this crate knows nothing of burn, Zenoh or tokio.

pub mod actuator;
pub mod catalog;
pub mod config;
pub mod gait;
pub mod infer;
pub mod io;
pub mod math;
pub mod mesh;
pub mod mirror;
pub mod model;
pub mod morphology;
pub mod task;
pub mod terrain;
pub mod urdf;

// Added robots; inferring one (`added::describe`) needs the simulator, registering one does not.
pub mod added;
// The simulator and what needs it (feature `sim`, on by default).
#[cfg(feature = "sim")]
pub mod bench;
#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "sim")]
pub mod vecenv;
