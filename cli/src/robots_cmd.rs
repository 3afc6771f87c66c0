//! `l3p robots list|check|add`: the robots (the catalog and those added from a user's URDF), a
//! load-and-stand check of a robot or URDF file, and `add`, which makes a quadruped URDF a robot
//! (`<data-dir>/robots/<name>.toml` + the URDF beside it). Glue only; the work is in
//! `l3p_robot::{catalog, added, urdf}` and `l3p_sim::{describe, bench}`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::model::RobotModel;
use l3p_sim::actuator::Actuator;
use l3p_sim::bench::stand_check;
use l3p_sim::world::RobotBinding;

/// `l3p robots ...`
#[derive(Debug, Args)]
pub struct RobotsArgs {
    #[command(subcommand)]
    pub command: RobotsCommand,
}

/// Robot subcommands.
#[derive(Debug, Subcommand)]
pub enum RobotsCommand {
    /// List the robots (built-in and added) with mass, standing height, gains and limits.
    List {
        /// Data directory whose `robots/` holds added robots.
        #[arg(long, default_value = "l3p-data")]
        data_dir: PathBuf,
    },
    /// Make a quadruped URDF a robot: infer its legs, feet, standing pose (checked in
    /// simulation), PD gains and limits, print them for review and write
    /// `<data-dir>/robots/<name>.toml` (edit it freely) with the URDF beside it. The robot then
    /// trains, evaluates, deploys and exports by name like a built-in one.
    Add(AddArgs),
    /// Load a robot (built-in name or URDF path), print its links, joints and mass, hold the default
    /// pose under PD for 2 s on flat ground and print the settled base height and the share of
    /// the weight on the feet (an error when under 90%, naming the links that carry the rest).
    Check {
        /// Robot name (built-in: a1, go1, go2, anymal_b, anymal_c, anymal_d, spot; or added) or a
        /// .urdf path.
        robot: String,
        /// Data directory whose `robots/` holds added robots.
        #[arg(long, default_value = "l3p-data")]
        data_dir: PathBuf,
        /// Seconds to hold the pose.
        #[arg(long, default_value_t = 2.0)]
        seconds: f32,
        /// Use the training gains instead of the stiff stand-test gains.
        #[arg(long)]
        training_gains: bool,
    },
}

/// `l3p robots add` arguments: every inferred value can be overridden here or in the file.
#[derive(Debug, Args)]
pub struct AddArgs {
    /// The robot's URDF file.
    pub urdf: PathBuf,
    /// Robot name (default: the URDF's robot name, lower-cased).
    #[arg(long)]
    pub name: Option<String>,
    /// Data directory; the robot goes to `<data-dir>/robots/`.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// PD stiffness (N·m/rad) instead of the inferred one.
    #[arg(long)]
    pub kp: Option<f32>,
    /// PD damping (N·m·s/rad) instead of kp / 50.
    #[arg(long)]
    pub kd: Option<f32>,
    /// Action scale instead of 0.25.
    #[arg(long)]
    pub action_scale: Option<f32>,
    /// Effort limit (N·m) for leg joints whose URDF has none, or one implausibly high for the
    /// robot's size (used instead of the inferred bound).
    #[arg(long)]
    pub effort: Option<f32>,
    /// Velocity limit (rad/s) for leg joints whose URDF has none, or one implausibly high for
    /// the robot's size (used instead of the inferred bound).
    #[arg(long)]
    pub velocity: Option<f32>,
    /// Write the description even if the robot does not stand at the inferred pose and gains,
    /// or stands but not on its feet (they carry under 90% of its weight).
    #[arg(long)]
    pub force: bool,
    /// Replace an added robot of the same name.
    #[arg(long)]
    pub replace: bool,
}

/// Runs a `robots` subcommand.
pub fn run(args: RobotsArgs) -> anyhow::Result<()> {
    match args.command {
        RobotsCommand::List { data_dir } => {
            load_added_robots(Some(&data_dir));
            list()
        }
        RobotsCommand::Add(add_args) => add(&add_args),
        RobotsCommand::Check {
            robot,
            data_dir,
            seconds,
            training_gains,
        } => {
            load_added_robots(Some(&data_dir));
            check(&robot, seconds, training_gains)
        }
    }
}

/// Registers the robots added under `data_dir/robots` (or, for `None`, `$L3P_ROBOTS_DIR`, else
/// `./l3p-data/robots`). A broken description is reported and skipped: it must not stop commands
/// that do not use it (using it then fails with "unknown robot" naming the known ones).
pub fn load_added_robots(data_dir: Option<&Path>) {
    l3p_robot::added::load_added_robots(data_dir);
}

fn add(args: &AddArgs) -> anyhow::Result<()> {
    use l3p_robot::added::Overrides;
    use l3p_sim::describe::describe;
    // The hulls of the meshes found beside the file go into the description: the robot it
    // registers, here and on other machines, has the colliders the standing check uses.
    let (model, mesh_hulls) = l3p_robot::urdf::load_urdf_file_with_hulls(&args.urdf)?;
    let overrides = Overrides {
        name: args.name.clone(),
        kp: args.kp,
        kd: args.kd,
        action_scale: args.action_scale,
        effort: args.effort,
        velocity: args.velocity,
    };
    let name = overrides
        .name
        .clone()
        .unwrap_or_else(|| l3p_robot::added::sanitize_name(&model.name));
    let dir = args.data_dir.join("robots");
    let toml_path = dir.join(format!("{name}.toml"));
    if toml_path.exists() && !args.replace {
        anyhow::bail!(
            "{} exists: robot `{name}` was added before\nhint: pass --replace, or --name for another name",
            toml_path.display()
        );
    }
    let urdf_file = format!("{name}.urdf");
    let mut inferred = describe(&model, &urdf_file, &overrides, args.force)?;
    inferred.description.mesh_hulls = mesh_hulls;
    let d = &inferred.description;
    print!("{}", inferred.legs.summary());
    println!("default pose (rad, canonical order; abduction, hip, knee per leg):");
    for (l, leg) in ["FL", "FR", "RL", "RR"].iter().enumerate() {
        println!(
            "  {leg}  {:+.3}  {:+.3}  {:+.3}",
            d.default_pose[3 * l],
            d.default_pose[3 * l + 1],
            d.default_pose[3 * l + 2]
        );
    }
    println!(
        "mass {:.2} kg; kp {:.1} N·m/rad, kd {:.2} N·m·s/rad; action scale {}; effort {:.1}–{:.1} N·m; velocity {:.1}–{:.1} rad/s",
        d.mass,
        d.kp,
        d.kd,
        d.action_scale,
        d.effort_limit.iter().cloned().fold(f32::INFINITY, f32::min),
        d.effort_limit.iter().cloned().fold(0.0, f32::max),
        d.velocity_limit
            .iter()
            .cloned()
            .fold(f32::INFINITY, f32::min),
        d.velocity_limit.iter().cloned().fold(0.0, f32::max),
    );
    println!(
        "penalised contacts: {}; episode ends on contact of: {}",
        d.penalised_links.join(", "),
        d.termination_links.join(", ")
    );
    println!(
        "stands: kinematic height {:.3} m, settled {:.3} m ({:.0}%) after {} s, gravity z {:.3}; feet carry {:.0}% of the weight (besides them: {})",
        inferred.standing_height,
        inferred.settled_height,
        100.0 * inferred.settled_height / inferred.standing_height.max(1e-6),
        l3p_robot::added::STAND_CHECK_SECONDS,
        inferred.settled_gravity_z,
        100.0 * inferred.foot_share,
        inferred.carriers
    );
    for n in &inferred.notes {
        println!("note: {n}");
    }
    if !d.mesh_hulls.is_empty() {
        println!(
            "collision meshes as convex hulls (recorded in the description as mesh_hulls): {}",
            d.mesh_hulls
                .iter()
                .map(|h| format!("{} ({} points)", h.file, h.points.len()))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let urdf_path = dir.join(&urdf_file);
    std::fs::copy(&args.urdf, &urdf_path)
        .with_context(|| format!("copying {} to {}", args.urdf.display(), urdf_path.display()))?;
    l3p_policy::write_atomic(&toml_path, d.to_toml().as_bytes())
        .with_context(|| format!("writing {}", toml_path.display()))?;
    println!(
        "wrote {} (and {}); train it with [[actors]] robot = \"{name}\"",
        toml_path.display(),
        urdf_path.display()
    );
    // The same robot for actors on other machines: a registry artifact they fetch by name.
    let bundle = RobotBundle {
        format: ROBOT_BUNDLE_FORMAT.into(),
        name: name.clone(),
        toml: d.to_toml(),
        urdf_file,
        urdf: std::fs::read_to_string(&urdf_path)
            .with_context(|| format!("reading {}", urdf_path.display()))?,
    };
    let registry = l3p_registry::Registry::open(&args.data_dir)?;
    let outcome = registry.put(
        l3p_registry::PutRequest::new(
            &robot_artifact(&name),
            l3p_registry::ArtifactKind::Robot,
            serde_json::to_vec(&bundle)?,
        )
        .robot(&name)
        .producer("l3p robots add"),
    )?;
    println!(
        "registry: {} (actors elsewhere fetch it with `l3p actor --robot {name}`)",
        outcome.meta.reference()
    );
    Ok(())
}

/// Registry name of an added robot's description.
pub fn robot_artifact(name: &str) -> String {
    format!("robot-{name}")
}

const ROBOT_BUNDLE_FORMAT: &str = "l3p-robot/1";

/// What a robot artifact holds: the description file and its URDF, as `l3p robots add` wrote them.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct RobotBundle {
    format: String,
    name: String,
    toml: String,
    urdf_file: String,
    urdf: String,
}

/// Writes a robot artifact's files into `dir` (an added-robots directory) and registers the robot;
/// refuses a bundle for another robot or of another format, and file names with a path in them.
pub fn install_robot_artifact(
    bytes: &[u8],
    expected_name: &str,
    dir: &Path,
) -> anyhow::Result<&'static RobotSpec> {
    let bundle: RobotBundle =
        serde_json::from_slice(bytes).context("robot artifact is not an l3p robot bundle")?;
    if bundle.format != ROBOT_BUNDLE_FORMAT {
        anyhow::bail!(
            "robot artifact has format `{}`, this l3p reads `{ROBOT_BUNDLE_FORMAT}`",
            bundle.format
        );
    }
    if bundle.name != expected_name {
        anyhow::bail!(
            "robot artifact describes `{}`, not `{expected_name}`",
            bundle.name
        );
    }
    let plain = |f: &str| {
        !f.is_empty() && Path::new(f).file_name().is_some_and(|n| n == f) && !f.starts_with('.')
    };
    if !plain(&bundle.urdf_file) || l3p_robot::added::sanitize_name(&bundle.name) != bundle.name {
        anyhow::bail!(
            "robot artifact names files `{}` / `{}`: expected plain file names",
            bundle.name,
            bundle.urdf_file
        );
    }
    // The description must name the bundled URDF: it is read relative to `dir`.
    let named = toml::from_str::<toml::Value>(&bundle.toml)
        .context("robot artifact's description is not TOML")?;
    if named.get("urdf").and_then(|v| v.as_str()) != Some(bundle.urdf_file.as_str()) {
        anyhow::bail!(
            "robot artifact's description does not name its URDF `{}`",
            bundle.urdf_file
        );
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let toml_path = dir.join(format!("{}.toml", bundle.name));
    l3p_policy::write_atomic(&dir.join(&bundle.urdf_file), bundle.urdf.as_bytes())?;
    l3p_policy::write_atomic(&toml_path, bundle.toml.as_bytes())?;
    let (desc, urdf) = l3p_robot::added::RobotDescription::load(&toml_path)?;
    Ok(l3p_robot::added::register(&desc, urdf)?)
}

fn list() -> anyhow::Result<()> {
    println!(
        "{:<9} {:<22} {:>8} {:>9} {:>6} {:>12} {:>14} {:>8}",
        "name", "robot", "mass kg", "stand m", "scale", "train kp/kd", "effort N·m", "vel r/s"
    );
    let added = l3p_robot::added::all_added();
    for s in RobotSpec::all().iter().chain(added.iter().copied()) {
        let m = s
            .model()
            .with_context(|| format!("loading robot {}", s.name))?;
        let h = m.standing_height(&s.model_order_pose(&m, &s.default_pose));
        println!(
            "{:<9} {:<22} {:>8.2} {:>9.3} {:>6.2} {:>12} {:>14} {:>8.1}",
            s.name,
            s.display_name,
            m.total_mass(),
            h,
            s.action_scale,
            format!("{}/{}", s.training_gains.kp, s.training_gains.kd),
            format!("{:.1}", s.effort_limit[2]),
            s.velocity_limit[2]
        );
    }
    println!(
        "joint order: front-left, front-right, rear-left, rear-right legs; hip abduction, hip flexion, knee"
    );
    Ok(())
}

/// Finds the built-in spec whose joint names the model has (Spot's SDK file writes `fl.hx` for
/// our `fl_hx`); returns the spec and the binding with the model's names.
fn match_spec(model: &RobotModel) -> Option<(&'static RobotSpec, RobotBinding)> {
    let names = model.joint_names();
    // Prefer the robot whose name appears in the file path or robot name (go2 before a1: same joints).
    let hint = format!("{} {}", model.source, model.name).to_ascii_lowercase();
    let mut specs: Vec<&'static RobotSpec> = RobotSpec::all().iter().collect();
    specs.sort_by_key(|s| !hint.contains(s.name));
    for spec in specs {
        for dotted in [false, true] {
            let map = |s: &str| {
                if dotted {
                    s.replace('_', ".")
                } else {
                    s.to_string()
                }
            };
            let joints: Vec<String> = spec.joint_names.iter().map(|j| map(j)).collect();
            if joints.iter().all(|j| names.contains(&j.as_str())) {
                let present = |links: &[&str]| -> Vec<String> {
                    links
                        .iter()
                        .map(|l| map(l))
                        .filter(|l| model.body_of_link(l).is_some())
                        .collect()
                };
                let binding = RobotBinding {
                    joints,
                    feet: present(&spec.foot_links),
                    penalised: present(spec.penalised_links),
                    termination: present(spec.termination_links),
                };
                return Some((spec, binding));
            }
        }
    }
    None
}

fn check(robot: &str, seconds: f32, training_gains: bool) -> anyhow::Result<()> {
    let is_path = robot.ends_with(".urdf") || Path::new(robot).exists();
    let (model, matched) = if is_path {
        let m = l3p_robot::urdf::load_urdf_file(robot)?;
        let matched = match_spec(&m);
        (m, matched)
    } else {
        let spec = RobotSpec::by_name(robot)?;
        let m = spec.model()?;
        let b = RobotBinding::from_spec(spec);
        (m, Some((spec, b)))
    };
    println!("robot `{}` from {}", model.name, model.source);
    println!("links: {}", model.link_names().len());
    println!("bodies after merging fixed joints: {}", model.bodies.len());
    for (i, b) in model.bodies.iter().enumerate() {
        let joint = b.joint.as_ref().map_or("floating base".to_string(), |j| {
            let lim = j.limits.map_or("continuous".to_string(), |(lo, hi)| {
                format!("[{lo:.3}, {hi:.3}]")
            });
            format!(
                "joint {} axis ({:.2}, {:.2}, {:.2}) {lim}",
                j.name, j.axis.x, j.axis.y, j.axis.z
            )
        });
        println!(
            "  body {i:2} {:<24} {:7.3} kg  {:2} colliders  {joint}",
            b.name,
            b.mass,
            b.colliders.len()
        );
    }
    println!("actuated joints: {}", model.num_actuated());
    println!("total mass: {:.3} kg", model.total_mass());
    for w in &model.warnings {
        println!("note: {w}");
    }
    // The leg structure as `l3p robots add` will infer it: from geometry, whatever the names.
    match l3p_robot::legs::infer_quadruped(&model) {
        Ok(legs) => print!(
            "inferred legs (canonical order FL, FR, RL, RR):\n{}",
            legs.summary()
        ),
        Err(e) => println!("not a quadruped l3p can infer: {e}"),
    }
    let Some((spec, binding)) = matched else {
        println!(
            "stand test skipped: the joints do not match a built-in robot's {NUM_JOINTS} leg joints (names)"
        );
        return Ok(());
    };
    if model.bodies.iter().all(|b| b.colliders.is_empty()) {
        println!("stand test skipped: the model has no collision shapes");
        return Ok(());
    }
    let gains = if training_gains {
        spec.training_gains
    } else {
        spec.stand_gains
    };
    println!(
        "stand test: {} default pose, kp {:.1} kd {:.2}, {seconds} s on flat ground",
        spec.name, gains.kp, gains.kd
    );
    let r = stand_check(
        &model,
        &binding,
        Actuator::from_spec(spec, gains),
        &spec.default_pose,
        seconds,
    )?;
    println!("kinematic standing height: {:.3} m", r.kinematic_height);
    println!(
        "settled base height: {:.3} m ({:+.1}%), gravity z in base frame {:.3}, feet carry {:.1} N, finite: {}",
        r.settled_height,
        100.0 * (r.settled_height - r.kinematic_height) / r.kinematic_height.max(1e-6),
        r.gravity_z,
        r.foot_force,
        r.finite
    );
    println!(
        "feet carry {:.0}% of the weight ({:.1} N); besides them: {}",
        100.0 * r.foot_share(),
        r.weight,
        r.carriers()
    );
    r.require_on_feet(&model.name)?;
    Ok(())
}
