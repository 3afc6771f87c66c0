//! Environment configuration of the locomotion task: what a user writes in TOML, and its resolution
//! into concrete, validated numbers for one robot.
//!
//! Main types:
//! - [`EnvConfig`]: the `[env]` section (serde, `deny_unknown_fields`, every key optional). Its
//!   `Default` is the IsaacLab 2.1 rough-terrain velocity task (`velocity_env_cfg.py`), see
//!   `reference/locomotion-env-and-ppo.md` §1–§2.
//! - [`TerrainConfig`] (preset `flat | simple-rough | curriculum | paper` plus range overrides),
//!   [`CommandConfig`], [`NoiseConfig`], [`TerminationConfig`], [`RewardParams`], and per-robot PD
//!   gains ([`GainsOverride`], `[env.gains.<robot>]`).
//! - [`RewardScales`] with the IsaacLab per-robot tables ([`RewardScales::for_robot`]) and
//!   [`RandomizationConfig`] ([`RandomizationConfig::for_robot`]); the TOML side holds
//!   [`RewardOverrides`] / [`RandomizationOverrides`] (every field optional) that are applied on top of
//!   the robot's table, so that setting one weight never silently resets the others to another robot's.
//! - [`EnvConfig::resolve`] → [`TaskSpec`]: everything concrete for one robot, validated
//!   ([`ConfigError`] names the key).
//!
//! Files: `config/rewards.rs` holds the reward-term table and weights, `config/randomization.rs` the
//! randomisation ranges, `config/tests.rs` the unit tests; all re-exported here.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::terrain::{SubTerrainParams, TerrainSpec, TerrainType, TypeProportions};
use l3p_robot::catalog::{Gains, RobotSpec};

/// Errors of configuration parsing and validation.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// TOML syntax error or unknown / misspelt key (the message names the key and line).
    #[error("invalid env config: {0}")]
    Toml(#[from] toml::de::Error),
    /// A value is out of its valid range.
    #[error("invalid env config value `{key}`: {reason}")]
    Invalid { key: String, reason: String },
}

fn invalid(key: &str, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: key.to_string(),
        reason: reason.into(),
    }
}

/// Robot families that IsaacLab 2.1 configures differently.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotFamily {
    /// A1, Go1, Go2 (`VEL/config/{a1,go1,go2}`).
    Unitree,
    /// ANYmal B/C/D (the base `velocity_env_cfg.py` values).
    Anymal,
    /// Spot (IsaacLab ships only a flat Spot task with its own reward set; see `TASK_NOTES.md`).
    Spot,
    /// Any other robot: the base `velocity_env_cfg.py` values.
    Other,
}

impl RobotFamily {
    /// Family of a robot name (case-insensitive; `-` and `_` equivalent: `anymal-c`, `ANYmal_C`).
    pub fn from_name(name: &str) -> RobotFamily {
        let n = name.trim().to_ascii_lowercase().replace('-', "_");
        match n.as_str() {
            "a1" | "go1" | "go2" | "unitree_a1" | "unitree_go1" | "unitree_go2" => {
                RobotFamily::Unitree
            }
            "anymal_b" | "anymal_c" | "anymal_d" | "anymal" => RobotFamily::Anymal,
            "spot" => RobotFamily::Spot,
            _ => RobotFamily::Other,
        }
    }
}

/// Declares an "overrides" struct: the same fields as `$target`, each optional, applied on top of a
/// per-robot table.
macro_rules! overrides {
    ($(#[$m:meta])* $name:ident for $target:ident { $($field:ident : $ty:ty),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct $name {
            $(#[allow(missing_docs)] pub $field: Option<$ty>,)*
        }
        impl $name {
            /// Overwrites the fields of `base` that are set here.
            pub fn apply(&self, base: &mut $target) {
                $(if let Some(v) = &self.$field { base.$field = v.clone(); })*
            }
        }
    };
}

mod randomization;
mod rewards;

pub use randomization::{RandomizationConfig, RandomizationOverrides};
pub use rewards::{NUM_REWARD_TERMS, RewardOverrides, RewardParams, RewardScales, RewardTerm};

// ---------------------------------------------------------------------------------------------
// Terrain

/// Terrain preset names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum TerrainPreset {
    /// Flat ground everywhere (IsaacLab flat tasks use a plane); no curriculum.
    Flat,
    /// Transfer-experiment ground: half the columns flat, half random rough with small noise
    /// (0.02–0.05 m, step 0.02), modelled on IsaacLab's `COBBLESTONE_ROAD_CFG`; no curriculum.
    SimpleRough,
    /// IsaacLab 2.1 `ROUGH_TERRAINS_CFG` with the terrain-level curriculum (small-robot ranges for
    /// A1/Go1/Go2 as in their `rough_env_cfg.py`).
    #[default]
    Curriculum,
    /// The L3P paper's terrain table (larger upper bounds: stairs and boxes to 0.8 m, rough noise to
    /// 0.3 m, slopes to 0.8) with the curriculum.
    Paper,
}

/// `[env.terrain]`: layout, resolution and optional overrides of the preset's difficulty ranges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerrainConfig {
    /// Which terrain set to build.
    pub preset: TerrainPreset,
    /// Difficulty levels (rows along x). IsaacLab: 10.
    pub num_rows: usize,
    /// Columns (along y); column → terrain type by proportions. IsaacLab: 20.
    pub num_cols: usize,
    /// Side of a square tile in metres. IsaacLab: 8.
    pub tile_size: f32,
    /// Height-grid spacing in metres (0.05 keeps stair risers within 5 cm; see `TASK_NOTES.md`).
    pub horizontal_resolution: f32,
    /// Flat border around the whole tile area in metres. IsaacLab: 20.
    pub border_width: f32,
    /// Initial levels are drawn from `0..=max_init_level`. IsaacLab: 5.
    pub max_init_level: usize,
    /// Every env starts at this level instead (with `curriculum = false` it stays there: `l3p eval
    /// --level`, a policy's skill at one difficulty).
    pub init_level: Option<usize>,
    /// Seed of the terrain generator (boxes, rough noise, per-tile difficulty jitter).
    pub seed: u64,
    /// Override of the stairs (both kinds) step-height range `[lo, hi]` in metres.
    pub stairs_step_height: Option<[f32; 2]>,
    /// Override of the boxes grid-height range in metres.
    pub boxes_height: Option<[f32; 2]>,
    /// Override of the random-rough noise range in metres.
    pub rough_noise: Option<[f32; 2]>,
    /// Override of the random-rough noise step in metres.
    pub rough_noise_step: Option<f32>,
    /// Override of the slope range (both kinds), rise over run.
    pub slope: Option<[f32; 2]>,
    /// Override of the type proportions (normalised; column `j` gets the type whose cumulative
    /// proportion first exceeds `j / num_cols + 0.001`).
    pub proportions: Option<TypeProportions>,
    /// Override of whether the terrain-level curriculum runs (default: on for `curriculum`/`paper`).
    pub curriculum: Option<bool>,
    /// parry's `FIX_INTERNAL_EDGES` on the heightfield: contact normals against the edges shared
    /// by two triangles are corrected from the neighbours, so a foot sliding over the grid is not
    /// kicked by edges that are not really there. Off by default (policies trained before it).
    pub fix_internal_edges: bool,
    /// Stairs and boxes with vertical faces: those tiles collide as a mesh of flat treads and
    /// vertical risers (IsaacLab builds them as meshes) and the height scan sees the same steps,
    /// instead of a heightfield whose risers are one-cell ramps (45–78° at 0.05 m). Off by default
    /// (policies trained before it).
    pub vertical_faces: bool,
}

impl Default for TerrainConfig {
    fn default() -> Self {
        TerrainConfig {
            preset: TerrainPreset::Curriculum,
            num_rows: 10,
            num_cols: 20,
            tile_size: 8.0,
            horizontal_resolution: 0.05,
            border_width: 20.0,
            max_init_level: 5,
            init_level: None,
            seed: 0,
            stairs_step_height: None,
            boxes_height: None,
            rough_noise: None,
            rough_noise_step: None,
            slope: None,
            proportions: None,
            curriculum: None,
            fix_internal_edges: false,
            vertical_faces: false,
        }
    }
}

impl TerrainConfig {
    /// A config with the given preset and all other keys at their defaults.
    pub fn with_preset(preset: TerrainPreset) -> Self {
        TerrainConfig {
            preset,
            ..Default::default()
        }
    }

    /// Concrete generator input for `robot` (IsaacLab small-robot ranges for A1/Go1/Go2 in the
    /// `curriculum` preset), validated.
    pub fn resolve(&self, robot: &str) -> Result<TerrainSpec, ConfigError> {
        let family = RobotFamily::from_name(robot);
        let mut p = SubTerrainParams::isaaclab_rough();
        let (mut proportions, mut curriculum) = (TypeProportions::isaaclab_rough(), true);
        match self.preset {
            TerrainPreset::Flat => {
                proportions = TypeProportions::only(TerrainType::Flat);
                curriculum = false;
            }
            TerrainPreset::SimpleRough => {
                proportions = TypeProportions {
                    flat: 0.5,
                    random_rough: 0.5,
                    ..TypeProportions::zero()
                };
                p.rough_noise = [0.02, 0.05];
                p.rough_noise_step = 0.02;
                curriculum = false;
            }
            TerrainPreset::Curriculum => {
                if family == RobotFamily::Unitree {
                    // VEL/config/{a1,go1,go2}/rough_env_cfg.py
                    p.boxes_height = [0.025, 0.1];
                    p.rough_noise = [0.01, 0.06];
                    p.rough_noise_step = 0.01;
                }
            }
            TerrainPreset::Paper => p = SubTerrainParams::paper(),
        }
        if let Some(v) = self.stairs_step_height {
            p.stairs_step_height = v;
        }
        if let Some(v) = self.boxes_height {
            p.boxes_height = v;
        }
        if let Some(v) = self.rough_noise {
            p.rough_noise = v;
        }
        if let Some(v) = self.rough_noise_step {
            p.rough_noise_step = v;
        }
        if let Some(v) = self.slope {
            p.slope = v;
        }
        if let Some(v) = &self.proportions {
            proportions = v.clone();
        }
        if let Some(v) = self.curriculum {
            curriculum = v;
        }
        let spec = TerrainSpec {
            num_rows: self.num_rows,
            num_cols: self.num_cols,
            tile_size: self.tile_size,
            horizontal_resolution: self.horizontal_resolution,
            border_width: self.border_width,
            max_init_level: self.max_init_level,
            init_level: self.init_level,
            seed: self.seed,
            curriculum,
            proportions,
            params: p,
            fix_internal_edges: self.fix_internal_edges,
            vertical_faces: self.vertical_faces,
        };
        spec.validate()?;
        Ok(spec)
    }
}

// ---------------------------------------------------------------------------------------------
// Commands, noise, terminations, reward parameters

/// `[env.commands]`: IsaacLab `UniformVelocityCommandCfg` (`CommandsCfg.base_velocity`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CommandConfig {
    /// Forward velocity range (m/s, base frame).
    pub lin_vel_x: [f32; 2],
    /// Lateral velocity range (m/s).
    pub lin_vel_y: [f32; 2],
    /// Yaw-rate range (rad/s); also the clip of the heading controller's output.
    pub ang_vel_z: [f32; 2],
    /// Target heading range (rad), used in heading mode.
    pub heading: [f32; 2],
    /// Heading mode: the yaw-rate command is `clip(stiffness · wrap(heading − yaw), ang_vel_z)`.
    pub heading_command: bool,
    /// Gain of the heading controller. IsaacLab: 0.5.
    pub heading_stiffness: f32,
    /// Fraction of resampled commands in heading mode. IsaacLab: 1.0.
    pub rel_heading_envs: f32,
    /// Heading mode holds the heading the robot has when the command starts instead of drawing
    /// one from `heading` (a heading hold, as a deploy controller's `--heading-hold`).
    pub heading_hold: bool,
    /// Fraction of resampled commands that are all-zero (standing). IsaacLab: 0.02.
    pub rel_standing_envs: f32,
    /// Resampling period drawn uniformly from this range (s). IsaacLab: (10, 10).
    pub resampling_time_s: [f32; 2],
}

impl Default for CommandConfig {
    fn default() -> Self {
        CommandConfig {
            lin_vel_x: [-1.0, 1.0],
            lin_vel_y: [-1.0, 1.0],
            ang_vel_z: [-1.0, 1.0],
            heading: [-std::f32::consts::PI, std::f32::consts::PI],
            heading_command: true,
            heading_stiffness: 0.5,
            rel_heading_envs: 1.0,
            heading_hold: false,
            rel_standing_envs: 0.02,
            resampling_time_s: [10.0, 10.0],
        }
    }
}

/// `[env.noise]`: additive uniform observation noise `U(−n, n)` in physical units (IsaacLab
/// `ObservationsCfg.PolicyCfg`; no observation scaling).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseConfig {
    /// Master switch (`enable_corruption`).
    pub enabled: bool,
    /// Base linear velocity (m/s).
    pub lin_vel: f32,
    /// Base angular velocity (rad/s).
    pub ang_vel: f32,
    /// Projected gravity (unit vector components).
    pub gravity: f32,
    /// Joint position relative to default (rad).
    pub joint_pos: f32,
    /// Joint velocity (rad/s).
    pub joint_vel: f32,
    /// Height-scan samples (m), added before the ±1 clip.
    pub height_scan: f32,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        NoiseConfig {
            enabled: true,
            lin_vel: 0.1,
            ang_vel: 0.2,
            gravity: 0.05,
            joint_pos: 0.01,
            joint_vel: 1.5,
            height_scan: 0.1,
        }
    }
}

/// `[env.termination]`: episode ends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerminationConfig {
    /// Base (trunk) contact force norm above which the episode is terminated (N). IsaacLab: 1.0.
    pub base_contact_threshold: f32,
    /// Fall guard (not in IsaacLab): terminate when the base tilt (angle between the base z axis
    /// and world up) exceeds this many radians. A value >= π (e.g. 4.0) never triggers; `None`
    /// (not writable in TOML) disables it too.
    pub max_tilt_rad: Option<f32>,
    /// Fall guard (not in IsaacLab): terminate when the base is less than this height above the
    /// terrain under it (m). Robot-specific, so off by default.
    pub min_base_height: Option<f32>,
}

impl Default for TerminationConfig {
    fn default() -> Self {
        TerminationConfig {
            base_contact_threshold: 1.0,
            max_tilt_rad: Some(1.4),
            min_base_height: None,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The env section and its resolution

/// Which defaults the reward weights and randomisation start from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Recipe {
    /// IsaacLab 2.1's per-robot tables plus l3p's gait terms
    /// ([`RewardScales::add_gait_terms`]) and actuator randomisation
    /// ([`RandomizationConfig::add_actuator_randomization`]).
    #[default]
    L3p,
    /// IsaacLab 2.1's per-robot tables alone.
    Isaaclab,
}

/// `[env]`: the locomotion task. Default = IsaacLab 2.1 rough velocity task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvConfig {
    /// Defaults of reward weights and randomisation: `l3p` (IsaacLab + gait terms + actuator
    /// randomisation) or `isaaclab`.
    pub recipe: Recipe,
    /// Physics step (s). IsaacLab: 0.005.
    pub sim_dt: f32,
    /// Physics steps per policy step. IsaacLab: 4 (policy at 50 Hz).
    pub decimation: u32,
    /// Episode length (s); time-outs are `truncated`. IsaacLab: 20.
    pub episode_length_s: f32,
    /// Append the 187 height-scan samples to the 48 proprioceptive observations.
    pub height_scan: bool,
    /// Final clip of every observation entry (legged_gym `clip_observations`).
    pub obs_clip: f32,
    /// Clip of raw actions before use (legged_gym `clip_actions`; IsaacLab: none). Non-finite
    /// actions are replaced by 0 regardless.
    pub action_clip: f32,
    /// Low-pass filter of the applied action, `a = a_prev + α (clip(raw) − a_prev)` per control
    /// step (1 = none, IsaacLab). The filtered action is what becomes the joint target and the
    /// `last_action` observation; the deploy side applies the same filter (`io`).
    pub action_filter_alpha: f32,
    /// Frequency (Hz) of a trot clock the policy observes (`[sin 2πφ, cos 2πφ]` appended to the
    /// observation, φ = fraction of the clock's period since the episode began) and the
    /// `gait_clock` reward follows; 0 = no clock (IsaacLab). Part of the export's `io` contract.
    pub gait_clock_hz: f32,
    /// Phase (fraction of the period, in [0, 1)) at which every episode's clock starts; 0 as in
    /// deployment. 0.5 starts with the other diagonal pair in stance: the mirror image of an
    /// episode's start (`l3p eval --clock-start`, a diagnostic of a drift's sign).
    pub gait_clock_start: f32,
    pub terrain: TerrainConfig,
    pub commands: CommandConfig,
    pub noise: NoiseConfig,
    pub termination: TerminationConfig,
    pub reward_params: RewardParams,
    pub rewards: RewardOverrides,
    pub randomization: RandomizationOverrides,
    /// PD gains trained around, per robot (`[env.gains.a1] kp = 60.0`), replacing the catalog's
    /// `training_gains` for that robot only; `randomization.kp_scale`/`kd_scale` scale around them
    /// and the export's `io` carries them. Robots not named keep their catalog gains, so one config
    /// can tune A1 and still train other robots as the catalog describes them.
    pub gains: BTreeMap<String, GainsOverride>,
}

/// `[env.gains.<robot>]`: PD gains for one robot; an absent key keeps the catalog's value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GainsOverride {
    /// Stiffness (N·m/rad).
    pub kp: Option<f32>,
    /// Damping (N·m·s/rad).
    pub kd: Option<f32>,
}

impl GainsOverride {
    /// `base` with this override's values in place of its own.
    pub fn apply(&self, base: Gains) -> Gains {
        Gains {
            kp: self.kp.unwrap_or(base.kp),
            kd: self.kd.unwrap_or(base.kd),
        }
    }
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            sim_dt: 0.005,
            decimation: 4,
            episode_length_s: 20.0,
            height_scan: true,
            obs_clip: 100.0,
            action_clip: 100.0,
            action_filter_alpha: 1.0,
            gait_clock_hz: 0.0,
            gait_clock_start: 0.0,
            recipe: Recipe::L3p,
            terrain: TerrainConfig::default(),
            commands: CommandConfig::default(),
            noise: NoiseConfig::default(),
            termination: TerminationConfig::default(),
            reward_params: RewardParams::default(),
            rewards: RewardOverrides::default(),
            randomization: RandomizationOverrides::default(),
            gains: BTreeMap::new(),
        }
    }
}

/// Number of proprioceptive observations.
pub const PROPRIO_OBS: usize = 48;
/// Where the velocity command `[vx, vy, wz]` sits in the observation (noise-free).
pub const COMMAND_OBS: std::ops::Range<usize> = 9..12;
/// Number of height-scan samples (17 × 11).
pub const HEIGHT_SCAN_OBS: usize = 187;
/// Number of gait-clock observations (`sin`, `cos` of the phase).
pub const GAIT_CLOCK_OBS: usize = 2;

/// Observation length of a task: proprioception, then the height scan, then the gait clock.
pub fn obs_dim_of(height_scan: bool, gait_clock: bool) -> usize {
    PROPRIO_OBS
        + if height_scan { HEIGHT_SCAN_OBS } else { 0 }
        + if gait_clock { GAIT_CLOCK_OBS } else { 0 }
}

/// Everything concrete for one robot: what the task and the vectorised env run on.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    /// Robot name the tables were resolved for.
    pub robot: String,
    pub sim_dt: f32,
    pub decimation: u32,
    /// Policy step `sim_dt · decimation` (s); the `dt` of the reward terms.
    pub step_dt: f32,
    pub episode_length_s: f32,
    /// `ceil(episode_length_s / step_dt)` (IsaacLab `max_episode_length`): 1000 by default.
    pub max_episode_steps: u32,
    pub height_scan: bool,
    /// [`obs_dim_of`]: 48, + 187 with the height scan, + 2 with the gait clock.
    pub obs_dim: usize,
    pub obs_clip: f32,
    pub action_clip: f32,
    /// See [`EnvConfig::action_filter_alpha`]; in (0, 1].
    pub action_filter_alpha: f32,
    /// See [`EnvConfig::gait_clock_hz`]; 0 = no clock.
    pub gait_clock_hz: f32,
    /// See [`EnvConfig::gait_clock_start`].
    pub gait_clock_start: f32,
    pub terrain: TerrainSpec,
    pub commands: CommandConfig,
    pub noise: NoiseConfig,
    pub termination: TerminationConfig,
    pub reward_params: RewardParams,
    pub rewards: RewardScales,
    pub randomization: RandomizationConfig,
    /// `[env.gains.<robot>]` for this robot (empty: the catalog's training gains).
    pub gains: GainsOverride,
}

fn check_range(key: &str, r: [f32; 2]) -> Result<(), ConfigError> {
    if !r[0].is_finite() || !r[1].is_finite() || r[0] > r[1] {
        return Err(invalid(
            key,
            format!(
                "expected finite [lo, hi] with lo <= hi, got [{}, {}]",
                r[0], r[1]
            ),
        ));
    }
    Ok(())
}

fn check_nonneg(key: &str, v: f32) -> Result<(), ConfigError> {
    if !v.is_finite() || v < 0.0 {
        return Err(invalid(
            key,
            format!("expected a finite value >= 0, got {v}"),
        ));
    }
    Ok(())
}

fn check_pos(key: &str, v: f32) -> Result<(), ConfigError> {
    if !v.is_finite() || v <= 0.0 {
        return Err(invalid(
            key,
            format!("expected a finite value > 0, got {v}"),
        ));
    }
    Ok(())
}

impl EnvConfig {
    /// Parses an `[env]` table body (the keys of this struct at top level) strictly.
    pub fn from_toml_str(text: &str) -> Result<EnvConfig, ConfigError> {
        Ok(toml::from_str(text)?)
    }

    /// Observation length of this task ([`obs_dim_of`]).
    pub fn obs_dim(&self) -> usize {
        obs_dim_of(self.height_scan, self.gait_clock_hz > 0.0)
    }

    /// Whether the terrain preset is rough (selects IsaacLab's rough or flat reward table).
    pub fn is_rough(&self) -> bool {
        self.terrain.preset != TerrainPreset::Flat
    }

    /// Reward weights for `robot`: the IsaacLab table, then `[env.rewards]` overrides.
    pub fn reward_scales(&self, robot: &str) -> RewardScales {
        let mut s = RewardScales::for_robot(robot, self.is_rough());
        if self.recipe == Recipe::L3p {
            s.add_gait_terms(RobotFamily::from_name(robot));
        }
        self.rewards.apply(&mut s);
        s
    }

    /// Randomisation for `robot`: the IsaacLab table, then `[env.randomization]` overrides.
    pub fn randomization(&self, robot: &str) -> RandomizationConfig {
        let mut r = RandomizationConfig::for_robot(robot);
        if self.recipe == Recipe::L3p {
            r.add_actuator_randomization(RobotFamily::from_name(robot));
        }
        self.randomization.apply(&mut r);
        r
    }

    /// Steps physics at `dt` and keeps the control step `sim_dt · decimation`: evaluating a policy
    /// at a finer step than it trained at shows whether it relies on the coarse step's artefacts
    /// (the shipped A1 configs train at 20 ms; the walk criterion is checked at 5 ms).
    pub fn set_physics_dt(&mut self, dt: f32) -> Result<(), ConfigError> {
        check_pos("physics dt", dt)?;
        let control_dt = self.sim_dt as f64 * self.decimation as f64;
        let ratio = control_dt / dt as f64;
        let decimation = ratio.round();
        if decimation < 1.0 || (ratio - decimation).abs() > 1e-3 {
            return Err(invalid(
                "physics dt",
                format!(
                    "{dt} s does not divide the control step {control_dt} s into whole physics steps"
                ),
            ));
        }
        self.decimation = decimation as u32;
        self.sim_dt = (control_dt / decimation) as f32;
        Ok(())
    }

    /// The PD gains `spec` trains around: the catalog's, with `[env.gains.<robot>]` applied.
    pub fn training_gains(&self, spec: &RobotSpec) -> Gains {
        self.gains
            .get(spec.name)
            .map_or(spec.training_gains, |g| g.apply(spec.training_gains))
    }

    /// Resolves and validates everything for `robot`.
    pub fn resolve(&self, robot: &str) -> Result<TaskSpec, ConfigError> {
        check_pos("sim_dt", self.sim_dt)?;
        for (name, g) in &self.gains {
            if RobotSpec::by_name(name).is_err() {
                let known: Vec<&str> = RobotSpec::all().iter().map(|s| s.name).collect();
                return Err(invalid(
                    &format!("gains.{name}"),
                    format!("no robot named {name:?} (known: {})", known.join(", ")),
                ));
            }
            if let Some(kp) = g.kp {
                check_pos(&format!("gains.{name}.kp"), kp)?;
            }
            if let Some(kd) = g.kd {
                check_pos(&format!("gains.{name}.kd"), kd)?;
            }
        }
        if self.decimation == 0 {
            return Err(invalid("decimation", "expected >= 1"));
        }
        check_pos("episode_length_s", self.episode_length_s)?;
        check_pos("obs_clip", self.obs_clip)?;
        check_pos("action_clip", self.action_clip)?;
        if !(self.action_filter_alpha > 0.0 && self.action_filter_alpha <= 1.0) {
            return Err(invalid(
                "action_filter_alpha",
                format!("{} not in (0, 1]", self.action_filter_alpha),
            ));
        }
        check_nonneg("gait_clock_hz", self.gait_clock_hz)?;
        if !(0.0..1.0).contains(&self.gait_clock_start) {
            return Err(invalid(
                "gait_clock_start",
                format!("expected a phase in [0, 1), got {}", self.gait_clock_start),
            ));
        }
        let c = &self.commands;
        check_range("commands.lin_vel_x", c.lin_vel_x)?;
        check_range("commands.lin_vel_y", c.lin_vel_y)?;
        check_range("commands.ang_vel_z", c.ang_vel_z)?;
        check_range("commands.heading", c.heading)?;
        check_range("commands.resampling_time_s", c.resampling_time_s)?;
        check_pos("commands.resampling_time_s", c.resampling_time_s[0])?;
        check_nonneg("commands.heading_stiffness", c.heading_stiffness)?;
        for (k, v) in [
            ("commands.rel_heading_envs", c.rel_heading_envs),
            ("commands.rel_standing_envs", c.rel_standing_envs),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(
                    k,
                    format!("expected a fraction in [0, 1], got {v}"),
                ));
            }
        }
        let n = &self.noise;
        for (k, v) in [
            ("noise.lin_vel", n.lin_vel),
            ("noise.ang_vel", n.ang_vel),
            ("noise.gravity", n.gravity),
            ("noise.joint_pos", n.joint_pos),
            ("noise.joint_vel", n.joint_vel),
            ("noise.height_scan", n.height_scan),
        ] {
            check_nonneg(k, v)?;
        }
        let t = &self.termination;
        check_nonneg(
            "termination.base_contact_threshold",
            t.base_contact_threshold,
        )?;
        if let Some(v) = t.max_tilt_rad {
            check_pos("termination.max_tilt_rad", v)?;
        }
        if let Some(v) = t.min_base_height
            && !v.is_finite()
        {
            return Err(invalid(
                "termination.min_base_height",
                "expected a finite value",
            ));
        }
        let rp = &self.reward_params;
        check_pos("reward_params.tracking_std", rp.tracking_std)?;
        check_pos("reward_params.coarse_tracking_std", rp.coarse_tracking_std)?;
        check_pos("reward_params.yaw_mean_std", rp.yaw_mean_std)?;
        check_pos("reward_params.yaw_mean_window_s", rp.yaw_mean_window_s)?;
        if let Some(std) = rp.yaw_tracking_std {
            check_pos("reward_params.yaw_tracking_std", std)?;
        }
        check_nonneg("reward_params.air_time_threshold", rp.air_time_threshold)?;
        check_nonneg(
            "reward_params.air_time_min_command",
            rp.air_time_min_command,
        )?;
        check_nonneg("reward_params.contact_threshold", rp.contact_threshold)?;
        let rewards = self.reward_scales(robot);
        for (k, v) in rewards.named() {
            if !v.is_finite() {
                return Err(invalid(&format!("rewards.{k}"), "expected a finite weight"));
            }
        }
        let rz = self.randomization(robot);
        check_range("randomization.static_friction", rz.static_friction)?;
        check_range("randomization.dynamic_friction", rz.dynamic_friction)?;
        check_nonneg("randomization.static_friction", rz.static_friction[0])?;
        check_nonneg("randomization.dynamic_friction", rz.dynamic_friction[0])?;
        check_range("randomization.added_base_mass", rz.added_base_mass)?;
        check_range("randomization.push_interval_s", rz.push_interval_s)?;
        check_pos("randomization.push_interval_s", rz.push_interval_s[0])?;
        for v in rz.base_com_offset {
            check_nonneg("randomization.base_com_offset", v)?;
        }
        check_nonneg("randomization.push_velocity_xy", rz.push_velocity_xy)?;
        check_nonneg("randomization.reset_base_xy", rz.reset_base_xy)?;
        check_nonneg("randomization.reset_yaw", rz.reset_yaw)?;
        check_nonneg("randomization.reset_base_velocity", rz.reset_base_velocity)?;
        check_range(
            "randomization.reset_joint_pos_scale",
            rz.reset_joint_pos_scale,
        )?;
        for (key, r) in [
            ("randomization.joint_damping", rz.joint_damping),
            ("randomization.joint_friction", rz.joint_friction),
            ("randomization.latency_s", rz.latency_s),
        ] {
            check_range(key, r)?;
            check_nonneg(key, r[0])?;
        }
        for (key, r) in [
            ("randomization.motor_strength", rz.motor_strength),
            ("randomization.kp_scale", rz.kp_scale),
            ("randomization.kd_scale", rz.kd_scale),
        ] {
            check_range(key, r)?;
            check_pos(key, r[0])?;
        }
        check_pos(
            "reward_params.base_height_fraction",
            self.reward_params.base_height_fraction,
        )?;
        check_nonneg(
            "reward_params.feet_clearance_fraction",
            self.reward_params.feet_clearance_fraction,
        )?;
        let terrain = self.terrain.resolve(robot)?;
        let step_dt = self.sim_dt * self.decimation as f32;
        // IsaacLab: math.ceil(episode_length_s / step_dt) in doubles; 0.005f32 * 4 is slightly below
        // 0.02, so a tolerance keeps 20 s at 1000 steps rather than 1001.
        let steps = (self.episode_length_s as f64 / step_dt as f64 - 1e-4)
            .ceil()
            .max(1.0) as u32;
        Ok(TaskSpec {
            robot: robot.to_string(),
            sim_dt: self.sim_dt,
            decimation: self.decimation,
            step_dt,
            episode_length_s: self.episode_length_s,
            max_episode_steps: steps,
            height_scan: self.height_scan,
            obs_dim: self.obs_dim(),
            obs_clip: self.obs_clip,
            action_clip: self.action_clip,
            action_filter_alpha: self.action_filter_alpha,
            gait_clock_hz: self.gait_clock_hz,
            gait_clock_start: self.gait_clock_start,
            terrain,
            commands: self.commands.clone(),
            noise: self.noise.clone(),
            termination: self.termination.clone(),
            reward_params: self.reward_params.clone(),
            rewards,
            randomization: rz,
            gains: self.gains.get(robot).copied().unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests;
