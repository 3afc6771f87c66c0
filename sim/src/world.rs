//! Rapier physics for legged robots: a [`SimWorld`] holds several robots (each a rapier multibody
//! built from a [`RobotModel`]) on one ground (flat or a heightfield), steps them with a PD
//! [`crate::actuator`] and reads [`SimState`] snapshots. One world per worker thread; robots in a
//! world never collide with each other (collision groups robot↔ground only, no self-contacts).
//!
//! Choices (measured facts in `reference/rapier-quadruped-notes.md`, our numbers in `NOTES.md`):
//! multibody joints (impulse joints pulled apart at high gains), Z-up with gravity −Z, CCD off,
//! `can_sleep(false)`, 1 solver iteration in the default [`ActuatorMode::ImplicitSpring`] mode.
//!
//! [`ActuatorMode::ImplicitSpring`]: the PD law runs as rapier's implicit joint spring (stiffness
//! `kp`) and joint damping (`kd`), which is unconditionally stable at 1 iteration. To honour the
//! DC-motor torque–speed curve and effort limit, every substep computes the explicit PD torque
//! `τ = kp (q* − q) − kd q̇`, clips it, and moves the spring's rest position to
//! `q + (τ_clipped + kd q̇) / kp` so that the spring applies the clipped torque at the start of the
//! substep. [`ActuatorMode::ExplicitTorque`] applies the clipped torque as a body torque pair
//! (needs 2 solver iterations at stiff gains).

use rapier3d::math::{Mat3, Pose, Rot3, Vec3};
use rapier3d::prelude::*;

use crate::actuator::Actuator;
use l3p_robot::model::{JointKind, RobotModel, ShapeSpec};
use l3p_task::task::{MAX_PENALISED_BODIES, NUM_FEET, NUM_JOINTS, SimState};

/// How PD torques reach rapier.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActuatorMode {
    /// Implicit joint spring + damping with a clipped rest target (default, 1 iteration).
    ImplicitSpring,
    /// Explicit clipped torque on the child/parent bodies.
    ExplicitTorque,
}

/// Physics settings.
#[derive(Debug, Clone, Copy)]
pub struct SimConfig {
    /// Physics step (s).
    pub dt: f32,
    /// Rapier solver iterations (substeps).
    pub solver_iterations: usize,
    /// PD implementation.
    pub actuator_mode: ActuatorMode,
    /// Ground friction coefficient (multiplied with the robot's).
    pub ground_friction: f32,
    /// Gravity along −z (m/s²).
    pub gravity: f32,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            dt: 0.005,
            solver_iterations: 1,
            actuator_mode: ActuatorMode::ImplicitSpring,
            ground_friction: 1.0,
            gravity: 9.81,
        }
    }
}

/// Errors building a robot in the world.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A joint the caller named is not in the model.
    #[error(
        "robot `{robot}` has no actuated joint `{joint}`\nhint: the model's joints are {known}"
    )]
    MissingJoint {
        /// Model name.
        robot: String,
        /// Requested joint.
        joint: String,
        /// Model joints.
        known: String,
    },
    /// A link the caller named is not in the model.
    #[error("robot `{robot}` has no link `{link}`")]
    MissingLink {
        /// Model name.
        robot: String,
        /// Requested link.
        link: String,
    },
    /// Wrong number of joints.
    #[error("robot `{robot}`: expected {expected} actuated joints, got {got}")]
    JointCount {
        /// Model name.
        robot: String,
        /// Expected.
        expected: usize,
        /// Got.
        got: usize,
    },
}

/// Which model parts the simulator reports on.
#[derive(Debug, Clone)]
pub struct RobotBinding {
    /// Actuated joints in canonical order (must be [`NUM_JOINTS`]).
    pub joints: Vec<String>,
    /// Foot links (canonical order, [`NUM_FEET`]).
    pub feet: Vec<String>,
    /// Penalised links (≤ [`MAX_PENALISED_BODIES`]).
    pub penalised: Vec<String>,
    /// Termination links (their summed contact is `base_force`).
    pub termination: Vec<String>,
}

impl RobotBinding {
    /// Binding for a built-in robot.
    pub fn from_spec(spec: &l3p_robot::catalog::RobotSpec) -> Self {
        Self {
            joints: spec.joint_names.iter().map(|s| s.to_string()).collect(),
            feet: spec.foot_links.iter().map(|s| s.to_string()).collect(),
            penalised: spec.penalised_links.iter().map(|s| s.to_string()).collect(),
            termination: spec
                .termination_links
                .iter()
                .map(|s| s.to_string())
                .collect(),
        }
    }
}

struct JointSlot {
    link_id: usize,
    dof: usize,
    child: RigidBodyHandle,
    parent: RigidBodyHandle,
    /// Joint axis in the child body frame.
    axis_local: Vec3,
}

/// Per-robot actuator and joint imperfections (domain randomisation; real motors have them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointDynamics {
    /// Passive viscous joint damping added to the PD's kd (N·m·s/rad).
    pub damping: f32,
    /// Coulomb joint friction (N·m) opposing the joint velocity. Applied implicitly, as extra joint
    /// damping `friction / max(|q̇|, 0.05 rad/s)` (an explicit ±friction torque chatters at 5 ms
    /// on light legs): exactly `friction` above 0.05 rad/s, viscous below.
    pub friction: f32,
    /// Scale of the motor torque after clipping (motor strength).
    pub strength: f32,
    /// Control latency in physics steps: new targets take effect this many steps late.
    pub latency_steps: u32,
}

impl Default for JointDynamics {
    fn default() -> Self {
        JointDynamics {
            damping: 0.0,
            friction: 0.0,
            strength: 1.0,
            latency_steps: 0,
        }
    }
}

/// Joint velocity (rad/s) below which Coulomb friction turns viscous (see [`JointDynamics::friction`]).
const FRICTION_SMOOTHING_VEL: f32 = 0.05;

struct RobotInstance {
    bodies: Vec<RigidBodyHandle>,
    root: RigidBodyHandle,
    mb: MultibodyIndex,
    joints: Vec<JointSlot>,
    feet: [Vec<ColliderHandle>; NUM_FEET],
    penalised: Vec<Vec<ColliderHandle>>,
    termination: Vec<ColliderHandle>,
    /// Every collider with the URDF link it came from (for [`SimWorld::ground_contact_by_link`]).
    link_colliders: Vec<(String, ColliderHandle)>,
    actuator: Actuator,
    targets: [f32; NUM_JOINTS],
    /// Targets before the last `set_targets` (applied during the latency).
    prev_targets: [f32; NUM_JOINTS],
    /// Physics steps since the last `set_targets`.
    steps_since_targets: u32,
    dynamics: JointDynamics,
    torque: [f32; NUM_JOINTS],
    /// Contact maxima over the current control step.
    foot_force: [f32; NUM_FEET],
    penalised_force: [f32; MAX_PENALISED_BODIES],
    base_force: f32,
    base_mass: f32,
    base_com: Vec3,
    /// The model's base mass properties (randomisation starts from these).
    base_mprops: MassProperties,
}

/// A rapier world with robots and ground.
pub struct SimWorld {
    world: PhysicsWorld,
    robots: Vec<RobotInstance>,
    ground: Vec<ColliderHandle>,
    cfg: SimConfig,
    disp: Vec<f32>,
}

impl std::fmt::Debug for SimWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimWorld")
            .field("robots", &self.robots.len())
            .field("cfg", &self.cfg)
            .finish()
    }
}

const ROBOT_GROUP: Group = Group::GROUP_1;
const GROUND_GROUP: Group = Group::GROUP_2;

fn robot_groups() -> InteractionGroups {
    InteractionGroups::new(ROBOT_GROUP, GROUND_GROUP, InteractionTestMode::And)
}
fn ground_groups() -> InteractionGroups {
    InteractionGroups::new(GROUND_GROUP, ROBOT_GROUP, InteractionTestMode::And)
}

/// Rotation taking +x to `axis`.
fn axis_frame(axis: Vec3) -> Rot3 {
    Rot3::from_rotation_arc(Vec3::X, axis.normalize())
}

fn mass_props(mass: f32, com: Vec3, inertia: Mat3) -> MassProperties {
    let mp = MassProperties::with_inertia_matrix(com, mass, inertia);
    let p = mp.principal_inertia();
    let floor = 1e-6_f32;
    if p.x >= floor && p.y >= floor && p.z >= floor && p.is_finite() {
        return mp;
    }
    let clamped = Vec3::new(p.x.max(floor), p.y.max(floor), p.z.max(floor));
    let clamped = if clamped.is_finite() {
        clamped
    } else {
        Vec3::splat(floor)
    };
    MassProperties::with_principal_inertia_frame(
        com,
        mass,
        clamped,
        mp.principal_inertia_local_frame,
    )
}

impl SimWorld {
    /// Empty world (no ground) with the given settings.
    pub fn new(cfg: SimConfig) -> Self {
        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::new(0.0, 0.0, -cfg.gravity);
        world.integration_parameters.dt = cfg.dt;
        world.integration_parameters.num_solver_iterations = cfg.solver_iterations.max(1);
        world.integration_parameters.max_ccd_substeps = 0;
        Self {
            world,
            robots: Vec::new(),
            ground: Vec::new(),
            cfg,
            disp: Vec::new(),
        }
    }

    /// Settings.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Number of robots.
    pub fn num_robots(&self) -> usize {
        self.robots.len()
    }

    /// Adds a flat ground plane at `z = height` (a large thin box).
    pub fn add_flat_ground(&mut self, height: f32) {
        self.add_ground_shape(
            SharedShape::cuboid(2000.0, 2000.0, 1.0),
            Pose::from_translation(Vec3::new(0.0, 0.0, height - 1.0)),
        );
    }

    /// Adds a prebuilt ground shape (e.g. one heightfield shared by every worker's world) at `pose`.
    pub fn add_ground_shape(&mut self, shape: SharedShape, pose: Pose) {
        let body = self.world.insert_body(RigidBodyBuilder::fixed().pose(pose));
        let c = ColliderBuilder::new(shape)
            .friction(self.cfg.ground_friction)
            .friction_combine_rule(CoefficientCombineRule::Multiply)
            .collision_groups(ground_groups());
        let h = self
            .world
            .colliders
            .insert_with_parent(c.build(), body, &mut self.world.bodies);
        self.ground.push(h);
    }

    /// Adds a heightfield ground: `heights[iy * nx + ix]` is the height (m) at
    /// `(origin_x + ix·cell, origin_y + iy·cell)`, `nx × ny` samples.
    pub fn add_heightfield_ground(
        &mut self,
        heights: &[f32],
        nx: usize,
        ny: usize,
        cell: f32,
        origin_xy: [f32; 2],
    ) {
        if nx < 2 || ny < 2 || heights.len() != nx * ny {
            return;
        }
        // parry's HeightField is Y-up: rows run along local z, columns along local x, heights along
        // local y; it is centred on its origin. A +90° rotation about x maps local y → world z and
        // local z → world −y, so row i (local z) goes to world −y: store rows in reversed y order.
        let mut m = rapier3d::parry::utils::Array2::zeros(ny, nx);
        for ix in 0..nx {
            for iy in 0..ny {
                m[(ny - 1 - iy, ix)] = heights[iy * nx + ix];
            }
        }
        let sx = (nx - 1) as f32 * cell;
        let sy = (ny - 1) as f32 * cell;
        let centre = Vec3::new(
            origin_x_plus(origin_xy[0], sx),
            origin_x_plus(origin_xy[1], sy),
            0.0,
        );
        self.add_ground_shape(
            SharedShape::heightfield(m, Vec3::new(sx, 1.0, sy)),
            Pose::from_parts(centre, Rot3::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        );
    }

    /// Adds a robot with its base at `base_pose` and joints (canonical order) at `q`; returns its index.
    pub fn add_robot(
        &mut self,
        model: &RobotModel,
        binding: &RobotBinding,
        actuator: Actuator,
        base_pose: Pose,
        q: &[f32; NUM_JOINTS],
    ) -> Result<usize, SimError> {
        if binding.joints.len() != NUM_JOINTS {
            return Err(SimError::JointCount {
                robot: model.name.clone(),
                expected: NUM_JOINTS,
                got: binding.joints.len(),
            });
        }
        let mut q_body = vec![0.0; model.bodies.len()];
        let mut joint_bodies = [0usize; NUM_JOINTS];
        for (k, name) in binding.joints.iter().enumerate() {
            let b = model
                .body_of_joint(name)
                .ok_or_else(|| SimError::MissingJoint {
                    robot: model.name.clone(),
                    joint: name.clone(),
                    known: model.joint_names().join(", "),
                })?;
            q_body[b] = q[k];
            joint_bodies[k] = b;
        }
        let poses = model.body_poses(&q_body);
        let mut handles = Vec::with_capacity(model.bodies.len());
        let mut link_colliders: Vec<(String, ColliderHandle)> = Vec::new();
        for (b, rel) in model.bodies.iter().zip(&poses) {
            let pose = base_pose * *rel;
            let rb = RigidBodyBuilder::dynamic()
                .pose(pose)
                .can_sleep(false)
                .ccd_enabled(false)
                .additional_mass_properties(mass_props(b.mass, b.com, b.inertia))
                .build();
            let h = self.world.bodies.insert(rb);
            for c in &b.colliders {
                let (shape, local) = collider_shape(&c.shape, &c.link);
                let col = ColliderBuilder::new(shape)
                    .position(c.pose * local)
                    .density(0.0)
                    .friction(1.0)
                    .friction_combine_rule(CoefficientCombineRule::Multiply)
                    .collision_groups(robot_groups())
                    .build();
                let ch = self
                    .world
                    .colliders
                    .insert_with_parent(col, h, &mut self.world.bodies);
                link_colliders.push((c.link.clone(), ch));
            }
            handles.push(h);
        }
        for (i, b) in model.bodies.iter().enumerate() {
            let (Some(p), Some(j)) = (b.parent, &b.joint) else {
                continue;
            };
            let frame = axis_frame(j.axis);
            let mask = match j.kind {
                JointKind::Revolute => JointAxesMask::LOCKED_REVOLUTE_AXES,
                JointKind::Prismatic => JointAxesMask::LOCKED_PRISMATIC_AXES,
            };
            let mut builder = GenericJointBuilder::new(mask)
                .local_frame1(Pose::from_parts(
                    j.origin.translation,
                    j.origin.rotation * frame,
                ))
                .local_frame2(Pose::from_rotation(frame))
                .contacts_enabled(false);
            if let Some((lo, hi)) = j.limits {
                let axis = if j.kind == JointKind::Revolute {
                    JointAxis::AngX
                } else {
                    JointAxis::LinX
                };
                builder = builder.limits(axis, [lo, hi]);
            }
            self.world
                .multibody_joints
                .insert(handles[p], handles[i], builder.build(), true);
        }
        let root = handles[0];
        let mb = self
            .world
            .multibody_joints
            .rigid_body_link(root)
            .map(|l| l.multibody);
        let Some(mb) = mb else {
            return Err(SimError::JointCount {
                robot: model.name.clone(),
                expected: NUM_JOINTS,
                got: 0,
            });
        };
        let mut joints = Vec::with_capacity(NUM_JOINTS);
        {
            let bodies = &self.world.bodies;
            let Some(multibody) = self.world.multibody_joints.get_multibody_mut(mb) else {
                return Err(SimError::JointCount {
                    robot: model.name.clone(),
                    expected: NUM_JOINTS,
                    got: 0,
                });
            };
            multibody.set_self_contacts_enabled(false);
            multibody.forward_kinematics(bodies, true);
            for (k, &b) in joint_bodies.iter().enumerate() {
                let child = handles[b];
                let link_id = (0..multibody.num_links())
                    .find(|&l| {
                        multibody
                            .link(l)
                            .is_some_and(|ln| ln.rigid_body_handle() == child)
                    })
                    .unwrap_or(0);
                let dof = multibody
                    .link(link_id)
                    .map(|l| l.assembly_id())
                    .unwrap_or(0);
                let parent = handles[model.bodies[b].parent.unwrap_or(0)];
                let axis_local = model.bodies[b]
                    .joint
                    .as_ref()
                    .map(|j| j.axis)
                    .unwrap_or(Vec3::X);
                joints.push(JointSlot {
                    link_id,
                    dof,
                    child,
                    parent,
                    axis_local,
                });
                let _ = k;
            }
            let damping = multibody.damping_mut();
            for d in damping.iter_mut() {
                *d = 0.0;
            }
        }
        let find = |name: &str| -> Result<Vec<ColliderHandle>, SimError> {
            if model.body_of_link(name).is_none() {
                return Err(SimError::MissingLink {
                    robot: model.name.clone(),
                    link: name.to_string(),
                });
            }
            Ok(link_colliders
                .iter()
                .filter(|(l, _)| l == name)
                .map(|(_, h)| *h)
                .collect())
        };
        let mut feet: [Vec<ColliderHandle>; NUM_FEET] = Default::default();
        for (i, f) in binding.feet.iter().take(NUM_FEET).enumerate() {
            feet[i] = find(f)?;
        }
        let mut penalised = Vec::new();
        for p in binding.penalised.iter().take(MAX_PENALISED_BODIES) {
            penalised.push(find(p)?);
        }
        let mut termination = Vec::new();
        for t in &binding.termination {
            termination.extend(find(t)?);
        }
        let inst = RobotInstance {
            bodies: handles,
            root,
            mb,
            joints,
            feet,
            penalised,
            termination,
            link_colliders,
            actuator,
            targets: *q,
            prev_targets: *q,
            steps_since_targets: 0,
            dynamics: JointDynamics::default(),
            torque: [0.0; NUM_JOINTS],
            foot_force: [0.0; NUM_FEET],
            penalised_force: [0.0; MAX_PENALISED_BODIES],
            base_force: 0.0,
            base_mass: model.bodies[0].mass,
            base_com: model.bodies[0].com,
            base_mprops: mass_props(
                model.bodies[0].mass,
                model.bodies[0].com,
                model.bodies[0].inertia,
            ),
        };
        self.robots.push(inst);
        let id = self.robots.len() - 1;
        self.apply_gains(id);
        // The multibody starts with zero joint coordinates: move it to `q`.
        self.reset_robot(id, base_pose, Vec3::ZERO, Vec3::ZERO, q, &[0.0; NUM_JOINTS]);
        Ok(id)
    }

    /// Replaces a robot's actuator (gains and limits).
    pub fn set_actuator(&mut self, robot: usize, actuator: Actuator) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.actuator = actuator;
            self.apply_gains(robot);
        }
    }

    fn apply_gains(&mut self, robot: usize) {
        let mode = self.cfg.actuator_mode;
        let r = &self.robots[robot];
        let Some(mb) = self.world.multibody_joints.get_multibody_mut(r.mb) else {
            return;
        };
        for (k, j) in r.joints.iter().enumerate() {
            let (kp, kd) = match mode {
                ActuatorMode::ImplicitSpring => (r.actuator.kp[k], r.actuator.kd[k]),
                ActuatorMode::ExplicitTorque => (0.0, 0.0),
            };
            // Passive damping is physical in both modes: it always goes to the implicit damping.
            if let Some(d) = mb.damping_mut().get_mut(j.dof) {
                *d = kd + r.dynamics.damping;
            }
            if let Some(link) = mb.link_mut(j.link_id) {
                link.joint.set_spring(3, kp, r.targets[k]);
            }
        }
    }

    /// Sets joint position targets (canonical order) for the next steps; with a latency they take
    /// effect `latency_steps` physics steps later.
    pub fn set_targets(&mut self, robot: usize, q_target: &[f32; NUM_JOINTS]) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.prev_targets = r.targets;
            r.targets = *q_target;
            r.steps_since_targets = 0;
        }
    }

    /// Sets a robot's joint damping, friction, motor strength and latency.
    pub fn set_joint_dynamics(&mut self, robot: usize, dynamics: JointDynamics) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.dynamics = dynamics;
            self.apply_gains(robot);
        }
    }

    /// A robot's joint dynamics.
    pub fn joint_dynamics(&self, robot: usize) -> Option<JointDynamics> {
        self.robots.get(robot).map(|r| r.dynamics)
    }

    /// Base mass and centre of mass for domain randomisation: `added` kg on the model's base mass
    /// (inertia scaled with it, mass kept ≥ 10% of the model's) and the CoM shifted by `com_offset`
    /// (base frame, m). Always computed from the model's values, so repeated calls do not compound.
    pub fn set_base_randomization(&mut self, robot: usize, added: f32, com_offset: [f32; 3]) {
        let Some(r) = self.robots.get(robot) else {
            return;
        };
        let mass = (r.base_mass + added).max(0.1 * r.base_mass);
        let scale = mass / r.base_mass.max(1e-6);
        let com = r.base_com + Vec3::from(com_offset);
        let nominal = r.base_mprops;
        if let Some(rb) = self.world.bodies.get_mut(r.root) {
            let new = MassProperties::with_principal_inertia_frame(
                com,
                mass,
                nominal.principal_inertia() * scale,
                nominal.principal_inertia_local_frame,
            );
            rb.set_additional_mass_properties(new, true);
        }
    }

    /// Sets the friction coefficient of every collider of a robot.
    pub fn set_friction(&mut self, robot: usize, friction: f32) {
        let Some(r) = self.robots.get(robot) else {
            return;
        };
        for &b in &r.bodies {
            let Some(rb) = self.world.bodies.get(b) else {
                continue;
            };
            let cols: Vec<ColliderHandle> = rb.colliders().to_vec();
            for c in cols {
                if let Some(col) = self.world.colliders.get_mut(c) {
                    col.set_friction(friction);
                }
            }
        }
    }

    /// Advances the world by one physics step, running every robot's actuator first.
    pub fn step(&mut self) {
        let dt = self.cfg.dt;
        let mode = self.cfg.actuator_mode;
        for r in &mut self.robots {
            let Some(mb) = self.world.multibody_joints.get_multibody_mut(r.mb) else {
                continue;
            };
            let delayed = r.steps_since_targets < r.dynamics.latency_steps;
            r.steps_since_targets = r.steps_since_targets.saturating_add(1);
            let dynamics = r.dynamics;
            for (k, j) in r.joints.iter().enumerate() {
                let q = mb
                    .link(j.link_id)
                    .map(|l| l.joint().coords()[3])
                    .unwrap_or(0.0);
                let qd = mb.generalized_velocity().get(j.dof).copied().unwrap_or(0.0);
                let target = if delayed {
                    r.prev_targets[k]
                } else {
                    r.targets[k]
                };
                let tau = dynamics.strength * r.actuator.torque(k, target, q, qd);
                r.torque[k] = tau;
                // Passive damping and Coulomb friction act at the joint, not through the motor
                // (they are not in `torque`); both go into rapier's implicit joint damping.
                let friction_damping = if dynamics.friction > 0.0 {
                    dynamics.friction / qd.abs().max(FRICTION_SMOOTHING_VEL)
                } else {
                    0.0
                };
                let pd_damping = match mode {
                    ActuatorMode::ImplicitSpring => r.actuator.kd[k],
                    ActuatorMode::ExplicitTorque => 0.0,
                };
                if let Some(d) = mb.damping_mut().get_mut(j.dof) {
                    *d = pd_damping + dynamics.damping + friction_damping;
                }
                if mode == ActuatorMode::ImplicitSpring {
                    let kp = r.actuator.kp[k];
                    if kp > 0.0 {
                        // The spring applies kp (rest − q) − kd q̇; the passive terms are extra damping.
                        let rest = q + (tau + r.actuator.kd[k] * qd) / kp;
                        if let Some(link) = mb.link_mut(j.link_id) {
                            link.joint.set_spring(3, kp, rest);
                        }
                    }
                }
            }
            if mode == ActuatorMode::ExplicitTorque {
                for (k, j) in r.joints.iter().enumerate() {
                    let rot = self
                        .world
                        .bodies
                        .get(j.child)
                        .map(|b| *b.rotation())
                        .unwrap_or(Rot3::IDENTITY);
                    let t = rot * j.axis_local * r.torque[k];
                    if let Some(b) = self.world.bodies.get_mut(j.child) {
                        if k == 0 || r.joints[k - 1].child != j.child {
                            b.reset_torques(false);
                        }
                        b.add_torque(t, false);
                    }
                    if let Some(b) = self.world.bodies.get_mut(j.parent) {
                        b.add_torque(-t, false);
                    }
                }
            }
        }
        if mode == ActuatorMode::ExplicitTorque {
            // Torques were accumulated above; clear them after the step (below).
        }
        self.world.step();
        if mode == ActuatorMode::ExplicitTorque {
            for r in &self.robots {
                for &b in &r.bodies {
                    if let Some(rb) = self.world.bodies.get_mut(b) {
                        rb.reset_torques(false);
                    }
                }
            }
        }
        // Contact maxima.
        for r in &mut self.robots {
            for (i, cols) in r.feet.iter().enumerate() {
                let f = contact_force(&self.world.narrow_phase, cols, dt);
                r.foot_force[i] = r.foot_force[i].max(f);
            }
            for (i, cols) in r.penalised.iter().enumerate() {
                let f = contact_force(&self.world.narrow_phase, cols, dt);
                r.penalised_force[i] = r.penalised_force[i].max(f);
            }
            let f = contact_force(&self.world.narrow_phase, &r.termination, dt);
            r.base_force = r.base_force.max(f);
        }
    }

    /// Ground contact force (N) of robot `robot` in the last physics step, per URDF link that
    /// touches the ground, in collider order (links without contact are left out).
    pub fn ground_contact_by_link(&self, robot: usize) -> Vec<(String, f32)> {
        let mut out: Vec<(String, f32)> = Vec::new();
        let Some(r) = self.robots.get(robot) else {
            return out;
        };
        let dt = self.cfg.dt;
        for (link, h) in &r.link_colliders {
            let f = contact_force(&self.world.narrow_phase, std::slice::from_ref(h), dt);
            if f <= 0.0 {
                continue;
            }
            match out.iter_mut().find(|(l, _)| l == link) {
                Some((_, total)) => *total += f,
                None => out.push((link.clone(), f)),
            }
        }
        out
    }

    /// Clears the per-control-step contact maxima (call before the substeps of a control step).
    pub fn clear_contact_maxima(&mut self) {
        for r in &mut self.robots {
            r.foot_force = [0.0; NUM_FEET];
            r.penalised_force = [0.0; MAX_PENALISED_BODIES];
            r.base_force = 0.0;
        }
    }

    /// Fills `out` with robot `robot`'s state.
    pub fn read_state(&self, robot: usize, out: &mut SimState) {
        let Some(r) = self.robots.get(robot) else {
            return;
        };
        let Some(rb) = self.world.bodies.get(r.root) else {
            return;
        };
        let t = rb.translation();
        let q = rb.rotation();
        out.base_pos = [t.x, t.y, t.z];
        out.base_quat = [q.w, q.x, q.y, q.z];
        // linvel is at the centre of mass; the task wants the base frame origin's velocity.
        let w = rb.angvel();
        let com_w = rb.center_of_mass();
        let v = rb.linvel() + w.cross(t - com_w);
        out.base_lin_vel_w = [v.x, v.y, v.z];
        out.base_ang_vel_w = [w.x, w.y, w.z];
        if let Some(mb) = self.world.multibody_joints.get_multibody(r.mb) {
            let gv = mb.generalized_velocity();
            for (k, j) in r.joints.iter().enumerate() {
                out.joint_pos[k] = mb
                    .link(j.link_id)
                    .map(|l| l.joint().coords()[3])
                    .unwrap_or(0.0);
                out.joint_vel[k] = gv.get(j.dof).copied().unwrap_or(0.0);
            }
        }
        out.joint_torque = r.torque;
        out.foot_force = r.foot_force;
        out.penalised_force = r.penalised_force;
        out.base_force = r.base_force;
        for (sole, cols) in out.foot_sole.iter_mut().zip(&r.feet) {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for c in cols.iter().filter_map(|h| self.world.colliders.get(*h)) {
                let aabb = c.compute_aabb();
                for k in 0..3 {
                    lo[k] = lo[k].min(aabb.mins[k]);
                    hi[k] = hi[k].max(aabb.maxs[k]);
                }
            }
            if lo[2].is_finite() {
                *sole = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]];
            }
        }
    }

    /// Teleports a robot: base pose, base velocity (world frame, linear at the base origin and
    /// angular), joint positions and velocities (canonical order). Targets are set to `q`.
    pub fn reset_robot(
        &mut self,
        robot: usize,
        base_pose: Pose,
        lin_vel: Vec3,
        ang_vel: Vec3,
        q: &[f32; NUM_JOINTS],
        qd: &[f32; NUM_JOINTS],
    ) {
        let Some(r) = self.robots.get_mut(robot) else {
            return;
        };
        r.targets = *q;
        r.prev_targets = *q;
        r.steps_since_targets = u32::MAX;
        r.torque = [0.0; NUM_JOINTS];
        r.foot_force = [0.0; NUM_FEET];
        r.penalised_force = [0.0; MAX_PENALISED_BODIES];
        r.base_force = 0.0;
        if let Some(rb) = self.world.bodies.get_mut(r.root) {
            rb.set_position(base_pose, true);
        }
        let Some(mb) = self.world.multibody_joints.get_multibody_mut(r.mb) else {
            return;
        };
        let n = mb.ndofs();
        self.disp.clear();
        self.disp.resize(n, 0.0);
        for (k, j) in r.joints.iter().enumerate() {
            let cur = mb
                .link(j.link_id)
                .map(|l| l.joint().coords()[3])
                .unwrap_or(0.0);
            if let Some(d) = self.disp.get_mut(j.dof) {
                *d = q[k] - cur;
            }
        }
        // Root displacement must be zero: its pose is read from the rigid body below.
        for d in self.disp.iter_mut().take(6) {
            *d = 0.0;
        }
        mb.apply_displacements(&self.disp);
        {
            let mut gv = mb.generalized_velocity_mut();
            for v in gv.iter_mut() {
                *v = 0.0;
            }
            // Root: linear velocity of the root origin (world) then angular (world).
            if gv.len() >= 6 {
                gv[0] = lin_vel.x;
                gv[1] = lin_vel.y;
                gv[2] = lin_vel.z;
                gv[3] = ang_vel.x;
                gv[4] = ang_vel.y;
                gv[5] = ang_vel.z;
            }
            for (k, j) in r.joints.iter().enumerate() {
                if let Some(v) = gv.get_mut(j.dof) {
                    *v = qd[k];
                }
            }
        }
        mb.forward_kinematics(&self.world.bodies, true);
        mb.update_rigid_bodies(&mut self.world.bodies, true);
        for (k, j) in r.joints.iter().enumerate() {
            if let Some(link) = mb.link_mut(j.link_id) {
                let (kp, _) = link.joint.spring(3);
                link.joint.set_spring(3, kp, q[k]);
            }
        }
        for &b in &r.bodies {
            if let Some(rb) = self.world.bodies.get_mut(b) {
                rb.set_linvel(lin_vel, false);
                rb.set_angvel(Vec3::ZERO, false);
            }
        }
    }

    /// Sets the base linear velocity in the world xy plane (a push), keeping everything else.
    pub fn push_base(&mut self, robot: usize, vx: f32, vy: f32) {
        let Some(r) = self.robots.get(robot) else {
            return;
        };
        if let Some(mb) = self.world.multibody_joints.get_multibody_mut(r.mb) {
            let mut gv = mb.generalized_velocity_mut();
            if gv.len() >= 6 {
                gv[0] = vx;
                gv[1] = vy;
            }
        }
    }

    /// World poses of a robot's bodies in its model's body order (what a viewer draws: each
    /// body's `colliders` sit at their `pose` in this frame). Empty for an unknown robot.
    pub fn body_poses(&self, robot: usize) -> Vec<Pose> {
        self.robots
            .get(robot)
            .map(|r| {
                r.bodies
                    .iter()
                    .filter_map(|h| self.world.bodies.get(*h).map(|b| *b.position()))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// World position of each foot (canonical order): the centre of its first collider.
    pub fn foot_positions(&self, robot: usize) -> [[f32; 3]; NUM_FEET] {
        let mut out = [[0.0; 3]; NUM_FEET];
        let Some(r) = self.robots.get(robot) else {
            return out;
        };
        for (slot, colliders) in out.iter_mut().zip(&r.feet) {
            if let Some(c) = colliders.first().and_then(|h| self.world.colliders.get(*h)) {
                let t = c.position().translation;
                *slot = [t.x, t.y, t.z];
            }
        }
        out
    }

    /// Base position of a robot (world).
    pub fn base_position(&self, robot: usize) -> Vec3 {
        self.robots
            .get(robot)
            .and_then(|r| self.world.bodies.get(r.root))
            .map(|b| b.translation())
            .unwrap_or(Vec3::ZERO)
    }

    /// Adds a free rigid body (sphere of radius `r`, mass `m`) for sanity tests; returns its handle.
    pub fn add_free_ball(&mut self, pos: Vec3, radius: f32, mass: f32) -> RigidBodyHandle {
        let h = self.world.bodies.insert(
            RigidBodyBuilder::dynamic()
                .translation(pos)
                .can_sleep(false)
                .build(),
        );
        let c = ColliderBuilder::ball(radius)
            .mass(mass)
            .collision_groups(robot_groups())
            .build();
        self.world
            .colliders
            .insert_with_parent(c, h, &mut self.world.bodies);
        h
    }

    /// Position and linear velocity of a rigid body.
    pub fn body_state(&self, h: RigidBodyHandle) -> Option<(Vec3, Vec3)> {
        self.world
            .bodies
            .get(h)
            .map(|b| (b.translation(), b.linvel()))
    }
}

/// The parry shape of `shape` and its pose in the shape's frame (parry cylinders are along y,
/// URDF's along z). Hull points are checked for volume when loaded; should parry still find them
/// degenerate, their bounding box stands in (with a warning naming `link`).
fn collider_shape(shape: &ShapeSpec, link: &str) -> (SharedShape, Pose) {
    match *shape {
        ShapeSpec::Cuboid { half } => (SharedShape::cuboid(half.x, half.y, half.z), Pose::IDENTITY),
        ShapeSpec::Sphere { radius } => (SharedShape::ball(radius), Pose::IDENTITY),
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => (SharedShape::capsule_z(half_length, radius), Pose::IDENTITY),
        ShapeSpec::Cylinder {
            half_length,
            radius,
        } => (
            SharedShape::cylinder(half_length, radius),
            Pose::from_rotation(Rot3::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        ),
        ShapeSpec::ConvexHull { ref points } => match SharedShape::convex_hull(points) {
            Some(hull) => (hull, Pose::IDENTITY),
            None => {
                let lo = points.iter().fold(Vec3::INFINITY, |a, p| a.min(*p));
                let hi = points.iter().fold(Vec3::NEG_INFINITY, |a, p| a.max(*p));
                let half = (0.5 * (hi - lo)).max(Vec3::splat(1e-3));
                tracing::warn!(
                    "link `{link}`: no convex hull of its {} mesh points; their bounding box stands in",
                    points.len()
                );
                (
                    SharedShape::cuboid(half.x, half.y, half.z),
                    Pose::from_translation(0.5 * (lo + hi)),
                )
            }
        },
    }
}

/// The triangles of the convex hull of `points` (a [`ShapeSpec::ConvexHull`]) for viewers: its
/// vertices and their index triples; `None` when the points have no volume.
pub fn convex_hull_mesh(points: &[Vec3]) -> Option<(Vec<Vec3>, Vec<[u32; 3]>)> {
    rapier3d::parry::transformation::try_convex_hull(points).ok()
}

fn origin_x_plus(origin: f32, size: f32) -> f32 {
    origin + 0.5 * size
}

/// Sum of contact normal-impulse magnitudes on `cols` divided by `dt` (N).
fn contact_force(np: &NarrowPhase, cols: &[ColliderHandle], dt: f32) -> f32 {
    let mut total = 0.0;
    for &c in cols {
        for pair in np.contact_pairs_with(c) {
            total += pair.total_impulse_magnitude();
        }
    }
    total / dt
}
