//! [`describe`]: a URDF model as an added robot's description ([`RobotDescription`]), inferred and
//! checked standing in simulation. Registering and finding described robots
//! (`l3p_robot::added`) needs no simulator, so the `l3p-deploy` binary knows added robots too.

use crate::bench::stand_check;
use crate::world::RobotBinding;
use l3p_robot::added::*;
use l3p_robot::catalog::MAX_PENALISED_BODIES;
use l3p_robot::catalog::NUM_JOINTS;
use l3p_robot::legs::{InferredLegs, LegId, infer_quadruped};
use l3p_robot::math::Vec3;
use l3p_robot::model::{JointKind, RobotModel};

/// Infers a description of `model` (loaded from a file the description will call `urdf_file`),
/// and checks by simulation that it stands (unless `force`). Its `mesh_hulls` are left empty: a
/// caller that loaded `model` with [`l3p_robot::urdf::load_urdf_file_with_hulls`] records the hulls
/// that call returned, so that the registered robot has the colliders checked here.
pub fn describe(
    model: &RobotModel,
    urdf_file: &str,
    overrides: &Overrides,
    force: bool,
) -> Result<Inference, AddError> {
    let legs = infer_quadruped(model)?;
    // A file that only describes kinematics (Spot's SDK URDF: no inertia, no collision shapes)
    // cannot be simulated: say which body lacks what.
    let mut bodies = vec![legs.base_body];
    bodies.extend(legs.joints().map(|j| j.body));
    for b in bodies {
        let body = &model.bodies[b];
        let placeholder = format!("body `{}` has no mass in the file", body.name);
        if model.warnings.iter().any(|w| w.starts_with(&placeholder)) {
            return Err(AddError::bad_value(
                "inertial",
                &body.name,
                "the body has no <inertial> mass in the URDF; l3p cannot simulate it (a kinematics-only file?)",
            ));
        }
    }
    for leg in &legs.legs {
        if model.bodies[leg.foot_body].colliders.is_empty() {
            return Err(AddError::bad_value(
                "collision",
                &leg.foot_link,
                "the foot has no <collision> (or visual stand-in) shape; l3p cannot simulate its contacts",
            ));
        }
    }
    let name = overrides
        .name
        .clone()
        .unwrap_or_else(|| sanitize_name(&model.name));
    check_name(&name)?;
    // The legs' own warnings stay in `legs` (its summary prints them).
    let mut notes = Vec::new();
    let joints: Vec<_> = legs.joints().collect();

    // Rounded so that the file reads as written by hand (mrad, 0.1 N·m/rad, 0.01 N·m·s/rad).
    let round = |v: f32, unit: f32| (v / unit).round() / (1.0 / unit).round();
    let default_pose = standing_pose(model, &legs)?.map(|q| round(q, 1e-3));
    let pose_model = pose_in_model_order(model, &legs, &default_pose);
    let standing_height = model.standing_height(&pose_model);
    let mass = model.total_mass();
    let stance_torque = static_stance_torque(model, &legs, &default_pose, mass);
    let (effort_limit, velocity_limit) =
        limits(model, &legs, overrides, (mass, stance_torque), &mut notes)?;

    let kp = match overrides.kp {
        Some(kp) => kp,
        None => {
            let tau = stance_torque;
            let cap = effort_limit.iter().cloned().fold(f32::INFINITY, f32::min)
                / MIN_SATURATION_ERROR_RAD;
            (tau / STATIC_SAG_RAD).clamp(5.0, cap.max(5.0))
        }
    };
    let kp = round(kp, 0.1);
    let kd = overrides.kd.unwrap_or(round(kp / KP_OVER_KD, 0.01));

    let mut penalised = Vec::new();
    for leg in &legs.legs {
        for j in &leg.joints[1..] {
            let body = &model.bodies[j.body];
            if let Some((link, _)) = body
                .links
                .iter()
                .find(|(l, _)| *l != leg.foot_link && body.colliders.iter().any(|c| &c.link == l))
                && penalised.len() < MAX_PENALISED_BODIES
            {
                penalised.push(link.clone());
            }
        }
    }

    let description = RobotDescription {
        display_name: model.name.clone(),
        urdf: urdf_file.to_string(),
        joint_names: std::array::from_fn(|k| joints[k].name.clone()),
        axis_signs: std::array::from_fn(|k| joints[k].sign),
        default_pose,
        base_link: legs.base_link.clone(),
        foot_links: std::array::from_fn(|i| legs.legs[i].foot_link.clone()),
        penalised_links: penalised,
        termination_links: vec![legs.base_link.clone()],
        kp,
        kd,
        effort_limit,
        velocity_limit,
        action_scale: overrides.action_scale.unwrap_or(DEFAULT_ACTION_SCALE),
        spawn_height: round(standing_height + 0.02, 1e-3),
        mass: round(mass, 1e-3),
        mesh_hulls: Vec::new(),
        name,
    };
    description.validate()?;
    let spec = description.spec_with_model(model, "")?;
    let report = stand_check(
        model,
        &RobotBinding::from_spec(&spec),
        crate::actuator::Actuator::from_spec(&spec, spec.training_gains),
        &spec.default_pose,
        STAND_CHECK_SECONDS,
    )
    .map_err(|e| AddError::Sim(e.to_string()))?;
    let stands = report.finite
        && report.settled_height >= MIN_SETTLED_FRACTION * standing_height
        && report.gravity_z < -0.95;
    if !stands && !force {
        return Err(AddError::DoesNotStand {
            name: description.name.clone(),
            settled: report.settled_height,
            standing: standing_height,
            gravity_z: report.gravity_z,
            feet: 100.0 * report.foot_share(),
            carriers: report.carriers(),
        });
    }
    if stands && !force {
        report.require_on_feet(&description.name)?;
    }
    if !stands {
        notes.push(format!(
            "written with --force although it does not stand: settled at {:.3} m of {:.3} m",
            report.settled_height, standing_height
        ));
    } else if !report.on_feet() {
        notes.push(format!(
            "written with --force although it does not stand on its feet: they carry {:.0}% of its weight; the rest is carried by {}",
            100.0 * report.foot_share(),
            report.carriers()
        ));
    }
    Ok(Inference {
        description,
        legs,
        standing_height,
        settled_height: report.settled_height,
        settled_gravity_z: report.gravity_z,
        foot_share: report.foot_share(),
        carriers: report.carriers(),
        notes,
    })
}

/// Effort and velocity limits of the leg joints (canonical order) from the URDF: every missing
/// one is filled from `overrides` or reported in one [`AddError::MissingLimits`]; one far above
/// what a robot of `mass` (kg) with `stance_torque` (N·m) needs is replaced by the bound (or the
/// override), with a note.
fn limits(
    model: &RobotModel,
    legs: &InferredLegs,
    overrides: &Overrides,
    (mass, stance_torque): (f32, f32),
    notes: &mut Vec<String>,
) -> Result<([f32; NUM_JOINTS], [f32; NUM_JOINTS]), AddError> {
    let joints: Vec<_> = legs.joints().collect();
    // The knee joint's offset from the hip joint: the thigh.
    let thigh = legs
        .legs
        .iter()
        .map(|l| {
            model.bodies[l.joints[2].body]
                .joint
                .as_ref()
                .map_or(0.0, |j| j.origin.translation.length())
        })
        .fold(0.0f32, f32::max);
    let round1 = |v: f32| (v * 10.0).round() / 10.0;
    let bounds = [
        (
            "effort",
            "N·m",
            round1(EFFORT_OVER_STANCE * stance_torque),
            overrides.effort,
        ),
        (
            "velocity",
            "rad/s",
            round1(MAX_THIGH_TIP_SPEED / thigh.max(1e-3)),
            overrides.velocity,
        ),
    ];
    let mut out = [[0.0f32; NUM_JOINTS]; 2];
    let mut missing: [Vec<String>; 2] = Default::default();
    for (w, (what, unit, bound, fill)) in bounds.into_iter().enumerate() {
        let mut implausible: Vec<String> = Vec::new();
        let mut filled = false;
        for (k, j) in joints.iter().enumerate() {
            let spec = model.bodies[j.body].joint.as_ref();
            let v = spec
                .and_then(|s| if w == 0 { s.effort } else { s.velocity })
                .filter(|x| *x > 0.0 && x.is_finite());
            out[w][k] = match (v, fill) {
                (None, Some(f)) => {
                    filled = true;
                    f
                }
                (None, None) => {
                    missing[w].push(j.name.clone());
                    0.0
                }
                (Some(v), _) if bound > 0.0 && v > bound => {
                    implausible.push(format!("{} ({v} {unit})", j.name));
                    fill.unwrap_or(bound)
                }
                (Some(v), _) => v,
            };
        }
        if filled {
            notes.push(format!(
                "{what} limits missing from the URDF were filled in from --{what}"
            ));
        }
        if !implausible.is_empty() {
            let why = if w == 0 {
                format!(
                    "more than {EFFORT_OVER_STANCE} times the {stance_torque:.1} N·m its stance needs"
                )
            } else {
                format!(
                    "moves the end of its {thigh:.3} m thigh faster than {MAX_THIGH_TIP_SPEED} m/s"
                )
            };
            let used = match fill {
                Some(f) => format!("using {f} {unit} from --{what}"),
                None => format!("using {bound} {unit} instead (pass --{what} to choose the value)"),
            };
            notes.push(format!(
                "implausible {what} limits for a {mass:.2} kg robot ({why}): {}; {used}",
                implausible.join(", ")
            ));
        }
    }
    if missing.iter().any(|m| !m.is_empty()) {
        let [effort, velocity] = missing;
        return Err(AddError::MissingLimits { effort, velocity });
    }
    Ok((out[0], out[1]))
}

/// Per-body joint positions for a canonical-order pose.
fn per_body(model: &RobotModel, legs: &InferredLegs, pose: &[f32; NUM_JOINTS]) -> Vec<f32> {
    let mut q = vec![0.0; model.bodies.len()];
    for (k, j) in legs.joints().enumerate() {
        q[j.body] = pose[k];
    }
    q
}

/// A canonical-order pose in `model.joint_names()` order (joints of no leg at 0).
fn pose_in_model_order(
    model: &RobotModel,
    legs: &InferredLegs,
    pose: &[f32; NUM_JOINTS],
) -> Vec<f32> {
    let names = legs.joint_names();
    model
        .joint_names()
        .iter()
        .map(|n| names.iter().position(|j| j == n).map_or(0.0, |k| pose[k]))
        .collect()
}

/// Foot position in the trunk frame for per-body joint positions `q`.
fn foot_position(model: &RobotModel, foot_link: &str, q: &[f32]) -> Vec3 {
    let poses = model.body_poses(q);
    match model.body_of_link(foot_link) {
        Some((b, offset)) => (poses[b] * offset).translation,
        None => Vec3::ZERO,
    }
}

fn joint_limits(model: &RobotModel, body: usize) -> (f32, f32) {
    let pi = std::f32::consts::PI;
    match model.bodies[body].joint.as_ref().and_then(|j| j.limits) {
        Some((lo, hi)) => (lo.max(-pi), hi.min(pi)),
        None => (-pi, pi),
    }
}

/// `(|dx|, hip angle, depth)` of the hip angle whose foot is closest to under the hip.
type HipScan = (f32, f32, f32);

/// Scans a leg's hip angles for the foot closest to under the hip (x of the leg's first joint).
struct HipScanner<'a> {
    model: &'a RobotModel,
    foot_link: &'a str,
    hip_body: usize,
    hip_x: f32,
    hip_z: f32,
}

impl HipScanner<'_> {
    fn run(&self, q: &mut [f32], lo: f32, hi: f32, step: f32, best: &mut Option<HipScan>) {
        let mut h = lo;
        while h <= hi {
            q[self.hip_body] = h;
            let foot = foot_position(self.model, self.foot_link, q);
            let dx = (foot.x - self.hip_x).abs();
            if best.is_none_or(|b| dx < b.0) {
                *best = Some((dx, h, self.hip_z - foot.z));
            }
            h += step;
        }
    }
}

/// The default pose search of the module doc, leg by leg.
fn standing_pose(model: &RobotModel, legs: &InferredLegs) -> Result<[f32; NUM_JOINTS], AddError> {
    const KNEE_STEP: f32 = 0.02;
    const HIP_STEP: f32 = 0.02;
    const HIP_FINE_STEP: f32 = 0.002;
    let mut pose = [0.0; NUM_JOINTS];
    for (l, leg) in legs.legs.iter().enumerate() {
        let [abduction, hip, knee] = &leg.joints;
        let (h_lo, h_hi) = joint_limits(model, hip.body);
        let (k_lo, k_hi) = joint_limits(model, knee.body);
        let hip_x = abduction.position.x;
        // For each knee angle, the hip angle that puts the foot closest to under the hip (a
        // coarse scan, then a fine one around its best).
        let mut candidates = Vec::new();
        let mut reach: f32 = 0.0;
        let mut q = vec![0.0; model.bodies.len()];
        let mut k = k_lo;
        while k <= k_hi {
            q[knee.body] = k;
            let mut best: Option<HipScan> = None;
            let scan = HipScanner {
                model,
                foot_link: &leg.foot_link,
                hip_body: hip.body,
                hip_x,
                hip_z: hip.position.z,
            };
            scan.run(&mut q, h_lo, h_hi, HIP_STEP, &mut best);
            if let Some((_, h, _)) = best {
                let (lo, hi) = ((h - HIP_STEP).max(h_lo), (h + HIP_STEP).min(h_hi));
                scan.run(&mut q, lo, hi, HIP_FINE_STEP, &mut best);
            }
            if let Some((dx, h, depth)) = best
                && dx < 0.01
                && depth > 0.0
            {
                reach = reach.max(depth);
                candidates.push((k, h, depth));
            }
            k += KNEE_STEP;
        }
        // Bend the knee to the side with more room; on a tie (symmetric or no limits), towards
        // the body's middle: front knees backwards, rear knees forwards (ANYmal's "X").
        // "Backwards" is a negative canonical knee angle; the file's angle is `sign` times it.
        let room = k_hi + k_lo;
        let rear = matches!(leg.id, LegId::RL | LegId::RR);
        let bend_positive = if room.abs() < 1e-3 {
            rear == (knee.sign > 0.0)
        } else {
            room > 0.0
        };
        let target = STANDING_EXTENSION * reach;
        let pick = |positive: bool| {
            candidates
                .iter()
                .filter(|(k, _, _)| if positive { *k > 0.2 } else { *k < -0.2 })
                .min_by(|a, b| (a.2 - target).abs().total_cmp(&(b.2 - target).abs()))
                .copied()
        };
        let (k, h, _) = pick(bend_positive)
            .or_else(|| pick(!bend_positive))
            .ok_or_else(|| AddError::NoStandingPose {
                leg: leg.id.to_string(),
            })?;
        pose[3 * l] = 0.0;
        pose[3 * l + 1] = h;
        pose[3 * l + 2] = k;
    }
    Ok(pose)
}

/// Largest joint torque (N·m) when each foot carries a quarter of the weight at `pose`.
fn static_stance_torque(
    model: &RobotModel,
    legs: &InferredLegs,
    pose: &[f32; NUM_JOINTS],
    mass: f32,
) -> f32 {
    let q = per_body(model, legs, pose);
    let poses = model.body_poses(&q);
    let force = Vec3::new(0.0, 0.0, mass * 9.81 / 4.0);
    let mut worst: f32 = 0.0;
    for leg in &legs.legs {
        let foot = foot_position(model, &leg.foot_link, &q);
        for j in &leg.joints {
            let body = &model.bodies[j.body];
            let (Some(parent), Some(spec)) = (body.parent, body.joint.as_ref()) else {
                continue;
            };
            if spec.kind != JointKind::Revolute {
                continue;
            }
            let frame = poses[parent] * spec.origin;
            let axis = frame.rotation * spec.axis;
            let tau = axis.cross(foot - frame.translation).dot(force);
            worst = worst.max(tau.abs());
        }
    }
    worst
}
