//! Library side of `l3p robots check` and `l3p bench sim`: [`stand_check`] holds a model at a pose
//! under PD and reports the settled base, [`run_sim_bench`] steps a [`VecEnv`] with random actions
//! and reports [`SimBenchReport`] (control steps/s and stage timings).

use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rapier3d::math::{Pose, Vec3};

use crate::actuator::Actuator;
use crate::vecenv::{StageTimings, VecEnv, VecEnvError};
use crate::world::{RobotBinding, SimConfig, SimError, SimWorld};
pub use l3p_robot::added::NotOnFeet;
use l3p_robot::catalog::{Gains, NUM_JOINTS, RobotSpec};
use l3p_robot::model::RobotModel;
use l3p_task::config::EnvConfig;
use l3p_task::task::{SimState, projected_gravity};

/// Share of the robot's weight the feet must carry at the settled pose for a robot to stand on
/// its feet (the rest is carried by other links: shanks, knees, the trunk).
pub const MIN_FOOT_SHARE: f32 = 0.9;
/// Seconds at the end of a standing check over which contact forces are averaged.
const CONTACT_WINDOW_S: f32 = 0.25;

/// Result of a standing check.
#[derive(Debug, Clone)]
pub struct StandReport {
    /// Base height the pose's kinematics give with the lowest collider on the ground (m).
    pub kinematic_height: f32,
    /// Settled base height (m).
    pub settled_height: f32,
    /// z component of gravity in the base frame (−1 = upright).
    pub gravity_z: f32,
    /// Foot contact force at the end, averaged over the last 0.25 s (N).
    pub foot_force: f32,
    /// The robot's weight `m·g` (N).
    pub weight: f32,
    /// Ground contact force of every other link that touches the ground, averaged as
    /// `foot_force`, largest first (N).
    pub other_contacts: Vec<(String, f32)>,
    /// Every state value stayed finite.
    pub finite: bool,
}

impl StandReport {
    /// Share of the weight the feet carry (`foot_force / weight`).
    pub fn foot_share(&self) -> f32 {
        self.foot_force / self.weight.max(1e-6)
    }

    /// The feet carry at least [`MIN_FOOT_SHARE`] of the weight.
    pub fn on_feet(&self) -> bool {
        self.foot_share() >= MIN_FOOT_SHARE
    }

    /// `Ok` when the robot (named `name` in the error) stands on its feet, else the error naming
    /// the links that carry the rest of its weight.
    pub fn require_on_feet(&self, name: &str) -> Result<(), NotOnFeet> {
        if self.on_feet() {
            return Ok(());
        }
        Err(NotOnFeet {
            name: name.to_string(),
            share: 100.0 * self.foot_share(),
            min: 100.0 * MIN_FOOT_SHARE,
            carriers: self.carriers(),
        })
    }

    /// The links other than feet that carry weight, with their share: `FL_calf 31% (40.2 N), …`,
    /// or `nothing else` when only the feet touch the ground.
    pub fn carriers(&self) -> String {
        if self.other_contacts.is_empty() {
            return "nothing else".into();
        }
        self.other_contacts
            .iter()
            .map(|(l, f)| format!("{l} {:.0}% ({f:.1} N)", 100.0 * f / self.weight.max(1e-6)))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Drops `model` 2 cm above its kinematic standing height at pose `q` (canonical order of
/// `binding.joints`) on flat ground and holds `q` with `actuator` for `seconds`; ground contact
/// forces are averaged over the last 0.25 s (or the whole run if shorter), feet (`binding.feet`)
/// apart from the other links.
pub fn stand_check(
    model: &RobotModel,
    binding: &RobotBinding,
    actuator: Actuator,
    q: &[f32; NUM_JOINTS],
    seconds: f32,
) -> Result<StandReport, SimError> {
    let q_model: Vec<f32> = model
        .joint_names()
        .iter()
        .map(|n| {
            binding
                .joints
                .iter()
                .position(|j| j == n)
                .map(|k| q[k])
                .unwrap_or(0.0)
        })
        .collect();
    let h = model.standing_height(&q_model);
    let cfg = SimConfig::default();
    let mut w = SimWorld::new(cfg);
    w.add_flat_ground(0.0);
    let id = w.add_robot(
        model,
        binding,
        actuator,
        Pose::from_translation(Vec3::new(0.0, 0.0, h + 0.02)),
        q,
    )?;
    let mut s = SimState::default();
    let mut finite = true;
    let steps = (seconds / cfg.dt).round() as usize;
    let window = ((CONTACT_WINDOW_S / cfg.dt).round() as usize).clamp(1, steps.max(1));
    let mut foot_force = 0.0;
    let mut others: Vec<(String, f32)> = Vec::new();
    for i in 0..steps {
        if i % 4 == 0 {
            w.clear_contact_maxima();
        }
        w.step();
        w.read_state(id, &mut s);
        finite &= s.is_finite();
        if i + window >= steps {
            for (link, f) in w.ground_contact_by_link(id) {
                let f = f / window as f32;
                if binding.feet.contains(&link) {
                    foot_force += f;
                } else if let Some(o) = others.iter_mut().find(|(l, _)| *l == link) {
                    o.1 += f;
                } else {
                    others.push((link, f));
                }
            }
        }
    }
    others.sort_by(|a, b| b.1.total_cmp(&a.1));
    Ok(StandReport {
        kinematic_height: h,
        settled_height: s.base_pos[2],
        gravity_z: projected_gravity(s.base_quat)[2],
        foot_force,
        weight: model.total_mass() * cfg.gravity,
        other_contacts: others,
        finite,
    })
}

/// Standing check of a built-in robot with `gains`.
pub fn stand_check_spec(
    spec: &RobotSpec,
    gains: Gains,
    seconds: f32,
) -> Result<StandReport, crate::vecenv::VecEnvError> {
    let model = spec.model()?;
    Ok(stand_check(
        &model,
        &RobotBinding::from_spec(spec),
        Actuator::from_spec(spec, gains),
        &spec.default_pose,
        seconds,
    )?)
}

/// Result of [`run_sim_bench`].
#[derive(Debug, Clone, Copy)]
pub struct SimBenchReport {
    /// Envs.
    pub envs: usize,
    /// Worker threads.
    pub threads: usize,
    /// `step` calls timed.
    pub steps: u64,
    /// Wall time of the timed loop.
    pub wall: Duration,
    /// Control steps (env steps) per second: `envs × steps / wall`.
    pub control_steps_per_s: f64,
    /// Physics steps per second (`× decimation`).
    pub physics_steps_per_s: f64,
    /// Stage timings (per-worker averages) over the timed loop.
    pub timings: StageTimings,
    /// Episodes finished.
    pub episodes: u64,
    /// NaN/explosion resets.
    pub nan_resets: u64,
    /// Mean terrain level at the end.
    pub mean_terrain_level: f32,
}

/// Steps `envs` envs of `spec` for `seconds` of wall time with uniform random actions in
/// [−1, 1] (after 20 warm-up steps), all task work included.
pub fn run_sim_bench(
    spec: &RobotSpec,
    cfg: &EnvConfig,
    envs: usize,
    threads: usize,
    seconds: f64,
    seed: u64,
) -> Result<SimBenchReport, VecEnvError> {
    let mut env = VecEnv::new(spec, cfg, envs, threads, seed)?;
    let mut rng = SmallRng::seed_from_u64(seed ^ 0xA5A5);
    let mut actions = vec![0.0f32; envs * NUM_JOINTS];
    env.reset_all();
    let mut episodes = 0u64;
    for _ in 0..20 {
        actions
            .iter_mut()
            .for_each(|a| *a = rng.random_range(-1.0..1.0));
        env.step(&actions)?;
    }
    env.reset_timings();
    let start = Instant::now();
    let mut steps = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        actions
            .iter_mut()
            .for_each(|a| *a = rng.random_range(-1.0..1.0));
        let out = env.step(&actions)?;
        episodes += out.episodes.len() as u64;
        steps += 1;
    }
    let wall = start.elapsed();
    let cps = (envs as u64 * steps) as f64 / wall.as_secs_f64().max(1e-9);
    Ok(SimBenchReport {
        envs,
        threads,
        steps,
        wall,
        control_steps_per_s: cps,
        physics_steps_per_s: cps * env.task().spec.decimation as f64,
        timings: env.timings(),
        episodes,
        nan_resets: env.nan_resets(),
        mean_terrain_level: env.curriculum().mean_level(),
    })
}
