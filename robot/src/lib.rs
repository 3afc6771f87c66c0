//! Robot models: what a robot is, read from its URDF.
//!
//! Main types: [`catalog::RobotSpec`] (the seven built-in robots and the ones users add),
//! [`model::RobotModel`] (bodies, joints and colliders after fixed-joint merging), the tolerant
//! URDF loader ([`urdf`]), leg inference ([`legs::InferredLegs`]) and added robots
//! ([`added::RobotDescription`]).
//!
//! # Public API
//! - [`catalog::RobotSpec`]: `RobotSpec::by_name("a1")?`, `RobotSpec::all()`; fields `joint_names`
//!   (canonical order FL, FR, RL, RR × hip abduction, hip flexion, knee), `default_pose`,
//!   `training_gains`, `stand_gains`, `effort_limit`, `saturation_effort`, `velocity_limit`,
//!   `action_scale`, `base_link`, `foot_links`, `penalised_links`, `termination_links`;
//!   `spec.model()` parses the embedded URDF, `spec.nominal_standing_height()`.
//! - [`urdf::load_urdf_file`] / [`urdf::load_urdf_str`] → [`model::RobotModel`] (bodies after
//!   fixed-joint merging; `total_mass()`, `num_actuated()`, `joint_names()`, `standing_height(q)`),
//!   errors [`urdf::UrdfError`] with file, element and line. From a file, collision meshes found
//!   beside it (STL, OBJ) are convex hulls ([`mesh`]); [`urdf::load_urdf_file_with_hulls`] returns
//!   them as [`mesh::MeshHull`]s and [`urdf::load_urdf_str_with_hulls`] builds the same model from
//!   the text (an added robot's description records them).
//! - [`legs::infer_quadruped`] → [`legs::InferredLegs`]: a quadruped's trunk, legs in canonical
//!   order, feet and axis signs from geometry, whatever the names.
//! - [`added::RobotDescription`] (a user's URDF as a robot: the TOML of `l3p robots add`, inferred
//!   and checked standing by `l3p_sim::describe::describe`); [`added::register`] /
//!   [`added::load_dir`] make it a [`catalog::RobotSpec`] that `RobotSpec::by_name` finds. No
//!   simulator is needed for that, so the `l3p-deploy` binary knows added robots too.
//!
//! Architecture invariant: this crate knows nothing of the task, the simulator, burn, Zenoh or
//! tokio (`l3p-task` and `l3p-sim` build on it).

pub mod added;
pub mod catalog;
pub mod legs;
pub mod math;
pub mod mesh;
pub mod model;
pub mod urdf;
