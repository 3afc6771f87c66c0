//! Tolerant URDF loading: [`load_urdf_file`] / [`load_urdf_str`] turn any vendor URDF into a
//! [`RobotModel`], reporting problems as [`UrdfError`] (file, element, line).
//!
//! Pipeline:
//! 1. A pre-pass over the XML text (xml-rs) checks the numeric attributes of the elements the model
//!    uses, with line numbers, and rewrites the document without what makes `urdf-rs` 0.10 fail or
//!    what it does not need: the second and later `<material>` of a `<visual>` (the current Go2 file
//!    has several, which urdf-rs rejects with `duplicate field material`), `<gazebo>` and
//!    `<transmission>` blocks, comments; a `<limit>` without `velocity` (which urdf-rs requires)
//!    gets `velocity="0"`, read as no limit.
//! 2. `urdf-rs` parses the cleaned text.
//! 3. Links are merged across fixed joints into rigid bodies (masses, centres of mass and inertia
//!    tensors combined with the parallel-axis rule, colliders re-expressed in the body frame).
//!    A mesh collider of a URDF loaded from a file ([`load_urdf_file`]) whose STL or OBJ file is
//!    found beside it (relative, `package://` and `file://` paths: see [`crate::mesh`]) is the
//!    convex hull of its scaled vertices ([`ShapeSpec::ConvexHull`], at most
//!    [`crate::mesh::MAX_HULL_POINTS`] points), named in `warnings`; text loaded with the hulls
//!    such a load returned ([`load_urdf_file_with_hulls`] → [`load_urdf_str_with_hulls`]: an added
//!    robot, whose description records them) gets the same hulls. Any other mesh collider — a
//!    URDF loaded from text alone ([`load_urdf_str`]: no directory to look in), a missing file,
//!    an unread format, an unreadable, empty, flat or non-finite mesh (a warning names the file and why) — gets
//!    primitive stand-ins, [`MeshStandIn`]: on a leg link, capsules along the link's
//!    joint-to-child segments with a radius from its inertia, stopping short of a foot's shapes,
//!    so that no stand-in hangs below the feet; on the trunk and on leaf links (nothing to run a
//!    segment to), a box sized from the link's inertia. Each replaced mesh is named in `warnings`
//!    with its stand-in. Links without inertia or with zero mass contribute no mass, and a moving
//!    body left with no mass gets a small placeholder mass (recorded in `warnings`).
//!    Continuous joints have no limits. Floating, planar and spherical joints are rejected.

use std::collections::HashMap;
use std::path::Path;

use crate::math::{Mat3, Pose, Rot3, Vec3};
use crate::mesh::MeshHull;
use xml::common::Position;
use xml::reader::{EventReader, ParserConfig, XmlEvent};
use xml::writer::EmitterConfig;

use crate::model::{
    BodySpec, ColliderSpec, JointKind, JointSpec, RobotModel, ShapeSpec, parallel_axis,
};

/// Mass given to a moving body that has no mass in the file (kg).
pub const PLACEHOLDER_MASS: f32 = 0.01;

/// Errors from URDF loading.
#[derive(Debug, thiserror::Error)]
pub enum UrdfError {
    /// The file could not be read.
    #[error("cannot read urdf file {file}: {source}")]
    Io {
        /// Path.
        file: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The text is not well-formed XML.
    #[error("{file}:{line}: malformed xml: {message}")]
    Xml {
        /// Path or name.
        file: String,
        /// 1-based line.
        line: u64,
        /// Parser message.
        message: String,
    },
    /// An element has a missing or malformed attribute.
    #[error("{file}:{line}: <{element}>: {message}")]
    Invalid {
        /// Path or name.
        file: String,
        /// Element name.
        element: String,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
    /// urdf-rs rejected the (cleaned) document.
    #[error("{file}: urdf-rs rejected the file: {message}")]
    Parse {
        /// Path or name.
        file: String,
        /// urdf-rs message.
        message: String,
    },
    /// The kinematic tree is unusable (no root, several roots, unknown links, unsupported joints).
    #[error("{file}: {message}")]
    Structure {
        /// Path or name.
        file: String,
        /// What is wrong.
        message: String,
    },
}

/// Loads a URDF file from disk; collision meshes found beside it are convex hulls (module doc).
pub fn load_urdf_file(path: impl AsRef<Path>) -> Result<RobotModel, UrdfError> {
    load_urdf_file_with_hulls(path).map(|(model, _)| model)
}

/// [`load_urdf_file`], with the hull of every mesh used as one (each file and scale once, in the
/// file's order): what [`load_urdf_str_with_hulls`] needs to build the same model from the text.
pub fn load_urdf_file_with_hulls(
    path: impl AsRef<Path>,
) -> Result<(RobotModel, Vec<MeshHull>), UrdfError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| UrdfError::Io {
        file: file.clone(),
        source,
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    load(&text, &file, MeshStandIn::default(), MeshSource::Dir(dir))
}

/// Loads a URDF document from text; `file` names it in errors. No mesh is read (there is no
/// directory to find one in): every mesh collider gets stand-ins.
pub fn load_urdf_str(text: &str, file: &str) -> Result<RobotModel, UrdfError> {
    load_urdf_str_with(text, file, MeshStandIn::default())
}

/// [`load_urdf_str`] with another rule for the shapes that stand in for meshes.
pub fn load_urdf_str_with(
    text: &str,
    file: &str,
    stand_in: MeshStandIn,
) -> Result<RobotModel, UrdfError> {
    load(text, file, stand_in, MeshSource::None).map(|(model, _)| model)
}

/// Loads a URDF document from text whose mesh colliders are the given `hulls` (matched by the
/// `<mesh>`'s filename and scale, as [`load_urdf_file_with_hulls`] returned them): an added
/// robot's model where only its URDF text and description travel. A mesh without a hull, or
/// whose points make no hull (checked as a mesh file's are), gets stand-ins.
pub fn load_urdf_str_with_hulls(
    text: &str,
    file: &str,
    hulls: &[MeshHull],
) -> Result<RobotModel, UrdfError> {
    load(text, file, MeshStandIn::default(), MeshSource::Hulls(hulls)).map(|(model, _)| model)
}

/// Where the points of mesh colliders come from.
#[derive(Debug, Clone, Copy)]
enum MeshSource<'a> {
    /// Nowhere: every mesh gets stand-ins.
    None,
    /// Mesh files looked for relative to this directory (the URDF's).
    Dir(&'a Path),
    /// Hulls given by filename and scale (an added robot's description).
    Hulls(&'a [MeshHull]),
}

/// Loads a URDF document whose meshes come from `meshes`; also returns the hulls used.
fn load(
    text: &str,
    file: &str,
    stand_in: MeshStandIn,
    meshes: MeshSource,
) -> Result<(RobotModel, Vec<MeshHull>), UrdfError> {
    let cleaned = prepass(text, file)?;
    let robot = urdf_rs::read_from_string(&cleaned).map_err(|e| UrdfError::Parse {
        file: file.to_string(),
        message: e.to_string(),
    })?;
    build(&robot, file, stand_in, meshes)
}

/// What replaces a mesh collider that is not used as a convex hull (a URDF loaded from text, or
/// a mesh file missing or unreadable: see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MeshStandIn {
    /// On links of moving bodies that have child joints: a capsule along each segment from the
    /// link's frame (its joint) to a child joint, radius from the link's inertia about the
    /// segment (a rod's `I = m r² / 2`, at most a quarter of the segment), stopping
    /// short of a tip's shapes (a child below which no joint moves: a foot) by their extent;
    /// elsewhere (the trunk, leaf links) the box of [`MeshStandIn::InertiaBox`]. Boxes and
    /// capsules are shrunk to a plausible density (a 1 g sensor with a large inertia is not a
    /// large box). Thin capsules on the segments cannot reach below the foot that ends them
    /// while the leg stands.
    #[default]
    Segments,
    /// A box sized from the link's inertia at its centre of mass, for every mesh. On slender
    /// shank links (Unitree B1, Solo-12, Mini Cheetah) the box reaches below the foot and the
    /// robot stands on its shanks: kept to show that.
    InertiaBox,
}

/// Lowest density (kg/m³) of a stand-in under [`MeshStandIn::Segments`]: a box or capsule from
/// inertia is shrunk to this density at the most (A1's `imu_link`, 1 g with the inertia of a
/// 0.77 m cube, would otherwise be a 0.77 m cube on the trunk; real links are 500–3000).
const MIN_STAND_IN_DENSITY: f32 = 100.0;
/// Smallest radius of a capsule stand-in (m).
const MIN_CAPSULE_RADIUS: f32 = 0.005;
/// A capsule stand-in's radius is at most its segment's length over this.
const MAX_CAPSULE_ASPECT: f32 = 4.0;

/// Half extents of the box with mass `m` and inertia diagonal `d` (about its centre), each side
/// at least 2 cm.
fn inertia_box_half(m: f32, d: Vec3) -> Vec3 {
    let side = |a: f32, b: f32, c: f32| ((6.0 * (b + c - a) / m).max(0.0).sqrt()).max(0.02);
    Vec3::new(
        side(d.x, d.y, d.z),
        side(d.y, d.x, d.z),
        side(d.z, d.x, d.y),
    ) * 0.5
}

/// [`inertia_box_half`] shrunk (keeping its proportions) to [`MIN_STAND_IN_DENSITY`] at the most.
fn dense_box_half(m: f32, d: Vec3) -> Vec3 {
    let half = inertia_box_half(m, d);
    let volume = 8.0 * half.x * half.y * half.z;
    let most = m / MIN_STAND_IN_DENSITY;
    if volume > most {
        half * (most / volume).cbrt()
    } else {
        half
    }
}

/// Radius of a sphere about the shape's frame that holds the shape; `hull`: the points of a mesh
/// used as a convex hull.
fn bounding_radius(
    g: &urdf_rs::Geometry,
    hull: Option<&[Vec3]>,
    inertial: &urdf_rs::Inertial,
) -> f32 {
    if let Some(points) = hull {
        return points.iter().map(|p| p.length()).fold(0.0, f32::max);
    }
    match g {
        urdf_rs::Geometry::Box { size } => v3(size).length() * 0.5,
        urdf_rs::Geometry::Sphere { radius } => *radius as f32,
        urdf_rs::Geometry::Cylinder { radius, length } => {
            (*radius as f32).hypot(*length as f32 * 0.5)
        }
        urdf_rs::Geometry::Capsule { radius, length } => (*radius + *length * 0.5) as f32,
        // Its stand-in is an inertia box at the centre of mass (a tip is a leaf link).
        urdf_rs::Geometry::Mesh { .. } => {
            let m = inertial.mass.value as f32;
            if m > 0.0 {
                let i = &inertial.inertia;
                let d = Vec3::new(i.ixx as f32, i.iyy as f32, i.izz as f32);
                v3(&inertial.origin.xyz).length() + dense_box_half(m, d).length()
            } else {
                0.0
            }
        }
    }
}

/// One segment a capsule stand-in runs along: from a link's frame to `end` (link frame).
struct SegmentEnd {
    end: Vec3,
    /// Distance from `end` the capsule keeps: the extent of the tip's shapes, 0 when `end` is not
    /// a tip.
    clearance: f32,
    /// The child link at `end`.
    child: String,
}

const SKIPPED_TOP_LEVEL: [&str; 2] = ["gazebo", "transmission"];

/// Largest URDF accepted (bytes): vendor files are 10–500 KB; the limit only bounds the work a
/// hostile file can cause.
pub const MAX_URDF_BYTES: usize = 16 * 1024 * 1024;
/// Deepest element nesting accepted: URDF needs 5 (`robot/link/visual/geometry/mesh`), and the
/// serde parser behind `urdf-rs` recurses once per level (20,000 levels overflowed its stack).
pub const MAX_URDF_DEPTH: usize = 32;
/// Largest magnitude of any number in a URDF (masses in kg, lengths in m, limits): far above any
/// robot, far below where `f32` overflows (a mass of 1e300 became infinity).
pub const MAX_URDF_MAGNITUDE: f64 = 1.0e6;

/// Validates attributes (with line numbers) and rewrites the document without the parts urdf-rs
/// trips on. Returns the cleaned XML text.
fn prepass(text: &str, file: &str) -> Result<String, UrdfError> {
    if text.len() > MAX_URDF_BYTES {
        return Err(UrdfError::Xml {
            file: file.to_string(),
            line: 0,
            message: format!(
                "{} bytes is more than the {MAX_URDF_BYTES} a URDF may have",
                text.len()
            ),
        });
    }
    let config = ParserConfig::new()
        .ignore_comments(true)
        .trim_whitespace(true);
    let mut reader = EventReader::new_with_config(text.as_bytes(), config);
    let mut out = Vec::with_capacity(text.len());
    let mut writer = EmitterConfig::new()
        .perform_indent(false)
        .write_document_declaration(false)
        .create_writer(&mut out);
    // Stack of open elements: (name, number of <material> children seen so far).
    let mut stack: Vec<(String, usize)> = Vec::new();
    let mut skip_depth = 0usize;
    loop {
        let mut ev = reader.next().map_err(|e| UrdfError::Xml {
            file: file.to_string(),
            line: e.position().row + 1,
            message: e.msg().to_string(),
        })?;
        let line = reader.position().row + 1;
        let mut no_velocity = false;
        match &ev {
            XmlEvent::EndDocument => break,
            XmlEvent::StartElement {
                name, attributes, ..
            } => {
                let local = name.local_name.clone();
                if stack.len() + skip_depth >= MAX_URDF_DEPTH {
                    return Err(UrdfError::Xml {
                        file: file.to_string(),
                        line,
                        message: format!(
                            "<{local}> is nested more than {MAX_URDF_DEPTH} elements deep"
                        ),
                    });
                }
                if skip_depth > 0 {
                    skip_depth += 1;
                    continue;
                }
                let parent = stack.last().map(|(n, _)| n.clone()).unwrap_or_default();
                let parent = parent.as_str();
                let mut skip = stack.len() == 1 && SKIPPED_TOP_LEVEL.contains(&local.as_str());
                if local == "material"
                    && parent == "visual"
                    && let Some(top) = stack.last_mut()
                {
                    top.1 += 1;
                    skip |= top.1 > 1;
                }
                if skip {
                    skip_depth = 1;
                    continue;
                }
                let attr = |k: &str| {
                    attributes
                        .iter()
                        .find(|a| a.name.local_name == k)
                        .map(|a| a.value.as_str())
                };
                validate(&local, parent, &attr, file, line)?;
                no_velocity = local == "limit" && parent == "joint" && attr("velocity").is_none();
                stack.push((local, 0));
            }
            XmlEvent::EndElement { .. } => {
                if skip_depth > 0 {
                    skip_depth -= 1;
                    continue;
                }
                stack.pop();
            }
            _ => {
                if skip_depth > 0 {
                    continue;
                }
            }
        }
        // urdf-rs requires `velocity` on a `<limit>`: a missing one is written as 0, which the
        // model reads as "no velocity limit" (as a missing `effort`).
        if no_velocity && let XmlEvent::StartElement { attributes, .. } = &mut ev {
            attributes.push(xml::attribute::OwnedAttribute::new(
                xml::name::OwnedName::local("velocity"),
                "0",
            ));
        }
        if let Some(w) = ev.as_writer_event() {
            writer.write(w).map_err(|e| UrdfError::Xml {
                file: file.to_string(),
                line,
                message: e.to_string(),
            })?;
        }
    }
    drop(writer);
    String::from_utf8(out).map_err(|e| UrdfError::Xml {
        file: file.to_string(),
        line: 0,
        message: e.to_string(),
    })
}

fn parse_floats(s: &str) -> Option<Vec<f64>> {
    s.split_whitespace()
        .map(|t| t.parse::<f64>().ok().filter(|v| plausible_magnitude(*v)))
        .collect()
}

fn plausible_magnitude(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_URDF_MAGNITUDE
}

fn validate<'a>(
    element: &str,
    parent: &str,
    attr: &dyn Fn(&str) -> Option<&'a str>,
    file: &str,
    line: u64,
) -> Result<(), UrdfError> {
    let err = |message: String| UrdfError::Invalid {
        file: file.to_string(),
        element: element.to_string(),
        line,
        message,
    };
    let vec3 = |k: &str, required: bool| -> Result<Option<Vec<f64>>, UrdfError> {
        match attr(k) {
            None if required => Err(err(format!("missing attribute `{k}`"))),
            None => Ok(None),
            Some(v) => match parse_floats(v) {
                Some(f) if f.len() == 3 => Ok(Some(f)),
                _ => Err(err(format!("attribute `{k}`=\"{v}\" is not three numbers"))),
            },
        }
    };
    let num = |k: &str, required: bool| -> Result<Option<f64>, UrdfError> {
        match attr(k) {
            None if required => Err(err(format!("missing attribute `{k}`"))),
            None => Ok(None),
            Some(v) => match v.trim().parse::<f64>() {
                Ok(f) if plausible_magnitude(f) => Ok(Some(f)),
                Ok(f) if f.is_finite() => Err(err(format!(
                    "attribute `{k}`=\"{v}\" is beyond ±{MAX_URDF_MAGNITUDE:e}"
                ))),
                _ => Err(err(format!("attribute `{k}`=\"{v}\" is not a number"))),
            },
        }
    };
    let non_negative = |k: &str, v: Option<f64>| -> Result<(), UrdfError> {
        match v {
            Some(v) if v < 0.0 => Err(err(format!("negative {k} {v}"))),
            _ => Ok(()),
        }
    };
    match element {
        "link" if attr("name").is_none() => {
            return Err(err("missing attribute `name`".into()));
        }
        "joint" if parent == "robot" => {
            if attr("name").is_none() {
                return Err(err("missing attribute `name`".into()));
            }
            match attr("type") {
                Some(
                    "revolute" | "continuous" | "prismatic" | "fixed" | "floating" | "planar"
                    | "spherical",
                ) => {}
                Some(t) => return Err(err(format!("unknown joint type `{t}`"))),
                None => return Err(err("missing attribute `type`".into())),
            }
        }
        "parent" | "child" if parent == "joint" && attr("link").is_none() => {
            return Err(err("missing attribute `link`".into()));
        }
        "origin" => {
            vec3("xyz", false)?;
            vec3("rpy", false)?;
        }
        "axis" => {
            vec3("xyz", true)?;
        }
        "mass" => {
            if let Some(m) = num("value", true)?
                && m < 0.0
            {
                return Err(err(format!("negative mass {m}")));
            }
        }
        "inertia" => {
            let mut m = [0.0; 6];
            for (v, k) in m.iter_mut().zip(["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]) {
                *v = num(k, false)?.unwrap_or(0.0);
            }
            if let Some(why) = implausible_inertia(m) {
                return Err(err(why));
            }
        }
        "limit" if parent == "joint" => {
            for k in ["effort", "velocity"] {
                if let Some(v) = num(k, false)?
                    && v < 0.0
                {
                    return Err(err(format!("negative {k} {v}")));
                }
            }
            if let (Some(lo), Some(hi)) = (num("lower", false)?, num("upper", false)?)
                && lo > hi
            {
                return Err(err(format!("lower limit {lo} is above upper limit {hi}")));
            }
        }
        "box" => {
            if let Some(size) = vec3("size", true)?
                && size.iter().any(|v| *v < 0.0)
            {
                return Err(err(format!("negative box size {size:?}")));
            }
        }
        "sphere" => {
            non_negative("radius", num("radius", true)?)?;
        }
        "cylinder" | "capsule" => {
            non_negative("radius", num("radius", true)?)?;
            non_negative("length", num("length", true)?)?;
        }
        "mesh" => {
            if attr("filename").is_none() {
                return Err(err("missing attribute `filename`".into()));
            }
            vec3("scale", false)?;
        }
        _ => {}
    }
    Ok(())
}

/// Why an inertia tensor `[ixx, ixy, ixz, iyy, iyz, izz]` cannot be a body's, if it cannot: it
/// must be positive semi-definite (leading minors ≥ 0) and its principal moments must satisfy the
/// triangle inequality (checked on the diagonal, which bounds them for a physical body).
fn implausible_inertia([ixx, ixy, ixz, iyy, iyz, izz]: [f64; 6]) -> Option<String> {
    // Relative slack for rounding in vendor files.
    let scale = ixx.abs().max(iyy.abs()).max(izz.abs()).max(1e-12);
    let eps = 1e-9 * scale;
    if ixx < -eps || iyy < -eps || izz < -eps {
        return Some(format!(
            "negative moment of inertia (ixx {ixx}, iyy {iyy}, izz {izz})"
        ));
    }
    let minor2 = ixx * iyy - ixy * ixy;
    let det = ixx * (iyy * izz - iyz * iyz) - ixy * (ixy * izz - iyz * ixz)
        + ixz * (ixy * iyz - iyy * ixz);
    if minor2 < -1e-9 * scale * scale || det < -1e-9 * scale * scale * scale {
        return Some("inertia tensor is not positive semi-definite".into());
    }
    let slack = 1e-6 * scale;
    if ixx + iyy + slack < izz || iyy + izz + slack < ixx || izz + ixx + slack < iyy {
        return Some(format!(
            "moments of inertia break the triangle inequality (ixx {ixx}, iyy {iyy}, izz {izz})"
        ));
    }
    None
}

fn v3(v: &urdf_rs::Vec3) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

fn pose_of(p: &urdf_rs::Pose) -> Pose {
    let rot = Rot3::from_rotation_z(p.rpy[2] as f32)
        * Rot3::from_rotation_y(p.rpy[1] as f32)
        * Rot3::from_rotation_x(p.rpy[0] as f32);
    Pose::from_parts(v3(&p.xyz), rot)
}

/// Accumulates mass properties about the body origin.
#[derive(Clone, Copy)]
struct MassAcc {
    mass: f32,
    first_moment: Vec3,
    inertia_origin: Mat3,
}

impl Default for MassAcc {
    // Not derived: glam's `Mat3::default()` is the identity.
    fn default() -> Self {
        Self {
            mass: 0.0,
            first_moment: Vec3::ZERO,
            inertia_origin: Mat3::ZERO,
        }
    }
}

struct Builder<'a> {
    file: &'a str,
    robot: &'a urdf_rs::Robot,
    links: HashMap<&'a str, usize>,
    children: HashMap<&'a str, Vec<usize>>,
    bodies: Vec<BodySpec>,
    acc: Vec<MassAcc>,
    warnings: Vec<String>,
    stand_in: MeshStandIn,
    /// Each mesh collider (link index, collision index) that was looked for: its hull points or
    /// why there are none. Empty for a URDF loaded from text.
    meshes: HashMap<(usize, usize), Result<Vec<Vec3>, String>>,
}

/// The hull points of every collision mesh of `robot` by (link, collision) index, or why it has
/// none (each file and scale read or checked once); no entry for a mesh without a source.
fn read_meshes(
    robot: &urdf_rs::Robot,
    source: MeshSource,
) -> HashMap<(usize, usize), Result<Vec<Vec3>, String>> {
    let mut by_file: HashMap<(&str, [u32; 3]), Option<Result<Vec<Vec3>, String>>> = HashMap::new();
    let mut out = HashMap::new();
    for (li, link) in robot.links.iter().enumerate() {
        for (ci, col) in link.collision.iter().enumerate() {
            if let urdf_rs::Geometry::Mesh { filename, scale } = &col.geometry {
                let scale = scale.as_ref().map_or(Vec3::ONE, v3);
                let read = by_file
                    .entry((filename.as_str(), scale.to_array().map(f32::to_bits)))
                    .or_insert_with(|| match source {
                        MeshSource::None => None,
                        MeshSource::Dir(dir) => Some(crate::mesh::load_hull(filename, scale, dir)),
                        MeshSource::Hulls(hulls) => hulls
                            .iter()
                            .find(|h| h.file == *filename && h.scale == scale.to_array())
                            .map(|h| {
                                let points: Vec<Vec3> =
                                    h.points.iter().map(|p| Vec3::from_array(*p)).collect();
                                crate::mesh::hull_points(&points, Vec3::ONE).map_err(|why| {
                                    format!("its hull in the robot description: {why}")
                                })
                            }),
                    });
                if let Some(read) = read {
                    out.insert((li, ci), read.clone());
                }
            }
        }
    }
    out
}

/// The hulls of `meshes` by filename and scale, each once, in the file's order.
fn used_hulls(
    robot: &urdf_rs::Robot,
    meshes: &HashMap<(usize, usize), Result<Vec<Vec3>, String>>,
) -> Vec<MeshHull> {
    let mut out: Vec<MeshHull> = Vec::new();
    for (li, link) in robot.links.iter().enumerate() {
        for (ci, col) in link.collision.iter().enumerate() {
            if let urdf_rs::Geometry::Mesh { filename, scale } = &col.geometry
                && let Some(Ok(points)) = meshes.get(&(li, ci))
            {
                let scale = scale.as_ref().map_or(Vec3::ONE, v3).to_array();
                if !out.iter().any(|h| h.file == *filename && h.scale == scale) {
                    out.push(MeshHull {
                        file: filename.clone(),
                        scale,
                        points: points.iter().map(|p| p.to_array()).collect(),
                    });
                }
            }
        }
    }
    out
}

fn build(
    robot: &urdf_rs::Robot,
    file: &str,
    stand_in: MeshStandIn,
    source: MeshSource,
) -> Result<(RobotModel, Vec<MeshHull>), UrdfError> {
    let structure = |message: String| UrdfError::Structure {
        file: file.to_string(),
        message,
    };
    if robot.links.is_empty() {
        return Err(structure("the file has no <link>".into()));
    }
    let mut links = HashMap::new();
    for (i, l) in robot.links.iter().enumerate() {
        if links.insert(l.name.as_str(), i).is_some() {
            return Err(structure(format!("link `{}` is defined twice", l.name)));
        }
    }
    let mut children: HashMap<&str, Vec<usize>> = HashMap::new();
    let mut is_child = vec![false; robot.links.len()];
    for (ji, j) in robot.joints.iter().enumerate() {
        let Some(&ci) = links.get(j.child.link.as_str()) else {
            return Err(structure(format!(
                "joint `{}` names unknown child link `{}`",
                j.name, j.child.link
            )));
        };
        if !links.contains_key(j.parent.link.as_str()) {
            return Err(structure(format!(
                "joint `{}` names unknown parent link `{}`",
                j.name, j.parent.link
            )));
        }
        if is_child[ci] {
            return Err(structure(format!(
                "link `{}` is the child of two joints",
                j.child.link
            )));
        }
        is_child[ci] = true;
        children.entry(j.parent.link.as_str()).or_default().push(ji);
    }
    let roots: Vec<usize> = (0..robot.links.len()).filter(|&i| !is_child[i]).collect();
    let root = match roots.as_slice() {
        [r] => *r,
        [] => return Err(structure("no root link (the joints form a cycle)".into())),
        many => {
            let names: Vec<&str> = many.iter().map(|&i| robot.links[i].name.as_str()).collect();
            return Err(structure(format!(
                "several root links: {}",
                names.join(", ")
            )));
        }
    };
    let mut b = Builder {
        file,
        robot,
        links,
        children,
        bodies: Vec::new(),
        acc: Vec::new(),
        warnings: Vec::new(),
        stand_in,
        meshes: read_meshes(robot, source),
    };
    b.new_body(&robot.links[root].name, None, None);
    b.visit(root, 0, Pose::IDENTITY, 0)?;
    b.finish();
    let hulls = used_hulls(robot, &b.meshes);
    let model = RobotModel {
        name: robot.name.clone(),
        source: file.to_string(),
        bodies: b.bodies,
        warnings: b.warnings,
    };
    Ok((model, hulls))
}

impl<'a> Builder<'a> {
    /// The hull points of link `li`'s collision `ci`, when it is a mesh used as a hull.
    fn hull(&self, li: usize, ci: usize) -> Option<&[Vec3]> {
        match self.meshes.get(&(li, ci)) {
            Some(Ok(points)) => Some(points),
            _ => None,
        }
    }

    fn new_body(&mut self, name: &str, parent: Option<usize>, joint: Option<JointSpec>) -> usize {
        self.bodies.push(BodySpec {
            name: name.to_string(),
            parent,
            joint,
            mass: 0.0,
            com: Vec3::ZERO,
            inertia: Mat3::ZERO,
            colliders: Vec::new(),
            links: Vec::new(),
        });
        self.acc.push(MassAcc::default());
        self.bodies.len() - 1
    }

    fn visit(&mut self, li: usize, body: usize, t: Pose, depth: usize) -> Result<(), UrdfError> {
        if depth > 1000 {
            return Err(UrdfError::Structure {
                file: self.file.to_string(),
                message: "kinematic tree deeper than 1000".into(),
            });
        }
        let robot = self.robot;
        let link = &robot.links[li];
        self.bodies[body].links.push((link.name.clone(), t));
        // Mass.
        let m = link.inertial.mass.value as f32;
        let (mut lm, mut lcom, mut lrot, mut lin) = (0.0, Vec3::ZERO, Rot3::IDENTITY, Mat3::ZERO);
        if m > 0.0 {
            let ip = pose_of(&link.inertial.origin);
            let i = &link.inertial.inertia;
            let it = Mat3::from_cols(
                Vec3::new(i.ixx as f32, i.ixy as f32, i.ixz as f32),
                Vec3::new(i.ixy as f32, i.iyy as f32, i.iyz as f32),
                Vec3::new(i.ixz as f32, i.iyz as f32, i.izz as f32),
            );
            let rot = Mat3::from_quat(t.rotation * ip.rotation);
            let c = t * ip.translation;
            let i_world = rot * it * rot.transpose();
            let acc = &mut self.acc[body];
            acc.mass += m;
            acc.first_moment += c * m;
            acc.inertia_origin += i_world + parallel_axis(m, c);
            (lm, lcom, lrot, lin) = (m, ip.translation, ip.rotation, it);
        }
        // Colliders.
        let mut meshes_replaced = false;
        for (ci, col) in link.collision.iter().enumerate() {
            let pose = t * pose_of(&col.origin);
            let shape = match &col.geometry {
                urdf_rs::Geometry::Box { size } => Some(ShapeSpec::Cuboid {
                    half: v3(size) * 0.5,
                }),
                urdf_rs::Geometry::Sphere { radius } => Some(ShapeSpec::Sphere {
                    radius: *radius as f32,
                }),
                urdf_rs::Geometry::Cylinder { radius, length } => Some(ShapeSpec::Cylinder {
                    half_length: *length as f32 * 0.5,
                    radius: *radius as f32,
                }),
                urdf_rs::Geometry::Capsule { radius, length } => Some(ShapeSpec::Capsule {
                    half_length: *length as f32 * 0.5,
                    radius: *radius as f32,
                }),
                urdf_rs::Geometry::Mesh { filename, .. }
                    if let Some(points) = self.hull(li, ci).map(<[Vec3]>::to_vec) =>
                {
                    let (points, trim) = match body {
                        0 => (points, None),
                        _ => self.trim_at_tips(li, &pose_of(&col.origin), points),
                    };
                    self.warnings.push(format!(
                        "link `{}`: mesh `{filename}` used as a convex hull of {} points{}",
                        link.name,
                        points.len(),
                        trim.map(|t| format!(" ({t})")).unwrap_or_default()
                    ));
                    Some(ShapeSpec::ConvexHull { points })
                }
                urdf_rs::Geometry::Mesh { filename, .. } => {
                    if let Some(Err(why)) = self.meshes.get(&(li, ci)).cloned() {
                        self.warnings.push(format!(
                            "link `{}`: mesh `{filename}` not used: {why}",
                            link.name
                        ));
                    }
                    // Primitives stand in for the mesh (see `MeshStandIn`).
                    let mut segments = match self.stand_in {
                        MeshStandIn::Segments if body != 0 => {
                            self.segment_ends(li, Pose::IDENTITY, 0)
                        }
                        _ => Vec::new(),
                    };
                    segments.retain(|s| s.end.length() >= 1e-3);
                    if lm <= 0.0 {
                        self.warnings.push(format!(
                            "link `{}`: mesh `{filename}` ignored (no inertia to size a stand-in)",
                            link.name
                        ));
                    } else if !segments.is_empty() {
                        if !meshes_replaced {
                            self.capsule_stand_ins(
                                (body, &link.name, t),
                                filename,
                                &segments,
                                (lm, lrot, lin),
                            );
                        }
                    } else {
                        let d = Vec3::new(lin.x_axis.x, lin.y_axis.y, lin.z_axis.z);
                        let half = match self.stand_in {
                            MeshStandIn::Segments => dense_box_half(lm, d),
                            MeshStandIn::InertiaBox => inertia_box_half(lm, d),
                        };
                        self.warnings.push(format!("link `{}`: mesh `{filename}` replaced by a {:.3}x{:.3}x{:.3} m box from its inertia", link.name, half.x * 2.0, half.y * 2.0, half.z * 2.0));
                        let p = t * Pose::from_parts(lcom, lrot);
                        self.bodies[body].colliders.push(ColliderSpec {
                            shape: ShapeSpec::Cuboid { half },
                            pose: p,
                            link: link.name.clone(),
                            stand_in: true,
                        });
                    }
                    meshes_replaced |= !segments.is_empty();
                    None
                }
            };
            if let Some(shape) = shape {
                self.bodies[body].colliders.push(ColliderSpec {
                    shape,
                    pose,
                    link: link.name.clone(),
                    stand_in: false,
                });
            }
        }
        // Children.
        let kids = self
            .children
            .get(link.name.as_str())
            .cloned()
            .unwrap_or_default();
        for ji in kids {
            let j = &robot.joints[ji];
            let origin = t * pose_of(&j.origin);
            let ci = self.links[j.child.link.as_str()];
            let kind = match &j.joint_type {
                urdf_rs::JointType::Fixed => {
                    self.visit(ci, body, origin, depth + 1)?;
                    continue;
                }
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
                    JointKind::Revolute
                }
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                other => {
                    return Err(UrdfError::Structure {
                        file: self.file.to_string(),
                        message: format!(
                            "joint `{}` has unsupported type {other:?}\nhint: only revolute, continuous, prismatic and fixed joints below a floating base are supported",
                            j.name
                        ),
                    });
                }
            };
            let axis = v3(&j.axis.xyz);
            if axis.length() < 1e-6 {
                return Err(UrdfError::Structure {
                    file: self.file.to_string(),
                    message: format!("joint `{}` has a zero axis", j.name),
                });
            }
            let lim = &j.limit;
            let limits = match j.joint_type {
                urdf_rs::JointType::Continuous => None,
                _ if lim.upper > lim.lower && lim.lower.is_finite() && lim.upper.is_finite() => {
                    Some((lim.lower as f32, lim.upper as f32))
                }
                _ => None,
            };
            let pos = |v: f64| (v.is_finite() && v > 0.0).then_some(v as f32);
            let spec = JointSpec {
                name: j.name.clone(),
                kind,
                origin,
                axis: axis.normalize(),
                limits,
                effort: pos(lim.effort),
                velocity: pos(lim.velocity),
            };
            let nb = self.new_body(&j.child.link, Some(body), Some(spec));
            self.visit(ci, nb, Pose::IDENTITY, depth + 1)?;
        }
        Ok(())
    }

    /// The segments capsule stand-ins of link `li` run along, in the frame of `li` (`t`: the
    /// frame of the link being searched in it): to each child joint's origin; through a fixed
    /// joint to a link without collision shapes that has children, on to that link's child
    /// joints.
    fn segment_ends(&self, li: usize, t: Pose, depth: usize) -> Vec<SegmentEnd> {
        let robot = self.robot;
        let mut out = Vec::new();
        if depth > 32 {
            return out;
        }
        let kids = self.children.get(robot.links[li].name.as_str());
        for &ji in kids.into_iter().flatten() {
            let j = &robot.joints[ji];
            let origin = t * pose_of(&j.origin);
            let ci = self.links[j.child.link.as_str()];
            let child = &robot.links[ci];
            let fixed = matches!(j.joint_type, urdf_rs::JointType::Fixed);
            let has_kids = self.children.contains_key(child.name.as_str());
            if fixed && child.collision.is_empty() && has_kids {
                out.extend(self.segment_ends(ci, origin, depth + 1));
                continue;
            }
            let clearance = if fixed {
                self.tip_extent(ci, 0).unwrap_or(0.0)
            } else {
                0.0
            };
            out.push(SegmentEnd {
                end: origin.translation,
                clearance,
                child: child.name.clone(),
            });
        }
        out
    }

    /// A shank's mesh hull (`points` in the collision frame `origin` of link `li`, a leg link with
    /// no moving joint below it) cut off at the top of a tip's shapes — the plane across each
    /// segment to a fixed child with shapes (a foot), at the segment's length less the shapes'
    /// extent, where the capsule stand-ins stop — and a note saying so. A vendor's shank mesh
    /// often holds its foot: its hull then reaches as low as the foot's sphere and takes the
    /// ground contact (and the foot's role) from it whenever the shank tilts (Unitree B1's calves
    /// carried 20% of its weight standing). A hull that would lose its volume is kept whole, with
    /// a note.
    fn trim_at_tips(
        &self,
        li: usize,
        origin: &Pose,
        points: Vec<Vec3>,
    ) -> (Vec<Vec3>, Option<String>) {
        // Only a chain's last moving link holds a foot: a thigh's fixed children are rotors and
        // the like (B1's `FL_calf_rotor` sits 1 mm from the thigh's origin), not where it ends.
        let robot = self.robot;
        let moves_on = self
            .children
            .get(robot.links[li].name.as_str())
            .into_iter()
            .flatten()
            .any(|&ji| !matches!(robot.joints[ji].joint_type, urdf_rs::JointType::Fixed));
        if moves_on {
            return (points, None);
        }
        let cuts: Vec<(Vec3, f32, String)> = self
            .segment_ends(li, Pose::IDENTITY, 0)
            .into_iter()
            .filter(|s| s.clearance > 0.0 && s.end.length() >= 1e-3)
            .map(|s| {
                let length = s.end.length();
                (s.end / length, length - s.clearance, s.child)
            })
            .collect();
        // The hull cut by each plane: the points on the near side, and where every segment
        // between a near and a far point crosses the plane (every edge of the hull is such a
        // segment, so these hold the cut face's corners).
        let mut kept: Vec<Vec3> = points.clone();
        for (u, at, _) in &cuts {
            let axial = |p: &Vec3| (*origin * *p).dot(*u);
            let (near, far): (Vec<Vec3>, Vec<Vec3>) = kept.iter().partition(|p| axial(p) <= *at);
            if far.is_empty() {
                continue;
            }
            let mut crossings = Vec::with_capacity(near.len() * far.len());
            for a in &near {
                for b in &far {
                    let (da, db) = (axial(a), axial(b));
                    crossings.push(*a + (*b - *a) * ((at - da) / (db - da)));
                }
            }
            // Only the cut face's corners: the plane's normal in the collision frame.
            let normal = origin.rotation.inverse() * *u;
            kept = near;
            kept.extend(crate::mesh::hull_in_plane(&crossings, normal));
        }
        if kept == points {
            return (points, None);
        }
        let tips: Vec<String> = cuts
            .iter()
            .map(|(_, at, child)| format!("`{child}` at {at:.3} m"))
            .collect();
        match crate::mesh::hull_points(&kept, Vec3::ONE) {
            Ok(kept) => (
                kept,
                Some(format!(
                    "cut short of its tip's shapes: {}",
                    tips.join(", ")
                )),
            ),
            Err(why) => (
                points,
                Some(format!(
                    "kept whole: cut at {} it would be no hull ({why})",
                    tips.join(", ")
                )),
            ),
        }
    }

    /// Radius about link `li`'s frame that holds its shapes and those of the links fixed below
    /// it; `None` when a joint below it moves (not a tip).
    fn tip_extent(&self, li: usize, depth: usize) -> Option<f32> {
        let robot = self.robot;
        let link = &robot.links[li];
        if depth > 32 {
            return None;
        }
        let mut extent: f32 = 0.0;
        for (ci, col) in link.collision.iter().enumerate() {
            let r = bounding_radius(&col.geometry, self.hull(li, ci), &link.inertial);
            extent = extent.max(v3(&col.origin.xyz).length() + r);
        }
        for &ji in self.children.get(link.name.as_str()).into_iter().flatten() {
            let j = &robot.joints[ji];
            if !matches!(j.joint_type, urdf_rs::JointType::Fixed) {
                return None;
            }
            let ci = self.links[j.child.link.as_str()];
            let below = self.tip_extent(ci, depth + 1)?;
            if below > 0.0 {
                extent = extent.max(v3(&j.origin.xyz).length() + below);
            }
        }
        Some(extent)
    }

    /// Adds the capsules of [`MeshStandIn::Segments`] for link `link` (frame `t` in body
    /// `body`) whose mass properties are `(mass, inertia frame, inertia)`, with one warning
    /// naming them.
    fn capsule_stand_ins(
        &mut self,
        (body, link, t): (usize, &str, Pose),
        filename: &str,
        segments: &[SegmentEnd],
        (m, rot, inertia): (f32, Rot3, Mat3),
    ) {
        let r_link = Mat3::from_quat(rot);
        let inertia = r_link * inertia * r_link.transpose();
        let mut parts = Vec::new();
        for seg in segments {
            let length = seg.end.length();
            let room = length - seg.clearance;
            // Too short for the thinnest capsule (or a child joint at the link's origin): a
            // zero-radius capsule would be a degenerate shape.
            if room < 2.0 * MIN_CAPSULE_RADIUS {
                parts.push(format!(
                    "nothing towards `{}` ({length:.3} m: the segment lies within its shapes or is \
                     too short)",
                    seg.child
                ));
                continue;
            }
            let u = seg.end / length;
            let axial = u.dot(inertia * u).max(0.0);
            // At most a quarter of the segment, and no lighter than `MIN_STAND_IN_DENSITY`.
            let densest = (m / (MIN_STAND_IN_DENSITY * std::f32::consts::PI * length)).sqrt();
            let radius = (2.0 * axial / m)
                .sqrt()
                .min(length / MAX_CAPSULE_ASPECT)
                .min(densest)
                .max(MIN_CAPSULE_RADIUS)
                .min(0.5 * room);
            // From the joint to `room - radius` along the segment: the end cap reaches `room`.
            let reach = room - radius;
            let local = Pose::from_parts(u * (0.5 * reach), Rot3::from_rotation_arc(Vec3::Z, u));
            self.bodies[body].colliders.push(ColliderSpec {
                shape: ShapeSpec::Capsule {
                    half_length: 0.5 * reach,
                    radius,
                },
                pose: t * local,
                link: link.to_string(),
                stand_in: true,
            });
            let short = if seg.clearance > 0.0 {
                format!(", stopping {:.3} m short of its shapes", seg.clearance)
            } else {
                String::new()
            };
            parts.push(format!(
                "a capsule of radius {radius:.3} m to `{}` ({length:.3} m{short})",
                seg.child
            ));
        }
        self.warnings.push(format!(
            "link `{link}`: mesh `{filename}` replaced by capsules along its joint-to-child segments (radius from its inertia): {}",
            parts.join("; ")
        ));
    }

    fn finish(&mut self) {
        for (b, acc) in self.bodies.iter_mut().zip(&self.acc) {
            if acc.mass > 0.0 {
                let com = acc.first_moment / acc.mass;
                b.mass = acc.mass;
                b.com = com;
                b.inertia = acc.inertia_origin - parallel_axis(acc.mass, com);
            } else {
                self.warnings.push(format!(
                    "body `{}` has no mass in the file; using {PLACEHOLDER_MASS} kg",
                    b.name
                ));
                b.mass = PLACEHOLDER_MASS;
                b.com = Vec3::ZERO;
                b.inertia = Mat3::IDENTITY * 1e-6;
            }
        }
    }
}
