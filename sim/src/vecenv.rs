//! The vectorised environment: [`VecEnv`] runs `N` envs of one robot split over `T` workers (one
//! rapier [`SimWorld`] per worker, stepped in parallel on a rayon pool), with the task's
//! observations, rewards, terminations, commands and terrain curriculum.
//!
//! Step order (legged_gym / IsaacLab): actions → `decimation` physics steps → rewards and
//! terminations → curriculum update and reset of finished envs → commands → pushes →
//! observations (of the new episode for reset envs). Buffers are preallocated; a step allocates
//! nothing. An env whose state goes non-finite or explodes (or whose world panics) is reset and
//! counted in [`VecEnv::nan_resets`]; it never takes the process down.

use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rapier3d::math::{Pose, Rot3, Vec3};
use rapier3d::parry::shape::{HeightField, HeightFieldCellStatus, HeightFieldFlags};
use rayon::prelude::*;

use crate::actuator::Actuator;
use crate::world::{JointDynamics, RobotBinding, SimConfig, SimWorld};
use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::model::RobotModel;
use l3p_robot::urdf::UrdfError;
use l3p_task::config::{ConfigError, EnvConfig};
use l3p_task::gait::{GaitMeter, GaitReport, GaitSample};
use l3p_task::task::{
    Command, DoneReason, NUM_FEET, NUM_REWARD_TERMS, RobotTaskParams, SimState, StepResult, Task,
    TaskEnvState, TaskError,
};
use l3p_task::terrain::{Curriculum, Terrain, TerrainError, TerrainType};

/// Errors building or stepping a [`VecEnv`].
#[derive(Debug, thiserror::Error)]
pub enum VecEnvError {
    /// Bad config.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Terrain generation failed.
    #[error(transparent)]
    Terrain(#[from] TerrainError),
    /// The robot model failed to load.
    #[error(transparent)]
    Urdf(#[from] UrdfError),
    /// The task rejected the robot or an input.
    #[error(transparent)]
    Task(#[from] TaskError),
    /// The simulator rejected the robot.
    #[error(transparent)]
    Sim(#[from] crate::world::SimError),
    /// Wrong action length.
    #[error("actions: expected {expected} values ({num_envs} envs x {action_dim}), got {got}")]
    ActionLength {
        /// Expected length.
        expected: usize,
        /// Envs.
        num_envs: usize,
        /// Per env.
        action_dim: usize,
        /// Got.
        got: usize,
    },
    /// Zero envs or threads.
    #[error("num_envs and threads must be >= 1 (got {num_envs} envs, {threads} threads)")]
    Size {
        /// Envs.
        num_envs: usize,
        /// Threads.
        threads: usize,
    },
    /// Thread pool creation failed.
    #[error("cannot build the worker thread pool: {0}")]
    Pool(String),
}

/// A finished episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpisodeInfo {
    /// Env index.
    pub env: usize,
    /// Undiscounted return.
    pub ret: f32,
    /// Length in control steps.
    pub length: u32,
    /// Terrain level the episode ran on.
    pub terrain_level: usize,
    /// Terrain type of its column.
    pub terrain_type: TerrainType,
    /// Mean xy velocity tracking error (m/s).
    pub lin_vel_error: f32,
    /// Mean yaw-rate tracking error (rad/s).
    pub yaw_rate_error: f32,
    /// Why it ended.
    pub reason: DoneReason,
    /// Per reward term (weighted, × dt), summed over the episode, [`l3p_task::config::RewardTerm`] order.
    pub terms: [f32; NUM_REWARD_TERMS],
}

/// Accumulated wall time per stage (summed over steps; per worker stages are averaged over
/// workers).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimings {
    /// Physics substeps (incl. actuators and contact reading).
    pub physics: Duration,
    /// Observations (incl. height scan and noise), commands and pushes.
    pub observations: Duration,
    /// Rewards and terminations.
    pub rewards: Duration,
    /// Resets (curriculum, physics reset, task reset).
    pub resets: Duration,
    /// Whole `step` calls.
    pub total: Duration,
    /// Number of `step` calls.
    pub steps: u64,
}

/// What [`VecEnv::step`] returns; slices borrow the env's buffers.
#[derive(Debug)]
pub struct StepOutput<'a> {
    /// `[num_envs * obs_dim]`, reset envs show their new episode's first observation.
    pub obs: &'a [f32],
    /// `[num_envs]`.
    pub rewards: &'a [f32],
    /// `[num_envs]`: episode ended by failure (no bootstrap).
    pub terminated: &'a [bool],
    /// `[num_envs]`: episode ended by time-out (bootstrap with V(s_t)).
    pub truncated: &'a [bool],
    /// Episodes that finished in this step.
    pub episodes: &'a [EpisodeInfo],
}

struct Worker {
    sim: SimWorld,
    first_env: usize,
    n: usize,
    envs: Vec<TaskEnvState>,
    states: Vec<SimState>,
    actions: Vec<[f32; NUM_JOINTS]>,
    /// The policy's mean actions for the next step (see [`VecEnv::set_action_means`]).
    means: Vec<[f32; NUM_JOINTS]>,
    has_means: bool,
    targets: Vec<[f32; NUM_JOINTS]>,
    results: Vec<StepResult>,
    origins: Vec<[f32; 3]>,
    obs: Vec<f32>,
    rng: SmallRng,
    nan_resets: u64,
    /// Gait meters, one per env (empty unless [`VecEnv::enable_gait_meter`]).
    gait: Vec<GaitMeter>,
    t_physics: Duration,
    t_obs: Duration,
    t_rewards: Duration,
    t_resets: Duration,
}

/// Shared read-only pieces every worker needs.
struct Shared {
    task: Task,
    terrain: Terrain,
    model: RobotModel,
    binding: RobotBinding,
    actuator: Actuator,
    sim_cfg: SimConfig,
    decimation: usize,
    spawn_clearance: f32,
    default_pose: [f32; NUM_JOINTS],
    /// Heightfield blocks and their poses (`None` on flat ground).
    ground: Option<Vec<(rapier3d::prelude::SharedShape, Pose)>>,
}

/// One env as a viewer sees it (see [`VecEnv::snapshot`]).
#[derive(Debug, Clone)]
pub struct EnvSnapshot<'a> {
    pub state: &'a SimState,
    /// World poses of the model's bodies, in [`RobotModel::bodies`] order.
    pub body_poses: Vec<Pose>,
    /// World position of each foot (canonical order).
    pub foot_positions: [[f32; 3]; NUM_FEET],
    /// Joint position targets of the last step (canonical order, rad).
    pub joint_targets: [f32; NUM_JOINTS],
    /// The command the env follows.
    pub command: Command,
    /// The env's terrain tile origin.
    pub origin: [f32; 3],
}

/// N envs of one robot, stepped in parallel.
pub struct VecEnv {
    shared: Arc<Shared>,
    workers: Vec<Worker>,
    pool: rayon::ThreadPool,
    curriculum: Curriculum,
    num_envs: usize,
    obs_dim: usize,
    obs: Vec<f32>,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    episodes: Vec<EpisodeInfo>,
    timings: StageTimings,
    rng: SmallRng,
}

impl std::fmt::Debug for VecEnv {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VecEnv")
            .field("num_envs", &self.num_envs)
            .field("workers", &self.workers.len())
            .finish()
    }
}

/// Speed (m/s) or joint speed (rad/s) above which an env counts as exploded.
const EXPLODED_LIN_VEL: f32 = 50.0;
const EXPLODED_JOINT_VEL: f32 = 500.0;

fn exploded(s: &SimState) -> bool {
    !s.is_finite()
        || s.base_lin_vel_w.iter().any(|v| v.abs() > EXPLODED_LIN_VEL)
        || s.base_ang_vel_w
            .iter()
            .any(|v| v.abs() > 4.0 * EXPLODED_LIN_VEL)
        || s.joint_vel.iter().any(|v| v.abs() > EXPLODED_JOINT_VEL)
        || s.base_pos[2].abs() > 1e3
}

fn build_world(shared: &Shared, n: usize, origins: &[[f32; 3]]) -> Result<SimWorld, VecEnvError> {
    let mut sim = SimWorld::new(shared.sim_cfg);
    match &shared.ground {
        Some(blocks) => {
            for (shape, pose) in blocks {
                sim.add_ground_shape(shape.clone(), *pose);
            }
        }
        None => sim.add_flat_ground(0.0),
    }
    for o in origins.iter().take(n) {
        let pose = Pose::from_translation(Vec3::new(o[0], o[1], o[2] + shared.spawn_clearance));
        sim.add_robot(
            &shared.model,
            &shared.binding,
            shared.actuator,
            pose,
            &shared.default_pose,
        )?;
    }
    Ok(sim)
}

impl VecEnv {
    /// Builds `num_envs` envs of `spec` with `cfg`, split over `threads` workers, seeded with `seed`.
    pub fn new(
        spec: &RobotSpec,
        cfg: &EnvConfig,
        num_envs: usize,
        threads: usize,
        seed: u64,
    ) -> Result<Self, VecEnvError> {
        if num_envs == 0 || threads == 0 {
            return Err(VecEnvError::Size { num_envs, threads });
        }
        let task_spec = cfg.resolve(spec.name)?;
        let model = spec.model()?;
        let params = RobotTaskParams::of(spec, &model);
        let decimation = task_spec.decimation as usize;
        let sim_cfg = SimConfig {
            dt: task_spec.sim_dt,
            ..SimConfig::default()
        };
        let terrain = Terrain::generate(&task_spec.terrain)?;
        let gains = task_spec.gains.apply(spec.training_gains);
        let task = Task::new(task_spec, params)?;
        let ground = (!terrain.is_flat()).then(|| terrain_blocks(&terrain, GROUND_BLOCK));
        let standing = model.standing_height(&spec.model_order_pose(&model, &spec.default_pose));
        let mut rng = SmallRng::seed_from_u64(seed);
        let curriculum = Curriculum::new(num_envs, &task.spec.terrain, &mut rng);
        let shared = Arc::new(Shared {
            task,
            terrain,
            model,
            binding: RobotBinding::from_spec(spec),
            actuator: Actuator::from_spec(spec, gains),
            sim_cfg,
            decimation,
            spawn_clearance: standing + 0.05,
            default_pose: spec.default_pose,
            ground,
        });
        let threads = threads.min(num_envs);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| VecEnvError::Pool(e.to_string()))?;
        let obs_dim = shared.task.obs_dim();
        let mut workers = Vec::with_capacity(threads);
        let mut first = 0;
        for w in 0..threads {
            let n = num_envs / threads + usize::from(w < num_envs % threads);
            let origins: Vec<[f32; 3]> = (first..first + n)
                .map(|e| {
                    shared
                        .terrain
                        .tile_origin(curriculum.level(e), curriculum.col(e))
                })
                .collect();
            let sim = build_world(&shared, n, &origins)?;
            workers.push(Worker {
                sim,
                first_env: first,
                n,
                envs: vec![TaskEnvState::new(); n],
                states: vec![SimState::default(); n],
                actions: vec![[0.0; NUM_JOINTS]; n],
                means: vec![[0.0; NUM_JOINTS]; n],
                has_means: false,
                targets: vec![spec.default_pose; n],
                results: vec![StepResult::default(); n],
                origins,
                obs: vec![0.0; n * obs_dim],
                rng: SmallRng::seed_from_u64(
                    seed.wrapping_add(1 + w as u64)
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15),
                ),
                nan_resets: 0,
                gait: Vec::new(),
                t_physics: Duration::ZERO,
                t_obs: Duration::ZERO,
                t_rewards: Duration::ZERO,
                t_resets: Duration::ZERO,
            });
            first += n;
        }
        for w in &mut workers {
            for i in 0..w.n {
                randomize_body(&shared, w, i);
            }
        }
        Ok(Self {
            shared,
            workers,
            pool,
            curriculum,
            num_envs,
            obs_dim,
            obs: vec![0.0; num_envs * obs_dim],
            rewards: vec![0.0; num_envs],
            terminated: vec![false; num_envs],
            truncated: vec![false; num_envs],
            episodes: Vec::with_capacity(num_envs),
            timings: StageTimings::default(),
            rng,
        })
    }

    /// Number of envs.
    pub fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Observation size per env (48, or 235 with the height scan).
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Action size per env (12).
    pub fn action_dim(&self) -> usize {
        NUM_JOINTS
    }

    /// The task (config, reward weights, dt).
    pub fn task(&self) -> &Task {
        &self.shared.task
    }

    /// The terrain.
    pub fn terrain(&self) -> &Terrain {
        &self.shared.terrain
    }

    /// The curriculum (levels per env, mean level, per-type means).
    pub fn curriculum(&self) -> &Curriculum {
        &self.curriculum
    }

    /// Envs reset because their physics went non-finite or exploded.
    pub fn nan_resets(&self) -> u64 {
        self.workers.iter().map(|w| w.nan_resets).sum()
    }

    /// Accumulated stage timings since construction or [`Self::reset_timings`].
    pub fn timings(&self) -> StageTimings {
        self.timings
    }

    /// Clears the stage timings.
    pub fn reset_timings(&mut self) {
        self.timings = StageTimings::default();
        for w in &mut self.workers {
            w.t_physics = Duration::ZERO;
            w.t_obs = Duration::ZERO;
            w.t_rewards = Duration::ZERO;
            w.t_resets = Duration::ZERO;
        }
    }

    /// Latest robot state of env `e` (after the last step or reset).
    pub fn robot_state(&self, e: usize) -> Option<&SimState> {
        self.workers
            .iter()
            .find(|w| e >= w.first_env && e < w.first_env + w.n)
            .map(|w| &w.states[e - w.first_env])
    }

    /// What a viewer draws of env `e` after the last step or reset (`None` for an unknown env).
    pub fn snapshot(&self, e: usize) -> Option<EnvSnapshot<'_>> {
        let w = self
            .workers
            .iter()
            .find(|w| e >= w.first_env && e < w.first_env + w.n)?;
        let i = e - w.first_env;
        Some(EnvSnapshot {
            state: &w.states[i],
            body_poses: w.sim.body_poses(i),
            foot_positions: w.sim.foot_positions(i),
            joint_targets: w.targets[i],
            command: w.envs[i].command,
            origin: w.origins[i],
        })
    }

    /// Replaces env `e`'s command until the task resamples it (`l3p play`'s command schedule sets it
    /// every step); false for an unknown env.
    pub fn set_command(&mut self, e: usize, command: Command) -> bool {
        match self
            .workers
            .iter_mut()
            .find(|w| e >= w.first_env && e < w.first_env + w.n)
        {
            Some(w) => {
                w.envs[e - w.first_env].command = command;
                true
            }
            None => false,
        }
    }

    /// The simulated robot's model (bodies and their collision shapes, for viewers).
    pub fn model(&self) -> &RobotModel {
        &self.shared.model
    }

    /// The policy's mean actions (`[num_envs * 12]`) behind the next [`VecEnv::step`]'s sampled
    /// actions: `action_rate_l2` then penalises the mean's changes, not the exploration noise
    /// (see [`Task::evaluate_with_mean`]). Applies to one step; without it the sampled actions count.
    pub fn set_action_means(&mut self, means: &[f32]) -> Result<(), VecEnvError> {
        self.check_action_len(means)?;
        for w in &mut self.workers {
            for i in 0..w.n {
                let e = w.first_env + i;
                w.means[i].copy_from_slice(&means[e * NUM_JOINTS..(e + 1) * NUM_JOINTS]);
            }
            w.has_means = true;
        }
        Ok(())
    }

    /// Starts measuring gait diagnostics (see [`l3p_task::gait`]) on every env from the next step;
    /// clears earlier measurements.
    pub fn enable_gait_meter(&mut self) {
        for w in &mut self.workers {
            w.gait = vec![GaitMeter::new(); w.n];
        }
    }

    /// The gait diagnostics measured since [`VecEnv::enable_gait_meter`] (finished episodes and
    /// running ones), against the robot's standing height.
    pub fn gait_report(&self) -> GaitReport {
        let mut all = GaitMeter::new();
        for w in &self.workers {
            for g in &w.gait {
                all.merge(g);
            }
        }
        all.report(self.shared.task.robot.standing_height)
    }

    /// Resets every env and returns the first observations `[num_envs * obs_dim]`.
    pub fn reset_all(&mut self) -> &[f32] {
        let shared = &self.shared;
        let curriculum = &self.curriculum;
        self.pool.install(|| {
            self.workers.par_iter_mut().for_each(|w| {
                for i in 0..w.n {
                    let e = w.first_env + i;
                    w.origins[i] = shared
                        .terrain
                        .tile_origin(curriculum.level(e), curriculum.col(e));
                    reset_one(shared, w, i);
                }
                observe_all(shared, w);
            })
        });
        self.gather();
        &self.obs
    }

    /// Gives each env's current episode a random head start of `0..max_episode_steps` steps
    /// towards its time-out (rsl_rl's `init_at_random_ep_len`): call once after
    /// [`VecEnv::reset_all`]. Without it every env starts at step 0, so the episodes that do not
    /// fall all time out together, in waves one episode length apart; later episodes are full
    /// length either way.
    pub fn stagger_time_outs(&mut self) {
        let max = self.shared.task.spec.max_episode_steps.max(1);
        for w in &mut self.workers {
            for env in &mut w.envs {
                env.time_out_head_start = w.rng.random_range(0..max);
            }
        }
    }

    /// `[num_envs * 12]` or an error naming the expected shape.
    fn check_action_len(&self, values: &[f32]) -> Result<(), VecEnvError> {
        if values.len() != self.num_envs * NUM_JOINTS {
            return Err(VecEnvError::ActionLength {
                expected: self.num_envs * NUM_JOINTS,
                num_envs: self.num_envs,
                action_dim: NUM_JOINTS,
                got: values.len(),
            });
        }
        Ok(())
    }

    /// Steps every env once with `actions` (`[num_envs * 12]`, raw policy outputs).
    pub fn step(&mut self, actions: &[f32]) -> Result<StepOutput<'_>, VecEnvError> {
        self.check_action_len(actions)?;
        let t0 = Instant::now();
        let shared = &self.shared;
        // Phase A: actions, physics, rewards.
        self.pool.install(|| {
            self.workers.par_iter_mut().for_each(|w| {
                let a = &actions[w.first_env * NUM_JOINTS..(w.first_env + w.n) * NUM_JOINTS];
                physics_and_rewards(shared, w, a);
            })
        });
        // Phase B (serial, cheap): episode statistics and curriculum.
        let tb = Instant::now();
        self.episodes.clear();
        for w in &mut self.workers {
            for i in 0..w.n {
                let e = w.first_env + i;
                let r = w.results[i];
                self.rewards[e] = r.reward;
                self.terminated[e] = r.terminated;
                self.truncated[e] = r.truncated && !r.terminated;
                if r.terminated || r.truncated {
                    let s = shared.task.finish_episode(&w.envs[i], &w.states[i]);
                    let level = self.curriculum.level(e);
                    let col = self.curriculum.col(e);
                    self.episodes.push(EpisodeInfo {
                        env: e,
                        ret: s.ret,
                        length: s.length,
                        terrain_level: level,
                        terrain_type: shared.terrain.tile_type(col),
                        lin_vel_error: s.mean_lin_vel_error,
                        yaw_rate_error: s.mean_yaw_rate_error,
                        reason: s.reason,
                        terms: s.terms,
                    });
                    self.curriculum.update(
                        e,
                        s.distance,
                        s.command_xy_norm,
                        shared.task.spec.episode_length_s,
                        &mut self.rng,
                    );
                    w.origins[i] = shared.terrain.tile_origin(self.curriculum.level(e), col);
                }
            }
        }
        let serial = tb.elapsed();
        // Phase C: resets, commands, pushes, observations.
        self.pool.install(|| {
            self.workers.par_iter_mut().for_each(|w| {
                let t = Instant::now();
                for i in 0..w.n {
                    if w.results[i].terminated || w.results[i].truncated {
                        reset_one(shared, w, i);
                    }
                }
                w.t_resets += t.elapsed();
                let t = Instant::now();
                observe_all(shared, w);
                w.t_obs += t.elapsed();
            })
        });
        self.gather();
        let k = self.workers.len() as u32;
        let sum = |f: fn(&Worker) -> Duration| self.workers.iter().map(f).sum::<Duration>() / k;
        self.timings.physics = sum(|w| w.t_physics);
        self.timings.rewards = sum(|w| w.t_rewards);
        self.timings.observations = sum(|w| w.t_obs);
        self.timings.resets = sum(|w| w.t_resets) + serial;
        self.timings.total += t0.elapsed();
        self.timings.steps += 1;
        Ok(StepOutput {
            obs: &self.obs,
            rewards: &self.rewards,
            terminated: &self.terminated,
            truncated: &self.truncated,
            episodes: &self.episodes,
        })
    }

    fn gather(&mut self) {
        let d = self.obs_dim;
        for w in &self.workers {
            self.obs[w.first_env * d..(w.first_env + w.n) * d].copy_from_slice(&w.obs);
        }
    }
}

/// Samples per side of one heightfield block (blocks share their edge samples).
const GROUND_BLOCK: usize = 16;

/// Splits the terrain grid into `block × block`-cell heightfields. One global heightfield has an
/// AABB spanning the whole terrain's height range, so every robot collider would always be in a
/// narrow-phase pair with it; blocks keep the AABBs tight (see NOTES.md, benchmarks).
fn terrain_blocks(t: &Terrain, block: usize) -> Vec<(rapier3d::prelude::SharedShape, Pose)> {
    let (nx, ny) = (t.nx, t.ny);
    let mut out = Vec::new();
    let mut x_start = 0;
    while x_start + 1 < nx {
        let x_end = (x_start + block).min(nx - 1);
        let mut y_start = 0;
        while y_start + 1 < ny {
            let y_end = (y_start + block).min(ny - 1);
            let (bx, by) = (x_end - x_start + 1, y_end - y_start + 1);
            let mut m = rapier3d::parry::utils::Array2::zeros(by, bx);
            for iy in 0..by {
                for ix in 0..bx {
                    m[(by - 1 - iy, ix)] = t.heights[(y_start + iy) * nx + x_start + ix];
                }
            }
            let sx = (bx - 1) as f32 * t.resolution;
            let sy = (by - 1) as f32 * t.resolution;
            let centre = Vec3::new(
                t.x0 + x_start as f32 * t.resolution + 0.5 * sx,
                t.y0 + y_start as f32 * t.resolution + 0.5 * sy,
                0.0,
            );
            let pose = Pose::from_parts(centre, Rot3::from_rotation_x(std::f32::consts::FRAC_PI_2));
            let flags = if t.spec.fix_internal_edges {
                HeightFieldFlags::FIX_INTERNAL_EDGES
            } else {
                HeightFieldFlags::empty()
            };
            let mut field = HeightField::with_flags(m, Vec3::new(sx, 1.0, sy), flags);
            // Cells of stepped tiles are the meshes' (below); a block of only those is dropped.
            let mut kept = 0;
            for iy in 0..by - 1 {
                for ix in 0..bx - 1 {
                    let cx = t.x0 + (x_start + ix) as f32 * t.resolution + 0.5 * t.resolution;
                    let cy = t.y0 + (y_start + iy) as f32 * t.resolution + 0.5 * t.resolution;
                    if t.stepped_at(cx, cy) {
                        field.set_cell_status(by - 2 - iy, ix, HeightFieldCellStatus::CELL_REMOVED);
                    } else {
                        kept += 1;
                    }
                }
            }
            if kept > 0 {
                out.push((rapier3d::prelude::SharedShape::new(field), pose));
            }
            y_start = y_end;
        }
        x_start = x_end;
    }
    for rect in t.stepped_tiles() {
        let (vertices, triangles) = t.stepped_mesh(&rect);
        let vertices = vertices.into_iter().map(Vec3::from).collect();
        match rapier3d::prelude::SharedShape::trimesh(vertices, triangles) {
            Ok(mesh) => out.push((mesh, Pose::IDENTITY)),
            // Only an empty mesh fails (a tile of no samples); its cells are removed above.
            Err(e) => tracing::warn!(?rect, "stepped tile without a mesh: {e}"),
        }
    }
    out
}

fn physics_and_rewards(shared: &Shared, w: &mut Worker, actions: &[f32]) {
    let t = Instant::now();
    for i in 0..w.n {
        let raw = &actions[i * NUM_JOINTS..(i + 1) * NUM_JOINTS];
        // Length is checked by the caller; a bad length can only come from a bug.
        let _ = shared.task.process_action(
            raw,
            &w.envs[i].last_action,
            &mut w.actions[i],
            &mut w.targets[i],
        );
        w.sim.set_targets(i, &w.targets[i]);
    }
    w.sim.clear_contact_maxima();
    let sim = &mut w.sim;
    let decimation = shared.decimation;
    let ok = std::panic::catch_unwind(AssertUnwindSafe(|| {
        for _ in 0..decimation {
            sim.step();
        }
    }))
    .is_ok();
    if !ok {
        // The world is in an unknown state: rebuild it and fail every env in it.
        tracing::warn!(
            first_env = w.first_env,
            "physics panicked; rebuilding the worker's world"
        );
        if let Ok(sim) = build_world(shared, w.n, &w.origins) {
            w.sim = sim;
        }
    }
    for i in 0..w.n {
        w.sim.read_state(i, &mut w.states[i]);
        if !ok || exploded(&w.states[i]) {
            w.states[i].base_pos[2] = f32::NAN;
        }
    }
    w.t_physics += t.elapsed();
    let t = Instant::now();
    for i in 0..w.n {
        let mean = w.has_means.then_some(&w.means[i]);
        w.results[i] = shared.task.evaluate_with_mean(
            &mut w.envs[i],
            &w.states[i],
            &w.actions[i],
            mean,
            &shared.terrain,
        );
        if w.results[i].reason == DoneReason::NonFinite {
            w.nan_resets += 1;
        }
        if let Some(meter) = w.gait.get_mut(i) {
            let s = &w.states[i];
            meter.record(&GaitSample {
                state: s,
                targets: &w.targets[i],
                ground_height: shared.terrain.height_at(s.base_pos[0], s.base_pos[1]),
                num_penalised: shared.task.robot.num_penalised_bodies,
                contact_threshold: shared.task.spec.reward_params.contact_threshold,
                dt: shared.task.spec.step_dt,
            });
            if w.results[i].done() {
                meter.end_episode(w.results[i].reason);
            }
        }
    }
    w.has_means = false;
    w.t_rewards += t.elapsed();
}

/// Draws and applies one env's physical randomisation (at start-up and at every reset, so that
/// every episode meets new friction, mass, damping, gains and latency).
fn randomize_body(shared: &Shared, w: &mut Worker, i: usize) {
    let r = shared.task.sample_body_randomization(&mut w.rng);
    w.sim.set_friction(i, r.static_friction);
    w.sim
        .set_base_randomization(i, r.added_base_mass, r.base_com_offset);
    let mut actuator = shared.actuator;
    for k in 0..NUM_JOINTS {
        actuator.kp[k] *= r.kp_scale;
        actuator.kd[k] *= r.kd_scale;
    }
    w.sim.set_actuator(i, actuator);
    w.sim.set_joint_dynamics(
        i,
        JointDynamics {
            damping: r.joint_damping,
            friction: r.joint_friction,
            strength: r.motor_strength,
            latency_steps: (r.latency_s / shared.sim_cfg.dt).round() as u32,
        },
    );
}

fn reset_one(shared: &Shared, w: &mut Worker, i: usize) {
    randomize_body(shared, w, i);
    let s = shared
        .task
        .sample_reset(w.origins[i], &shared.terrain, &mut w.rng);
    let pos = Vec3::new(
        s.base_xy[0],
        s.base_xy[1],
        s.ground_z + shared.spawn_clearance,
    );
    let pose = Pose::from_parts(pos, Rot3::from_rotation_z(s.yaw));
    w.sim.reset_robot(
        i,
        pose,
        Vec3::from(s.lin_vel),
        Vec3::from(s.ang_vel),
        &s.joint_pos,
        &s.joint_vel,
    );
    w.targets[i] = s.joint_pos;
    w.sim.read_state(i, &mut w.states[i]);
    let origin = w.origins[i];
    shared
        .task
        .reset_env(&mut w.envs[i], &w.states[i], origin, &mut w.rng);
}

fn observe_all(shared: &Shared, w: &mut Worker) {
    let d = shared.task.obs_dim();
    for i in 0..w.n {
        shared
            .task
            .update_commands(&mut w.envs[i], &w.states[i], &mut w.rng);
        if let Some([vx, vy]) = shared.task.push_due(&mut w.envs[i], &mut w.rng) {
            w.sim.push_base(i, vx, vy);
            w.states[i].base_lin_vel_w[0] = vx;
            w.states[i].base_lin_vel_w[1] = vy;
        }
        let out = &mut w.obs[i * d..(i + 1) * d];
        if shared
            .task
            .observe(&w.envs[i], &w.states[i], &shared.terrain, &mut w.rng, out)
            .is_err()
        {
            out.fill(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use l3p_task::config::{TerrainConfig, TerrainPreset};
    use l3p_task::terrain::Terrain;

    /// A 2 × 2 curriculum terrain of stairs and boxes (one type per column).
    fn stepped_terrain(vertical_faces: bool, columns: [TerrainType; 2]) -> Terrain {
        let mut c = TerrainConfig::with_preset(TerrainPreset::Curriculum);
        c.border_width = 1.0;
        c.num_rows = 2;
        c.num_cols = 2;
        c.max_init_level = 1;
        c.vertical_faces = vertical_faces;
        let mut p = l3p_task::terrain::TypeProportions::zero();
        for t in columns {
            match t {
                TerrainType::PyramidStairs => p.pyramid_stairs = 1.0,
                TerrainType::InvertedPyramidStairs => p.inverted_pyramid_stairs = 1.0,
                TerrainType::Boxes => p.boxes = 1.0,
                _ => unreachable!("a stepped type"),
            }
        }
        c.proportions = Some(p);
        let t = Terrain::generate(&c.resolve("anymal_c").unwrap()).unwrap();
        assert_eq!([t.tile_type(0), t.tile_type(1)], columns);
        t
    }

    /// The first riser along x through the middle of tile (1, 0): the samples on either side
    /// and their heights (lower, higher).
    fn first_riser(t: &Terrain) -> (f32, f32, f32, f32) {
        let [cx, cy, _] = t.tile_origin(1, 0);
        let iy = ((cy - t.y0) / t.resolution).round() as usize;
        let ix0 = ((cx - 4.0 - t.x0) / t.resolution).round() as usize;
        for ix in ix0..t.nx - 1 {
            let (a, b) = (t.sample(ix, iy), t.sample(ix + 1, iy));
            if (a - b).abs() > 0.05 {
                let x_face = t.x0 + (ix as f32 + 0.5) * t.resolution;
                return (x_face, cy, a, b);
            }
        }
        panic!("no riser on the tile");
    }

    /// The closest contact of a ball of `radius` at `centre` with the ground shapes.
    fn ground_contact(
        blocks: &[(rapier3d::prelude::SharedShape, Pose)],
        centre: Vec3,
        radius: f32,
    ) -> rapier3d::parry::query::Contact {
        let ball = rapier3d::parry::shape::Ball::new(radius);
        let at = Pose::from_translation(centre);
        blocks
            .iter()
            .filter_map(|(shape, pose)| {
                rapier3d::parry::query::contact(pose, shape.as_ref(), &at, &ball, 0.01).unwrap()
            })
            .min_by(|a, b| a.dist.total_cmp(&b.dist))
            .expect("the ball touches the ground")
    }

    /// `[env.terrain] vertical_faces`: a foot pressed against a stair riser at mid-height meets a
    /// vertical face (horizontal contact normal); on the heightfield it meets a one-cell ramp.
    #[test]
    fn a_foot_meets_a_vertical_riser_only_with_vertical_faces() {
        let columns = [TerrainType::PyramidStairs, TerrainType::Boxes];
        for vertical in [true, false] {
            let t = stepped_terrain(vertical, columns);
            let blocks = terrain_blocks(&t, GROUND_BLOCK);
            let (x_face, y, a, b) = first_riser(&t);
            let (lo, hi) = (a.min(b), a.max(b));
            let radius = 0.02;
            // On the lower side, 1 mm from the face (ramp: from its midpoint), at mid-riser.
            let side = if a < b { -1.0 } else { 1.0 };
            let centre = Vec3::new(x_face + side * (radius + 0.001), y, 0.5 * (lo + hi));
            let contact = ground_contact(&blocks, centre, radius);
            // normal1 points from the ground into the ball.
            let n = contact.normal1;
            let tilt_deg = n.z.abs().asin().to_degrees();
            if vertical {
                assert!(
                    tilt_deg < 1.0 && (n.x * side) > 0.999,
                    "riser {lo}..{hi} m: normal {n:?} ({tilt_deg:.1}° from horizontal)"
                );
            } else {
                assert!(
                    tilt_deg > 10.0,
                    "a heightfield riser is a ramp: normal {n:?} ({tilt_deg:.1}°)"
                );
            }
        }
    }

    /// With vertical faces the stepped tiles are meshes whose every face is level or vertical,
    /// the heightfield keeps none of their cells, and a ray cast down onto the ground hits the
    /// height the height scan reads (`Terrain::height_at`).
    #[test]
    fn stepped_tiles_are_meshes_of_treads_and_risers_the_scan_sees() {
        let columns = [TerrainType::InvertedPyramidStairs, TerrainType::Boxes];
        let t = stepped_terrain(true, columns);
        let blocks = terrain_blocks(&t, GROUND_BLOCK);
        let meshes: Vec<_> = blocks.iter().filter_map(|(s, _)| s.as_trimesh()).collect();
        assert_eq!(meshes.len(), 4, "one mesh per stepped tile");
        for mesh in &meshes {
            assert!(
                mesh.indices().len() < 20_000,
                "merged: {}",
                mesh.indices().len()
            );
            for tri in mesh.triangles() {
                let n = tri.normal().expect("no degenerate triangle");
                assert!(
                    (n.z - 1.0).abs() < 1e-5 || n.z.abs() < 1e-5,
                    "a face that is neither level nor vertical: {n:?}"
                );
            }
        }
        for (shape, _) in &blocks {
            if let Some(field) = shape.as_heightfield() {
                let (rows, cols) = field.num_cells_ij();
                let kept = (0..rows)
                    .flat_map(|i| (0..cols).map(move |j| (i, j)))
                    .filter(|&(i, j)| {
                        !field
                            .cell_status(i, j)
                            .contains(HeightFieldCellStatus::CELL_REMOVED)
                    })
                    .count();
                assert!(kept > 0, "a block of only removed cells is dropped");
            }
        }
        let mut rng = SmallRng::seed_from_u64(3);
        let area = t.spec.tile_size * t.spec.num_rows as f32;
        for _ in 0..300 {
            let x = rng.random_range(-0.5 * area..0.5 * area);
            let y = rng.random_range(-area..area) * 0.5;
            let ray =
                rapier3d::parry::query::Ray::new(Vec3::new(x, y, 5.0), Vec3::new(0.0, 0.0, -1.0));
            let hit = blocks
                .iter()
                .filter_map(|(s, pose)| s.cast_ray(pose, &ray, 10.0, true))
                .fold(f32::INFINITY, f32::min);
            let z = 5.0 - hit;
            assert!(
                (z - t.height_at(x, y)).abs() < 1e-4,
                "at ({x}, {y}): ground {z}, scan {}",
                t.height_at(x, y)
            );
        }
    }

    /// `[env.terrain] fix_internal_edges` reaches every heightfield block the physics collides with.
    #[test]
    fn fix_internal_edges_reaches_every_heightfield_block() {
        for fix in [false, true] {
            let mut c = TerrainConfig::with_preset(TerrainPreset::Curriculum);
            c.border_width = 1.0;
            c.num_rows = 2;
            c.num_cols = 2;
            c.max_init_level = 1;
            c.fix_internal_edges = fix;
            let t = Terrain::generate(&c.resolve("a1").unwrap()).unwrap();
            let blocks = terrain_blocks(&t, GROUND_BLOCK);
            assert!(blocks.len() > 4);
            for (shape, _) in &blocks {
                let flags = shape.as_heightfield().expect("a heightfield").flags();
                assert_eq!(flags.contains(HeightFieldFlags::FIX_INTERNAL_EDGES), fix);
            }
        }
    }
}
