//! The articulated-robot model the simulator builds from: [`RobotModel`], a tree of rigid
//! [`BodySpec`]s (URDF links merged across fixed joints) connected by actuated [`JointSpec`]s, with
//! [`ShapeSpec`] colliders (primitives, and convex hulls of meshes). Produced by [`crate::urdf`], consumed by the simulator (`l3p_sim::world`).
//!
//! Frames follow URDF: a body's frame is the frame of its first (movable) link, which coincides with
//! its joint frame at zero joint angle. Math is `f32` glam (the types rapier uses).

pub use crate::math::Pose;
use crate::math::{Mat3, Rot3, Vec3};

/// A collision shape, in the body frame given by [`ColliderSpec::pose`].
#[derive(Debug, Clone, PartialEq)]
pub enum ShapeSpec {
    /// Box with half extents.
    Cuboid { half: Vec3 },
    /// Sphere.
    Sphere { radius: f32 },
    /// Capsule along the local z axis; `half_length` is half the cylindrical part.
    Capsule { half_length: f32, radius: f32 },
    /// Cylinder along the local z axis (URDF convention).
    Cylinder { half_length: f32, radius: f32 },
    /// The convex hull of `points` (a mesh's vertices, scaled; see [`crate::mesh`]): at least 4
    /// points not in one plane, at most [`crate::mesh::MAX_HULL_POINTS`].
    ConvexHull { points: Vec<Vec3> },
}

/// A pose as plain arrays: translation and rotation quaternion `[x, y, z, w]` (for callers, such
/// as viewers, that do not link rapier).
pub fn pose_arrays(pose: &Pose) -> ([f32; 3], [f32; 4]) {
    let (t, q) = (pose.translation, pose.rotation);
    ([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
}

/// A collider attached to a body.
#[derive(Debug, Clone)]
pub struct ColliderSpec {
    /// Shape.
    pub shape: ShapeSpec,
    /// Pose of the shape in the body frame.
    pub pose: Pose,
    /// URDF link this collider came from (used for contact sensing: feet, base, thighs).
    pub link: String,
    /// True when this is a stand-in for a mesh that could not be used (a mesh used as a
    /// [`ShapeSpec::ConvexHull`] is not a stand-in).
    pub stand_in: bool,
}

/// Kind of an actuated joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Revolute (limited) or continuous (no limits) hinge.
    Revolute,
    /// Prismatic slider.
    Prismatic,
}

/// The joint connecting a body to its parent body.
#[derive(Debug, Clone)]
pub struct JointSpec {
    /// URDF joint name.
    pub name: String,
    /// Hinge or slider.
    pub kind: JointKind,
    /// Joint frame (= child body frame at q = 0) in the parent body frame.
    pub origin: Pose,
    /// Unit joint axis in the joint frame.
    pub axis: Vec3,
    /// Position limits, `None` for continuous joints.
    pub limits: Option<(f32, f32)>,
    /// Effort limit from the file (N·m or N), `None` when absent or non-positive.
    pub effort: Option<f32>,
    /// Velocity limit from the file, `None` when absent or non-positive.
    pub velocity: Option<f32>,
}

/// One rigid body of the articulation.
#[derive(Debug, Clone)]
pub struct BodySpec {
    /// Name of the first link of the body (the one the joint moves).
    pub name: String,
    /// Parent body index (`None` for the root / floating base).
    pub parent: Option<usize>,
    /// Joint to the parent (`None` for the root).
    pub joint: Option<JointSpec>,
    /// Total mass (kg).
    pub mass: f32,
    /// Centre of mass in the body frame.
    pub com: Vec3,
    /// Inertia tensor about the centre of mass, body-frame axes.
    pub inertia: Mat3,
    /// Collision shapes.
    pub colliders: Vec<ColliderSpec>,
    /// Every URDF link merged into this body with its frame in the body frame.
    pub links: Vec<(String, Pose)>,
}

/// A loaded robot: bodies in topological order (parents before children), body 0 is the root.
#[derive(Debug, Clone)]
pub struct RobotModel {
    /// Robot name from the file.
    pub name: String,
    /// Where it came from (a path or `builtin:<name>`), for messages.
    pub source: String,
    /// Bodies; `bodies[0]` is the floating base.
    pub bodies: Vec<BodySpec>,
    /// Problems that were repaired while loading (mesh stand-ins, zero inertias), for reports.
    pub warnings: Vec<String>,
}

impl RobotModel {
    /// Sum of all body masses (kg).
    pub fn total_mass(&self) -> f32 {
        self.bodies.iter().map(|b| b.mass).sum()
    }

    /// Number of actuated (non-fixed) joints.
    pub fn num_actuated(&self) -> usize {
        self.bodies.iter().filter(|b| b.joint.is_some()).count()
    }

    /// Names of the actuated joints in body order.
    pub fn joint_names(&self) -> Vec<&str> {
        self.bodies
            .iter()
            .filter_map(|b| b.joint.as_ref().map(|j| j.name.as_str()))
            .collect()
    }

    /// Index of the body that moves with joint `name`.
    pub fn body_of_joint(&self, name: &str) -> Option<usize> {
        self.bodies
            .iter()
            .position(|b| b.joint.as_ref().is_some_and(|j| j.name == name))
    }

    /// The body that holds URDF link `name`, and the link frame in that body's frame.
    pub fn body_of_link(&self, name: &str) -> Option<(usize, Pose)> {
        self.bodies.iter().enumerate().find_map(|(i, b)| {
            b.links
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, p)| (i, *p))
        })
    }

    /// All link names.
    pub fn link_names(&self) -> Vec<&str> {
        self.bodies
            .iter()
            .flat_map(|b| b.links.iter().map(|(n, _)| n.as_str()))
            .collect()
    }

    /// Forward kinematics: every body's pose in the root frame for joint positions `q` given per body
    /// (`q[i]` is used for body `i`'s joint; ignored for the root).
    pub fn body_poses(&self, q_per_body: &[f32]) -> Vec<Pose> {
        let mut out = Vec::with_capacity(self.bodies.len());
        for (i, b) in self.bodies.iter().enumerate() {
            let pose = match (b.parent, &b.joint) {
                (Some(p), Some(j)) => {
                    let qi = q_per_body.get(i).copied().unwrap_or(0.0);
                    let motion = match j.kind {
                        JointKind::Revolute => {
                            Pose::from_rotation(Rot3::from_axis_angle(j.axis, qi))
                        }
                        JointKind::Prismatic => Pose::from_translation(j.axis * qi),
                    };
                    out[p] * j.origin * motion
                }
                _ => Pose::IDENTITY,
            };
            out.push(pose);
        }
        out
    }

    /// Base height above flat ground when the robot stands on its lowest collider at the given
    /// joint positions (per actuated joint, in [`Self::joint_names`] order) with a level base: the
    /// negative of the lowest collider point in the base frame. Only spheres, capsules, boxes and
    /// cylinders and convex hulls are considered.
    pub fn standing_height(&self, q: &[f32]) -> f32 {
        let mut q_body = vec![0.0; self.bodies.len()];
        let mut k = 0;
        for (i, b) in self.bodies.iter().enumerate() {
            if b.joint.is_some() {
                q_body[i] = q.get(k).copied().unwrap_or(0.0);
                k += 1;
            }
        }
        let poses = self.body_poses(&q_body);
        let mut lowest = f32::INFINITY;
        for (b, pose) in self.bodies.iter().zip(&poses) {
            for c in &b.colliders {
                let p = *pose * c.pose;
                let z = lowest_z(&c.shape, &p);
                lowest = lowest.min(z);
            }
        }
        if lowest.is_finite() { -lowest } else { 0.0 }
    }
}

/// Lowest world z of a shape at pose `p`.
fn lowest_z(shape: &ShapeSpec, p: &Pose) -> f32 {
    let c = p.translation;
    match *shape {
        ShapeSpec::Sphere { radius } => c.z - radius,
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => {
            let a = p.rotation * Vec3::Z * half_length;
            c.z - a.z.abs() - radius
        }
        ShapeSpec::Cylinder {
            half_length,
            radius,
        } => {
            let a = p.rotation * Vec3::Z;
            let radial = (1.0 - a.z * a.z).max(0.0).sqrt();
            c.z - a.z.abs() * half_length - radial * radius
        }
        ShapeSpec::ConvexHull { ref points } => points
            .iter()
            .map(|q| (*p * *q).z)
            .fold(f32::INFINITY, f32::min),
        ShapeSpec::Cuboid { half } => {
            let m = Mat3::from_quat(p.rotation);
            let ext =
                m.x_axis.z.abs() * half.x + m.y_axis.z.abs() * half.y + m.z_axis.z.abs() * half.z;
            c.z - ext
        }
    }
}

/// Inertia of a point mass `m` at offset `d` about the origin (parallel-axis term).
pub(crate) fn parallel_axis(m: f32, d: Vec3) -> Mat3 {
    let dd = d.dot(d);
    let outer = Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    (Mat3::IDENTITY * dd - outer) * m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_axis_of_offset_point_mass() {
        let i = parallel_axis(2.0, Vec3::new(0.1, 0.0, 0.0));
        assert!((i.y_axis.y - 0.02).abs() < 1e-6, "{i:?}");
        assert!(i.x_axis.x.abs() < 1e-6, "{i:?}");
    }
}
