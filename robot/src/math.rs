//! The math types of robot models: rapier's own (`rapier3d::math` re-exports these glamx/glam
//! `f32` types under the same names), named here so that a build without the simulator (no `sim`
//! feature) still loads and describes robots.

pub use glamx::{Mat3, Pose3 as Pose, Rot3, Vec3};
