//! The paper's transfer experiment as data: an [`ExperimentSpec`] (one TOML file) expands by
//! [`plan`] into [`Arm`]s — each an ordinary `l3p train` run with its own config file — and the
//! results of finished arms aggregate into [`ArmResult`]s and the paper-layout [`Table`].
//!
//! Beside the paper's grid, `[[variants]]` add named arms that change one thing — a core
//! pretrained on several robots, other latent sizes, warm-started transfer heads — and appear in
//! the report as `<method> [<variant>]` rows.
//!
//! Layout on disk (`<data_dir>/<name>/`): `arms/<arm>.toml` (the arm's full training config),
//! `<arm>/` (its data directory: registry, `<arm>/` run directory with metrics and checkpoints),
//! `<arm>/done.json` (written when the arm finished every iteration, with wall-clock and
//! evaluations), `<arm>/failed.json` (the last failure), `<arm>/running.pid`, `logs/<arm>.log`.
//!
//! Pure logic only; `experiment_cmd` runs the processes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use l3p_learner::{Mode, TransferHeads};
use l3p_report::ReportRow;
use l3p_task::config::TerrainPreset;
use l3p_task::terrain::TerrainType;
use serde::{Deserialize, Serialize};

use crate::config::{ActorSpec, Config};

/// `experiments/<name>.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSpec {
    pub experiment: ExperimentSection,
    pub pretrain: StageSpec,
    pub targets: StageSpec,
    #[serde(default)]
    pub evaluation: EvaluationSpec,
    /// Extra arms beside the paper's grid (`[[variants]]`).
    #[serde(default)]
    pub variants: Vec<VariantSpec>,
}

/// `[[variants]]`: named arms that change one thing against the main grid, run with every seed.
///
/// A variant that sets `pretrain_robots`, `pretrain_methods`, `d_h` or `d_z` pretrains its own
/// cores (`pretrain-<variant>-<method>-s<seed>`) and its transfer arms start from them; otherwise
/// its transfer arms start from the main pretraining arms. Target arms are
/// `<robot>-<method>-<variant>-s<seed>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantSpec {
    /// A single key segment, distinct from other variants.
    pub name: String,
    /// Target methods (none: the variant only pretrains, e.g. a latent-size ablation).
    #[serde(default)]
    pub methods: Vec<Mode>,
    /// Target robots (default: `targets.robots`).
    #[serde(default)]
    pub robots: Option<Vec<String>>,
    /// Robots of the variant's own pretraining: one core trained on all of them at once.
    #[serde(default)]
    pub pretrain_robots: Option<Vec<String>>,
    /// Methods of the variant's own pretraining (default: those its transfer methods start from).
    #[serde(default)]
    pub pretrain_methods: Option<Vec<Mode>>,
    /// Latent sizes of every network of the variant (default: the base config's).
    #[serde(default)]
    pub d_h: Option<usize>,
    #[serde(default)]
    pub d_z: Option<usize>,
    /// Environments per actor of the variant's own pretraining arms (default: the experiment's):
    /// e.g. to keep a joint pretraining's samples per iteration equal to a single robot's. Its
    /// target arms keep the experiment's envs, so they compare with the from-scratch arms at equal
    /// samples.
    #[serde(default)]
    pub envs: Option<usize>,
    /// How `l3p-transfer` target arms start (default: the base config's, normally `fresh`).
    #[serde(default)]
    pub transfer_heads: Option<TransferHeads>,
}

impl VariantSpec {
    /// Whether the variant trains its own cores rather than transferring the main ones.
    pub fn pretrains(&self) -> bool {
        self.pretrain_robots.is_some()
            || self.pretrain_methods.is_some()
            || self.d_h.is_some()
            || self.d_z.is_some()
    }

    /// Its own pretraining methods (empty when it does not pretrain).
    pub fn own_pretrain_methods(&self) -> Vec<Mode> {
        if !self.pretrains() {
            return Vec::new();
        }
        self.pretrain_methods.clone().unwrap_or_else(|| {
            let mut m: Vec<Mode> = self
                .methods
                .iter()
                .filter_map(|m| transfer_source(*m))
                .collect();
            m.dedup();
            m
        })
    }
}

/// `[experiment]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSection {
    /// Experiment name: a single key segment; data goes under `<data_dir>/<name>/`.
    pub name: String,
    /// Training config every arm starts from (env, rewards, networks, PPO); paths are relative
    /// to the working directory, as for every `l3p` command.
    pub base_config: PathBuf,
    #[serde(default = "default_data_dir")]
    pub data_dir: PathBuf,
    /// Seeds; every arm runs once per seed.
    pub seeds: Vec<u64>,
    /// Arms trained at once by `l3p experiment run` (each arm uses its actors' threads).
    #[serde(default = "one")]
    pub parallel: usize,
    /// Environments per actor (default: the base config's first actor).
    #[serde(default)]
    pub envs: Option<usize>,
    /// Simulator threads per actor (default: the base config's first actor).
    #[serde(default)]
    pub threads: Option<usize>,
    /// Samples to walk: every arm trains with `--until-walks` and stops when the walk criterion
    /// holds; each stage's `iterations` is then a cap. The report's first table is samples to walk.
    #[serde(default)]
    pub until_walks: bool,
    /// Run target arms robot by robot (every method and variant of the first robot, then the
    /// next), so that a partial run already compares the methods on some robots; the default runs
    /// the main grid, then each variant.
    #[serde(default)]
    pub by_robot: bool,
}

fn default_data_dir() -> PathBuf {
    PathBuf::from("l3p-data/experiments")
}

fn one() -> usize {
    1
}

/// `[pretrain]` and `[targets]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    /// Catalog robots. Pretraining with several robots trains one core on all of them at once
    /// (one actor each); every target robot is its own arm.
    pub robots: Vec<String>,
    /// `mlp`, `l3p` (from scratch); targets also `mlp-transfer`, `l3p-transfer` (from the
    /// pretraining arm of the same architecture and seed).
    pub methods: Vec<Mode>,
    pub iterations: u64,
    /// Terrain preset (default: the base config's).
    #[serde(default)]
    pub terrain: Option<TerrainPreset>,
}

/// `[evaluation]`: how a finished arm's final policy is evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvaluationSpec {
    /// Finished episodes per evaluation.
    pub episodes: usize,
    /// Parallel environments of an evaluation.
    pub envs: usize,
    /// Constant forward speeds evaluated with gait diagnostics (besides the training command mix).
    pub forward: Vec<f32>,
    pub seed: u64,
    /// Terrain types each target arm's final policy is also evaluated on, one at a time, with
    /// the terrain-level curriculum running (the paper's simple→complex radar: how far up each
    /// terrain's difficulty levels the policy walks itself). Empty: none.
    pub terrain_types: Vec<TerrainType>,
    /// Episodes per environment of each terrain-type evaluation (the curriculum moves a robot at
    /// most one level per episode, starting from levels `0..=max_init_level`).
    pub terrain_rounds: usize,
}

impl Default for EvaluationSpec {
    fn default() -> Self {
        Self {
            episodes: 16,
            envs: 16,
            forward: vec![0.5, 1.0],
            seed: 11,
            terrain_types: Vec::new(),
            terrain_rounds: 6,
        }
    }
}

impl ExperimentSpec {
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let spec: ExperimentSpec = l3p_proto::config::load_toml(path)?;
        spec.validate()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(spec)
    }

    /// Checks what would otherwise fail arms later; errors name the key.
    pub fn validate(&self) -> Result<(), String> {
        let e = &self.experiment;
        l3p_proto::keys::validate_segment("experiment.name", &e.name).map_err(|x| x.to_string())?;
        if e.seeds.is_empty() {
            return Err("experiment.seeds is empty".into());
        }
        let mut seeds = e.seeds.clone();
        seeds.sort_unstable();
        seeds.dedup();
        if seeds.len() != e.seeds.len() {
            return Err(format!("experiment.seeds {:?} repeats a seed", e.seeds));
        }
        if e.parallel == 0 {
            return Err("experiment.parallel = 0: expected >= 1".into());
        }
        if e.envs == Some(0) || e.threads == Some(0) {
            return Err("experiment.envs and experiment.threads must be >= 1".into());
        }
        for (stage, s) in [("pretrain", &self.pretrain), ("targets", &self.targets)] {
            // `[targets]` may be empty as a whole: a pretraining-only experiment (an ablation).
            let pretraining_only =
                stage == "targets" && s.robots.is_empty() && s.methods.is_empty();
            if (s.robots.is_empty() || s.methods.is_empty()) && !pretraining_only {
                return Err(format!(
                    "{stage}.robots and {stage}.methods must not be empty (an experiment \
                     without targets leaves both empty)"
                ));
            }
            if s.iterations == 0 {
                return Err(format!("{stage}.iterations = 0: expected >= 1"));
            }
            for r in &s.robots {
                l3p_robot::catalog::RobotSpec::by_name(r)
                    .map_err(|x| format!("{stage}.robots: {x}"))?;
            }
        }
        for m in &self.pretrain.methods {
            if !matches!(m, Mode::Mlp | Mode::L3p) {
                return Err(format!(
                    "pretrain.methods: {} is not a from-scratch method (mlp or l3p)",
                    m.as_str()
                ));
            }
        }
        for m in &self.targets.methods {
            if let Some(base) = transfer_source(*m)
                && !self.pretrain.methods.contains(&base)
            {
                return Err(format!(
                    "targets.methods has {} but pretrain.methods has no {}",
                    m.as_str(),
                    base.as_str()
                ));
            }
        }
        let mut names: Vec<&str> = Vec::new();
        for v in &self.variants {
            self.validate_variant(v)
                .map_err(|x| format!("variants.{}: {x}", v.name))?;
            if names.contains(&v.name.as_str()) {
                return Err(format!("variants: the name {} is used twice", v.name));
            }
            names.push(&v.name);
        }
        let ev = &self.evaluation;
        if ev.episodes == 0 || ev.envs == 0 {
            return Err("evaluation.episodes and evaluation.envs must be >= 1".into());
        }
        if !ev.terrain_types.is_empty() && ev.terrain_rounds == 0 {
            return Err("evaluation.terrain_rounds = 0: expected >= 1".into());
        }
        if ev.forward.iter().any(|v| !v.is_finite()) {
            return Err(format!(
                "evaluation.forward {:?}: speeds must be finite",
                ev.forward
            ));
        }
        Ok(())
    }

    fn validate_variant(&self, v: &VariantSpec) -> Result<(), String> {
        l3p_proto::keys::validate_segment("name", &v.name).map_err(|x| x.to_string())?;
        for r in v.robots.iter().chain(&v.pretrain_robots).flatten() {
            l3p_robot::catalog::RobotSpec::by_name(r).map_err(|x| x.to_string())?;
        }
        if v.pretrain_robots.as_ref().is_some_and(|r| r.is_empty()) {
            return Err("pretrain_robots is empty".into());
        }
        if v.d_h == Some(0) || v.d_z == Some(0) || v.envs == Some(0) {
            return Err("d_h, d_z and envs must be >= 1".into());
        }
        let own = v.own_pretrain_methods();
        for m in &own {
            if !matches!(m, Mode::Mlp | Mode::L3p) {
                return Err(format!(
                    "pretrain_methods: {} is not a from-scratch method (mlp or l3p)",
                    m.as_str()
                ));
            }
        }
        let available = if v.pretrains() {
            &own
        } else {
            &self.pretrain.methods
        };
        for m in &v.methods {
            if let Some(base) = transfer_source(*m)
                && !available.contains(&base)
            {
                return Err(format!(
                    "methods has {} but its pretraining has no {}",
                    m.as_str(),
                    base.as_str()
                ));
            }
        }
        if v.methods.is_empty() && own.is_empty() {
            return Err("no arms: give methods, or pretraining (pretrain_robots, d_h, d_z)".into());
        }
        Ok(())
    }

    /// `<data_dir>/<name>`.
    pub fn dir(&self) -> PathBuf {
        self.experiment.data_dir.join(&self.experiment.name)
    }
}

/// The pretraining method a transfer method starts from.
pub fn transfer_source(method: Mode) -> Option<Mode> {
    match method {
        Mode::MlpTransfer => Some(Mode::Mlp),
        Mode::L3pTransfer => Some(Mode::L3p),
        Mode::Mlp | Mode::L3p => None,
    }
}

/// Which half of the experiment an arm belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    Pretrain,
    Target,
}

/// One training run of the experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Arm {
    /// `pretrain-<method>-s<seed>` or `<robot>-<method>-s<seed>` (variants:
    /// `pretrain-<variant>-<method>-s<seed>`, `<robot>-<method>-<variant>-s<seed>`); also the run name.
    pub name: String,
    pub stage: Stage,
    /// The `[[variants]]` entry the arm belongs to (`None`: the main grid).
    pub variant: Option<String>,
    pub robots: Vec<String>,
    pub method: Mode,
    pub seed: u64,
    pub iterations: u64,
    /// The pretraining arm whose final checkpoint this arm starts from.
    pub depends_on: Option<String>,
    /// Trains with `--until-walks` (`iterations` is a cap).
    pub until_walks: bool,
    /// The arm's complete training config (run name, seed, data dir, mode, actors, init_from).
    pub config: Config,
}

impl Arm {
    /// The arm's data directory (its `run.data_dir`).
    pub fn data_dir(&self) -> &Path {
        &self.config.run.data_dir
    }

    /// Where `l3p train` keeps this arm's metrics and checkpoints.
    pub fn run_dir(&self) -> PathBuf {
        self.data_dir().join(&self.name)
    }

    /// The `l3p train` invocation of this arm, given where its config file lives.
    pub fn command(&self, config_file: &Path) -> Vec<String> {
        let mut c: Vec<String> = vec![
            "l3p".into(),
            "train".into(),
            config_file.display().to_string(),
            "--quiet".into(),
        ];
        if self.until_walks {
            c.push("--until-walks".into());
        }
        c
    }

    /// Samples one iteration collects (every actor's envs × steps per env).
    pub fn samples_per_iteration(&self) -> u64 {
        let envs: usize = self.config.actors.iter().map(|a| a.envs).sum();
        (envs * self.config.rollout.steps_per_env) as u64
    }
}

/// `<dir>/arms/<arm>.toml`.
pub fn arm_config_path(dir: &Path, arm: &str) -> PathBuf {
    dir.join("arms").join(format!("{arm}.toml"))
}

/// What one arm changes against the base config.
struct ArmRecipe<'a> {
    name: String,
    stage: Stage,
    variant: Option<&'a VariantSpec>,
    robots: Vec<String>,
    method: Mode,
    seed: u64,
    iterations: u64,
    terrain: Option<TerrainPreset>,
    depends_on: Option<String>,
}

/// Expands the spec into arms: the main grid's pretraining arms (`pretrain.methods × seeds`), its
/// targets (`targets.robots × targets.methods × seeds`), then each variant in file order (its own
/// pretraining, then its targets); each transfer arm depends on the pretraining arm of its
/// architecture and seed.
pub fn plan(spec: &ExperimentSpec, base: &Config) -> anyhow::Result<Vec<Arm>> {
    spec.validate().map_err(|e| anyhow::anyhow!(e))?;
    let first = base.actors.first();
    let envs = spec.experiment.envs.or(first.map(|a| a.envs)).unwrap_or(64);
    let threads = spec
        .experiment
        .threads
        .or(first.map(|a| a.threads))
        .unwrap_or(1);
    let dir = spec.dir();
    let make = |r: ArmRecipe| -> anyhow::Result<Arm> {
        let mut config = base.clone();
        config.run.name = r.name.clone();
        config.run.seed = r.seed;
        config.ppo.seed = r.seed;
        config.run.data_dir = dir.join(&r.name);
        config.ppo.mode = r.method;
        config.learner.max_iterations = r.iterations;
        config.learner.init_from = r
            .depends_on
            .as_ref()
            .map(|p| final_checkpoint(&dir.join(p).join(p)));
        // The base config's own preset keeps its tuning (a recipe's box heights, noise, edge
        // fix); another preset starts from that preset's defaults, keeping only the edge fix (a
        // simulator correction, not a terrain choice).
        if let Some(t) = r.terrain
            && t != base.env.terrain.preset
        {
            config.env.terrain = l3p_task::config::TerrainConfig {
                fix_internal_edges: base.env.terrain.fix_internal_edges,
                vertical_faces: base.env.terrain.vertical_faces,
                ..l3p_task::config::TerrainConfig::with_preset(t)
            };
            config.env.height_scan = t != TerrainPreset::Flat;
        }
        let mut arm_envs = envs;
        if let Some(v) = r.variant {
            config.model.d_h = v.d_h.unwrap_or(config.model.d_h);
            config.model.d_z = v.d_z.unwrap_or(config.model.d_z);
            config.ppo.transfer_heads = v.transfer_heads.unwrap_or(config.ppo.transfer_heads);
            if r.stage == Stage::Pretrain {
                arm_envs = v.envs.unwrap_or(envs);
            }
        }
        config.actors = r
            .robots
            .iter()
            .map(|robot| ActorSpec {
                robot: robot.clone(),
                envs: arm_envs,
                threads,
            })
            .collect();
        config
            .validate()
            .map_err(|e| anyhow::anyhow!("arm {}: {e}", r.name))?;
        Ok(Arm {
            name: r.name,
            stage: r.stage,
            variant: r.variant.map(|v| v.name.clone()),
            robots: r.robots,
            method: r.method,
            seed: r.seed,
            iterations: r.iterations,
            depends_on: r.depends_on,
            until_walks: spec.experiment.until_walks,
            config,
        })
    };
    let pretrain = |variant: Option<&'_ VariantSpec>, method: Mode, seed: u64| {
        let (name, robots) = match variant {
            Some(v) => (
                format!("pretrain-{}-{}-s{seed}", v.name, method.as_str()),
                v.pretrain_robots
                    .clone()
                    .unwrap_or_else(|| spec.pretrain.robots.clone()),
            ),
            None => (
                pretrain_arm_name(method, seed),
                spec.pretrain.robots.clone(),
            ),
        };
        make(ArmRecipe {
            name,
            stage: Stage::Pretrain,
            variant,
            robots,
            method,
            seed,
            iterations: spec.pretrain.iterations,
            terrain: spec.pretrain.terrain,
            depends_on: None,
        })
    };
    let target = |variant: Option<&'_ VariantSpec>, robot: &str, method: Mode, seed: u64| {
        let suffix = variant.map(|v| format!("-{}", v.name)).unwrap_or_default();
        let depends_on = transfer_source(method).map(|m| match variant {
            Some(v) if v.pretrains() => format!("pretrain-{}-{}-s{seed}", v.name, m.as_str()),
            _ => pretrain_arm_name(m, seed),
        });
        make(ArmRecipe {
            name: format!(
                "{}-{}{suffix}-s{seed}",
                robot.replace('_', "-"),
                method.as_str()
            ),
            stage: Stage::Target,
            variant,
            robots: vec![robot.to_string()],
            method,
            seed,
            iterations: spec.targets.iterations,
            terrain: spec.targets.terrain,
            depends_on,
        })
    };
    let seeds = &spec.experiment.seeds;
    let mut arms = Vec::new();
    for &seed in seeds {
        for &method in &spec.pretrain.methods {
            arms.push(pretrain(None, method, seed)?);
        }
    }
    for robot in &spec.targets.robots {
        for &method in &spec.targets.methods {
            for &seed in seeds {
                arms.push(target(None, robot, method, seed)?);
            }
        }
    }
    for v in &spec.variants {
        for &seed in seeds {
            for method in v.own_pretrain_methods() {
                arms.push(pretrain(Some(v), method, seed)?);
            }
        }
        for robot in v.robots.as_ref().unwrap_or(&spec.targets.robots) {
            for &method in &v.methods {
                for &seed in seeds {
                    arms.push(target(Some(v), robot, method, seed)?);
                }
            }
        }
    }
    if spec.experiment.by_robot {
        let mut robots: Vec<&str> = Vec::new();
        for arm in arms.iter().filter(|a| a.stage == Stage::Target) {
            if !robots.contains(&arm.robots[0].as_str()) {
                robots.push(&arm.robots[0]);
            }
        }
        let rank = |a: &Arm| match a.stage {
            Stage::Pretrain => 0,
            Stage::Target => 1 + robots.iter().position(|r| *r == a.robots[0]).unwrap_or(0),
        };
        let mut ranked: Vec<(usize, Arm)> = arms.iter().map(|a| (rank(a), a.clone())).collect();
        // Stable: pretraining first, then within a robot the main grid, then the variants.
        ranked.sort_by_key(|(r, _)| *r);
        arms = ranked.into_iter().map(|(_, a)| a).collect();
    }
    let mut names: Vec<&str> = arms.iter().map(|a| a.name.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        anyhow::bail!(
            "two arms are named {}\nhint: rename the variant that makes it",
            w[0]
        );
    }
    Ok(arms)
}

/// `pretrain-<method>-s<seed>`.
pub fn pretrain_arm_name(method: Mode, seed: u64) -> String {
    format!("pretrain-{}-s{seed}", method.as_str())
}

/// The checkpoint a run leaves behind (`<run_dir>/checkpoints/latest.ckpt`).
pub fn final_checkpoint(run_dir: &Path) -> PathBuf {
    l3p_learner::daemon::checkpoint_path(run_dir)
}

/// What `done.json` records about a finished arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArmDone {
    pub arm: String,
    pub iterations: u64,
    /// Wall-clock of the training process(es) of this arm, summed over resumptions.
    pub wall_seconds: f64,
    /// Final policy per robot: the training command mix, then each `evaluation.forward` speed.
    pub evaluations: BTreeMap<String, Vec<crate::eval_cmd::EvalRow>>,
    /// Transfer arms: the pretrained policy played on the target robot before any fine-tuning
    /// (its own encoder/decoder: every catalog robot has the same observation and action layout).
    #[serde(default)]
    pub zero_shot: Option<Vec<crate::eval_cmd::EvalRow>>,
    /// Target arms, per `evaluation.terrain_types` entry (snake_case name): the final policy on
    /// that terrain alone with the curriculum running.
    #[serde(default)]
    pub by_terrain: BTreeMap<String, crate::eval_cmd::EvalRow>,
    /// Transfer arms, per `evaluation.terrain_types` entry: the pretrained policy on the target
    /// robot on that terrain alone before any fine-tuning — the skill fine-tuning kept or lost.
    #[serde(default)]
    pub zero_shot_by_terrain: BTreeMap<String, crate::eval_cmd::EvalRow>,
    /// `until_walks` experiments: when the walk criterion held, or that it did not within the cap.
    #[serde(default)]
    pub walk: Option<WalkOutcome>,
    /// `until_walks` transfer arms: the walk check of the policy the arm starts from (its
    /// iteration-0 model, transfer heads included), before any fine-tuning.
    #[serde(default)]
    pub zero_shot_walk: Option<WalkOutcome>,
}

/// An arm's walk criterion verdict (`l3p train --until-walks`, at the walk check's 5 ms physics).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WalkOutcome {
    pub walks: bool,
    /// The passing check's iteration, or the cap when it did not walk (a lower bound).
    pub iteration: u64,
    /// The last walk check's iteration (0: none).
    #[serde(default)]
    pub last_check: u64,
    /// Samples to the checked iteration (walked) or to the cap (a lower bound on samples to walk).
    pub samples: u64,
    /// Wall-clock to the passing check over every attempt (walked only).
    #[serde(default)]
    pub wall_seconds: Option<f64>,
    /// The bounds the last check failed (empty when it walks).
    #[serde(default)]
    pub failures: Vec<String>,
    /// Walk checks recorded in `walk_checks.jsonl`.
    #[serde(default)]
    pub checks: usize,
    /// The first check that failed no bound but the heading bound (a gait that tracks, stands
    /// tall, steps and is smooth, turning or not): its iteration and samples.
    #[serde(default)]
    pub gait: Option<(u64, u64)>,
    /// The first check at which xy tracking held at every checked speed, whatever else failed:
    /// its iteration and samples. The samples between it and walking went to the other bounds.
    #[serde(default)]
    pub tracks: Option<(u64, u64)>,
    /// The checked rows (0.5 and 1.0 m/s; only 1.0 when it failed there).
    #[serde(default)]
    pub rows: Vec<crate::eval_cmd::EvalRow>,
}

/// How the walk criterion's heading bound words its failure (`l3p_task::gait::WalkCriterion`).
const HEADING_FAILURE: &str = "heading changes";

/// Whether every failing bound (none included) is the heading bound: a gait that tracks, stands
/// tall, steps and is smooth, turning or not.
pub fn only_heading_fails<'a>(mut failures: impl Iterator<Item = &'a str>) -> bool {
    failures.all(|f| f.starts_with(HEADING_FAILURE))
}

/// How the walk criterion words an xy tracking failure (`l3p_task::gait::WalkCriterion`).
const TRACKING_FAILURE: &str = "xy tracking error";

/// Whether no failing bound is the xy tracking bound: the policy goes where it is told.
pub fn tracking_holds<'a>(mut failures: impl Iterator<Item = &'a str>) -> bool {
    !failures.any(|f| f.starts_with(TRACKING_FAILURE))
}

/// Where an `--until-walks` arm stands once its trainer exited.
#[derive(Debug, Clone, PartialEq)]
pub enum WalkProgress {
    /// The criterion held (or the cap was reached without it): the arm is finished.
    Settled(WalkOutcome),
    /// Stopped before the cap without walking (interrupted): resume it; its check history stays
    /// in `walk_checks.jsonl`.
    Interrupted { iteration: u64 },
}

/// The walk checks an `--until-walks` run recorded (`<run_dir>/walk_checks.jsonl`), oldest first;
/// lines that do not parse are skipped.
pub fn read_walk_checks(run_dir: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run_dir.join("walk_checks.jsonl"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// The first walk checks at which parts of the criterion held: (iteration, samples) each.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Milestones {
    /// Every bound but the heading bound ([`WalkOutcome::gait`]).
    pub gait: Option<(u64, u64)>,
    /// The xy tracking bound ([`WalkOutcome::tracks`]).
    pub tracks: Option<(u64, u64)>,
}

/// [`Milestones`] of a run's walk checks (as [`read_walk_checks`] returns them).
pub fn milestones(checks: &[serde_json::Value], samples_per_iteration: u64) -> Milestones {
    // The first check whose every row's failures satisfy `holds`.
    let first_check = |holds: &dyn Fn(&[serde_json::Value]) -> bool| {
        checks
            .iter()
            .find(|c| {
                c["rows"].as_array().is_some_and(|rows| {
                    !rows.is_empty()
                        && rows.iter().all(|r| {
                            r["walk_failures"].as_array().is_some_and(|f| {
                                f.iter().all(serde_json::Value::is_string) && holds(f)
                            })
                        })
                })
            })
            .and_then(|c| c["iteration"].as_u64())
            .map(|i| (i, i * samples_per_iteration))
    };
    Milestones {
        gait: first_check(&|f| only_heading_fails(f.iter().filter_map(|x| x.as_str()))),
        tracks: first_check(&|f| tracking_holds(f.iter().filter_map(|x| x.as_str()))),
    }
}

/// Reads an `--until-walks` run's `walk.json` and `walk_checks.jsonl`. `reached` is the last
/// trained iteration, `cap` the arm's iteration cap; `earlier_wall` the seconds of the attempts
/// before the one that wrote `walk.json`.
pub fn walk_progress(
    run_dir: &Path,
    reached: u64,
    cap: u64,
    samples_per_iteration: u64,
    earlier_wall: f64,
) -> WalkProgress {
    let walk: serde_json::Value = std::fs::read_to_string(run_dir.join("walk.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(serde_json::Value::Null);
    let checks = read_walk_checks(run_dir);
    let rows_of = |v: &serde_json::Value| -> Vec<crate::eval_cmd::EvalRow> {
        serde_json::from_value(v["rows"].clone()).unwrap_or_default()
    };
    let Milestones { gait, tracks } = milestones(&checks, samples_per_iteration);
    if walk["walks"].as_bool() == Some(true) {
        let iteration = walk["iteration"].as_u64().unwrap_or(reached);
        return WalkProgress::Settled(WalkOutcome {
            walks: true,
            iteration,
            samples: walk["samples"]
                .as_u64()
                .unwrap_or(iteration * samples_per_iteration),
            last_check: iteration,
            wall_seconds: walk["wall_clock_s"].as_f64().map(|s| s + earlier_wall),
            failures: Vec::new(),
            checks: checks.len(),
            gait,
            tracks,
            rows: rows_of(&walk),
        });
    }
    if reached < cap {
        return WalkProgress::Interrupted { iteration: reached };
    }
    let last = checks.last().cloned().unwrap_or(serde_json::Value::Null);
    let rows = rows_of(&last);
    // Read from the JSON itself: a row an older or newer `l3p` wrote still names its failures.
    let failures = last["rows"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|r| r["walk_failures"].as_array().cloned().unwrap_or_default())
        .filter_map(|f| f.as_str().map(str::to_string))
        .collect();
    WalkProgress::Settled(WalkOutcome {
        walks: false,
        iteration: cap,
        last_check: last["iteration"].as_u64().unwrap_or(0),
        samples: cap * samples_per_iteration,
        wall_seconds: None,
        failures,
        checks: checks.len(),
        gait,
        tracks,
        rows,
    })
}

/// Where an arm stands, from its files.
#[derive(Debug, Clone, PartialEq)]
pub enum ArmState {
    Done(Box<ArmDone>),
    /// A `running.pid` whose process is alive.
    Running {
        pid: u32,
        iteration: u64,
    },
    /// Interrupted or failed: `iteration` reached so far, and the last failure if any.
    Partial {
        iteration: u64,
        failure: Option<String>,
    },
    Pending,
}

/// The arm's `done.json`, when it has finished.
pub fn read_done(arm: &Arm) -> Option<ArmDone> {
    let text = std::fs::read_to_string(arm.data_dir().join("done.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// The live process its `running.pid` names, if any.
pub fn live_pid(arm: &Arm) -> Option<u32> {
    std::fs::read_to_string(arm.data_dir().join("running.pid"))
        .ok()
        .and_then(|s| s.trim().parse::<u32>().ok())
        .filter(|pid| process_alive(*pid))
}

/// Reads the state of `arm` from `<arm data dir>` (the iteration from its metrics file).
pub fn arm_state(arm: &Arm) -> ArmState {
    if let Some(done) = read_done(arm) {
        return ArmState::Done(Box::new(done));
    }
    let iteration = last_iteration(&arm.run_dir());
    if let Some(pid) = live_pid(arm) {
        return ArmState::Running { pid, iteration };
    }
    // `failed.json` is `{"arm", "error", "log"}`: the failure is its error message.
    let failure = std::fs::read_to_string(arm.data_dir().join("failed.json"))
        .ok()
        .map(|text| {
            serde_json::from_str::<serde_json::Value>(&text)
                .ok()
                .and_then(|v| v["error"].as_str().map(str::to_string))
                .unwrap_or(text)
        });
    if iteration == 0 && failure.is_none() {
        ArmState::Pending
    } else {
        ArmState::Partial { iteration, failure }
    }
}

/// Whether a process with this id exists (Linux: `/proc/<pid>`).
pub fn process_alive(pid: u32) -> bool {
    Path::new(&format!("/proc/{pid}")).exists()
}

/// The last learner iteration in a run's metrics file (0 when none).
pub fn last_iteration(run_dir: &Path) -> u64 {
    l3p_report::load_learner_records(&l3p_learner::daemon::metrics_path(run_dir))
        .ok()
        .and_then(|r| r.last().map(|r| r.iteration))
        .unwrap_or(0)
}

/// One finished arm's numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmResult {
    pub robot: String,
    pub method: Mode,
    /// The `[[variants]]` entry (`None`: the main grid).
    pub variant: Option<String>,
    pub seed: u64,
    pub row: ReportRow,
    pub wall_seconds: f64,
    /// Tracking errors of the final policy under the training command mix (m/s, rad/s).
    pub eval_lin_vel_error: f64,
    pub eval_yaw_rate_error: f64,
    pub eval_return: f64,
    pub zero_shot_return: Option<f64>,
    /// `(iteration, reward)` for "when did it reach a bar" ([`l3p_report::reward_for_bars`]).
    pub reward_for_bars: Vec<(f64, f64)>,
    /// Whether the arm trained over a terrain curriculum (on flat ground the level is meaningless
    /// and its columns stay empty).
    pub terrain_levels: bool,
    /// Level reached per evaluated terrain type (`ArmDone::by_terrain`'s `final_terrain_level`).
    pub terrain_reach: BTreeMap<String, f64>,
    /// Transfer arms: the pretrained policy's level per terrain type on this robot before
    /// fine-tuning (`ArmDone::zero_shot_by_terrain`), with its pretraining arm's name and method
    /// label (arms sharing a pretraining arm share these values).
    pub zero_shot_reach: Option<ZeroShotReach>,
    /// `until_walks` experiments: [`ArmDone::walk`] and [`ArmDone::zero_shot_walk`].
    pub walk: Option<WalkOutcome>,
    pub zero_shot_walk: Option<WalkOutcome>,
}

/// The pretrained policy's per-terrain levels on a target robot, before fine-tuning.
#[derive(Debug, Clone, PartialEq)]
pub struct ZeroShotReach {
    /// The pretraining arm, e.g. `pretrain-mlp-s1`.
    pub source: String,
    /// Its method label, e.g. `mlp` or `l3p [joint]`.
    pub source_label: String,
    pub levels: BTreeMap<String, f64>,
}

/// Mean and sample standard deviation (0 for one value); `None` when there are no values.
pub fn mean_std(values: &[f64]) -> Option<(f64, f64)> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt()))
}

/// The paper's Table "Accuracy and Performance Comparison" (5 seeds, rough-terrain curriculum,
/// IsaacLab): `(robot, method, level 85%, level 95%, final level, reward 85%, reward 95%, final
/// reward)`; convergence in iterations.
#[rustfmt::skip]
pub const PAPER_TABLE: &[(&str, &str, f64, f64, f64, f64, f64, f64)] = &[
    ("a1", "mlp", 796.0, 1156.0, 5.88, 851.0, 1328.0, 22.04),
    ("a1", "l3p", 760.0, 978.0, 5.77, 740.0, 1202.0, 23.16),
    ("a1", "mlp-transfer", 648.0, 933.0, 5.98, 545.0, 1337.0, 24.56),
    ("a1", "l3p-transfer", 394.0, 462.0, 5.95, 179.0, 226.0, 24.36),
    ("go1", "mlp", 691.0, 975.0, 5.95, 463.0, 1238.0, 23.42),
    ("go1", "l3p", 830.0, 1078.0, 5.78, 664.0, 1190.0, 23.14),
    ("go1", "mlp-transfer", 591.0, 930.0, 5.85, 296.0, 1086.0, 23.45),
    ("go1", "l3p-transfer", 428.0, 512.0, 6.02, 181.0, 234.0, 24.45),
    ("go2", "mlp", 663.0, 1080.0, 6.10, 615.0, 1106.0, 26.19),
    ("go2", "l3p", 780.0, 948.0, 5.76, 1015.0, 1291.0, 25.30),
    ("go2", "mlp-transfer", 678.0, 890.0, 5.96, 672.0, 1140.0, 25.67),
    ("go2", "l3p-transfer", 412.0, 477.0, 6.08, 214.0, 279.0, 25.88),
    ("anymal_b", "mlp", 609.0, 825.0, 5.86, 292.0, 378.0, 9.57),
    ("anymal_b", "l3p", 642.0, 917.0, 5.85, 313.0, 402.0, 9.85),
    ("anymal_b", "mlp-transfer", 897.0, 1136.0, 5.84, 514.0, 848.0, 9.75),
    ("anymal_b", "l3p-transfer", 399.0, 459.0, 5.83, 147.0, 174.0, 13.20),
    ("anymal_c", "mlp", 499.0, 624.0, 6.10, 221.0, 299.0, 12.02),
    ("anymal_c", "l3p", 569.0, 829.0, 6.07, 266.0, 357.0, 11.38),
    ("anymal_c", "mlp-transfer", 817.0, 1035.0, 6.17, 457.0, 593.0, 10.55),
    ("anymal_c", "l3p-transfer", 401.0, 488.0, 5.99, 123.0, 154.0, 13.41),
    ("anymal_d", "mlp", 588.0, 803.0, 6.12, 307.0, 408.0, 11.28),
    ("anymal_d", "l3p", 763.0, 1039.0, 6.03, 403.0, 945.0, 10.42),
    ("anymal_d", "mlp-transfer", 1285.0, 1414.0, 5.28, 1233.0, 1431.0, 9.80),
    ("anymal_d", "l3p-transfer", 519.0, 695.0, 5.69, 172.0, 229.0, 11.49),
    ("spot", "mlp", 834.0, 1283.0, 3.54, 261.0, 389.0, 162.26),
    ("spot", "l3p", 877.0, 936.0, 3.24, 258.0, 434.0, 160.40),
    ("spot", "mlp-transfer", 897.0, 1344.0, 3.20, 429.0, 600.0, 135.26),
    ("spot", "l3p-transfer", 412.0, 864.0, 3.74, 171.0, 217.0, 181.99),
];

impl ArmResult {
    /// The method column: `l3p-transfer`, or `l3p-transfer [warm]` for a variant's arm.
    pub fn method_label(&self) -> String {
        method_label(self.method, self.variant.as_deref())
    }
}

/// `<method>` or `<method> [<variant>]`.
pub fn method_label(method: Mode, variant: Option<&str>) -> String {
    match variant {
        Some(v) => format!("{} [{v}]", method.as_str()),
        None => method.as_str().to_string(),
    }
}

/// The result table: one row per (robot, method or method [variant]), mean ± std over seeds, the
/// paper's reward convergence beside ours (main grid only). A transfer row's "% of scratch" is
/// against the main grid's from-scratch arms of the same robot and architecture.
pub fn markdown_table(results: &[ArmResult]) -> String {
    let mut groups: BTreeMap<(String, String), Vec<&ArmResult>> = BTreeMap::new();
    for r in results {
        groups
            .entry((r.robot.clone(), r.method_label()))
            .or_default()
            .push(r);
    }
    let fmt = |v: Option<(f64, f64)>, digits: usize| match v {
        Some((m, s)) => format!("{m:.digits$} ± {s:.digits$}"),
        None => "—".into(),
    };
    let conv = |rs: &[&ArmResult], f: &dyn Fn(&ReportRow) -> Option<u64>| {
        let v: Vec<f64> = rs
            .iter()
            .filter_map(|r| f(&r.row))
            .map(|x| x as f64)
            .collect();
        let reached = v.len();
        let s = fmt(mean_std(&v), 0);
        if reached < rs.len() {
            format!("{s} ({reached}/{} reached)", rs.len())
        } else {
            s
        }
    };
    let mut out = String::from(
        "| robot | method | seeds | level 85% Cv. | level 95% Cv. | final level | reward 85% Cv. | reward 95% Cv. | final reward | % of scratch | xy-vel err (m/s) | yaw err (rad/s) | zero-shot return | wall (min) | paper reward 85% / 95% Cv. |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mean_final = |robot: &str, method: &str| -> Option<f64> {
        groups
            .get(&(robot.to_string(), method.to_string()))
            .and_then(|rs| mean_std(&rs.iter().map(|r| r.row.final_reward).collect::<Vec<_>>()))
            .map(|(m, _)| m)
    };
    for ((robot, method), rs) in &groups {
        let col = |f: &dyn Fn(&ArmResult) -> f64| -> Vec<f64> { rs.iter().map(|r| f(r)).collect() };
        // A transferred policy's final reward as a share of the same architecture from scratch.
        let scratch = transfer_source(rs[0].method).map(Mode::as_str);
        let share = match (
            scratch.and_then(|m| mean_final(robot, m)),
            mean_final(robot, method),
        ) {
            (Some(base), Some(ours)) if base.abs() > 1e-9 => format!("{:.0}%", 100.0 * ours / base),
            _ => "—".into(),
        };
        let levels = rs.iter().any(|r| r.terrain_levels);
        let level = |text: String| if levels { text } else { "— (flat)".into() };
        let paper = PAPER_TABLE
            .iter()
            .find(|p| p.0 == robot && p.1 == method)
            .map(|p| format!("{:.0} / {:.0}", p.5, p.6))
            .unwrap_or_else(|| "—".into());
        let zero: Vec<f64> = rs.iter().filter_map(|r| r.zero_shot_return).collect();
        out.push_str(&format!(
            "| {robot} | {method} | {} | {} | {} | {} | {} | {} | {} | {share} | {} | {} | {} | {} | {paper} |\n",
            rs.len(),
            level(conv(rs, &|r| r.level_85)),
            level(conv(rs, &|r| r.level_95)),
            level(fmt(mean_std(&col(&|r| r.row.final_level)), 2)),
            conv(rs, &|r| r.reward_85),
            conv(rs, &|r| r.reward_95),
            fmt(mean_std(&col(&|r| r.row.final_reward)), 2),
            fmt(mean_std(&col(&|r| r.eval_lin_vel_error)), 3),
            fmt(mean_std(&col(&|r| r.eval_yaw_rate_error)), 3),
            fmt(mean_std(&zero), 2),
            fmt(mean_std(&col(&|r| r.wall_seconds / 60.0)), 1),
        ));
    }
    out
}

/// `env` on one terrain type alone, difficulty levels and curriculum on: the curriculum preset's
/// ranges (the paper's if the arm trained on them), every column of type `t`.
pub fn single_terrain_env(
    env: &l3p_task::config::EnvConfig,
    t: TerrainType,
) -> l3p_task::config::EnvConfig {
    let mut env = env.clone();
    let terrain = &mut env.terrain;
    if !matches!(terrain.preset, TerrainPreset::Paper) {
        terrain.preset = TerrainPreset::Curriculum;
    }
    terrain.proportions = Some(l3p_task::terrain::TypeProportions::only(t));
    terrain.curriculum = Some(true);
    env
}

/// The per-terrain levels to compare, grouped by `(robot, label)`: each target arm group's final
/// policies (label: its method), and before fine-tuning each pretrained policy on that robot
/// (label `zero-shot <pretraining method>`, one entry per pretraining arm — the arms that start
/// from one pretraining arm share its zero-shot levels).
pub fn terrain_reach_groups(
    results: &[ArmResult],
) -> BTreeMap<(String, String), Vec<&BTreeMap<String, f64>>> {
    let mut groups: BTreeMap<(String, String), Vec<&BTreeMap<String, f64>>> = BTreeMap::new();
    let mut sources_seen = std::collections::BTreeSet::new();
    for r in results.iter().filter(|r| !r.terrain_reach.is_empty()) {
        groups
            .entry((r.robot.clone(), r.method_label()))
            .or_default()
            .push(&r.terrain_reach);
        if let Some(z) = r.zero_shot_reach.as_ref().filter(|z| !z.levels.is_empty())
            && sources_seen.insert((r.robot.clone(), z.source.clone()))
        {
            groups
                .entry((r.robot.clone(), format!("zero-shot {}", z.source_label)))
                .or_default()
                .push(&z.levels);
        }
    }
    groups
}

/// The levels a group's entries reached on terrain type `t` (entries without it left out).
fn levels_on(entries: &[&BTreeMap<String, f64>], t: TerrainType) -> Vec<f64> {
    entries
        .iter()
        .filter_map(|e| e.get(t.as_str()).copied())
        .collect()
}

/// Mean level per terrain type over a group's entries (NaN where none has the type).
pub fn mean_reach(entries: &[&BTreeMap<String, f64>], types: &[TerrainType]) -> Vec<f64> {
    types
        .iter()
        .map(|&t| mean_std(&levels_on(entries, t)).map_or(f64::NAN, |(m, _)| m))
        .collect()
}

/// The simple→complex table: per (robot, method) the mean ± std over seeds of the level reached
/// on each terrain type, and the pretrained policies' zero-shot levels beside them.
pub fn terrain_reach_table(results: &[ArmResult], types: &[TerrainType]) -> String {
    let mut out = String::from("| robot | method | seeds |");
    for t in types {
        out.push_str(&format!(" {} |", t.as_str()));
    }
    out.push_str("\n|---|---|---|");
    out.push_str(&"---|".repeat(types.len()));
    out.push('\n');
    for ((robot, method), entries) in &terrain_reach_groups(results) {
        out.push_str(&format!("| {robot} | {method} | {} |", entries.len()));
        for &t in types {
            out.push_str(&match mean_std(&levels_on(entries, t)) {
                Some((m, sd)) => format!(" {m:.2} ± {sd:.2} |"),
                None => " — |".into(),
            });
        }
        out.push('\n');
    }
    out
}

/// Per robot and family: the iterations each arm group needs until its reward reaches `share` of
/// the mean final reward of the robot's from-scratch arms of that family (main grid), mean over
/// seeds (a seed that never gets there counts as its arm's length and marks the mean "≥"), and
/// the speed-up against the from-scratch arms. Empty without from-scratch target arms.
pub fn time_to_scratch_table(results: &[ArmResult], share: f64) -> String {
    let mut rows = String::new();
    let mut robots: Vec<&str> = results.iter().map(|r| r.robot.as_str()).collect();
    robots.sort_unstable();
    robots.dedup();
    for robot in robots {
        for fam in [Mode::L3p, Mode::Mlp] {
            let scratch: Vec<&ArmResult> = results
                .iter()
                .filter(|r| r.robot == robot && r.method == fam && r.variant.is_none())
                .collect();
            let Some((scratch_final, _)) = mean_std(
                &scratch
                    .iter()
                    .map(|r| r.row.final_reward)
                    .collect::<Vec<_>>(),
            ) else {
                continue;
            };
            let bar = share * scratch_final;
            let mut groups: BTreeMap<(bool, String), Vec<&ArmResult>> = BTreeMap::new();
            for r in results.iter().filter(|r| {
                r.robot == robot && transfer_source(r.method).unwrap_or(r.method) == fam
            }) {
                let is_transfer = !(r.method == fam && r.variant.is_none());
                groups
                    .entry((is_transfer, r.method_label()))
                    .or_default()
                    .push(r);
            }
            let mut scratch_time: Option<(f64, bool)> = None;
            for ((is_transfer, label), arms) in &groups {
                let hits: Vec<Option<u64>> = arms
                    .iter()
                    .map(|r| {
                        r.reward_for_bars
                            .iter()
                            .find(|p| p.1 >= bar)
                            .map(|p| p.0 as u64)
                    })
                    .collect();
                let counted: Vec<f64> = hits
                    .iter()
                    .zip(arms)
                    .map(|(h, r)| h.unwrap_or(r.row.iterations) as f64)
                    .collect();
                let mean = counted.iter().sum::<f64>() / counted.len() as f64;
                let missed = hits.iter().any(Option::is_none);
                let per_seed = hits
                    .iter()
                    .map(|h| h.map_or("—".to_string(), |i| i.to_string()))
                    .collect::<Vec<_>>()
                    .join(", ");
                let speedup = match (*is_transfer, scratch_time) {
                    (false, _) => {
                        scratch_time = Some((mean, missed));
                        String::new()
                    }
                    (true, None) => String::new(),
                    (true, Some((s, s_missed))) => match (missed, s_missed) {
                        (false, false) => format!("{:.2}×", s / mean),
                        (true, false) => format!("≤ {:.2}×", s / mean),
                        (false, true) => format!("≥ {:.2}×", s / mean),
                        (true, true) => "—".into(),
                    },
                };
                rows.push_str(&format!(
                    "| {robot} | {label} | {bar:.2} | {}{mean:.0} | {per_seed} | {speedup} |\n",
                    if missed { "≥ " } else { "" },
                ));
            }
        }
    }
    if rows.is_empty() {
        return rows;
    }
    format!(
        "| robot | method | bar (reward) | iterations, mean over seeds | per seed | vs scratch |\n\
         |---|---|---|---|---|---|\n{rows}"
    )
}

/// Per-iteration mean and min/max over seeds of `key` (smoothed per seed), for one curve band.
pub fn band(curves: &[Vec<(f64, f64)>]) -> Vec<(f64, f64, f64, f64)> {
    let mut at: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for c in curves {
        for &(x, y) in c {
            if y.is_finite() {
                at.entry(x as u64).or_default().push(y);
            }
        }
    }
    at.into_iter()
        .filter(|(_, v)| v.len() == curves.len())
        .map(|(x, v)| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (x as f64, mean, lo, hi)
        })
        .collect()
}

#[cfg(test)]
mod tests;

/// A median over seeds where an arm that did not walk counts as its cap: `at_least` when such an
/// arm decides the median (the true median is then at least `value`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CensoredMedian {
    pub value: f64,
    pub at_least: bool,
}

/// Median of `(value, censored)` pairs, censored values being lower bounds.
pub fn censored_median(values: &[(f64, bool)]) -> Option<CensoredMedian> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    // Censored values sort after exact ones of the same size: they are at least that large.
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let n = v.len();
    let (lo, hi) = (v[(n - 1) / 2], v[n / 2]);
    Some(CensoredMedian {
        value: (lo.0 + hi.0) / 2.0,
        at_least: lo.1 || hi.1,
    })
}

/// `transfer / scratch` of two censored medians: `≤` when only scratch is a lower bound, `≥` when
/// only transfer is, `?` when both are.
pub fn censored_ratio(transfer: CensoredMedian, scratch: CensoredMedian) -> String {
    let r = transfer.value / scratch.value;
    match (transfer.at_least, scratch.at_least) {
        (false, false) => format!("{r:.2}×"),
        (false, true) => format!("≤ {r:.2}×"),
        (true, false) => format!("≥ {r:.2}×"),
        (true, true) => "?".into(),
    }
}

/// The samples-to-walk table of an `until_walks` experiment: per target (robot, method) the seeds
/// that walked within the cap, the median and range of samples to walk (an arm that did not walk
/// counts as its cap, marked `>`), its ratio to the same robot's from-scratch arms of the same
/// family, and how many of the policies the arms started from walked before any fine-tuning.
/// Empty when no arm has a walk outcome.
pub fn samples_to_walk_table(results: &[ArmResult]) -> String {
    let mut keys: Vec<(String, Mode, Option<String>)> = results
        .iter()
        .filter(|r| r.walk.is_some())
        .map(|r| (r.robot.clone(), r.method, r.variant.clone()))
        .collect();
    if keys.is_empty() {
        return String::new();
    }
    keys.sort_by_key(|(robot, m, v)| (robot.clone(), v.clone(), method_rank(*m)));
    keys.dedup();
    let group = |robot: &str, method: Mode, variant: Option<&str>| -> Vec<&ArmResult> {
        results
            .iter()
            .filter(|r| {
                r.robot == robot
                    && r.method == method
                    && r.variant.as_deref() == variant
                    && r.walk.is_some()
            })
            .collect()
    };
    let samples = |arms: &[&ArmResult]| -> Vec<(f64, bool)> {
        arms.iter()
            .filter_map(|r| r.walk.as_ref())
            .map(|w| (w.samples as f64 / 1e6, !w.walks))
            .collect()
    };
    let mut md = String::from(
        "| robot | method | walked | samples to walk, median (M) | range (M) | vs scratch | iterations, median | tracking (xy error within its bound): median (M), vs scratch | gait without the heading bound: median (M), vs scratch | started walking |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (robot, method, variant) in &keys {
        let arms = group(robot, *method, variant.as_deref());
        let s = samples(&arms);
        let walked = s.iter().filter(|(_, c)| !c).count();
        let median = censored_median(&s);
        let fmt = |(v, c): (f64, bool)| format!("{}{v:.2}", if c { ">" } else { "" });
        let (lo, hi) = (
            s.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0)),
            s.iter().copied().max_by(|a, b| a.0.total_cmp(&b.0)),
        );
        let range = match (lo, hi) {
            (Some(lo), Some(hi)) => format!("{}–{}", fmt(lo), fmt(hi)),
            _ => "—".into(),
        };
        let scratch_method = transfer_source(*method).unwrap_or(*method);
        let vs = if transfer_source(*method).is_none() && variant.is_none() {
            "1×".to_string()
        } else {
            match (
                median,
                censored_median(&samples(&group(robot, scratch_method, None))),
            ) {
                (Some(t), Some(sc)) => censored_ratio(t, sc),
                _ => "—".into(),
            }
        };
        let its: Vec<(f64, bool)> = arms
            .iter()
            .filter_map(|r| r.walk.as_ref())
            .map(|w| (w.iteration as f64, !w.walks))
            .collect();
        let its = censored_median(&its)
            .map(|m| format!("{}{:.0}", if m.at_least { "≥ " } else { "" }, m.value))
            .unwrap_or_else(|| "—".into());
        // Samples to a milestone (an arm that never reached it counts as its cap, censored),
        // median and ratio to the same robot's scratch arms.
        let milestone = |pick: fn(&WalkOutcome) -> Option<(u64, u64)>| -> String {
            let samples_to = |arms: &[&ArmResult]| -> Vec<(f64, bool)> {
                arms.iter()
                    .filter_map(|r| r.walk.as_ref())
                    .map(|w| match pick(w) {
                        Some((_, samples)) => (samples as f64 / 1e6, false),
                        None => (w.samples as f64 / 1e6, true),
                    })
                    .collect()
            };
            match censored_median(&samples_to(&arms)) {
                Some(g) => {
                    let vs = if transfer_source(*method).is_none() && variant.is_none() {
                        "1×".to_string()
                    } else {
                        censored_median(&samples_to(&group(robot, scratch_method, None)))
                            .map_or_else(|| "—".into(), |sc| censored_ratio(g, sc))
                    };
                    format!("{}{:.2}, {vs}", if g.at_least { "≥ " } else { "" }, g.value)
                }
                None => "—".into(),
            }
        };
        let tracks = milestone(|w| w.tracks);
        let gait = milestone(|w| w.gait);
        let zero: Vec<bool> = arms
            .iter()
            .filter_map(|r| r.zero_shot_walk.as_ref().map(|w| w.walks))
            .collect();
        let zero = if zero.is_empty() {
            "—".to_string()
        } else {
            format!("{}/{}", zero.iter().filter(|w| **w).count(), zero.len())
        };
        md.push_str(&format!(
            "| {robot} | {} | {walked}/{} | {} | {range} | {vs} | {its} | {tracks} | {gait} | {zero} |\n",
            method_label(*method, variant.as_deref()),
            s.len(),
            median
                .map(|m| format!("{}{:.2}", if m.at_least { "≥ " } else { "" }, m.value))
                .unwrap_or_else(|| "—".into()),
        ));
    }
    md
}

fn method_rank(m: Mode) -> u8 {
    match m {
        Mode::Mlp => 0,
        Mode::L3p => 1,
        Mode::MlpTransfer => 2,
        Mode::L3pTransfer => 3,
    }
}
