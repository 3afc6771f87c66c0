//! `l3p robots list|check`: the built-in robot catalog and a load-and-stand check of a robot or URDF
//! file. Glue only; the work is in `l3p_robots::{catalog, urdf, bench}`.

use std::path::Path;

use anyhow::Context;
use clap::{Args, Subcommand};
use l3p_robots::actuator::Actuator;
use l3p_robots::bench::stand_check;
use l3p_robots::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robots::model::RobotModel;
use l3p_robots::sim::RobotBinding;

/// `l3p robots ...`
#[derive(Debug, Args)]
pub struct RobotsArgs {
    #[command(subcommand)]
    pub command: RobotsCommand,
}

/// Robot subcommands.
#[derive(Debug, Subcommand)]
pub enum RobotsCommand {
    /// List the built-in robots with mass, standing height, gains and limits.
    List,
    /// Load a robot (built-in name or URDF path), print its links, joints and mass, hold the default
    /// pose under PD for 2 s on flat ground and print the settled base height.
    Check {
        /// Built-in robot name (a1, go1, go2, anymal_b, anymal_c, anymal_d, spot) or a .urdf path.
        robot: String,
        /// Seconds to hold the pose.
        #[arg(long, default_value_t = 2.0)]
        seconds: f32,
        /// Use the training gains instead of the stiff stand-test gains.
        #[arg(long)]
        training_gains: bool,
    },
}

/// Runs a `robots` subcommand.
pub fn run(args: RobotsArgs) -> anyhow::Result<()> {
    match args.command {
        RobotsCommand::List => list(),
        RobotsCommand::Check {
            robot,
            seconds,
            training_gains,
        } => check(&robot, seconds, training_gains),
    }
}

fn list() -> anyhow::Result<()> {
    println!(
        "{:<9} {:<22} {:>8} {:>9} {:>6} {:>12} {:>14} {:>8}",
        "name", "robot", "mass kg", "stand m", "scale", "train kp/kd", "effort N·m", "vel r/s"
    );
    for s in RobotSpec::all() {
        let m = s
            .model()
            .with_context(|| format!("loading built-in {}", s.name))?;
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
        let m = l3p_robots::urdf::load_urdf_file(robot)?;
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
    match l3p_robots::infer::infer_quadruped(&model) {
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
        "stand test: {} default pose, kp {} kd {}, {seconds} s on flat ground",
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
    Ok(())
}
