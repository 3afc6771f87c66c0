//! The seven built-in robots: [`RobotSpec`] (URDF text embedded with `include_str!` plus the
//! metadata the task needs) looked up with [`RobotSpec::by_name`] or listed with [`RobotSpec::all`].
//!
//! **Canonical joint order** (actions, observations, gains, limits): legs front-left, front-right,
//! rear-left, rear-right (Unitree FL, FR, RL, RR; ANYmal LF, RF, LH, RH; Spot fl, fr, hl, hr), and in
//! each leg hip abduction/adduction, hip flexion, knee (Unitree hip, thigh, calf; ANYmal HAA, HFE, KFE;
//! Spot hx, hy, kn). This is legged_gym's / IsaacLab's order for the Unitree robots.
//!
//! Values and sources (see `reference/locomotion-env-and-ppo.md` §1.8 and `robots/NOTES.md`):
//! default poses and action scales are IsaacLab 2.1's; training gains are IsaacLab 2.1's DC-motor gains
//! for A1/Go2, the same PD for Go1 (IsaacLab uses an actuator net; walk-these-ways reports it mainly
//! adds ~0.2 damping, which we add), legged_gym's ANYmal PD (kp 80, kd 2) with IsaacLab's ANYdrive limits
//! (saturation 120 N·m, effort 80 N·m, 7.5 rad/s) for ANYmal B/C/D (IsaacLab uses an LSTM actuator
//! net; its DC-motor substitute, kp 40 / kd 5, let them sag to 80% of standing), and IsaacLab's
//! Spot PD (kp 60, kd 1.5). Stand-test gains are stiff gains for the standing check only.

use crate::mesh::MeshHull;
use crate::model::RobotModel;
use crate::urdf::{UrdfError, load_urdf_str_with_hulls};

/// Number of actuated leg joints of every built-in robot.
pub const NUM_JOINTS: usize = 12;
/// Links whose ground contact a task can penalise, at most (the fixed-size force array of a
/// simulator state snapshot).
pub const MAX_PENALISED_BODIES: usize = 8;

/// PD gains applied to every joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Stiffness (N·m/rad).
    pub kp: f32,
    /// Damping (N·m·s/rad).
    pub kd: f32,
}

/// Robot family (decides naming conventions and default task settings).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// Unitree A1, Go1, Go2.
    Unitree,
    /// ANYbotics ANYmal B, C, D.
    Anymal,
    /// Boston Dynamics Spot.
    Spot,
    /// A robot added from the user's URDF (`crate::added`).
    Other,
}

/// A built-in robot: URDF text and metadata.
#[derive(Debug, Clone)]
pub struct RobotSpec {
    /// Short name used on the command line (`a1`, `go1`, `go2`, `anymal_b`, `anymal_c`, `anymal_d`, `spot`).
    pub name: &'static str,
    /// Human-readable name.
    pub display_name: &'static str,
    /// Family.
    pub family: Family,
    /// The project's own URDF (primitive collision shapes), embedded; an added robot's URDF text.
    pub urdf: &'static str,
    /// Hulls of the URDF's collision meshes (an added robot's, from its description); none for
    /// the catalog's robots, whose URDFs have primitive shapes only.
    pub mesh_hulls: &'static [MeshHull],
    /// Actuated joints in canonical order.
    pub joint_names: [&'static str; NUM_JOINTS],
    /// Default standing joint positions (rad), canonical order.
    pub default_pose: [f32; NUM_JOINTS],
    /// Floating-base link (contact on it terminates the episode).
    pub base_link: &'static str,
    /// Foot links, canonical leg order.
    pub foot_links: [&'static str; 4],
    /// Links whose ground contact is penalised (undesired contacts).
    pub penalised_links: &'static [&'static str],
    /// Links whose ground contact terminates the episode (always includes the base).
    pub termination_links: &'static [&'static str],
    /// PD gains used for training.
    pub training_gains: Gains,
    /// Stiff PD gains used by the standing check.
    pub stand_gains: Gains,
    /// Continuous torque limit per joint (N·m).
    pub effort_limit: [f32; NUM_JOINTS],
    /// DC-motor stall (saturation) torque per joint (N·m).
    pub saturation_effort: [f32; NUM_JOINTS],
    /// No-load speed limit per joint (rad/s).
    pub velocity_limit: [f32; NUM_JOINTS],
    /// Action scale: `q* = default + scale · a`.
    pub action_scale: f32,
    /// Base height used when spawning (IsaacLab `init_state.pos` z), metres.
    pub spawn_height: f32,
    /// Published total mass (kg) the model is checked against.
    pub published_mass: f32,
}

fn legs3(v: [f32; 3]) -> [f32; NUM_JOINTS] {
    let mut out = [0.0; NUM_JOINTS];
    for l in 0..4 {
        out[3 * l..3 * l + 3].copy_from_slice(&v);
    }
    out
}

/// Unitree default pose (IsaacLab 2.1 `unitree.py`): hips ±0.1, thighs 0.8 front / 1.0 rear, calves −1.5.
const UNITREE_POSE: [f32; NUM_JOINTS] = [
    0.1, 0.8, -1.5, -0.1, 0.8, -1.5, 0.1, 1.0, -1.5, -0.1, 1.0, -1.5,
];
/// ANYmal default pose (IsaacLab 2.1 `anymal.py`): HAA 0, HFE ±0.4, KFE ∓0.8.
const ANYMAL_POSE: [f32; NUM_JOINTS] = [
    0.0, 0.4, -0.8, 0.0, 0.4, -0.8, 0.0, -0.4, 0.8, 0.0, -0.4, 0.8,
];
/// Spot default pose (IsaacLab 2.1 `spot.py`): hx ±0.1, hy 0.9 front / 1.1 hind, kn −1.5.
const SPOT_POSE: [f32; NUM_JOINTS] = [
    0.1, 0.9, -1.5, -0.1, 0.9, -1.5, 0.1, 1.1, -1.5, -0.1, 1.1, -1.5,
];

const UNITREE_JOINTS: [&str; NUM_JOINTS] = [
    "FL_hip_joint",
    "FL_thigh_joint",
    "FL_calf_joint",
    "FR_hip_joint",
    "FR_thigh_joint",
    "FR_calf_joint",
    "RL_hip_joint",
    "RL_thigh_joint",
    "RL_calf_joint",
    "RR_hip_joint",
    "RR_thigh_joint",
    "RR_calf_joint",
];
const ANYMAL_JOINTS: [&str; NUM_JOINTS] = [
    "LF_HAA", "LF_HFE", "LF_KFE", "RF_HAA", "RF_HFE", "RF_KFE", "LH_HAA", "LH_HFE", "LH_KFE",
    "RH_HAA", "RH_HFE", "RH_KFE",
];
const SPOT_JOINTS: [&str; NUM_JOINTS] = [
    "fl_hx", "fl_hy", "fl_kn", "fr_hx", "fr_hy", "fr_kn", "hl_hx", "hl_hy", "hl_kn", "hr_hx",
    "hr_hy", "hr_kn",
];

const UNITREE_FEET: [&str; 4] = ["FL_foot", "FR_foot", "RL_foot", "RR_foot"];
const ANYMAL_FEET: [&str; 4] = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
const SPOT_FEET: [&str; 4] = ["fl_foot", "fr_foot", "hl_foot", "hr_foot"];

const UNITREE_PENALISED: &[&str] = &[
    "FL_thigh", "FR_thigh", "RL_thigh", "RR_thigh", "FL_calf", "FR_calf", "RL_calf", "RR_calf",
];
const ANYMAL_PENALISED: &[&str] = &["LF_THIGH", "RF_THIGH", "LH_THIGH", "RH_THIGH"];
const SPOT_PENALISED: &[&str] = &["fl_uleg", "fr_uleg", "hl_uleg", "hr_uleg"];

fn unitree(
    name: &'static str,
    display_name: &'static str,
    urdf: &'static str,
    base_link: &'static str,
    training_gains: Gains,
    effort: f32,
    velocity: f32,
    spawn_height: f32,
    published_mass: f32,
) -> RobotSpec {
    RobotSpec {
        name,
        display_name,
        family: Family::Unitree,
        urdf,
        mesh_hulls: &[],
        joint_names: UNITREE_JOINTS,
        default_pose: UNITREE_POSE,
        base_link,
        foot_links: UNITREE_FEET,
        penalised_links: UNITREE_PENALISED,
        termination_links: if base_link == "trunk" {
            &["trunk"]
        } else {
            &["base"]
        },
        training_gains,
        stand_gains: Gains { kp: 100.0, kd: 2.0 },
        effort_limit: [effort; NUM_JOINTS],
        saturation_effort: [effort; NUM_JOINTS],
        velocity_limit: [velocity; NUM_JOINTS],
        action_scale: 0.25,
        spawn_height,
        published_mass,
    }
}

fn anymal(
    name: &'static str,
    display_name: &'static str,
    urdf: &'static str,
    published_mass: f32,
) -> RobotSpec {
    RobotSpec {
        name,
        display_name,
        family: Family::Anymal,
        urdf,
        mesh_hulls: &[],
        joint_names: ANYMAL_JOINTS,
        default_pose: ANYMAL_POSE,
        base_link: "base",
        foot_links: ANYMAL_FEET,
        penalised_links: ANYMAL_PENALISED,
        termination_links: &["base"],
        // legged_gym's ANYmal PD (without its actuator net): IsaacLab's simple-actuator kp 40 / kd 5
        // let the 50-57 kg robots sag to 80% of standing with zero actions (robots/tests/vecenv.rs).
        training_gains: Gains { kp: 80.0, kd: 2.0 },
        stand_gains: Gains { kp: 300.0, kd: 8.0 },
        effort_limit: [80.0; NUM_JOINTS],
        saturation_effort: [120.0; NUM_JOINTS],
        velocity_limit: [7.5; NUM_JOINTS],
        action_scale: 0.5,
        spawn_height: 0.6,
        published_mass,
    }
}

fn build_all() -> Vec<RobotSpec> {
    vec![
        // A1: IsaacLab DCMotorCfg kp 25, kd 0.5, 33.5 N·m, 21 rad/s (legged_gym: kp 20).
        unitree(
            "a1",
            "Unitree A1",
            include_str!("../assets/a1.urdf"),
            "trunk",
            Gains { kp: 25.0, kd: 0.5 },
            33.5,
            21.0,
            0.42,
            13.741,
        ),
        // Go1: IsaacLab limits 23.7 N·m, 30 rad/s; PD substitute for its actuator net (kd +0.2).
        unitree(
            "go1",
            "Unitree Go1",
            include_str!("../assets/go1.urdf"),
            "trunk",
            Gains { kp: 25.0, kd: 0.7 },
            23.7,
            30.0,
            0.4,
            13.101,
        ),
        // Go2: IsaacLab DCMotorCfg kp 25, kd 0.5, 23.5 N·m, 30 rad/s.
        unitree(
            "go2",
            "Unitree Go2",
            include_str!("../assets/go2.urdf"),
            "base",
            Gains { kp: 25.0, kd: 0.5 },
            23.5,
            30.0,
            0.4,
            16.087,
        ),
        anymal(
            "anymal_b",
            "ANYbotics ANYmal B",
            include_str!("../assets/anymal_b.urdf"),
            30.421,
        ),
        anymal(
            "anymal_c",
            "ANYbotics ANYmal C",
            include_str!("../assets/anymal_c.urdf"),
            52.135,
        ),
        // ANYmal D: the vendor file's inspection payload (5.27 kg, 2 joints) is fixed into the base.
        anymal(
            "anymal_d",
            "ANYbotics ANYmal D",
            include_str!("../assets/anymal_d.urdf"),
            57.028,
        ),
        RobotSpec {
            name: "spot",
            display_name: "Boston Dynamics Spot",
            family: Family::Spot,
            urdf: include_str!("../assets/spot.urdf"),
            mesh_hulls: &[],
            joint_names: SPOT_JOINTS,
            default_pose: SPOT_POSE,
            base_link: "body",
            foot_links: SPOT_FEET,
            penalised_links: SPOT_PENALISED,
            termination_links: &["body", "fl_uleg", "fr_uleg", "hl_uleg", "hr_uleg"],
            training_gains: Gains { kp: 60.0, kd: 1.5 },
            stand_gains: Gains { kp: 300.0, kd: 8.0 },
            // IsaacLab: hips 45 N·m; knees follow a remotized lookup table (peak ~115 N·m, used here
            // as a constant). Velocity limits are estimates (the SDK file has placeholders).
            effort_limit: {
                let mut e = legs3([45.0, 45.0, 115.0]);
                e[0] = 45.0;
                e
            },
            saturation_effort: legs3([45.0, 45.0, 115.0]),
            velocity_limit: [12.0; NUM_JOINTS],
            action_scale: 0.2,
            spawn_height: 0.5,
            // Boston Dynamics Spot specifications: 32.7 kg (with battery).
            published_mass: 32.7,
        },
    ]
}

static CATALOG: std::sync::OnceLock<Vec<RobotSpec>> = std::sync::OnceLock::new();

/// Error for an unknown robot name.
#[derive(Debug, thiserror::Error)]
#[error(
    "unknown robot `{name}`\nhint: known robots are {known} (add your own with `l3p robots add <file.urdf>`)"
)]
pub struct UnknownRobot {
    /// The requested name.
    pub name: String,
    /// Comma-separated known names.
    pub known: String,
}

/// A robot added in this process (`crate::added`).
fn added_robot(key: &str) -> Option<&'static RobotSpec> {
    crate::added::find(key)
}

fn added_robots() -> Vec<&'static RobotSpec> {
    crate::added::all_added()
}

impl RobotSpec {
    /// All built-in robots.
    pub fn all() -> &'static [RobotSpec] {
        CATALOG.get_or_init(build_all)
    }

    /// Looks a robot up by short name (case-insensitive, `-` and `_` equivalent): the catalog,
    /// then the robots added in this process (`crate::added`).
    pub fn by_name(name: &str) -> Result<&'static RobotSpec, UnknownRobot> {
        let key = name.to_ascii_lowercase().replace('-', "_");
        Self::all()
            .iter()
            .find(|r| r.name == key)
            .or_else(|| added_robot(&key))
            .ok_or_else(|| UnknownRobot {
                name: name.to_string(),
                known: Self::all()
                    .iter()
                    .map(|r| r.name)
                    .chain(added_robots().iter().map(|r| r.name))
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }

    /// Parses the robot's URDF (embedded, or the added robot's file as loaded) with its
    /// [`Self::mesh_hulls`].
    pub fn model(&self) -> Result<RobotModel, UrdfError> {
        let origin = if self.family == Family::Other {
            "robot"
        } else {
            "builtin"
        };
        load_urdf_str_with_hulls(
            self.urdf,
            &format!("{origin}:{}", self.name),
            self.mesh_hulls,
        )
    }

    /// Base height over flat ground at the default pose with feet on the ground (forward kinematics of
    /// the embedded model).
    pub fn nominal_standing_height(&self) -> Result<f32, UrdfError> {
        let model = self.model()?;
        let q = self.model_order_pose(&model, &self.default_pose);
        Ok(model.standing_height(&q))
    }

    /// Reorders a canonical-order joint vector into `model.joint_names()` order (joints the spec does
    /// not name get 0).
    pub fn model_order_pose(&self, model: &RobotModel, canonical: &[f32; NUM_JOINTS]) -> Vec<f32> {
        model
            .joint_names()
            .iter()
            .map(|n| {
                self.joint_names
                    .iter()
                    .position(|j| j == n)
                    .map(|k| canonical[k])
                    .unwrap_or(0.0)
            })
            .collect()
    }
}
