//! `l3p experiment plan|run|status|evaluate|report <experiment.toml>`: the paper's transfer
//! experiment as one command. `plan` writes every arm's config and prints it as the `l3p train`
//! invocation it is (for a cluster scheduler); `run` trains the arms locally, `parallel` at a time,
//! resumably (finished arms are skipped, an interrupted arm resumes from its checkpoint, a failed
//! arm is reported and the others go on); `status` shows progress; `evaluate` runs the
//! evaluations finished arms lack; `report` writes the table and curves.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use l3p_proto::MetricsRecord;
use l3p_report::{ReportRow, load_learner_records, series, smooth};
use l3p_task::config::TerrainPreset;

use crate::config::Config;
use crate::experiment::{
    Arm, ArmDone, ArmResult, ArmState, ExperimentSpec, Stage, WalkOutcome, WalkProgress,
    arm_config_path, arm_state, band, live_pid, markdown_table, plan, read_done,
    samples_to_walk_table, walk_progress,
};
use crate::runtime;

#[derive(Debug, Args)]
pub struct ExperimentArgs {
    #[command(subcommand)]
    pub command: ExperimentCommand,
}

#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Write every arm's training config under `<data_dir>/<name>/arms/` and print the arms as
    /// `l3p train` invocations, pretraining first (transfer arms need its checkpoints).
    Plan(SpecArg),
    /// Train every unfinished arm locally, `[experiment] parallel` at a time, then evaluate it.
    Run(SpecArg),
    /// Each arm's state: done (with wall-clock), running, partial (iteration reached, failure),
    /// pending.
    Status(SpecArg),
    /// Run the evaluations finished arms lack, without training: after `[evaluation]
    /// terrain_types` was added, or for arms finished by an older `l3p` (the per-terrain levels of
    /// the final policy and of the pretrained policy zero-shot). Updates each arm's `done.json`.
    Evaluate(SpecArg),
    /// The result table (Markdown, mean ± std over seeds, the paper's numbers beside ours) and
    /// per-robot learning curves (SVG, the methods overlaid) under `<data_dir>/<name>/report/`.
    Report(ReportArg),
}

#[derive(Debug, Args)]
pub struct SpecArg {
    /// Experiment file, e.g. experiments/laptop.toml.
    pub spec: PathBuf,
}

#[derive(Debug, Args)]
pub struct ReportArg {
    /// Experiment file, e.g. experiments/laptop.toml.
    pub spec: PathBuf,
    /// Moving-average window (iterations) for the curves and convergence.
    #[arg(long, default_value_t = 10)]
    pub window: usize,
}

pub fn run(args: ExperimentArgs) -> anyhow::Result<()> {
    match args.command {
        ExperimentCommand::Plan(a) => plan_cmd(&a.spec),
        ExperimentCommand::Run(a) => run_cmd(&a.spec),
        ExperimentCommand::Status(a) => status_cmd(&a.spec),
        ExperimentCommand::Evaluate(a) => evaluate_cmd(&a.spec),
        ExperimentCommand::Report(a) => report_cmd(&a.spec, a.window),
    }
}

fn load(spec_path: &Path) -> anyhow::Result<(ExperimentSpec, Vec<Arm>)> {
    let spec = ExperimentSpec::load(spec_path)?;
    let base = Config::load(&spec.experiment.base_config)?;
    let arms = plan(&spec, &base)?;
    Ok((spec, arms))
}

fn evaluate_cmd(spec_path: &Path) -> anyhow::Result<()> {
    let (spec, arms) = load(spec_path)?;
    let (mut updated, mut finished) = (0, 0);
    for arm in &arms {
        let Some(mut done) = read_done(arm) else {
            continue;
        };
        finished += 1;
        let started = Instant::now();
        if fill_terrain_evaluations(&spec, &arms, arm, &mut done)? {
            write_done(arm, &done)?;
            updated += 1;
            println!(
                "{}: evaluated in {:.0} s",
                arm.name,
                started.elapsed().as_secs_f64()
            );
        }
    }
    println!("{updated} of {finished} finished arms updated; the others had every evaluation");
    Ok(())
}

/// Writes each arm's config file (unchanged files are left alone, so a running arm's config
/// never changes under it).
fn write_configs(spec: &ExperimentSpec, arms: &[Arm]) -> anyhow::Result<()> {
    let dir = spec.dir();
    std::fs::create_dir_all(dir.join("arms"))?;
    for arm in arms {
        let path = arm_config_path(&dir, &arm.name);
        let text = format!(
            "# Arm {} of experiment {} (written by `l3p experiment plan`).\n{}",
            arm.name,
            spec.experiment.name,
            toml::to_string(&arm.config)?
        );
        if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
            std::fs::write(&path, text)?;
        }
    }
    Ok(())
}

fn plan_cmd(spec_path: &Path) -> anyhow::Result<()> {
    let (spec, arms) = load(spec_path)?;
    write_configs(&spec, &arms)?;
    let dir = spec.dir();
    println!(
        "# experiment {}: {} arms; configs in {}",
        spec.experiment.name,
        arms.len(),
        dir.join("arms").display()
    );
    println!("# stage 1 — pretraining (the transfer arms start from these checkpoints)");
    for arm in arms.iter().filter(|a| a.stage == Stage::Pretrain) {
        println!(
            "{}",
            arm.command(&arm_config_path(&dir, &arm.name)).join(" ")
        );
    }
    println!("# stage 2 — targets (run after stage 1; from-scratch arms may run alongside it)");
    for arm in arms.iter().filter(|a| a.stage == Stage::Target) {
        println!(
            "{}",
            arm.command(&arm_config_path(&dir, &arm.name)).join(" ")
        );
    }
    Ok(())
}

fn status_cmd(spec_path: &Path) -> anyhow::Result<()> {
    let (spec, arms) = load(spec_path)?;
    println!(
        "experiment {} ({})",
        spec.experiment.name,
        spec.dir().display()
    );
    let mut done = 0;
    for arm in &arms {
        let state = match arm_state(arm) {
            ArmState::Done(d) => {
                done += 1;
                let walk = match &d.walk {
                    Some(w) if w.walks => format!(
                        "; walked at iteration {} ({:.2} M samples)",
                        w.iteration,
                        w.samples as f64 / 1e6
                    ),
                    Some(w) => format!(
                        "; did not walk within its cap ({})",
                        w.failures.first().map_or("no check", String::as_str)
                    ),
                    None => String::new(),
                };
                format!(
                    "done, {} iterations in {:.1} min{walk}",
                    d.iterations,
                    d.wall_seconds / 60.0
                )
            }
            ArmState::Running { pid, iteration } => {
                format!(
                    "running (pid {pid}), iteration {iteration}/{}",
                    arm.iterations
                )
            }
            ArmState::Partial { iteration, failure } => match failure {
                Some(f) => format!(
                    "failed at iteration {iteration}/{}: {}",
                    arm.iterations,
                    f.lines().next().unwrap_or("")
                ),
                None if iteration >= arm.iterations => format!(
                    "trained ({iteration}/{}), not yet evaluated: `l3p experiment run` evaluates it",
                    arm.iterations
                ),
                None if arm.until_walks => format!(
                    "interrupted at iteration {iteration} (cap {}); its walk checks are kept",
                    arm.iterations
                ),
                None => format!("interrupted at iteration {iteration}/{}", arm.iterations),
            },
            ArmState::Pending => "pending".into(),
        };
        println!("  {:<32} {state}", arm.name);
    }
    println!("{done}/{} arms done", arms.len());
    Ok(())
}

/// A training process of one arm.
struct Running {
    arm: usize,
    child: Child,
    started: Instant,
    /// The arm's training seconds before this attempt.
    earlier_wall: f64,
}

fn run_cmd(spec_path: &Path) -> anyhow::Result<()> {
    let (spec, arms) = load(spec_path)?;
    write_configs(&spec, &arms)?;
    let dir = spec.dir();
    std::fs::create_dir_all(dir.join("logs"))?;
    let exe = std::env::current_exe()?;
    let parallel = spec.experiment.parallel;
    // Arms not to start again in this invocation (finished, failed, or blocked by a failure).
    let mut settled = vec![false; arms.len()];
    let mut failed: Vec<String> = Vec::new();
    let mut running: Vec<Running> = Vec::new();
    // Ctrl-C or SIGTERM: start nothing more, pass the signal on to the running trainers (a
    // terminal's Ctrl-C reaches them already; a `kill` of this process alone does not), and leave
    // their arms interrupted, to resume on the next run. Handled rather than left to the default
    // action, which a process started in the background with SIGINT ignored would not get.
    let signals = runtime::tokio_runtime()?;
    let cancel = signals.block_on(async { runtime::cancel_on_signal() });
    let mut forwarded = false;
    loop {
        if cancel.is_cancelled() && !forwarded {
            forwarded = true;
            for r in &running {
                // SIGTERM, not a second SIGINT: a trainer that got the terminal's Ctrl-C already
                // would take a second one as "exit now", without its final checkpoint.
                let _ = Command::new("kill")
                    .args(["-TERM", &r.child.id().to_string()])
                    .status();
            }
        }
        // Reap finished processes.
        let mut i = 0;
        while i < running.len() {
            if let Some(status) = running[i].child.try_wait()? {
                let r = running.remove(i);
                let arm = &arms[r.arm];
                let _ = std::fs::remove_file(arm.data_dir().join("running.pid"));
                settled[r.arm] = true;
                let wall = add_wall_seconds(arm, r.started.elapsed().as_secs_f64())?;
                let earlier_wall = r.earlier_wall;
                // Stopping: no evaluation either (it can take minutes); the next run resumes
                // the training or evaluates what finished.
                if cancel.is_cancelled() {
                    let reached = crate::experiment::last_iteration(&arm.run_dir());
                    println!(
                        "arm {} stopped at iteration {reached}/{}; rerun to resume",
                        arm.name, arm.iterations
                    );
                    continue;
                }
                match finish_arm(
                    &spec,
                    &arms,
                    arm,
                    status
                        .success()
                        .then_some(())
                        .ok_or_else(|| status.to_string()),
                    wall,
                    earlier_wall,
                ) {
                    Ok(()) => println!("arm {} done", arm.name),
                    Err(e) => {
                        let message = format!("{e:#}");
                        eprintln!("arm {} failed: {message}", arm.name);
                        std::fs::write(
                            arm.data_dir().join("failed.json"),
                            serde_json::to_string_pretty(&serde_json::json!({
                                "arm": arm.name, "error": message,
                                "log": dir.join("logs").join(format!("{}.log", arm.name)),
                            }))?,
                        )?;
                        failed.push(arm.name.clone());
                    }
                }
            } else {
                i += 1;
            }
        }
        // Start what can start.
        let mut waiting = false;
        for (k, arm) in arms.iter().enumerate() {
            if settled[k] || running.iter().any(|r| r.arm == k) {
                continue;
            }
            // Polled every half second: only the marker files, never the metrics.
            if read_done(arm).is_some() {
                settled[k] = true;
                continue;
            }
            // Walked, but its evaluation did not finish (interrupted): finish it without
            // training on past the passing check.
            if arm.until_walks && walked_already(arm) && live_pid(arm).is_none() {
                settled[k] = true;
                let wall = read_wall_seconds(arm);
                let walk_clock = walk_clock_seconds(arm);
                match finish_arm(
                    &spec,
                    &arms,
                    arm,
                    Ok(()),
                    wall,
                    (wall - walk_clock).max(0.0),
                ) {
                    Ok(()) => println!("arm {} done (it had walked)", arm.name),
                    Err(e) => {
                        eprintln!("arm {} failed: {e:#}", arm.name);
                        failed.push(arm.name.clone());
                    }
                }
                continue;
            }
            if let Some(pid) = live_pid(arm) {
                // Another `experiment run` (or a scheduler) is training it.
                println!("arm {} is already running (pid {pid}); skipped", arm.name);
                settled[k] = true;
                continue;
            }
            if let Some(dep) = &arm.depends_on {
                let dep_index = arms.iter().position(|a| &a.name == dep);
                let dep_done = dep_index
                    .map(|d| read_done(&arms[d]).is_some())
                    .unwrap_or(false);
                if !dep_done {
                    if failed.contains(dep) || dep_index.map(|d| settled[d]).unwrap_or(true) {
                        eprintln!(
                            "arm {} skipped: its pretraining arm {dep} did not finish",
                            arm.name
                        );
                        settled[k] = true;
                        failed.push(arm.name.clone());
                    } else {
                        waiting = true;
                    }
                    continue;
                }
            }
            if running.len() >= parallel {
                waiting = true;
                break;
            }
            if cancel.is_cancelled() {
                break;
            }
            running.push(start_arm(&exe, &dir, arm, k)?);
        }
        if cancel.is_cancelled() && running.is_empty() {
            break;
        }
        if running.is_empty() && !waiting {
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let done = arms.iter().filter(|a| read_done(a).is_some()).count();
    println!("{done}/{} arms done", arms.len());
    if cancel.is_cancelled() {
        return Err(runtime::Interrupted(format!(
            "interrupted\nhint: rerun `l3p experiment run {}` to resume",
            spec_path.display()
        ))
        .into());
    }
    if !failed.is_empty() {
        anyhow::bail!(
            "{} arms did not finish: {}\nhint: `l3p experiment status {}` shows where each stands; \
             rerun `l3p experiment run` to retry them",
            failed.len(),
            failed.join(", "),
            spec_path.display()
        );
    }
    Ok(())
}

fn start_arm(exe: &Path, dir: &Path, arm: &Arm, index: usize) -> anyhow::Result<Running> {
    std::fs::create_dir_all(arm.data_dir())?;
    let _ = std::fs::remove_file(arm.data_dir().join("failed.json"));
    let log_path = dir.join("logs").join(format!("{}.log", arm.name));
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)?;
    let config = arm_config_path(dir, &arm.name);
    println!(
        "arm {} starting ({} iterations; log {})",
        arm.name,
        arm.iterations,
        log_path.display()
    );
    let mut command = Command::new(exe);
    command.arg("train").arg(&config).arg("--quiet");
    if arm.until_walks {
        command.arg("--until-walks");
    }
    let child = command
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()?;
    std::fs::write(arm.data_dir().join("running.pid"), child.id().to_string())?;
    Ok(Running {
        arm: index,
        child,
        started: Instant::now(),
        earlier_wall: read_wall_seconds(arm),
    })
}

/// Adds one attempt's training seconds to the arm's `wall_seconds` file; returns the total over
/// every attempt (an interrupted arm's earlier attempts count).
fn add_wall_seconds(arm: &Arm, seconds: f64) -> anyhow::Result<f64> {
    let total = read_wall_seconds(arm) + seconds;
    std::fs::write(arm.data_dir().join("wall_seconds"), format!("{total}\n"))?;
    Ok(total)
}

/// The arm's training seconds so far (0 before its first attempt ends).
fn read_wall_seconds(arm: &Arm) -> f64 {
    std::fs::read_to_string(arm.data_dir().join("wall_seconds"))
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(0.0)
}

/// `<run_dir>/walk.json` says the criterion held.
fn walked_already(arm: &Arm) -> bool {
    walk_json(arm)["walks"].as_bool() == Some(true)
}

/// The walking attempt's own clock at its passing check (`walk.json`'s `wall_clock_s`).
fn walk_clock_seconds(arm: &Arm) -> f64 {
    walk_json(arm)["wall_clock_s"].as_f64().unwrap_or(0.0)
}

fn walk_json(arm: &Arm) -> serde_json::Value {
    std::fs::read_to_string(arm.run_dir().join("walk.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(serde_json::Value::Null)
}

/// After the training process exits (`status`: its exit, `Err` with the status when it failed):
/// checks it reached every iteration (an `until_walks` arm: that it walked or reached its cap),
/// evaluates the final policy (and, for a transfer arm, the pretrained one zero-shot) and writes
/// `done.json`. `earlier_wall`: the arm's training seconds before this attempt.
fn finish_arm(
    spec: &ExperimentSpec,
    arms: &[Arm],
    arm: &Arm,
    status: Result<(), String>,
    wall: f64,
    earlier_wall: f64,
) -> anyhow::Result<()> {
    let iteration = crate::experiment::last_iteration(&arm.run_dir());
    if let Err(status) = status {
        anyhow::bail!("training exited with {status} at iteration {iteration}");
    }
    let walk = if arm.until_walks {
        match walk_progress(
            &arm.run_dir(),
            iteration,
            arm.iterations,
            arm.samples_per_iteration(),
            earlier_wall,
        ) {
            WalkProgress::Settled(outcome) => Some(outcome),
            WalkProgress::Interrupted { iteration } => anyhow::bail!(
                "training stopped at iteration {iteration} of at most {} without walking \
                 (interrupted); rerun to resume (its walk checks are kept)",
                arm.iterations
            ),
        }
    } else {
        if iteration < arm.iterations {
            anyhow::bail!(
                "training stopped at iteration {iteration} of {} (interrupted); rerun to resume",
                arm.iterations
            );
        }
        None
    };
    let zero_shot_walk = match (&walk, &arm.depends_on) {
        (Some(_), Some(_)) => Some(initial_walk_check(arm)?),
        _ => None,
    };
    let ckpt = crate::experiment::final_checkpoint(&arm.run_dir());
    let mut evaluations = BTreeMap::new();
    for robot in &arm.robots {
        evaluations.insert(
            robot.clone(),
            evaluate(spec, &arm.config, &ckpt, robot, robot)?,
        );
    }
    let zero_shot = match pretrained_source(arms, arm)? {
        Some((source_ckpt, source_robot)) => Some(evaluate(
            spec,
            &arm.config,
            &source_ckpt,
            &source_robot,
            &arm.robots[0],
        )?),
        None => None,
    };
    let mut done = ArmDone {
        arm: arm.name.clone(),
        iterations: iteration,
        wall_seconds: wall,
        evaluations,
        zero_shot,
        by_terrain: BTreeMap::new(),
        zero_shot_by_terrain: BTreeMap::new(),
        walk,
        zero_shot_walk,
    };
    fill_terrain_evaluations(spec, arms, arm, &mut done)?;
    write_done(arm, &done)
}

/// The walk check of the policy a transfer arm starts from: its model at iteration 0 (the
/// pretrained core and the arm's transfer heads, seeded as the learner seeds them), before any
/// fine-tuning.
fn initial_walk_check(arm: &Arm) -> anyhow::Result<WalkOutcome> {
    let (_, bytes) = crate::train_cmd::start_export(&arm.config)?;
    let (rows, walks) = crate::train_cmd::walk_check_export(&arm.config, bytes)?;
    let failures: Vec<String> = rows.iter().flat_map(|r| r.walk_failures.clone()).collect();
    let gait_only = crate::experiment::only_heading_fails(failures.iter().map(String::as_str));
    let tracks = crate::experiment::tracking_holds(failures.iter().map(String::as_str));
    Ok(WalkOutcome {
        walks,
        gait: gait_only.then_some((0, 0)),
        tracks: tracks.then_some((0, 0)),
        iteration: 0,
        last_check: 0,
        samples: 0,
        wall_seconds: None,
        failures,
        checks: 1,
        rows,
    })
}

/// Writes `done.json` through a temporary file and a rename, so an interrupted `evaluate` never
/// leaves a finished arm with a torn file (which would make it look unfinished and train again).
fn write_done(arm: &Arm, done: &ArmDone) -> anyhow::Result<()> {
    let path = arm.data_dir().join("done.json");
    let tmp = arm.data_dir().join("done.json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(done)?)?;
    std::fs::rename(&tmp, &path)?;
    Ok(())
}

/// A transfer arm's pretraining arm: its final checkpoint and the robot whose adapters play it.
fn pretrained_source(arms: &[Arm], arm: &Arm) -> anyhow::Result<Option<(PathBuf, String)>> {
    let Some(dep) = &arm.depends_on else {
        return Ok(None);
    };
    let source = arms
        .iter()
        .find(|a| &a.name == dep)
        .ok_or_else(|| anyhow::anyhow!("unknown pretraining arm {dep}"))?;
    let source_robot = source
        .robots
        .first()
        .ok_or_else(|| anyhow::anyhow!("pretraining arm {dep} has no robot"))?;
    Ok(Some((
        crate::experiment::final_checkpoint(&source.run_dir()),
        source_robot.clone(),
    )))
}

/// Runs the per-terrain evaluations a target arm's `done` lacks: its final policy on each
/// `evaluation.terrain_types` entry and, for a transfer arm, the pretrained policy zero-shot on
/// each. Returns whether anything was added.
fn fill_terrain_evaluations(
    spec: &ExperimentSpec,
    arms: &[Arm],
    arm: &Arm,
    done: &mut ArmDone,
) -> anyhow::Result<bool> {
    if arm.stage != Stage::Target || spec.evaluation.terrain_types.is_empty() {
        return Ok(false);
    }
    let robot = &arm.robots[0];
    let mut added = false;
    if done.by_terrain.is_empty() {
        let ckpt = crate::experiment::final_checkpoint(&arm.run_dir());
        done.by_terrain = evaluate_terrains(spec, &arm.config, &ckpt, robot, robot)?;
        added = true;
    }
    if done.zero_shot_by_terrain.is_empty()
        && let Some((source_ckpt, source_robot)) = pretrained_source(arms, arm)?
    {
        done.zero_shot_by_terrain =
            evaluate_terrains(spec, &arm.config, &source_ckpt, &source_robot, robot)?;
        added = true;
    }
    Ok(added)
}

/// Plays `policy_robot`'s policy from `ckpt` on `robot`: the training command mix, then each
/// `evaluation.forward` speed.
fn evaluate(
    spec: &ExperimentSpec,
    config: &Config,
    ckpt: &Path,
    policy_robot: &str,
    robot: &str,
) -> anyhow::Result<Vec<crate::eval_cmd::EvalRow>> {
    let player = Player::load(spec, ckpt, policy_robot, robot)?;
    let mut speeds = vec![None];
    speeds.extend(spec.evaluation.forward.iter().map(|v| Some(*v)));
    speeds
        .into_iter()
        .map(|forward| {
            let mut env = config.env.clone();
            if let Some(v) = forward {
                crate::eval_cmd::constant_forward_command(&mut env, v);
            }
            player.play(&env, spec.evaluation.episodes, forward)
        })
        .collect()
}

/// `policy_robot`'s policy from `ckpt` on `robot`, on each `evaluation.terrain_types` entry
/// alone, with the curriculum running for `terrain_rounds` episodes per environment.
fn evaluate_terrains(
    spec: &ExperimentSpec,
    config: &Config,
    ckpt: &Path,
    policy_robot: &str,
    robot: &str,
) -> anyhow::Result<BTreeMap<String, crate::eval_cmd::EvalRow>> {
    let ev = &spec.evaluation;
    let player = Player::load(spec, ckpt, policy_robot, robot)?;
    ev.terrain_types
        .iter()
        .map(|&t| {
            let env = crate::experiment::single_terrain_env(&config.env, t);
            let row = player.play(&env, ev.envs * ev.terrain_rounds, None)?;
            Ok((t.as_str().to_string(), row))
        })
        .collect()
}

/// One robot's deployable policy from a checkpoint, and the robot it is played on.
struct Player<'a> {
    spec: &'a ExperimentSpec,
    policy: l3p_policy::DeployPolicy,
    robot: &'static l3p_robot::catalog::RobotSpec,
}

impl<'a> Player<'a> {
    fn load(
        spec: &'a ExperimentSpec,
        ckpt: &Path,
        policy_robot: &str,
        robot: &str,
    ) -> anyhow::Result<Self> {
        let checkpoint = l3p_policy::load_checkpoint(ckpt, &l3p_policy::cpu_device())?;
        let (bytes, _) = l3p_policy::export_bytes(&checkpoint.model, policy_robot)?;
        Ok(Self {
            spec,
            policy: l3p_policy::DeployPolicy::from_bytes(&bytes)?,
            robot: l3p_robot::catalog::RobotSpec::by_name(robot)?,
        })
    }

    fn play(
        &self,
        env: &l3p_task::config::EnvConfig,
        episodes: usize,
        forward: Option<f32>,
    ) -> anyhow::Result<crate::eval_cmd::EvalRow> {
        let ev = &self.spec.evaluation;
        crate::eval_cmd::evaluate_row(
            self.robot,
            env,
            &self.policy,
            ev.envs,
            episodes,
            ev.seed,
            forward,
            None,
        )
    }
}

/// A finished arm with its `done.json` and learner records, read once for the report.
struct Finished<'a> {
    arm: &'a Arm,
    done: ArmDone,
    records: Vec<MetricsRecord>,
}

fn finished_arms(arms: &[Arm]) -> Vec<Finished<'_>> {
    arms.iter()
        .filter_map(|arm| {
            let done = read_done(arm)?;
            let records =
                load_learner_records(&l3p_learner::daemon::metrics_path(&arm.run_dir())).ok()?;
            Some(Finished { arm, done, records })
        })
        .collect()
}

/// The level reached per terrain type (the last episode's, averaged over environments).
fn final_levels(rows: &BTreeMap<String, crate::eval_cmd::EvalRow>) -> BTreeMap<String, f64> {
    rows.iter()
        .map(|(t, row)| (t.clone(), row.summary.final_terrain_level as f64))
        .collect()
}

/// The results of every finished arm.
fn collect_results(arms: &[Arm], finished: &[Finished], window: usize) -> Vec<ArmResult> {
    let mut out = Vec::new();
    for Finished { arm, done, records } in finished {
        let robot = arm.robots.join("+");
        let mix = done
            .evaluations
            .get(&arm.robots[0])
            .and_then(|rows| rows.iter().find(|r| r.forward.is_none()));
        out.push(ArmResult {
            robot,
            method: arm.method,
            variant: arm.variant.clone(),
            seed: arm.seed,
            row: ReportRow::from_records(records, window),
            wall_seconds: done.wall_seconds,
            eval_lin_vel_error: mix
                .map(|r| r.summary.lin_vel_error as f64)
                .unwrap_or(f64::NAN),
            eval_yaw_rate_error: mix
                .map(|r| r.summary.yaw_rate_error as f64)
                .unwrap_or(f64::NAN),
            eval_return: mix
                .map(|r| r.summary.episode_return as f64)
                .unwrap_or(f64::NAN),
            terrain_levels: {
                let t = &arm.config.env.terrain;
                t.curriculum.unwrap_or(matches!(
                    t.preset,
                    TerrainPreset::Curriculum | TerrainPreset::Paper
                ))
            },
            reward_for_bars: l3p_report::reward_for_bars(records, window),
            terrain_reach: final_levels(&done.by_terrain),
            zero_shot_reach: arm
                .depends_on
                .as_ref()
                .and_then(|dep| arms.iter().find(|a| &a.name == dep))
                .map(|source| crate::experiment::ZeroShotReach {
                    source: source.name.clone(),
                    source_label: crate::experiment::method_label(
                        source.method,
                        source.variant.as_deref(),
                    ),
                    levels: final_levels(&done.zero_shot_by_terrain),
                }),
            zero_shot_return: done.zero_shot.as_ref().and_then(|rows| {
                rows.iter()
                    .find(|r| r.forward.is_none())
                    .map(|r| r.summary.episode_return as f64)
            }),
            walk: done.walk.clone().map(|mut w| {
                // Arms finished before `tracks` existed: read it from their check history.
                if w.tracks.is_none() {
                    let checks = crate::experiment::read_walk_checks(&arm.run_dir());
                    w.tracks =
                        crate::experiment::milestones(&checks, arm.samples_per_iteration()).tracks;
                }
                w
            }),
            zero_shot_walk: done.zero_shot_walk.clone(),
        });
    }
    out
}

/// Iterations each target arm needs to reach what its family's from-scratch arms end at (at 80%
/// and 100% of it); empty when the experiment has no from-scratch target arms.
fn time_to_scratch_section(results: &[ArmResult], window: usize) -> String {
    const SHARES: [f64; 2] = [0.8, 1.0];
    let tables: Vec<String> = SHARES
        .iter()
        .map(|&share| crate::experiment::time_to_scratch_table(results, share))
        .collect();
    if tables.iter().all(|t| t.is_empty()) {
        return String::new();
    }
    let mut md = format!(
        "\n## Iterations to the from-scratch final reward\n\nThe paper's \"converges faster\" asked \
         directly: the first iteration at which an arm's episode reward ({window}-iteration trailing \
         window, weighted by the episodes that ended in each; a window counts once {} episodes \
         have ended in it) reaches a share of the mean final reward of the same robot's \
         from-scratch arms of its family (`l3p` for `l3p-transfer` and its variants, `mlp` for \
         `mlp-transfer`; for a pretraining variant, the plain pretraining arms). The 85% / 95% convergence above measures each curve against its own \
         final value, so an arm that flattens early at a low reward \"converges\" fast. A seed \
         that never reaches the bar counts as its arm's length (\"—\"; the mean is then a lower \
         bound, ≥). Resolution: every environment starts its first episode at step 0, so episodes \
         that do not fall end together, once per episode length (≈ 42 iterations for 1,000-step \
         episodes at 24 steps per iteration): smaller differences are not resolved.\n",
        l3p_report::BAR_MIN_EPISODES
    );
    for (share, table) in SHARES.iter().zip(&tables) {
        md.push_str(&format!(
            "\n### {:.0}% of the from-scratch final reward\n\n{table}",
            share * 100.0
        ));
    }
    md
}

/// The simple→complex section of the report: the level each method's final policy reached on
/// each `evaluation.terrain_types` entry (table), and a radar per target robot.
fn terrain_reach_section(
    spec: &ExperimentSpec,
    arms: &[Arm],
    results: &[ArmResult],
    out: &Path,
) -> anyhow::Result<String> {
    let types = &spec.evaluation.terrain_types;
    if types.is_empty() || results.iter().all(|r| r.terrain_reach.is_empty()) {
        return Ok(String::new());
    }
    let max_level = arms
        .first()
        .map(|a| a.config.env.terrain.num_rows.saturating_sub(1).max(1))
        .unwrap_or(9) as f64;
    let mut md = format!(
        "\n## Simple → complex terrain\n\nEach target arm's final policy on one terrain type at a \
         time with the terrain-level curriculum running ({} episodes per environment from levels \
         0–{}); the value is the mean level of the last episode of each environment (0–{max_level}: \
         how far up that terrain's difficulty the policy walked itself).\n\n{}",
        spec.evaluation.terrain_rounds,
        arms.first()
            .map(|a| a.config.env.terrain.max_init_level)
            .unwrap_or(5),
        crate::experiment::terrain_reach_table(results, types),
    );
    let axes: Vec<String> = types.iter().map(|t| t.as_str().replace('_', " ")).collect();
    let groups = crate::experiment::terrain_reach_groups(results);
    let mut robots: Vec<&str> = groups.keys().map(|(robot, _)| robot.as_str()).collect();
    robots.dedup();
    for robot in robots {
        let series: Vec<(String, Vec<f64>)> = groups
            .iter()
            .filter(|((r, _), _)| r == robot)
            .map(|((_, label), entries)| {
                (
                    format!("{label} ({} seeds)", entries.len()),
                    crate::experiment::mean_reach(entries, types),
                )
            })
            .collect();
        let title = format!("{robot} — terrain level reached");
        std::fs::write(
            out.join(format!("{robot}-terrains.svg")),
            l3p_report::svg_radar(&title, &axes, &series, max_level),
        )?;
        std::fs::write(
            out.join(format!("{robot}-terrains.png")),
            l3p_report::png_radar(&title, &axes, &series, max_level),
        )?;
        md.push_str(&format!(
            "\n![{robot} terrain levels]({robot}-terrains.svg)\n"
        ));
    }
    Ok(md)
}

/// The paper's column order of the methods.
fn mode_order(m: l3p_learner::Mode) -> u8 {
    match m {
        l3p_learner::Mode::Mlp => 0,
        l3p_learner::Mode::L3p => 1,
        l3p_learner::Mode::MlpTransfer => 2,
        l3p_learner::Mode::L3pTransfer => 3,
    }
}

fn report_cmd(spec_path: &Path, window: usize) -> anyhow::Result<()> {
    let (spec, arms) = load(spec_path)?;
    let finished = finished_arms(&arms);
    let results = collect_results(&arms, &finished, window);
    if results.is_empty() {
        anyhow::bail!(
            "no arm of {} has finished yet\nhint: `l3p experiment status {}`",
            spec.experiment.name,
            spec_path.display()
        );
    }
    let out = spec.dir().join("report");
    std::fs::create_dir_all(&out)?;
    let table = markdown_table(&results);
    let walk_table = samples_to_walk_table(&results);
    let mut walk_section = String::new();
    if !walk_table.is_empty() {
        walk_section.push_str(&format!(
            "\n## Samples to walk\n\nEvery arm trained with `--until-walks` (the walk criterion, \
             checked every 25 iterations and after each promising 5-iteration screen, at 5 ms \
             physics with joint damping at the top of its range) and stopped when it held, or at \
             its cap. Per target robot and method: the seeds that walked within the cap; the \
             median and range of samples to the passing check, an arm that did not walk counting \
             as its cap (`>`; a median it decides is a lower bound, `≥`); the ratio of medians to \
             the same robot's from-scratch arms of the family (`l3p` for `l3p-transfer`, `mlp` \
             for `mlp-transfer`; `≤`/`≥` when one side is a bound); the median iteration; and how \
             many of the policies the arms started from (iteration 0: pretrained core and the \
             arm's transfer heads) already walked.\n\n{walk_table}\n## The paper's table\n\n"
        ));
    }
    let mut md = format!(
        "# Experiment {} — {} of {} arms finished\n\nExperiment file: `{}`; base config: `{}`.\n\
         Convergence (Cv.): the first iteration at which the smoothed curve ({window}-iteration \
         moving average) has travelled 85% / 95% of the way from its start to its final value \
         (means of the first and last 5% of iterations); final values are means over the last 5% of \
         iterations. Tracking errors: the final policy under the training command mix ({} episodes). \
         Zero-shot: the pretrained policy played on the target robot before any fine-tuning. \
         The paper's numbers are from its rough-terrain curriculum with 5 seeds.\n{walk_section}\n{table}",
        spec.experiment.name,
        results.len(),
        arms.len(),
        spec_path.display(),
        spec.experiment.base_config.display(),
        spec.evaluation.episodes,
    );
    // Curves per target robot: every method's mean over seeds with its min-max band.
    let mut robots: Vec<String> = results.iter().map(|r| r.robot.clone()).collect();
    robots.sort();
    robots.dedup();
    for robot in &robots {
        for (key, label) in [
            ("episode_return", "episode reward"),
            ("terrain_level", "terrain level"),
        ] {
            let levels = results
                .iter()
                .any(|r| r.robot == *robot && r.terrain_levels);
            if key == "terrain_level" && !levels {
                continue;
            }
            // Every (method, variant) present for this robot, the main grid's methods first.
            let mut kinds: Vec<(l3p_learner::Mode, Option<String>)> = finished
                .iter()
                .filter(|f| f.arm.robots.join("+") == *robot)
                .map(|f| (f.arm.method, f.arm.variant.clone()))
                .collect();
            kinds.sort_by_key(|(m, v)| (v.clone(), mode_order(*m)));
            kinds.dedup();
            let mut lines = Vec::new();
            for (method, variant) in kinds {
                let curves: Vec<Vec<(f64, f64)>> = finished
                    .iter()
                    .filter(|f| {
                        f.arm.robots.join("+") == *robot
                            && f.arm.method == method
                            && f.arm.variant == variant
                    })
                    .map(|f| smooth(&series(&f.records, key), window))
                    .collect();
                lines.push((
                    format!(
                        "{} ({} seeds)",
                        crate::experiment::method_label(method, variant.as_deref()),
                        curves.len()
                    ),
                    band(&curves),
                ));
            }
            if lines.is_empty() {
                continue;
            }
            let title = format!("{robot} — {label}");
            std::fs::write(
                out.join(format!("{robot}-{key}.svg")),
                l3p_report::svg_bands(&title, label, &lines),
            )?;
            std::fs::write(
                out.join(format!("{robot}-{key}.png")),
                l3p_report::png_bands(&title, label, &lines),
            )?;
            md.push_str(&format!("\n![{robot} {label}]({robot}-{key}.svg)\n"));
        }
    }
    let bars = time_to_scratch_section(&results, window);
    md.push_str(&bars);
    let terrains = terrain_reach_section(&spec, &arms, &results, &out)?;
    md.push_str(&terrains);
    let file = out.join("README.md");
    std::fs::write(&file, &md)?;
    println!("{walk_table}{table}{bars}{terrains}");
    println!("wrote {} and the curves beside it", file.display());
    Ok(())
}
