//! Robots, physics and the locomotion task.
//!
//! Main types: robot descriptions and metadata (`catalog`), the tolerant URDF loader (`urdf`), the
//! rapier simulation (`sim`), the terrain generator and curriculum (`terrain`), the locomotion task —
//! observations, rewards, commands, terminations (`task`) — and the vectorised environment (`vecenv`).
//!
//! Architecture invariant: this crate knows nothing of burn, Zenoh or tokio.

pub mod actuator;
pub mod bench;
pub mod catalog;
pub mod config;
pub mod model;
pub mod sim;
pub mod task;
pub mod terrain;
pub mod urdf;
pub mod vecenv;
