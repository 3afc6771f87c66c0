//! Robots users add from their own URDF ("bring your own robot"): a [`RobotDescription`] is the
//! TOML file `l3p robots add` writes for review and editing, `l3p_sim::describe::describe` infers one from a loaded
//! model, and [`register`] / [`load_dir`] turn descriptions into [`RobotSpec`]s that
//! [`RobotSpec::by_name`] finds beside the catalog, so an added robot trains, evaluates and deploys
//! like a built-in one.
//!
//! What `l3p_sim::describe::describe` infers (every value is printed for review and can be edited in the file):
//! - legs, joint order, feet and trunk from geometry ([`crate::legs::infer_quadruped`]);
//! - the default pose: abduction 0; per leg the hip and knee angles that put the foot under the
//!   hip with the leg at [`STANDING_EXTENSION`] of its reach, the knee bending to the side its
//!   limits leave more room for (on a tie towards the body's middle, ANYmal's "X": front knees
//!   backwards, rear knees forwards) — then checked by simulation: dropped on flat
//!   ground and held with the inferred gains for 2 s, the robot must stay upright above
//!   [`MIN_SETTLED_FRACTION`] of its kinematic standing height with its feet carrying at least
//!   `l3p_sim::bench::MIN_FOOT_SHARE` of its weight (a robot resting on its shanks or knees is refused, naming
//!   the links that carry the rest);
//! - PD gains from the load: `kp` so that a quarter of the robot's weight on each foot deflects
//!   the most loaded joint by [`STATIC_SAG_RAD`] (A1 → kp ≈ 60, the shipped A1 recipe's value),
//!   at most the smallest effort limit over [`MIN_SATURATION_ERROR_RAD`]; `kd = kp / 50` (the
//!   recipe's ratio);
//! - effort and velocity limits from the URDF (leg joints without them are one error naming every
//!   missing limit, unless the caller fills them in; a limit far above what the robot's size
//!   needs — effort over [`EFFORT_OVER_STANCE`] times the stance torque, velocity that moves a
//!   thigh's end faster than [`MAX_THIGH_TIP_SPEED`] — is replaced by that bound, or the
//!   caller's value, with a note), action scale [`DEFAULT_ACTION_SCALE`] (IsaacLab's Unitree
//!   value), penalised contacts on thighs and shanks, termination on trunk contact.
//!
//! Collision meshes: `l3p robots add` loads the URDF from its file, where STL/OBJ meshes found
//! beside it are convex hulls ([`crate::mesh`]), and records those hulls in the description
//! ([`RobotDescription::mesh_hulls`]); [`register`] builds the model from the URDF's text with
//! them, so training, evaluation and actors on other machines (which get the description and the
//! URDF's text, not the mesh files) simulate the colliders the standing check used.
//!
//! Joint positions stay in the file's convention: the canonical order is applied, the canonical
//! axis signs are not (they are recorded as `axis_signs`). Every robot has its own encoder and
//! decoder, so a transfer learns any sign convention; only zero-shot play of another robot's
//! policy assumes the catalog's.
//!
//! The registry of added robots is process-wide and append-only: a [`RobotSpec`] holds `'static`
//! strings, so a registered robot's strings are leaked once — a handful of small allocations per
//! robot and process.

use std::path::{Path, PathBuf};
use std::sync::RwLock;

use serde::{Deserialize, Serialize};

use crate::catalog::{Family, Gains, MAX_PENALISED_BODIES, NUM_JOINTS, RobotSpec};
use crate::legs::{InferError, InferredLegs};
use crate::mesh::{MAX_HULL_POINTS, MeshHull};
use crate::model::{JointKind, RobotModel};
use crate::urdf::{UrdfError, load_urdf_str_with_hulls};

/// A robot that stands, but not on its feet (the simulated standing check's verdict,
/// `l3p_sim::bench::StandReport::require_on_feet`).
#[derive(Debug, Clone, thiserror::Error)]
#[error(
    "`{name}` does not stand on its feet: they carry {share:.0}% of its weight at the settled pose (at least {min:.0}% needed); the rest is carried by {carriers}\nhint: a collision shape (or a mesh stand-in) that reaches below the feet, or a pose that puts the knees lowest: fix the URDF's <collision> shapes or the default pose"
)]
pub struct NotOnFeet {
    /// Robot name.
    pub name: String,
    /// Percent of the weight on the feet.
    pub share: f32,
    /// Percent needed (`l3p_sim::bench::MIN_FOOT_SHARE`).
    pub min: f32,
    /// The links that carry the rest (`l3p_sim::bench::StandReport::carriers`).
    pub carriers: String,
}

/// Environment variable naming a directory of added robots every `l3p` process loads.
pub const ROBOTS_DIR_ENV: &str = "L3P_ROBOTS_DIR";
/// Foot depth below the hip as a fraction of the leg's reach in the inferred default pose (A1's
/// catalog pose is at 0.73, Spot's at 0.73, ANYmal's at 0.92).
pub const STANDING_EXTENSION: f32 = 0.75;
/// Static deflection (rad) of the most loaded joint under a quarter of the weight per foot that
/// sets the inferred `kp`.
pub const STATIC_SAG_RAD: f32 = 0.08;
/// The inferred `kp` reaches the smallest effort limit at this position error (rad) at the most.
pub const MIN_SATURATION_ERROR_RAD: f32 = 0.25;
/// Inferred `kd` is `kp` over this.
pub const KP_OVER_KD: f32 = 50.0;
/// Action scale of added robots (IsaacLab's Unitree robots).
pub const DEFAULT_ACTION_SCALE: f32 = 0.25;
/// Settled base height under the inferred gains, as a fraction of the kinematic standing height,
/// below which the inferred pose does not count as standing.
pub const MIN_SETTLED_FRACTION: f32 = 0.85;
/// Seconds of the simulated standing check.
pub const STAND_CHECK_SECONDS: f32 = 2.0;
/// An effort limit above this many times the stance torque (the most loaded joint's torque with a
/// quarter of the weight on each foot) is implausible and replaced by that bound (A1: 33.5 N·m
/// is 7 times its stance torque; jumping robots need 4 g on one pair of legs, 8 times).
pub const EFFORT_OVER_STANCE: f32 = 20.0;
/// A velocity limit that moves the thigh's end (the knee) faster than this (m/s) is implausible
/// and replaced by that bound (A1's 21 rad/s on a 0.2 m thigh is 4.2 m/s, Mini Cheetah's 40 rad/s
/// 8.4 m/s).
pub const MAX_THIGH_TIP_SPEED: f32 = 10.0;

/// An added robot as its TOML file says (`<robots dir>/<name>.toml`, the URDF beside it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDescription {
    /// Short name (`[a-z0-9_]+`, not a catalog robot's).
    pub name: String,
    /// Human-readable name.
    pub display_name: String,
    /// URDF file, relative to the description's directory.
    pub urdf: String,
    /// Actuated leg joints, canonical order (FL, FR, RL, RR × abduction, hip, knee).
    pub joint_names: [String; NUM_JOINTS],
    /// +1 where the file's joint axis follows the catalog's convention, −1 where it is reversed
    /// (informational: positions stay in the file's convention).
    pub axis_signs: [f32; NUM_JOINTS],
    /// Default standing joint positions (rad), canonical order.
    pub default_pose: [f32; NUM_JOINTS],
    /// Trunk link (its ground contact ends an episode).
    pub base_link: String,
    /// Foot links, canonical leg order.
    pub foot_links: [String; 4],
    /// Links whose ground contact is penalised (at most 8).
    pub penalised_links: Vec<String>,
    /// Links whose ground contact ends an episode.
    pub termination_links: Vec<String>,
    /// PD stiffness for training (N·m/rad).
    pub kp: f32,
    /// PD damping for training (N·m·s/rad).
    pub kd: f32,
    /// Continuous torque limit per joint (N·m).
    pub effort_limit: [f32; NUM_JOINTS],
    /// No-load speed per joint (rad/s).
    pub velocity_limit: [f32; NUM_JOINTS],
    /// Action scale: `q* = default + scale · a`.
    pub action_scale: f32,
    /// Base height when spawning (m).
    pub spawn_height: f32,
    /// Total mass of the model (kg).
    pub mass: f32,
    /// Convex hulls of the URDF's collision meshes, read beside it by `l3p robots add` (by the
    /// `<mesh>`'s filename and scale, points in metres): the robot is simulated with them where
    /// only this file and the URDF's text travel (training, remote actors). Empty when no mesh
    /// was read; a mesh without a hull here gets the loader's stand-ins.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mesh_hulls: Vec<MeshHull>,
}

/// What `l3p_sim::describe::describe` found besides the description: the leg structure and notes for review.
#[derive(Debug, Clone)]
pub struct Inference {
    /// The description to write.
    pub description: RobotDescription,
    /// The inferred legs (for the review table).
    pub legs: InferredLegs,
    /// Kinematic standing height at the default pose (m).
    pub standing_height: f32,
    /// Settled base height of the simulated standing check (m).
    pub settled_height: f32,
    /// Base-frame gravity z after the standing check (−1 = level).
    pub settled_gravity_z: f32,
    /// Share of the weight the feet carry at the settled pose.
    pub foot_share: f32,
    /// Links other than the feet that carry weight at the settled pose (see
    /// `l3p_sim::bench::StandReport::carriers`).
    pub carriers: String,
    /// Things a reviewer should know besides the legs' own warnings (`legs.warnings`: loader
    /// repairs, mesh stand-ins): filled-in or replaced limits, a forced write.
    pub notes: Vec<String>,
}

/// Caller-supplied values that replace inferred ones.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Name (default: the URDF's robot name, lower-cased, non-alphanumerics as `_`).
    pub name: Option<String>,
    /// PD stiffness.
    pub kp: Option<f32>,
    /// PD damping.
    pub kd: Option<f32>,
    /// Action scale.
    pub action_scale: Option<f32>,
    /// Effort limit (N·m) for leg joints whose URDF has none or an implausible one.
    pub effort: Option<f32>,
    /// Velocity limit (rad/s) for leg joints whose URDF has none or an implausible one.
    pub velocity: Option<f32>,
}

/// Why a robot cannot be added or loaded.
#[derive(Debug, thiserror::Error)]
pub enum AddError {
    /// The URDF does not load.
    #[error(transparent)]
    Urdf(#[from] UrdfError),
    /// Not a quadruped l3p can map.
    #[error(transparent)]
    Infer(#[from] InferError),
    /// Leg joints without an effort or velocity limit, every one at once.
    #[error("{}", missing_limits_message(effort, velocity))]
    MissingLimits {
        /// Joints without an effort limit.
        effort: Vec<String>,
        /// Joints without a velocity limit.
        velocity: Vec<String>,
    },
    /// A value out of range.
    #[error("`{key}` = {value}: {why}")]
    BadValue {
        /// Key in the description.
        key: String,
        /// The value.
        value: String,
        /// What is wrong.
        why: String,
    },
    /// No hip/knee angles put a foot under its hip.
    #[error(
        "no standing pose for leg {leg}: no hip angle within the joint limits puts the foot under the hip"
    )]
    NoStandingPose {
        /// Leg (`FL`, …).
        leg: String,
    },
    /// The simulated standing check failed.
    #[error(
        "`{name}` does not stand at the inferred pose and gains: base settled at {settled:.3} m of {standing:.3} m (gravity z {gravity_z:.2}); its feet carry {feet:.0}% of its weight, besides them: {carriers}\nhint: edit default_pose, kp or kd in the description (or pass --kp/--kd, or --force to write it anyway)"
    )]
    DoesNotStand {
        /// Robot name.
        name: String,
        /// Settled base height (m).
        settled: f32,
        /// Kinematic standing height (m).
        standing: f32,
        /// Base-frame gravity z.
        gravity_z: f32,
        /// Percent of the weight on the feet.
        feet: f32,
        /// The links besides the feet that carry weight.
        carriers: String,
    },
    /// The robot stands, but not on its feet.
    #[error("{0}\n(or pass --force to write it anyway)")]
    NotOnFeet(#[from] NotOnFeet),
    /// A name already taken by a catalog robot, or not `[a-z0-9_]+`.
    #[error("robot name `{0}`: {1}")]
    Name(String, String),
    /// File I/O.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A description that does not parse.
    #[error("{path}: {message}")]
    Toml {
        /// File.
        path: PathBuf,
        /// Parser message.
        message: String,
    },
    /// A simulation error during the standing check.
    #[error("standing check: {0}")]
    Sim(String),
}

fn missing_limits_message(effort: &[String], velocity: &[String]) -> String {
    let mut parts = Vec::new();
    let mut flags = Vec::new();
    for (what, joints) in [("effort", effort), ("velocity", velocity)] {
        if !joints.is_empty() {
            parts.push(format!("no {what} limit: {}", joints.join(", ")));
            flags.push(format!("--{what}"));
        }
    }
    format!(
        "leg joints without limits in the URDF ({})\nhint: add <limit effort=\"…\" velocity=\"…\"/> to them, or pass {} for joints without one",
        parts.join("; "),
        flags.join(" and ")
    )
}

/// Lower-cased name with every non-alphanumeric as `_` (`Unitree A1` → `unitree_a1`).
pub fn sanitize_name(name: &str) -> String {
    let s: String = name
        .trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    s.trim_matches('_').to_string()
}

/// A robot name is `[a-z0-9_]+` and not a catalog robot's.
pub fn check_name(name: &str) -> Result<(), AddError> {
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
    {
        return Err(AddError::Name(
            name.into(),
            "expected lower-case letters, digits and `_`".into(),
        ));
    }
    if RobotSpec::all().iter().any(|r| r.name == name) {
        return Err(AddError::Name(
            name.into(),
            "is a built-in robot; pass --name".into(),
        ));
    }
    Ok(())
}

impl AddError {
    /// A value that is wrong for `key`, and why.
    pub fn bad_value(key: &str, value: impl std::fmt::Display, why: &str) -> AddError {
        AddError::BadValue {
            key: key.into(),
            value: value.to_string(),
            why: why.into(),
        }
    }
}

fn leak(s: String) -> &'static str {
    Box::leak(s.into_boxed_str())
}

impl RobotDescription {
    /// Checks every number and name list (not the names against a model: see [`Self::spec_with_model`]).
    pub fn validate(&self) -> Result<(), AddError> {
        check_name(&self.name)?;
        let positive = |key: &str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(AddError::bad_value(key, v, "expected a finite value > 0"))
            }
        };
        positive("kp", self.kp)?;
        positive("kd", self.kd)?;
        positive("action_scale", self.action_scale)?;
        positive("spawn_height", self.spawn_height)?;
        positive("mass", self.mass)?;
        for k in 0..NUM_JOINTS {
            positive(&format!("effort_limit[{k}]"), self.effort_limit[k])?;
            positive(&format!("velocity_limit[{k}]"), self.velocity_limit[k])?;
            let q = self.default_pose[k];
            if !q.is_finite() || q.abs() > 2.0 * std::f32::consts::PI {
                return Err(AddError::bad_value(
                    &format!("default_pose[{k}]"),
                    q,
                    "expected a finite angle within ±2π",
                ));
            }
            if self.axis_signs[k] != 1.0 && self.axis_signs[k] != -1.0 {
                return Err(AddError::bad_value(
                    &format!("axis_signs[{k}]"),
                    self.axis_signs[k],
                    "expected 1 or -1",
                ));
            }
        }
        if self.penalised_links.len() > MAX_PENALISED_BODIES {
            return Err(AddError::bad_value(
                "penalised_links",
                self.penalised_links.len(),
                &format!("at most {MAX_PENALISED_BODIES} links"),
            ));
        }
        for (i, h) in self.mesh_hulls.iter().enumerate() {
            if h.points.len() > MAX_HULL_POINTS {
                return Err(AddError::bad_value(
                    &format!("mesh_hulls[{i}].points"),
                    h.points.len(),
                    &format!("at most {MAX_HULL_POINTS} points (mesh `{}`)", h.file),
                ));
            }
        }
        Ok(())
    }

    /// A [`RobotSpec`] for this description and its URDF text (leaked, see the module doc);
    /// every joint and link it names must be in the model.
    pub fn spec_with_model(
        &self,
        model: &RobotModel,
        urdf: &'static str,
    ) -> Result<RobotSpec, AddError> {
        self.validate()?;
        for (k, j) in self.joint_names.iter().enumerate() {
            let ok = model
                .body_of_joint(j)
                .and_then(|b| model.bodies[b].joint.as_ref())
                .is_some_and(|s| s.kind == JointKind::Revolute);
            if !ok {
                return Err(AddError::bad_value(
                    &format!("joint_names[{k}]"),
                    j,
                    "no revolute joint of that name in the URDF",
                ));
            }
        }
        let links = [self.base_link.clone()]
            .into_iter()
            .chain(self.foot_links.iter().cloned())
            .chain(self.penalised_links.iter().cloned())
            .chain(self.termination_links.iter().cloned());
        for l in links {
            if model.body_of_link(&l).is_none() {
                return Err(AddError::bad_value(
                    "links",
                    &l,
                    "no link of that name in the URDF",
                ));
            }
        }
        let strs = |v: &[String]| -> &'static [&'static str] {
            Box::leak(
                v.iter()
                    .map(|s| leak(s.clone()))
                    .collect::<Vec<_>>()
                    .into_boxed_slice(),
            )
        };
        Ok(RobotSpec {
            name: leak(self.name.clone()),
            display_name: leak(self.display_name.clone()),
            family: Family::Other,
            urdf,
            mesh_hulls: Box::leak(self.mesh_hulls.clone().into_boxed_slice()),
            joint_names: std::array::from_fn(|k| leak(self.joint_names[k].clone())),
            default_pose: self.default_pose,
            base_link: leak(self.base_link.clone()),
            foot_links: std::array::from_fn(|i| leak(self.foot_links[i].clone())),
            penalised_links: strs(&self.penalised_links),
            termination_links: strs(&self.termination_links),
            training_gains: Gains {
                kp: self.kp,
                kd: self.kd,
            },
            stand_gains: Gains {
                kp: 3.0 * self.kp,
                kd: 3.0 * self.kd,
            },
            effort_limit: self.effort_limit,
            saturation_effort: self.effort_limit,
            velocity_limit: self.velocity_limit,
            action_scale: self.action_scale,
            spawn_height: self.spawn_height,
            published_mass: self.mass,
        })
    }

    /// The file `l3p robots add` writes: a header saying where each value came from, then the
    /// TOML.
    pub fn to_toml(&self) -> String {
        // toml writes an f32 as the f64 it widens to (0.83 → 0.8300000429153442): write each
        // float as the shortest decimal that reads back as the same f32.
        fn shortest(v: &mut toml::Value) {
            match v {
                toml::Value::Float(f) => {
                    *f = (*f as f32).to_string().parse().unwrap_or(*f);
                }
                toml::Value::Array(a) => a.iter_mut().for_each(shortest),
                toml::Value::Table(t) => t.iter_mut().for_each(|(_, v)| shortest(v)),
                _ => {}
            }
        }
        let mut body = match toml::Value::try_from(self) {
            Ok(mut value) => {
                shortest(&mut value);
                // Written below, one point a line (toml writes an array on one line).
                if let toml::Value::Table(t) = &mut value {
                    t.remove("mesh_hulls");
                }
                toml::to_string(&value).unwrap_or_default()
            }
            Err(_) => String::new(),
        };
        if !self.mesh_hulls.is_empty() {
            body.push_str(
                "\n# Convex hulls of the URDF's collision meshes, read beside it when the robot was added:\n\
                 # the `<mesh>` filename as the URDF writes it, its scale, the points (m, scale applied).\n",
            );
        }
        let float = |x: f32| {
            let mut v = toml::Value::Float(x.into());
            shortest(&mut v);
            v.to_string()
        };
        let triple = |p: [f32; 3]| format!("[{}, {}, {}]", float(p[0]), float(p[1]), float(p[2]));
        for h in &self.mesh_hulls {
            let points: String = h
                .points
                .iter()
                .map(|p| format!("    {},\n", triple(*p)))
                .collect();
            body.push_str(&format!(
                "\n[[mesh_hulls]]\nfile = {}\nscale = {}\npoints = [\n{points}]\n",
                toml::Value::String(h.file.clone()),
                triple(h.scale),
            ));
        }
        format!(
            "# An l3p robot description (`l3p robots add`); edit any value and run `l3p robots check {}`.\n\
             # Inferred: joint order, feet and trunk from geometry; default_pose (foot under hip at {:.0}% of\n\
             # the leg's reach, checked standing in simulation); kp from the stance load ({} rad of\n\
             # sag), kd = kp / {}; limits from the URDF. axis_signs are informational: joint positions\n\
             # use the file's axes.\n{body}",
            self.name,
            100.0 * STANDING_EXTENSION,
            STATIC_SAG_RAD,
            KP_OVER_KD,
        )
    }

    /// Reads a description file and its URDF (relative to the file's directory).
    pub fn load(path: &Path) -> Result<(RobotDescription, String), AddError> {
        let text = std::fs::read_to_string(path).map_err(|source| AddError::Io {
            path: path.into(),
            source,
        })?;
        let desc: RobotDescription = toml::from_str(&text).map_err(|e| AddError::Toml {
            path: path.into(),
            message: e.to_string(),
        })?;
        let urdf_path = path.parent().unwrap_or(Path::new(".")).join(&desc.urdf);
        let urdf = std::fs::read_to_string(&urdf_path).map_err(|source| AddError::Io {
            path: urdf_path,
            source,
        })?;
        Ok((desc, urdf))
    }
}

/// Registered robots with the description each came from.
static ADDED: RwLock<Vec<(RobotDescription, &'static RobotSpec)>> = RwLock::new(Vec::new());

/// Registers a description (with its URDF text) so that [`RobotSpec::by_name`] finds it; its
/// model has the description's mesh hulls ([`RobotDescription::mesh_hulls`]). The same
/// description and URDF registered again returns the earlier spec; a different one under the same
/// name replaces it for later lookups.
pub fn register(desc: &RobotDescription, urdf: String) -> Result<&'static RobotSpec, AddError> {
    {
        let added = ADDED.read().unwrap_or_else(|e| e.into_inner());
        if let Some((_, found)) = added
            .iter()
            .find(|(d, s)| d == desc && s.urdf == urdf.as_str())
        {
            return Ok(found);
        }
    }
    let model = load_urdf_str_with_hulls(&urdf, &format!("robot:{}", desc.name), &desc.mesh_hulls)?;
    let spec: &'static RobotSpec = Box::leak(Box::new(desc.spec_with_model(&model, leak(urdf))?));
    let mut added = ADDED.write().unwrap_or_else(|e| e.into_inner());
    added.retain(|(_, s)| s.name != spec.name);
    added.push((desc.clone(), spec));
    Ok(spec)
}

/// An added robot by its (normalised) name.
pub fn find(name: &str) -> Option<&'static RobotSpec> {
    ADDED
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .find(|(_, s)| s.name == name)
        .map(|(_, s)| *s)
}

/// Every added robot registered in this process.
pub fn all_added() -> Vec<&'static RobotSpec> {
    ADDED
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .map(|(_, s)| *s)
        .collect()
}

/// Registers the added robots every l3p process knows: `<data_dir>/robots` when a config names a
/// data directory, else `$L3P_ROBOTS_DIR`, else `./l3p-data/robots`. A bad file is logged as a
/// warning, not fatal: the catalog robots stay usable.
pub fn load_added_robots(data_dir: Option<&Path>) {
    let dir = match data_dir {
        Some(d) => d.join("robots"),
        None => std::env::var_os(ROBOTS_DIR_ENV)
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("l3p-data").join("robots")),
    };
    if let Err(e) = load_dir(&dir) {
        tracing::warn!("added robots in {}: {e}", dir.display());
    }
}

/// Registers every `*.toml` description in `dir` (a missing directory is empty); the first bad
/// file is an error naming it.
pub fn load_dir(dir: &Path) -> Result<Vec<&'static RobotSpec>, AddError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(source) => {
            return Err(AddError::Io {
                path: dir.into(),
                source,
            });
        }
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for p in paths {
        let (desc, urdf) = RobotDescription::load(&p)?;
        out.push(register(&desc, urdf).map_err(|e| AddError::Toml {
            path: p.clone(),
            message: e.to_string(),
        })?);
    }
    Ok(out)
}
