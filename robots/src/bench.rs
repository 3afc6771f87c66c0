//! Library side of `l3p robots check` and `l3p bench sim`: [`stand_check`] holds a model at a pose
//! under PD and reports the settled base, [`run_sim_bench`] steps a [`VecEnv`] with random actions
//! and reports [`SimBenchReport`] (control steps/s and stage timings).

use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rapier3d::math::{Pose, Vec3};

use crate::actuator::Actuator;
use crate::catalog::{Gains, NUM_JOINTS, RobotSpec};
use crate::config::EnvConfig;
use crate::model::RobotModel;
use crate::sim::{RobotBinding, SimConfig, SimError, SimWorld};
use crate::task::{SimState, projected_gravity};
use crate::vecenv::{StageTimings, VecEnv, VecEnvError};

/// Result of a standing check.
#[derive(Debug, Clone, Copy)]
pub struct StandReport {
    /// Base height the pose's kinematics give with the lowest collider on the ground (m).
    pub kinematic_height: f32,
    /// Settled base height (m).
    pub settled_height: f32,
    /// z component of gravity in the base frame (−1 = upright).
    pub gravity_z: f32,
    /// Sum of foot contact forces at the end (N).
    pub foot_force: f32,
    /// Every state value stayed finite.
    pub finite: bool,
}

/// Drops `model` 2 cm above its kinematic standing height at pose `q` (canonical order of
/// `binding.joints`) on flat ground and holds `q` with `actuator` for `seconds`.
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
    for i in 0..steps {
        if i % 4 == 0 {
            w.clear_contact_maxima();
        }
        w.step();
        w.read_state(id, &mut s);
        finite &= s.is_finite();
    }
    Ok(StandReport {
        kinematic_height: h,
        settled_height: s.base_pos[2],
        gravity_z: projected_gravity(s.base_quat)[2],
        foot_force: s.foot_force.iter().sum(),
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
