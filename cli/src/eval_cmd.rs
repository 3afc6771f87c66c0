//! `l3p eval --policy <ref> --robot a1 --terrain flat --episodes N`: play a policy without learning.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use l3p_policy::DeployPolicy;
use l3p_task::config::TerrainPreset;

use crate::config::Config;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A deployable policy: an export file/directory, or a registry ref `name@version|alias` (e.g.
    /// `a1-flat-a1@latest`) read from the local registry under --data-dir.
    #[arg(long)]
    pub policy: String,
    /// Robot to simulate.
    #[arg(long)]
    pub robot: String,
    /// Terrain preset: flat, simple-rough, curriculum, paper.
    #[arg(long, default_value = "flat")]
    pub terrain: String,
    /// Only this terrain type in every column (per-terrain skill): pyramid_stairs,
    /// inverted_pyramid_stairs, boxes, random_rough, pyramid_slope, inverted_pyramid_slope, flat.
    /// With `--terrain flat` (the default) the `curriculum` preset's tiles are used. Without
    /// `--level` the curriculum moves levels as in training: the final level is the skill.
    #[arg(long, value_name = "TYPE")]
    pub terrain_type: Option<String>,
    /// Start every env at this terrain level (0 = easiest) and keep it there (curriculum off): the
    /// falls and tracking at one difficulty.
    #[arg(long, value_name = "N")]
    pub level: Option<usize>,
    /// Finished episodes to average over.
    #[arg(long, default_value_t = 64)]
    pub episodes: usize,
    /// Parallel environments.
    #[arg(long, default_value_t = 32)]
    pub envs: usize,
    /// Config whose [env] section to use (defaults otherwise); its height_scan must match the policy.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Forward-velocity command range, e.g. `0.5,1.0` (sets vy and yaw commands to zero).
    #[arg(long, value_delimiter = ',', num_args = 1, value_name = "MIN,MAX")]
    pub lin_vel_x: Option<Vec<f32>>,
    /// Data directory holding the registry.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// Seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Evaluate at each of these constant forward speeds (m/s) separately, with zero lateral and
    /// yaw commands and heading mode off (what the walk criterion uses), e.g. `0.5,1.0`.
    #[arg(long, value_delimiter = ',', num_args = 1, value_name = "V,...")]
    pub forward: Option<Vec<f32>>,
    /// Print the results as JSON (one object: settings, and per speed tracking, gait, walk verdict).
    #[arg(long)]
    pub json: bool,
    /// Hold the heading each command starts with: yaw rate = clip(0.5 · heading error, ±1), the
    /// task's heading mode (deploy's `--heading-hold`). Off by default: the walk criterion's heading
    /// bound asks for walking straight unaided.
    #[arg(long)]
    pub heading_hold: bool,
    /// Play the policy's left-right mirror image, `M_a π(M_o o)` with the robot's task mirror maps
    /// (a diagnostic for a drifting robot: in a symmetric simulator the mirror image turns the
    /// other way by as much, so a heading change that keeps its sign is the simulator's, one that
    /// flips is the policy's).
    #[arg(long)]
    pub mirrored: bool,
    /// Start every episode's gait clock at this phase (fraction of the period; deployment starts
    /// at 0). 0.5 puts the other diagonal pair in stance first — the mirror image of the usual
    /// start: with `--mirrored` a symmetric world's exact mirror experiment.
    #[arg(long, value_name = "PHASE")]
    pub clock_start: Option<f32>,
    /// Play `½(π(o) + M_a π(M_o o))`: the policy averaged with its mirror image, exactly left-right
    /// symmetric at every state (one MLP of twice the width) — does a symmetric policy walk
    /// straight?
    #[arg(long, conflicts_with = "mirrored")]
    pub symmetrized: bool,
    #[command(flatten)]
    pub pins: PhysicsPins,
    /// Play the policy through this action filter instead of its own `io.action_filter_alpha`
    /// (a diagnostic: does the policy need its high-frequency target changes?).
    #[arg(long)]
    pub action_filter_alpha: Option<f32>,
}

/// Pins a randomised physical quantity at one value for the evaluation (otherwise the config's
/// training ranges apply), so a policy can be judged at the extremes.
#[derive(Debug, Clone, Default, Args)]
pub struct PhysicsPins {
    /// Passive joint damping (N·m·s/rad).
    #[arg(long)]
    pub joint_damping: Option<f32>,
    /// Coulomb joint friction (N·m).
    #[arg(long)]
    pub joint_friction: Option<f32>,
    /// Motor strength (torque scale).
    #[arg(long)]
    pub motor_strength: Option<f32>,
    /// PD stiffness scale.
    #[arg(long)]
    pub kp_scale: Option<f32>,
    /// PD damping scale.
    #[arg(long)]
    pub kd_scale: Option<f32>,
    /// Action latency (ms).
    #[arg(long)]
    pub latency_ms: Option<f32>,
    /// Ground/foot friction coefficient.
    #[arg(long)]
    pub ground_friction: Option<f32>,
    /// Mass added to the base (kg).
    #[arg(long)]
    pub added_mass: Option<f32>,
    /// Keep the config's pushes during evaluation (off by default: pushes are a training aid).
    #[arg(long)]
    pub pushes: bool,
    /// Physics step (s), the control step kept: e.g. 0.005 plays a policy trained at 20 ms × 1 at
    /// IsaacLab's 5 ms × 4 (does it rely on the coarse step?).
    #[arg(long)]
    pub physics_dt: Option<f32>,
}

impl PhysicsPins {
    /// Writes the pins into `[env.randomization]` overrides (and the physics step into `[env]`).
    pub fn apply(&self, env: &mut l3p_task::config::EnvConfig) -> anyhow::Result<()> {
        if let Some(dt) = self.physics_dt {
            env.set_physics_dt(dt)?;
        }
        let r = &mut env.randomization;
        let pin = |v: Option<f32>| v.map(|x| [x, x]);
        if let Some(v) = pin(self.joint_damping) {
            r.joint_damping = Some(v);
        }
        if let Some(v) = pin(self.joint_friction) {
            r.joint_friction = Some(v);
        }
        if let Some(v) = pin(self.motor_strength) {
            r.motor_strength = Some(v);
        }
        if let Some(v) = pin(self.kp_scale) {
            r.kp_scale = Some(v);
        }
        if let Some(v) = pin(self.kd_scale) {
            r.kd_scale = Some(v);
        }
        if let Some(v) = pin(self.latency_ms.map(|ms| ms / 1000.0)) {
            r.latency_s = Some(v);
        }
        if let Some(v) = pin(self.ground_friction) {
            r.static_friction = Some(v);
            r.dynamic_friction = Some(v);
        }
        if let Some(v) = pin(self.added_mass) {
            r.added_base_mass = Some(v);
        }
        if !self.pushes {
            r.pushes = Some(false);
        }
        Ok(())
    }
}

/// `--terrain`'s names.
/// `--terrain-type` and `--level`: one terrain type in every column (on the curriculum preset's
/// tiles when the preset is flat), every env at one level with the curriculum off.
fn pin_terrain(
    terrain: &mut l3p_task::config::TerrainConfig,
    kind: Option<&str>,
    level: Option<usize>,
) -> anyhow::Result<()> {
    use l3p_task::terrain::{TerrainType, TypeProportions};
    if (kind.is_some() || level.is_some()) && terrain.preset == TerrainPreset::Flat {
        terrain.preset = TerrainPreset::Curriculum;
    }
    if let Some(name) = kind {
        let kind = TerrainType::from_name(name).ok_or_else(|| {
            anyhow::anyhow!(
                "unknown terrain type {name}\nhint: one of {}",
                TerrainType::names()
            )
        })?;
        terrain.proportions = Some(TypeProportions::only(kind));
    }
    if let Some(level) = level {
        if level >= terrain.num_rows {
            anyhow::bail!(
                "--level {level}: the terrain has levels 0..={}",
                terrain.num_rows - 1
            );
        }
        terrain.init_level = Some(level);
        terrain.curriculum = Some(false);
    }
    Ok(())
}

pub fn terrain_preset(name: &str) -> anyhow::Result<TerrainPreset> {
    Ok(match name {
        "flat" => TerrainPreset::Flat,
        "simple-rough" => TerrainPreset::SimpleRough,
        "curriculum" => TerrainPreset::Curriculum,
        "paper" => TerrainPreset::Paper,
        other => {
            anyhow::bail!("unknown terrain {other}\nhint: flat, simple-rough, curriculum or paper")
        }
    })
}

/// Load a deployable policy from a path or from the local registry.
pub fn load_policy(reference: &str, data_dir: &Path) -> anyhow::Result<DeployPolicy> {
    Ok(load_policy_bytes(reference, data_dir)?.1)
}

/// [`load_policy`] with the export's safetensors bytes it was read from (its config is in their
/// metadata), for tools that hand the export on.
pub fn load_policy_bytes(
    reference: &str,
    data_dir: &Path,
) -> anyhow::Result<(Vec<u8>, DeployPolicy)> {
    let path = Path::new(reference);
    if path.exists() {
        let bytes = read_export_bytes(path)?;
        let policy = DeployPolicy::from_bytes(&bytes)
            .with_context(|| format!("reading the export {}", path.display()))?;
        return Ok((bytes, policy));
    }
    let registry = l3p_registry::Registry::open(data_dir)?;
    let (meta, bytes) = registry.get_blob(reference)?;
    if meta.kind != l3p_registry::ArtifactKind::Deploy {
        anyhow::bail!(
            "{reference} is a {:?} artifact, not a deployable policy",
            meta.kind
        );
    }
    let policy = DeployPolicy::from_bytes(&bytes)?;
    Ok((bytes, policy))
}

/// The bytes of an export file, or of `policy.safetensors` in an export directory.
pub fn read_export_bytes(path: &Path) -> anyhow::Result<Vec<u8>> {
    let file = if path.is_dir() {
        path.join("policy.safetensors")
    } else {
        path.to_path_buf()
    };
    std::fs::read(&file).with_context(|| format!("reading {}", file.display()))
}

/// One evaluation: settings in, tracking + gait + walk verdict out.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalRow {
    /// Forward speed command (m/s), or `None` for the config's command distribution.
    pub forward: Option<f32>,
    #[serde(flatten)]
    pub summary: l3p_actor::EvalSummary,
    /// Walk-criterion bounds that fail (empty: it walks).
    pub walk_failures: Vec<String>,
    /// What the row's conditions add to the command, when they are not the check's usual ones
    /// (the walk check's pass at the trained centre-of-mass shift with heading hold on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<String>,
}

/// Sets a constant forward command: vx = v, vy = wz = 0, heading mode off, nobody standing.
pub fn constant_forward_command(env: &mut l3p_task::config::EnvConfig, v: f32) {
    constant_command(env, v, 0.0, 0.0);
}

/// Sets one constant command (the one every env starts with and resamples to): heading mode
/// off, nobody standing.
pub fn constant_command(env: &mut l3p_task::config::EnvConfig, vx: f32, vy: f32, wz: f32) {
    env.commands.lin_vel_x = [vx, vx];
    env.commands.lin_vel_y = [vy, vy];
    env.commands.ang_vel_z = [wz, wz];
    env.commands.heading_command = false;
    env.commands.rel_standing_envs = 0.0;
}

/// Every command in heading mode, holding the heading it starts with (yaw rate clipped at ±1),
/// one command per episode: as `l3p deploy --heading-hold` holds the heading the base had when the
/// yaw command became zero, a resampled command must not take the heading the robot has drifted
/// to as its new target (a 10 s resampling doubled ANYmal-C's held heading change, 11-13° to
/// 18-22° per 20 s: BENCHMARKS.md "Session 34").
pub fn hold_heading(env: &mut l3p_task::config::EnvConfig) {
    env.commands.ang_vel_z = [-1.0, 1.0];
    env.commands.heading_command = true;
    env.commands.rel_heading_envs = 1.0;
    env.commands.heading_hold = true;
    let once = 2.0 * env.episode_length_s;
    env.commands.resampling_time_s = [once, once];
}

/// Plays `policy` on `robot` with `env` and applies the walk criterion; the observation contract,
/// action filter and (on the policy's own robot) PD gains are the policy's, the action filter
/// unless `action_filter_alpha` overrides it.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_row(
    robot: &l3p_robot::catalog::RobotSpec,
    env: &l3p_task::config::EnvConfig,
    policy: &DeployPolicy,
    envs: usize,
    episodes: usize,
    seed: u64,
    forward: Option<f32>,
    action_filter_alpha: Option<f32>,
) -> anyhow::Result<EvalRow> {
    // The policy's own observation and action contract, whatever the config says.
    let mut env = l3p_task::contract::sim_env_for_policy(env, &policy.config, robot.name);
    if let Some(alpha) = action_filter_alpha {
        env.action_filter_alpha = alpha;
    }
    let mut sim = l3p_actor::sim_env(robot, &env, envs, 1, seed)?;
    let max_steps = 1000 * (episodes / envs.max(1) + 2);
    let s = l3p_actor::evaluate(&mut sim, policy, episodes, max_steps)?;
    let walk_failures = match &s.gait {
        Some(g) => l3p_task::gait::WalkCriterion::default().failures(&s.tracking(), g),
        None => vec!["no gait diagnostics".into()],
    };
    Ok(EvalRow {
        forward,
        summary: s,
        walk_failures,
        condition: None,
    })
}

/// `policy`'s left-right mirror image on `robot` (its task mirror under the policy's own
/// observation layout).
pub(crate) fn mirror_policy(
    policy: &DeployPolicy,
    robot: &l3p_robot::catalog::RobotSpec,
) -> anyhow::Result<DeployPolicy> {
    let io = policy.config.io.as_ref();
    let gait_clock = io.is_some_and(|io| io.gait_clock_hz > 0.0);
    let height_scan = policy.obs_dim() == l3p_task::config::obs_dim_of(true, gait_clock);
    let mirror = l3p_task::mirror::TaskMirror::new(
        &robot.model()?,
        &robot.joint_names,
        &robot.default_pose,
        height_scan,
        gait_clock,
    )
    .map_err(|e| anyhow::anyhow!("{}: no mirror image: {e}", robot.name))?;
    Ok(policy.permuted(
        &mirror.observation.index,
        &mirror.observation.sign,
        &mirror.action.index,
        &mirror.action.sign,
    )?)
}

/// `policy` averaged with its left-right mirror image on `robot`: exactly symmetric.
pub(crate) fn symmetrized_policy(
    policy: &DeployPolicy,
    robot: &l3p_robot::catalog::RobotSpec,
) -> anyhow::Result<DeployPolicy> {
    Ok(policy.averaged(&mirror_policy(policy, robot)?)?)
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let mut config = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    crate::robots_cmd::load_added_robots(Some(&args.data_dir));
    let policy = load_policy(&args.policy, &args.data_dir)?;
    config.env.terrain.preset = terrain_preset(&args.terrain)?;
    pin_terrain(
        &mut config.env.terrain,
        args.terrain_type.as_deref(),
        args.level,
    )?;
    // A blind policy runs without the height scan (evaluate_row applies the whole contract).
    config.env = l3p_task::contract::env_for_policy(
        &config.env,
        policy.obs_dim(),
        policy.config.io.as_ref(),
    );
    if let Some(range) = &args.lin_vel_x {
        if range.len() != 2 || range[0] > range[1] {
            anyhow::bail!("--lin-vel-x takes MIN,MAX with MIN <= MAX, got {range:?}");
        }
        constant_forward_command(&mut config.env, range[0]);
        config.env.commands.lin_vel_x = [range[0], range[1]];
    }
    args.pins.apply(&mut config.env)?;
    if let Some(phase) = args.clock_start {
        config.env.gait_clock_start = phase;
    }
    let robot = l3p_robot::catalog::RobotSpec::by_name(&args.robot)?;
    let policy = if args.mirrored {
        mirror_policy(&policy, robot)?
    } else if args.symmetrized {
        symmetrized_policy(&policy, robot)?
    } else {
        policy
    };
    let speeds: Vec<Option<f32>> = match &args.forward {
        Some(v) if v.iter().any(|x| !x.is_finite()) => {
            anyhow::bail!("--forward takes finite speeds, got {v:?}")
        }
        Some(v) => v.iter().map(|x| Some(*x)).collect(),
        None => vec![None],
    };
    let mut rows = Vec::new();
    for forward in &speeds {
        let mut env = config.env.clone();
        if let Some(v) = forward {
            constant_forward_command(&mut env, *v);
        }
        if args.heading_hold {
            hold_heading(&mut env);
        }
        rows.push(evaluate_row(
            robot,
            &env,
            &policy,
            args.envs,
            args.episodes,
            args.seed,
            *forward,
            args.action_filter_alpha,
        )?);
    }
    if args.json {
        let out = serde_json::json!({
            "policy": args.policy,
            "robot": robot.name,
            "terrain": args.terrain,
            "terrain_type": args.terrain_type,
            "level": args.level,
            "heading_hold": args.heading_hold,
            "mirrored": args.mirrored,
            "clock_start": args.clock_start,
            "symmetrized": args.symmetrized,
            "pins": {
                "joint_damping": args.pins.joint_damping,
                "joint_friction": args.pins.joint_friction,
                "motor_strength": args.pins.motor_strength,
                "kp_scale": args.pins.kp_scale,
                "kd_scale": args.pins.kd_scale,
                "latency_ms": args.pins.latency_ms,
                "ground_friction": args.pins.ground_friction,
                "added_mass": args.pins.added_mass,
                "pushes": args.pins.pushes,
                "action_filter_alpha": args.action_filter_alpha,
            },
            "rows": rows,
            "walks": rows.iter().all(|r| r.walk_failures.is_empty()),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "policy {} on {} ({} terrain)",
        args.policy, robot.name, args.terrain
    );
    print!("{}", format_rows(&rows));
    Ok(())
}

/// The human-readable table: one column per evaluated command.
pub fn format_rows(rows: &[EvalRow]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let col = |f: &dyn Fn(&EvalRow) -> String| -> String {
        rows.iter()
            .map(|r| format!("{:>16}", f(r)))
            .collect::<String>()
    };
    let gait = |r: &EvalRow, f: &dyn Fn(&l3p_task::gait::GaitReport) -> String| {
        r.summary.gait.as_ref().map(f).unwrap_or_else(|| "-".into())
    };
    let lines: Vec<(&str, String)> = vec![
        (
            "command",
            col(&|r| {
                let command = match r.forward {
                    Some(v) => format!("vx {v:.2} m/s"),
                    None => "training mix".into(),
                };
                // The walk check's CoM-shift pass is held on its heading.
                match r.condition {
                    Some(_) => format!("hold {command}"),
                    None => command,
                }
            }),
        ),
        ("episodes", col(&|r| r.summary.episodes.to_string())),
        (
            "xy-velocity tracking error",
            col(&|r| format!("{:.3} m/s", r.summary.lin_vel_error)),
        ),
        (
            "mean velocity fwd / left",
            col(&|r| {
                gait(r, &|g| {
                    let [f, l] = g.mean_heading_velocity;
                    format!("{f:.2} / {l:.2} m/s")
                })
            }),
        ),
        (
            "yaw-rate tracking error",
            col(&|r| format!("{:.3} rad/s", r.summary.yaw_rate_error)),
        ),
        (
            "falls",
            col(&|r| format!("{:.1}%", 100.0 * r.summary.fall_fraction)),
        ),
        (
            "  terminations by cause",
            col(&|r| gait(r, &|g| g.endings.describe_terminations())),
        ),
        (
            "episode reward",
            col(&|r| format!("{:.3}", r.summary.episode_return)),
        ),
        (
            "episode length",
            col(&|r| format!("{:.1} steps", r.summary.episode_length)),
        ),
        (
            "terrain level",
            col(&|r| format!("{:.2}", r.summary.terrain_level)),
        ),
        (
            "base height above ground",
            col(&|r| gait(r, &|g| format!("{:.3} m", g.base_height_mean))),
        ),
        (
            "  % of standing",
            col(&|r| {
                gait(r, &|g| {
                    format!("{:.0}% of {:.2}", g.base_height_pct, g.standing_height)
                })
            }),
        ),
        (
            "  min",
            col(&|r| gait(r, &|g| format!("{:.3} m", g.base_height_min))),
        ),
        (
            "swing share FL FR RL RR",
            col(&|r| {
                gait(r, &|g| {
                    g.swing_share
                        .iter()
                        .map(|s| format!("{:.0}", 100.0 * s))
                        .collect::<Vec<_>>()
                        .join(" ")
                })
            }),
        ),
        (
            "touchdowns/s FL FR RL RR",
            col(&|r| {
                gait(r, &|g| {
                    g.touchdown_hz
                        .iter()
                        .map(|s| format!("{s:.1}"))
                        .collect::<Vec<_>>()
                        .join(" ")
                })
            }),
        ),
        (
            "non-foot ground contact",
            col(&|r| {
                gait(r, &|g| {
                    format!("{:.1}% steps", 100.0 * g.non_foot_contact_share)
                })
            }),
        ),
        (
            "  of which the base",
            col(&|r| {
                gait(r, &|g| {
                    format!("{:.1}% steps", 100.0 * g.base_contact_share)
                })
            }),
        ),
        (
            "joint-target change RMS",
            col(&|r| gait(r, &|g| format!("{:.3} rad", g.target_change_rms))),
        ),
        (
            "  second difference RMS",
            col(&|r| gait(r, &|g| format!("{:.3} rad", g.target_second_diff_rms))),
        ),
        (
            "  per joint abd/hip/knee",
            col(&|r| {
                gait(r, &|g| {
                    let d = &g.joint_second_diff_rms;
                    let leg = |j: usize| (d[j] + d[j + 3] + d[j + 6] + d[j + 9]) / 4.0;
                    format!("{:.2}/{:.2}/{:.2}", leg(0), leg(1), leg(2))
                })
            }),
        ),
        (
            "mean |torque|",
            col(&|r| gait(r, &|g| format!("{:.2} N·m", g.mean_abs_torque))),
        ),
        (
            "mechanical power",
            col(&|r| gait(r, &|g| format!("{:.1} W", g.mean_power))),
        ),
        (
            "heading drift / episode",
            col(&|r| gait(r, &|g| format!("{:.1}°", g.heading_drift_rad.to_degrees()))),
        ),
        (
            "  signed mean (+ left)",
            col(&|r| {
                gait(r, &|g| {
                    format!("{:+.1}°", g.heading_change_mean_rad.to_degrees())
                })
            }),
        ),
        (
            "  first 2 s / after",
            col(&|r| {
                gait(r, &|g| {
                    format!(
                        "{:.1}° / {:.1}°",
                        g.heading_start_change_rad.to_degrees(),
                        g.heading_settled_drift_rad.to_degrees()
                    )
                })
            }),
        ),
        (
            "walk criterion",
            col(&|r| {
                if r.walk_failures.is_empty() {
                    "PASS".into()
                } else {
                    format!("FAIL ({})", r.walk_failures.len())
                }
            }),
        ),
    ];
    for (name, values) in lines {
        let _ = writeln!(out, "  {name:<28}{values}");
    }
    for r in rows {
        for f in &r.walk_failures {
            let label = match r.forward {
                Some(v) => format!("vx {v:.2}"),
                None => "mix".into(),
            };
            let _ = writeln!(out, "  [{label}] {f}");
        }
    }
    out
}
