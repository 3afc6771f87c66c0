//! Morphology maps between two robots' tasks, for a warm start that carries a policy from one
//! robot to another (`[ppo] transfer_heads = "mapped"`).
//!
//! Main types: [`LegMap`] (per leg, the 3 × 3 map from the source's joint deltas to the target's)
//! and [`TransferMap`] (the observation and action maps of the whole task).
//!
//! Legs correspond by canonical order (front-left, front-right, hind-left, hind-right) and joints
//! by role within a leg, but not one to one: a joint delta of the source is carried to the target
//! as the **same foot displacement** in the base frame at the default pose, `Δq_t = J_t⁻¹ J_s Δq_s`
//! (`J` the foot position's Jacobian by finite differences on the model). Axis conventions, knee
//! directions (ANYmal's hind knees point forwards, A1's backwards) and link lengths all follow from
//! the kinematics; nothing is read from joint names. Metric, not scaled by leg length: the command
//! and the trot clock are shared, so a stride at a given speed is the same length on every robot.
//! Actions add the action scales: `a_t = (s_s / s_t) P a_s`.

use crate::config::{GAIT_CLOCK_OBS, HEIGHT_SCAN_OBS, PROPRIO_OBS};
use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::math::{Mat3, Vec3};
use l3p_robot::model::RobotModel;

/// Joints per leg.
const LEG_JOINTS: usize = 3;
/// Finite-difference step (rad).
const EPS: f32 = 1e-3;
/// Below this |det J| (m³) a leg's Jacobian is singular at the default pose.
const MIN_DET: f32 = 1e-7;

/// Per leg, the map from the source's joint deltas to the target's (`Δq_t = P Δq_s`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegMap(pub [Mat3; 4]);

/// The observation and action maps of a task carried from a source robot to a target robot.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferMap {
    /// Observation size `n`.
    pub obs_dim: usize,
    /// Row-major `n × n`: the source-equivalent observation `x_s = M x_t` of a target observation.
    pub observation: Vec<f32>,
    /// Row-major `12 × 12`: the target action `a_t = M a_s` of a source action.
    pub action: Vec<f32>,
    /// Row-major `12 × 12`: the inverse of `action`.
    pub action_inverse: Vec<f32>,
}

/// Foot position Jacobians (base frame, per leg) of `robot` at its default pose.
pub fn foot_jacobians(robot: &RobotSpec, model: &RobotModel) -> Result<[Mat3; 4], String> {
    let mut q = vec![0.0; model.bodies.len()];
    let mut bodies = [0usize; NUM_JOINTS];
    for (k, name) in robot.joint_names.iter().enumerate() {
        let b = model
            .body_of_joint(name)
            .ok_or_else(|| format!("{}: no joint {name:?} in the model", robot.name))?;
        bodies[k] = b;
        q[b] = robot.default_pose[k];
    }
    let mut out = [Mat3::ZERO; 4];
    for (leg, foot) in robot.foot_links.iter().enumerate() {
        let (foot_body, offset) = model
            .body_of_link(foot)
            .ok_or_else(|| format!("{}: no foot link {foot:?} in the model", robot.name))?;
        let mut cols = [Vec3::ZERO; LEG_JOINTS];
        for (j, col) in cols.iter_mut().enumerate() {
            let b = bodies[leg * LEG_JOINTS + j];
            let q0 = q[b];
            let mut at = |v: f32| {
                q[b] = v;
                (model.body_poses(&q)[foot_body] * offset).translation
            };
            let plus = at(q0 + EPS);
            let minus = at(q0 - EPS);
            q[b] = q0;
            *col = (plus - minus) / (2.0 * EPS);
        }
        out[leg] = Mat3::from_cols(cols[0], cols[1], cols[2]);
    }
    Ok(out)
}

impl LegMap {
    /// `P = J_t⁻¹ J_s` per leg; an error names a leg whose target Jacobian is singular.
    pub fn between(
        source: &RobotSpec,
        source_model: &RobotModel,
        target: &RobotSpec,
        target_model: &RobotModel,
    ) -> Result<LegMap, String> {
        let js = foot_jacobians(source, source_model)?;
        let jt = foot_jacobians(target, target_model)?;
        let mut out = [Mat3::ZERO; 4];
        for leg in 0..4 {
            let det = jt[leg].determinant();
            if det.abs() < MIN_DET {
                return Err(format!(
                    "{}: leg {} ({}) is singular at the default pose (det J = {det:.2e})",
                    target.name, leg, target.foot_links[leg]
                ));
            }
            out[leg] = jt[leg].inverse() * js[leg];
        }
        Ok(LegMap(out))
    }

    /// The 12 × 12 block-diagonal matrix (row-major) of `scale · P`, or of `scale · P⁻¹`.
    fn matrix(&self, scale: f32, inverse: bool) -> Vec<f32> {
        let mut m = vec![0.0; NUM_JOINTS * NUM_JOINTS];
        for (leg, p) in self.0.iter().enumerate() {
            let p = if inverse { p.inverse() } else { *p };
            for r in 0..LEG_JOINTS {
                for c in 0..LEG_JOINTS {
                    // glam is column-major: `col(c)[r]` is row r, column c.
                    m[(leg * LEG_JOINTS + r) * NUM_JOINTS + leg * LEG_JOINTS + c] =
                        scale * p.col(c)[r];
                }
            }
        }
        m
    }
}

impl TransferMap {
    /// The maps for the layout of `Task::observe` (proprioception, then the height scan, then the
    /// gait clock): base velocities, gravity, command, scan and clock are robot-independent; joint
    /// positions and velocities map by `P⁻¹`, the last action by the action map's inverse.
    pub fn new(
        source: &RobotSpec,
        target: &RobotSpec,
        height_scan: bool,
        gait_clock: bool,
    ) -> Result<TransferMap, String> {
        let source_model = source.model().map_err(|e| e.to_string())?;
        let target_model = target.model().map_err(|e| e.to_string())?;
        let legs = LegMap::between(source, &source_model, target, &target_model)?;
        let ratio = source.action_scale / target.action_scale;
        let action = legs.matrix(ratio, false);
        let action_inverse = legs.matrix(1.0 / ratio, true);
        let joint_obs = legs.matrix(1.0, true);
        let n = PROPRIO_OBS
            + if height_scan { HEIGHT_SCAN_OBS } else { 0 }
            + if gait_clock { GAIT_CLOCK_OBS } else { 0 };
        let mut observation = vec![0.0; n * n];
        for i in (0..12).chain(PROPRIO_OBS..n) {
            observation[i * n + i] = 1.0;
        }
        for (start, block) in [(12, &joint_obs), (24, &joint_obs), (36, &action_inverse)] {
            for r in 0..NUM_JOINTS {
                for c in 0..NUM_JOINTS {
                    observation[(start + r) * n + start + c] = block[r * NUM_JOINTS + c];
                }
            }
        }
        Ok(TransferMap {
            obs_dim: n,
            observation,
            action,
            action_inverse,
        })
    }
}
