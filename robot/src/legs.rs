//! Leg structure of any quadruped URDF, inferred from its geometry: [`infer_quadruped`] turns a
//! loaded [`RobotModel`] into [`InferredLegs`] (trunk, four [`InferredLeg`]s of three
//! [`InferredJoint`]s and a foot, in the catalog's canonical order) or an [`InferError`] naming
//! the offending body or joint. Pure: no simulation.
//!
//! Rules (the first part of "bring your own robot"):
//! - The trunk is the root body (after the loader's fixed-joint merging). A root with a single
//!   moving child is refused: a floating-base quadruped's legs hang off the root.
//! - Every child body of the trunk starts a chain. A **leg** is a serial chain (no branching) of
//!   exactly three revolute or continuous joints ending in a leaf body. Exactly four legs are
//!   required; chains that are not legs are refused when fewer than four legs remain (the error
//!   lists every chain and why it is not a leg) and only reported (`extra_joints`, `warnings`)
//!   when four legs are found beside them (ANYmal D's pan/tilt payload).
//! - Front/rear and left/right come from geometry, never names: each leg's first joint origin in
//!   the trunk frame at the zero pose (x forward, y left). The two legs with the largest x are the
//!   front pair, the larger y of a pair is left; a tie (under 1 mm) is refused.
//! - Within a leg, chain order gives abduction → hip flexion → knee, and the axes must agree:
//!   abduction within 30° of ±x, hip and knee within 30° of ±y (trunk frame, zero pose).
//! - Axis signs: the canonical convention is the one every catalog robot uses — abduction axis +x,
//!   hip and knee axes +y, in the trunk frame at the zero pose. [`InferredJoint::sign`] is +1 when
//!   the file's axis points that way and −1 when it points the opposite way, so that
//!   `q_canonical = sign · q_file`. (It is an axis convention, not "positive = outward".)
//! - The foot is the leaf body's link whose name contains `foot` (case-insensitive; the one
//!   farthest from the body frame if several), else its link farthest from the body frame (ties:
//!   the last one the loader merged) — for a file without foot links (Spot's SDK file) that is the
//!   lower leg itself.
//! - Mass: the loader already refuses negative or non-numeric masses and gives a massless moving
//!   body a placeholder mass with a warning; those warnings (and mesh stand-ins) for the trunk and
//!   leg links are copied into [`InferredLegs::warnings`]. A model built by other means whose trunk
//!   or leg body has a zero, negative or non-finite mass is refused naming the link.

use std::fmt;

use crate::math::{Pose, Vec3};

use crate::model::{JointKind, RobotModel};

/// Cosine of the largest angle between a joint axis and its expected direction (30°).
pub const AXIS_COS_TOLERANCE: f32 = 0.866;
/// Smallest separation (m) between the front and rear hips, or left and right hips of a pair.
pub const MIN_HIP_SEPARATION: f32 = 1e-3;
/// Joints per leg.
pub const JOINTS_PER_LEG: usize = 3;

/// A leg, canonical order `FL, FR, RL, RR`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegId {
    /// Front left.
    FL,
    /// Front right.
    FR,
    /// Rear left.
    RL,
    /// Rear right.
    RR,
}

l3p_names::string_enum!(LegId {
    FL => "FL",
    FR => "FR",
    RL => "RL",
    RR => "RR",
});

/// A joint's role within its leg, canonical order abduction, hip, knee.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointRole {
    /// Hip abduction/adduction (HAA, Unitree `hip`, Spot `hx`): axis along x.
    Abduction,
    /// Hip flexion/extension (HFE, Unitree `thigh`, Spot `hy`): axis along y.
    Hip,
    /// Knee (KFE, Unitree `calf`, Spot `kn`): axis along y.
    Knee,
}

l3p_names::string_enum!(JointRole {
    Abduction => "abduction",
    Hip => "hip",
    Knee => "knee",
});

impl JointRole {
    /// Canonical axis direction in the trunk frame (+x for abduction, +y otherwise).
    pub fn canonical_axis(self) -> Vec3 {
        match self {
            JointRole::Abduction => Vec3::X,
            JointRole::Hip | JointRole::Knee => Vec3::Y,
        }
    }
}

/// One actuated leg joint.
#[derive(Debug, Clone, PartialEq)]
pub struct InferredJoint {
    /// URDF joint name.
    pub name: String,
    /// Role in the leg.
    pub role: JointRole,
    /// Index of the body this joint moves in [`RobotModel::bodies`].
    pub body: usize,
    /// Unit axis in the trunk frame at the zero pose.
    pub axis: Vec3,
    /// +1 when `axis` points along the role's canonical axis, −1 when opposite.
    pub sign: f32,
    /// Joint origin in the trunk frame at the zero pose (m).
    pub position: Vec3,
}

/// One leg: three joints from the trunk to the foot.
#[derive(Debug, Clone, PartialEq)]
pub struct InferredLeg {
    /// Which leg.
    pub id: LegId,
    /// Abduction, hip, knee.
    pub joints: [InferredJoint; JOINTS_PER_LEG],
    /// The foot link (see the module doc for how it is chosen).
    pub foot_link: String,
    /// Index of the body holding the foot link (the chain's leaf).
    pub foot_body: usize,
    /// Foot link origin in the trunk frame at the zero pose (m).
    pub foot_position: Vec3,
}

impl InferredLeg {
    /// Origin of the leg's first joint in the trunk frame at the zero pose (m).
    pub fn hip_position(&self) -> Vec3 {
        self.joints[0].position
    }
}

/// A quadruped's leg structure in the catalog's canonical order.
#[derive(Debug, Clone, PartialEq)]
pub struct InferredLegs {
    /// Robot name from the file.
    pub robot: String,
    /// Where the model came from.
    pub source: String,
    /// Index of the trunk body (always 0: the root).
    pub base_body: usize,
    /// Name of the trunk body (its first link).
    pub base_body_name: String,
    /// The trunk link for contact sensing: the body's first link if it has a collider, else the
    /// first merged link that has one (Unitree's `base` → `trunk`), else the body name.
    pub base_link: String,
    /// FL, FR, RL, RR.
    pub legs: [InferredLeg; 4],
    /// Actuated joints that belong to no leg (chains beside the four legs), in body order.
    pub extra_joints: Vec<String>,
    /// What a reviewer should know: loader repairs on the trunk and legs, chains left out,
    /// unusual geometry.
    pub warnings: Vec<String>,
}

impl InferredLegs {
    /// The twelve leg joint names in canonical order.
    pub fn joint_names(&self) -> Vec<&str> {
        self.joints().map(|j| j.name.as_str()).collect()
    }

    /// The twelve leg joints in canonical order.
    pub fn joints(&self) -> impl Iterator<Item = &InferredJoint> {
        self.legs.iter().flat_map(|l| l.joints.iter())
    }

    /// The four foot links in canonical order.
    pub fn foot_links(&self) -> [&str; 4] {
        [0, 1, 2, 3].map(|i| self.legs[i].foot_link.as_str())
    }

    /// The twelve axis signs in canonical order (`q_canonical = sign · q_file`).
    pub fn axis_signs(&self) -> Vec<f32> {
        self.joints().map(|j| j.sign).collect()
    }

    /// A human-readable table for review: one line per leg with its joints (and signs), foot and
    /// hip position, then extra joints and warnings.
    pub fn summary(&self) -> String {
        let cell = |j: &InferredJoint| format!("{} {}", j.name, sign_str(j));
        let mut widths = [3usize, "abduction".len(), "hip".len(), "knee".len(), 4];
        for leg in &self.legs {
            for (k, j) in leg.joints.iter().enumerate() {
                widths[k + 1] = widths[k + 1].max(cell(j).chars().count());
            }
            widths[4] = widths[4].max(leg.foot_link.chars().count());
        }
        let mut out = format!(
            "robot `{}` ({}): trunk link `{}` (body `{}`)\n",
            self.robot, self.source, self.base_link, self.base_body_name
        );
        let [w0, w1, w2, w3, w4] = widths;
        out += &format!(
            "{:w0$}  {:w1$}  {:w2$}  {:w3$}  {:w4$}  hip position [m]        foot position [m]\n",
            "leg", "abduction", "hip", "knee", "foot"
        );
        for leg in &self.legs {
            let [a, h, k] = &leg.joints;
            out += &format!(
                "{:w0$}  {:w1$}  {:w2$}  {:w3$}  {:w4$}  {}  {}\n",
                leg.id.as_str(),
                cell(a),
                cell(h),
                cell(k),
                leg.foot_link,
                vec_str(leg.hip_position()),
                vec_str(leg.foot_position),
            );
        }
        if !self.extra_joints.is_empty() {
            out += &format!("extra joints (no leg): {}\n", self.extra_joints.join(", "));
        }
        for w in &self.warnings {
            out += &format!("warning: {w}\n");
        }
        out
    }
}

impl fmt::Display for InferredLegs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.summary())
    }
}

fn sign_str(j: &InferredJoint) -> String {
    let axis = if j.role == JointRole::Abduction {
        "x"
    } else {
        "y"
    };
    format!("{}{axis}", if j.sign > 0.0 { '+' } else { '-' })
}

fn vec_str(v: Vec3) -> String {
    format!("({:+.3}, {:+.3}, {:+.3})", v.x, v.y, v.z)
}

/// Why a model is not a quadruped this module can map.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InferError {
    /// The body tree itself is broken (a model not built by the loader).
    #[error("{file}: {message}")]
    Tree {
        /// Where the model came from.
        file: String,
        /// What is wrong, naming the body.
        message: String,
    },
    /// Not exactly four legs hang off the trunk.
    #[error(
        "{file}: expected 4 legs on trunk `{trunk}` (serial chains of exactly {JOINTS_PER_LEG} revolute joints from the trunk to a leaf), found {found}{details}\nhint: only quadrupeds with 3-joint legs (abduction, hip, knee) are supported"
    )]
    LegCount {
        /// Where the model came from.
        file: String,
        /// Trunk body name.
        trunk: String,
        /// Number of legs found.
        found: usize,
        /// The legs found and every chain that is not a leg, with the reason.
        details: String,
    },
    /// A leg joint's axis does not fit its role.
    #[error(
        "{file}: leg {leg}: joint `{joint}` (the {role} joint, number {index} along the chain) has axis ({:.2}, {:.2}, {:.2}) in the trunk frame at the zero pose; expected roughly ±{expected} (within 30°)\nhint: legs must be hip abduction (x) → hip flexion (y) → knee (y); a different leg topology is not supported",
        axis.x, axis.y, axis.z
    )]
    Axis {
        /// Where the model came from.
        file: String,
        /// Which leg (from geometry).
        leg: LegId,
        /// Joint name.
        joint: String,
        /// The role its position in the chain gives it.
        role: JointRole,
        /// 1-based position in the chain.
        index: usize,
        /// Its axis in the trunk frame.
        axis: Vec3,
        /// `x` or `y`.
        expected: &'static str,
    },
    /// Front/rear or left/right cannot be told apart.
    #[error("{file}: {message}")]
    Geometry {
        /// Where the model came from.
        file: String,
        /// Which hips are ambiguous.
        message: String,
    },
    /// A leg or trunk body has an unusable mass.
    #[error(
        "{file}: link `{link}` has mass {mass} kg\nhint: every moving body needs a positive, finite mass"
    )]
    Mass {
        /// Where the model came from.
        file: String,
        /// The body's first link.
        link: String,
        /// Its mass.
        mass: f32,
    },
}

/// A chain hanging off the trunk.
struct Chain {
    /// Bodies from the trunk's child down to the leaf or the branching body.
    bodies: Vec<usize>,
    /// Why it is not a leg, if it is not.
    not_a_leg: Option<String>,
}

/// Infers the trunk, the four legs (FL, FR, RL, RR) with their abduction, hip and knee joints,
/// and the feet of a quadruped model (see the module doc for the rules).
pub fn infer_quadruped(model: &RobotModel) -> Result<InferredLegs, InferError> {
    let file = model.source.clone();
    let children = check_tree(model)?;
    let trunk = 0usize;
    let trunk_name = model.bodies[trunk].name.clone();
    let trunk_mass = model.bodies[trunk].mass;
    if !(trunk_mass.is_finite() && trunk_mass > 0.0) {
        return Err(InferError::Mass {
            file,
            link: trunk_name,
            mass: trunk_mass,
        });
    }

    if let [only] = children[trunk].as_slice() {
        let j = model.bodies[*only].joint.as_ref().map(|j| j.name.as_str());
        return Err(InferError::Tree {
            file,
            message: format!(
                "root body `{trunk_name}` has a single moving child `{}` (joint `{}`): a quadruped's four legs must hang off the root\nhint: the trunk must be the root link; make that joint fixed or remove it",
                model.bodies[*only].name,
                j.unwrap_or("?")
            ),
        });
    }

    // Chains off the trunk.
    let chains: Vec<Chain> = children[trunk]
        .iter()
        .map(|&first| follow_chain(model, &children, first))
        .collect();
    let legs: Vec<&Chain> = chains.iter().filter(|c| c.not_a_leg.is_none()).collect();
    let others: Vec<&Chain> = chains.iter().filter(|c| c.not_a_leg.is_some()).collect();
    let first_joint = |c: &Chain| joint_name(model, c.bodies[0]).to_string();
    if legs.len() != 4 {
        let mut details = String::new();
        if !legs.is_empty() {
            let names: Vec<String> = legs
                .iter()
                .map(|c| format!("`{}`", first_joint(c)))
                .collect();
            details += &format!(" (chains starting at {})", names.join(", "));
        }
        for c in &others {
            details += &format!(
                "; not a leg: the chain starting at joint `{}` {}",
                first_joint(c),
                c.not_a_leg.as_deref().unwrap_or_default()
            );
        }
        return Err(InferError::LegCount {
            file,
            trunk: trunk_name,
            found: legs.len(),
            details,
        });
    }

    let poses = model.body_poses(&vec![0.0; model.bodies.len()]);
    let mut warnings = Vec::new();
    let mut extra_joints = Vec::new();
    for c in &others {
        let joints = subtree_joints(model, &children, c.bodies[0]);
        warnings.push(format!(
            "chain starting at joint `{}` is not a leg ({}); its {} joint(s) are left out of the leg map (`extra_joints`)",
            first_joint(c),
            c.not_a_leg.as_deref().unwrap_or_default(),
            joints.len()
        ));
        extra_joints.extend(joints);
    }
    extra_joints.sort_by_key(|n| model.body_of_joint(n));

    // Front/rear from x, left/right from y of the first joint.
    let hip = |c: &Chain| poses[c.bodies[0]].translation;
    let mut by_x: Vec<&Chain> = legs.clone();
    by_x.sort_by(|a, b| hip(b).x.total_cmp(&hip(a).x));
    let (front, rear) = by_x.split_at(2);
    if hip(front[1]).x - hip(rear[0]).x < MIN_HIP_SEPARATION {
        return Err(InferError::Geometry {
            file,
            message: format!(
                "cannot tell front from rear legs: the hips of the chains starting at `{}` (x = {:.4} m) and `{}` (x = {:.4} m) are level along the trunk's x axis\nhint: the trunk frame's x axis must point forward",
                first_joint(front[1]),
                hip(front[1]).x,
                first_joint(rear[0]),
                hip(rear[0]).x
            ),
        });
    }
    let mut ordered: Vec<(LegId, &Chain)> = Vec::with_capacity(4);
    for (pair, ids) in [
        (front, [LegId::FL, LegId::FR]),
        (rear, [LegId::RL, LegId::RR]),
    ] {
        let (l, r) = if hip(pair[0]).y >= hip(pair[1]).y {
            (pair[0], pair[1])
        } else {
            (pair[1], pair[0])
        };
        if hip(l).y - hip(r).y < MIN_HIP_SEPARATION {
            return Err(InferError::Geometry {
                file,
                message: format!(
                    "cannot tell left from right legs: the hips of the chains starting at `{}` and `{}` are both at y = {:.4} m in the trunk frame",
                    first_joint(l),
                    first_joint(r),
                    hip(l).y
                ),
            });
        }
        if hip(l).y <= 0.0 || hip(r).y >= 0.0 {
            warnings.push(format!(
                "legs {} and {} (joints `{}`, `{}`): the trunk frame's origin is not between their hips (y = {:.3}, {:.3} m)",
                ids[0],
                ids[1],
                first_joint(l),
                first_joint(r),
                hip(l).y,
                hip(r).y
            ));
        }
        ordered.push((ids[0], l));
        ordered.push((ids[1], r));
    }
    let spread = |f: fn(Vec3) -> f32| {
        let v: Vec<f32> = legs.iter().map(|c| f(hip(c))).collect();
        v.iter().copied().fold(f32::MIN, f32::max) - v.iter().copied().fold(f32::MAX, f32::min)
    };
    let (sx, sy) = (spread(|v| v.x), spread(|v| v.y));
    if sy > sx {
        warnings.push(format!(
            "the hips spread more across (y: {sy:.3} m) than along the trunk (x: {sx:.3} m): is the trunk frame's x axis forward?"
        ));
    }

    // Joints, axes, feet, masses.
    let mut out_legs = Vec::with_capacity(4);
    for (id, chain) in ordered {
        let mut joints = Vec::with_capacity(JOINTS_PER_LEG);
        for (index, (&b, role)) in chain.bodies.iter().zip(JointRole::ALL).enumerate() {
            let body = &model.bodies[b];
            if !(body.mass.is_finite() && body.mass > 0.0) {
                return Err(InferError::Mass {
                    file,
                    link: body.name.clone(),
                    mass: body.mass,
                });
            }
            let spec = body.joint.as_ref().ok_or_else(|| InferError::Tree {
                file: file.clone(),
                message: format!("body `{}` has a parent but no joint", body.name),
            })?;
            let axis = (poses[b].rotation * spec.axis).normalize_or_zero();
            let along = axis.dot(role.canonical_axis());
            if along.abs() < AXIS_COS_TOLERANCE {
                return Err(InferError::Axis {
                    file,
                    leg: id,
                    joint: spec.name.clone(),
                    role,
                    index: index + 1,
                    axis,
                    expected: if role == JointRole::Abduction {
                        "x"
                    } else {
                        "y"
                    },
                });
            }
            joints.push(InferredJoint {
                name: spec.name.clone(),
                role,
                body: b,
                axis,
                sign: along.signum(),
                position: poses[b].translation,
            });
        }
        let leaf = *chain.bodies.last().unwrap_or(&chain.bodies[0]);
        let (foot_link, foot_pose) = choose_foot(model, leaf);
        let joints: [InferredJoint; JOINTS_PER_LEG] =
            joints.try_into().map_err(|_| InferError::Tree {
                file: file.clone(),
                message: format!("leg {id}: not {JOINTS_PER_LEG} joints"),
            })?;
        out_legs.push(InferredLeg {
            id,
            joints,
            foot_link,
            foot_body: leaf,
            foot_position: (poses[leaf] * foot_pose).translation,
        });
    }
    let legs: [InferredLeg; 4] = out_legs.try_into().map_err(|_| InferError::Tree {
        file: file.clone(),
        message: "not four legs".into(),
    })?;

    // Loader repairs (placeholder masses, mesh stand-ins) on the trunk and the legs.
    let mut watched: Vec<&str> = model.bodies[trunk]
        .links
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    for leg in &legs {
        for j in &leg.joints {
            watched.extend(model.bodies[j.body].links.iter().map(|(n, _)| n.as_str()));
        }
    }
    for w in &model.warnings {
        if watched.iter().any(|n| w.contains(&format!("`{n}`"))) {
            warnings.push(w.clone());
        }
    }

    Ok(InferredLegs {
        robot: model.name.clone(),
        source: model.source.clone(),
        base_body: trunk,
        base_body_name: trunk_name,
        base_link: choose_base_link(model, trunk),
        legs,
        extra_joints,
        warnings,
    })
}

/// Checks that the bodies form one tree rooted at body 0 with parents before children, and
/// returns each body's children.
fn check_tree(model: &RobotModel) -> Result<Vec<Vec<usize>>, InferError> {
    let err = |message: String| InferError::Tree {
        file: model.source.clone(),
        message,
    };
    let Some(root) = model.bodies.first() else {
        return Err(err("the model has no bodies".into()));
    };
    if root.parent.is_some() {
        return Err(err(format!("root body `{}` has a parent", root.name)));
    }
    let mut children = vec![Vec::new(); model.bodies.len()];
    for (i, b) in model.bodies.iter().enumerate().skip(1) {
        match b.parent {
            None => {
                return Err(err(format!(
                    "body `{}` is not connected to the root body `{}`",
                    b.name, root.name
                )));
            }
            Some(p) if p >= i => {
                return Err(err(format!(
                    "body `{}` comes before its parent (index {p}); bodies must be in topological order",
                    b.name
                )));
            }
            Some(p) => children[p].push(i),
        }
        if b.joint.is_none() {
            return Err(err(format!("body `{}` has a parent but no joint", b.name)));
        }
    }
    Ok(children)
}

/// Follows a chain from `first` (a child of the trunk) to its leaf, classifying it.
fn follow_chain(model: &RobotModel, children: &[Vec<usize>], first: usize) -> Chain {
    let mut bodies = vec![first];
    let mut b = first;
    let mut branch = None;
    loop {
        match children[b].as_slice() {
            [] => break,
            [next] => {
                bodies.push(*next);
                b = *next;
            }
            many => {
                let names: Vec<String> = many
                    .iter()
                    .map(|&c| format!("`{}`", joint_name(model, c)))
                    .collect();
                branch = Some(format!(
                    "branches at body `{}` (joints {})",
                    model.bodies[b].name,
                    names.join(", ")
                ));
                break;
            }
        }
    }
    let names: Vec<&str> = bodies.iter().map(|&b| joint_name(model, b)).collect();
    let prismatic = bodies.iter().find(|&&b| {
        model.bodies[b]
            .joint
            .as_ref()
            .is_some_and(|j| j.kind == JointKind::Prismatic)
    });
    let not_a_leg = if let Some(why) = branch {
        Some(format!(
            "{why} after {} joint(s): {}",
            names.len(),
            names.join(", ")
        ))
    } else if let Some(&p) = prismatic {
        Some(format!(
            "has prismatic joint `{}` (legs need revolute joints): {}",
            joint_name(model, p),
            names.join(", ")
        ))
    } else if names.len() != JOINTS_PER_LEG {
        Some(format!(
            "has {} joint(s) instead of {JOINTS_PER_LEG}: {}",
            names.len(),
            names.join(", ")
        ))
    } else {
        None
    };
    Chain { bodies, not_a_leg }
}

/// Names of every joint in the subtree from `first` down, in body order.
fn subtree_joints(model: &RobotModel, children: &[Vec<usize>], first: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![first];
    while let Some(b) = stack.pop() {
        out.push(b);
        stack.extend(children[b].iter().rev());
    }
    out.sort_unstable();
    out.into_iter()
        .map(|b| joint_name(model, b).to_string())
        .collect()
}

fn joint_name(model: &RobotModel, body: usize) -> &str {
    model.bodies[body]
        .joint
        .as_ref()
        .map_or("?", |j| j.name.as_str())
}

/// The foot link of leaf body `b` and its frame in the body frame.
fn choose_foot(model: &RobotModel, b: usize) -> (String, Pose) {
    let links = &model.bodies[b].links;
    // `max_by` keeps the last of equal elements: ties go to the link merged last.
    let farthest = |it: &mut dyn Iterator<Item = &(String, Pose)>| {
        it.max_by(|a, c| {
            a.1.translation
                .length()
                .total_cmp(&c.1.translation.length())
        })
        .cloned()
    };
    farthest(
        &mut links
            .iter()
            .filter(|(n, _)| n.to_ascii_lowercase().contains("foot")),
    )
    .or_else(|| farthest(&mut links.iter()))
    .unwrap_or_else(|| (model.bodies[b].name.clone(), Pose::IDENTITY))
}

/// The trunk's contact link: the body's own first link if it has a collider, else the first
/// merged link with one, else the body name.
fn choose_base_link(model: &RobotModel, b: usize) -> String {
    let body = &model.bodies[b];
    let has_collider = |n: &str| body.colliders.iter().any(|c| c.link == n);
    body.links
        .iter()
        .map(|(n, _)| n)
        .find(|n| has_collider(n))
        .cloned()
        .unwrap_or_else(|| body.name.clone())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::RobotSpec;

    #[test]
    fn infer_every_catalog_robot_in_canonical_order_with_positive_signs() {
        for spec in RobotSpec::all() {
            let model = spec.model().unwrap();
            let legs = infer_quadruped(&model).unwrap_or_else(|e| panic!("{}: {e}", spec.name));
            assert_eq!(legs.joint_names(), spec.joint_names, "{}", spec.name);
            assert_eq!(legs.foot_links(), spec.foot_links, "{}", spec.name);
            assert_eq!(legs.base_link, spec.base_link, "{}", spec.name);
            assert!(legs.axis_signs().iter().all(|s| *s == 1.0), "{}", spec.name);
            assert!(legs.extra_joints.is_empty(), "{}", spec.name);
        }
    }

    #[test]
    fn infer_refuses_a_model_without_bodies_and_a_parentless_body() {
        let mut model = RobotSpec::by_name("a1").unwrap().model().unwrap();
        model.bodies[5].parent = None;
        let name = model.bodies[5].name.clone();
        let e = infer_quadruped(&model).unwrap_err();
        assert!(matches!(e, InferError::Tree { .. }), "{e}");
        assert!(e.to_string().contains(&format!("`{name}`")), "{e}");
        model.bodies.clear();
        assert!(infer_quadruped(&model).is_err());
    }

    #[test]
    fn summary_has_one_row_per_leg() {
        let model = RobotSpec::by_name("spot").unwrap().model().unwrap();
        let s = infer_quadruped(&model).unwrap().summary();
        for (leg, joint) in [
            ("FL", "fl_hx"),
            ("FR", "fr_hx"),
            ("RL", "hl_hx"),
            ("RR", "hr_hx"),
        ] {
            assert!(
                s.lines()
                    .any(|l| l.starts_with(leg) && l.contains(joint) && l.contains("+x")),
                "{s}"
            );
        }
    }
}
