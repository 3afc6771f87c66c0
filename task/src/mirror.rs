//! Left-right mirror symmetry of a robot and its task (for PPO's symmetry loss).
//!
//! Main types: [`SignedPermutation`] (`out[i] = sign[i] · in[index[i]]`) and [`TaskMirror`] (the
//! observation and action maps of one robot under one observation layout).
//!
//! The reflection is `y → −y` in the base frame (the sagittal plane). Vectors keep x and z and
//! negate y; angular velocities (pseudovectors) keep y and negate x and z; the command
//! `(vx, vy, yaw rate)` becomes `(vx, −vy, −yaw rate)`. Joints are derived from the model's
//! geometry, not from names: joint `i`'s mirror is the joint whose frame origin is `i`'s reflected
//! across the plane, and its sign follows from the axes — reflecting a rotation about `a` gives a
//! rotation about `(−a_x, a_y, −a_z)`, so `q_j = q_i` where `a_j` is that axis and `−q_i` where it
//! is its opposite (hip abduction flips, hip flexion and knee keep their sign on every catalog
//! robot). The trot clock's pairs swap (FL + RR ↔ FR + RL), i.e. its phase moves by half a period:
//! `[sin, cos] → [−sin, −cos]`. The height scan's rows (y) reverse.

use crate::config::{GAIT_CLOCK_OBS, HEIGHT_SCAN_OBS, PROPRIO_OBS};
use crate::task::NUM_JOINTS;
use crate::terrain::{SCAN_NX, SCAN_NY};
use l3p_robot::math::Vec3;
use l3p_robot::model::RobotModel;

/// A permutation with signs: `out[i] = sign[i] · in[index[i]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SignedPermutation {
    pub index: Vec<usize>,
    pub sign: Vec<f32>,
}

impl SignedPermutation {
    /// Applies the map to `input` (its length must equal the map's).
    pub fn apply(&self, input: &[f32], out: &mut [f32]) {
        for ((o, &i), s) in out.iter_mut().zip(&self.index).zip(&self.sign) {
            *o = s * input[i];
        }
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Whether applying the map twice is the identity (a reflection must be).
    pub fn is_involution(&self) -> bool {
        self.index
            .iter()
            .zip(&self.sign)
            .enumerate()
            .all(|(i, (&j, s))| self.index.get(j) == Some(&i) && self.sign[j] * s == 1.0)
    }
}

/// Observation and action mirror maps of one robot's task.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskMirror {
    pub observation: SignedPermutation,
    pub action: SignedPermutation,
}

/// How far (m) a joint origin may be from the reflection of its mirror's.
const ORIGIN_TOLERANCE: f32 = 0.005;

/// The mirror of each actuated joint, in `joint_names` order: `(index of the mirror joint, sign)`.
/// Errors name the joint when the model is not left-right symmetric (no joint at the reflected
/// origin, or a mirror joint whose axis is not the reflected axis) or when `default_pose` is not
/// (the relative joint observations would then not mirror).
pub fn joint_mirror(
    model: &RobotModel,
    joint_names: &[&str],
    default_pose: &[f32],
) -> Result<SignedPermutation, String> {
    let poses = model.body_poses(&vec![0.0; model.bodies.len()]);
    let mut frames = Vec::with_capacity(joint_names.len());
    for name in joint_names {
        let b = model
            .body_of_joint(name)
            .ok_or_else(|| format!("no joint {name:?} in the model"))?;
        let joint = model.bodies[b].joint.as_ref().expect("body_of_joint");
        let parent = model.bodies[b].parent.expect("a jointed body has a parent");
        let frame = poses[parent] * joint.origin;
        frames.push((frame.translation, frame.rotation * joint.axis));
    }
    let reflect = |v: Vec3| Vec3::new(v.x, -v.y, v.z);
    let mut index = Vec::with_capacity(frames.len());
    let mut sign = Vec::with_capacity(frames.len());
    for (i, (origin, axis)) in frames.iter().enumerate() {
        let target = reflect(*origin);
        let (j, distance) = frames
            .iter()
            .enumerate()
            .map(|(j, (o, _))| (j, (*o - target).length()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .ok_or("no joints")?;
        if distance > ORIGIN_TOLERANCE {
            return Err(format!(
                "joint {}: no joint at its mirrored origin (nearest {} is {distance:.4} m away); \
                 the robot is not left-right symmetric",
                joint_names[i], joint_names[j]
            ));
        }
        let mirrored_axis = Vec3::new(-axis.x, axis.y, -axis.z);
        let s = frames[j].1.dot(mirrored_axis);
        if s.abs() < 0.99 {
            return Err(format!(
                "joint {}: the axis of its mirror {} is not its reflected axis (dot {s:.3})",
                joint_names[i], joint_names[j]
            ));
        }
        let s = s.signum();
        if (default_pose[j] - s * default_pose[i]).abs() > 1e-4 {
            return Err(format!(
                "default pose is not symmetric: {} = {} but {} = {}",
                joint_names[i], default_pose[i], joint_names[j], default_pose[j]
            ));
        }
        index.push(j);
        sign.push(s);
    }
    Ok(SignedPermutation { index, sign })
}

/// The task's observation map for a robot whose joints mirror as `joints`, with the layout of
/// `Task::observe` (proprioception, then the height scan, then the gait clock).
pub fn observation_mirror(
    joints: &SignedPermutation,
    height_scan: bool,
    gait_clock: bool,
) -> SignedPermutation {
    let mut index = Vec::new();
    let mut sign = Vec::new();
    let mut push = |i: usize, s: f32| {
        index.push(i);
        sign.push(s);
    };
    // base linear velocity, angular velocity, gravity, command.
    for (k, s) in [
        1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, -1.0,
    ]
    .into_iter()
    .enumerate()
    {
        push(k, s);
    }
    // joint positions, velocities, last action.
    for block in [12, 24, 36] {
        for (&j, &s) in joints.index.iter().zip(&joints.sign) {
            push(block + j, s);
        }
    }
    let mut at = PROPRIO_OBS;
    if height_scan {
        for iy in 0..SCAN_NY {
            for ix in 0..SCAN_NX {
                push(at + (SCAN_NY - 1 - iy) * SCAN_NX + ix, 1.0);
            }
        }
        at += HEIGHT_SCAN_OBS;
    }
    if gait_clock {
        for k in 0..GAIT_CLOCK_OBS {
            push(at + k, -1.0);
        }
    }
    SignedPermutation { index, sign }
}

impl TaskMirror {
    /// Both maps for a robot (`joint_names` and `default_pose` in canonical order).
    pub fn new(
        model: &RobotModel,
        joint_names: &[&str],
        default_pose: &[f32],
        height_scan: bool,
        gait_clock: bool,
    ) -> Result<TaskMirror, String> {
        if joint_names.len() != NUM_JOINTS {
            return Err(format!(
                "{} joints; the task's observation has {NUM_JOINTS}",
                joint_names.len()
            ));
        }
        let action = joint_mirror(model, joint_names, default_pose)?;
        let observation = observation_mirror(&action, height_scan, gait_clock);
        Ok(TaskMirror {
            observation,
            action,
        })
    }
}
