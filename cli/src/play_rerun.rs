//! The Rerun half of `l3p play` (cargo feature `rerun`): steps one single-env [`VecEnv`] per scene
//! entry with its policy and logs each control step.
//!
//! Entity layout (every name below is a stable contract; the tests read it back):
//! - `world` (z up); `world/ground` (flat) or `world/<label>/terrain` (a mesh of the heights
//!   around the robot's tile);
//! - `world/<label>`: static offset, robots side by side along y; `world/<label>/<body>`: the
//!   body's world pose every step, its collision shapes as static children `…/<body>/shape<k>`;
//! - `world/<label>/contacts` (arrows at feet in contact, length ∝ force / weight),
//!   `world/<label>/velocity/{command,measured}` (arrows from the base);
//! - `plots/<label>/…`: `velocity/{vx,vy,wz}_{command,measured}`, `base_height`,
//!   `joints/<joint>/{target,position}`, `torque/<joint>`, `gait_diagram/<foot>` (lane i is
//!   `4 − i`, raised 0.6 while the foot is down), `target_change_rms`, `power_w`;
//! - `summary/<label>` (markdown: the gait diagnostics of the whole play), `events` (episode ends).
//!
//! Timelines: `step` (control steps) and `sim_time` (seconds).

use std::time::{Duration, Instant};

use l3p_policy::DeployPolicy;
use l3p_policy::InferScratch;
use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::model::{ShapeSpec, pose_arrays};
use l3p_sim::vecenv::VecEnv;
use l3p_task::config::COMMAND_OBS;
use l3p_task::gait::GaitReport;
use l3p_task::task::{Command, NUM_FEET, yaw_of};
use rerun::{
    Arrows3D, Boxes3D, Capsules3D, Color, Cylinders3D, Ellipsoids3D, Mesh3D, RecordingStream,
    Scalars, TextDocument, TextLog, Transform3D,
};

use crate::config::Config;
use crate::play_cmd::{
    CommandSchedule, PlayArgs, SceneEntry, Sink, VelocityCommand, sanitize, scene,
};

/// Lateral spacing of side-by-side robots (m).
const SPACING: f32 = 1.5;
/// Half-width of the drawn terrain window around a robot's start (m).
const TERRAIN_WINDOW: f32 = 6.0;
/// Arrow length for a foot carrying the whole robot's weight (m).
const FORCE_ARROW_PER_WEIGHT: f32 = 0.3;

/// Where a robot's world is drawn: rotated by `yaw` about z, then moved by `translation`.
#[derive(Debug, Clone, Copy)]
struct Offset {
    translation: [f32; 3],
    yaw: f32,
}

struct Player {
    entry: SceneEntry,
    spec: &'static RobotSpec,
    policy: DeployPolicy,
    env: VecEnv,
    obs: Vec<f32>,
    means: Vec<f32>,
    scratch: InferScratch,
    body_names: Vec<String>,
    weight: f32,
    offset: Offset,
    prev_targets: Option<[f32; NUM_JOINTS]>,
}

fn rec_err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("rerun: {e}")
}

/// Runs `l3p play` (arguments already checked by `play_cmd::run`).
pub fn play(args: &PlayArgs) -> anyhow::Result<()> {
    crate::robots_cmd::load_added_robots(Some(&args.data_dir));
    let mut config = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    config.env.terrain.preset = crate::eval_cmd::terrain_preset(&args.terrain)?;
    args.pins.apply(&mut config.env)?;
    let schedule = args.schedule()?;
    let mut scene_policies = Vec::new();
    for entry in scene(&args.robot, &args.policy)? {
        let policy = crate::eval_cmd::load_policy(&entry.policy, &args.data_dir)?;
        scene_policies.push((entry, policy));
    }
    let mut players = build_players(&config.env, scene_policies, schedule.at(0.0), args.seed)?;

    let builder = rerun::RecordingStreamBuilder::new("l3p");
    let rec = match args.sink()? {
        Sink::Save(path) => builder.save(&path).map_err(rec_err)?,
        Sink::Connect(url) => builder.connect_grpc_opts(url).map_err(rec_err)?,
        Sink::Spawn => builder.spawn().map_err(rec_err)?,
    };
    send_layout(&rec, &players)?;
    let (steps, summaries) = record(&rec, &mut players, &schedule, args.seconds, args.realtime)?;
    for text in summaries {
        println!("{text}");
    }
    rec.flush_blocking().map_err(rec_err)?;
    if let Some(path) = &args.save {
        println!(
            "wrote {} ({steps} control steps); open it with rerun-sdk {} (`pip install \
             rerun-sdk=={}`, then `rerun {}`)",
            path.display(),
            crate::play_cmd::RERUN_VERSION,
            crate::play_cmd::RERUN_VERSION,
            path.display()
        );
    }
    Ok(())
}

/// One single-env player per scene entry, spawned facing +x, side by side along y.
fn build_players(
    env: &l3p_task::config::EnvConfig,
    entries: Vec<(SceneEntry, DeployPolicy)>,
    first: VelocityCommand,
    seed: u64,
) -> anyhow::Result<Vec<Player>> {
    let mut players = Vec::with_capacity(entries.len());
    for (k, (entry, policy)) in entries.into_iter().enumerate() {
        let spec = RobotSpec::by_name(&entry.robot)?;
        let mut env_cfg = l3p_task::contract::sim_env_for_policy(env, &policy.config, spec.name);
        crate::eval_cmd::constant_command(&mut env_cfg, first.vx, first.vy, first.wz);
        let mut env = VecEnv::new(spec, &env_cfg, 1, 1, seed)?;
        if env.obs_dim() != policy.obs_dim() || env.action_dim() != policy.action_dim() {
            anyhow::bail!(
                "policy {} has obs {} / action {}, but {} here has obs {} / action {}",
                entry.policy,
                policy.obs_dim(),
                policy.action_dim(),
                spec.name,
                env.obs_dim(),
                env.action_dim()
            );
        }
        env.enable_gait_meter();
        let obs = env.reset_all().to_vec();
        // Drawn from its spawn point facing +x (the env spawns at a random yaw near its tile
        // origin), robots side by side along y: p' = R(−yaw₀)(p − spawn) + lane.
        let (spawn, yaw0) = env
            .snapshot(0)
            .map(|s| (s.state.base_pos, yaw_of(s.state.base_quat)))
            .unwrap_or_default();
        let (c, sn) = (yaw0.cos(), yaw0.sin());
        let rotated = [c * spawn[0] + sn * spawn[1], -sn * spawn[0] + c * spawn[1]];
        let offset = Offset {
            translation: [-rotated[0], k as f32 * SPACING - rotated[1], 0.0],
            yaw: -yaw0,
        };
        let model = env.model();
        let body_names = unique_body_names(model.bodies.iter().map(|b| b.name.as_str()));
        let weight = model.total_mass() * 9.81;
        players.push(Player {
            entry,
            spec,
            policy,
            env,
            obs,
            means: Vec::new(),
            scratch: InferScratch::default(),
            body_names,
            weight,
            offset,
            prev_targets: None,
        });
    }
    Ok(players)
}

/// Logs the scene's static parts, then plays `seconds` of `schedule` (on the `step` and
/// `sim_time` timelines) and each player's gait summary; returns the control steps played and the
/// summaries (markdown).
fn record(
    rec: &RecordingStream,
    players: &mut [Player],
    schedule: &CommandSchedule,
    seconds: f32,
    realtime: bool,
) -> anyhow::Result<(usize, Vec<String>)> {
    rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())
        .map_err(rec_err)?;
    let speed = |f: &dyn Fn(&VelocityCommand) -> f32| {
        schedule
            .0
            .iter()
            .map(|(_, c)| f(c).abs())
            .fold(0.0f32, f32::max)
    };
    let reach = speed(&|c| c.vx.abs().max(c.vy.abs())) * seconds;
    // Turning or side-stepping leaves the lane: then the ground is a square around the start.
    let straight = speed(&|c| c.vy) == 0.0 && speed(&|c| c.wz) == 0.0;
    log_ground(rec, players, reach, straight)?;
    for p in players.iter() {
        log_robot_static(rec, p)?;
    }

    let dt = players[0].env.task().spec.step_dt;
    let steps = (seconds / dt).round().max(1.0) as usize;
    let mut started = Instant::now();
    let mut current = schedule.at(0.0);
    for step in 0..steps {
        let t = step as f32 * dt;
        let wanted = schedule.at(t);
        if wanted != current {
            current = wanted;
            for p in players.iter_mut() {
                let command = to_task_command(current);
                p.env.set_command(0, command);
                // The observation the policy acts on next was taken before the change: give it
                // the new command now, as the task's next observation would, not one step late.
                let clip = p.env.task().spec.obs_clip;
                for (o, c) in p.obs[COMMAND_OBS].iter_mut().zip(command.as_array()) {
                    *o = c.clamp(-clip, clip);
                }
            }
            rec.log(
                "events",
                &TextLog::new(format!(
                    "t = {t:.2} s: command vx {:.2} vy {:.2} wz {:.2}",
                    current.vx, current.vy, current.wz
                )),
            )
            .map_err(rec_err)?;
        }
        for p in players.iter_mut() {
            p.policy
                .act_into(&p.obs, &mut p.means, &mut p.scratch)
                .map_err(|e| anyhow::anyhow!("policy {}: {e}", p.entry.policy))?;
            let out = p.env.step(&p.means)?;
            p.obs.copy_from_slice(out.obs);
            let ended: Vec<String> = out
                .episodes
                .iter()
                .map(|e| format!("{}: episode ended ({:?})", p.entry.label, e.reason))
                .collect();
            rec.set_time_sequence("step", step as i64 + 1);
            rec.set_duration_secs("sim_time", (t + dt) as f64);
            for text in ended {
                rec.log("events", &TextLog::new(text)).map_err(rec_err)?;
            }
            log_step(rec, p)?;
        }
        if realtime {
            let due = started + Duration::from_secs_f32((step + 1) as f32 * dt);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            } else if Instant::now() - due > Duration::from_secs(1) {
                // Far behind (a slow machine): stop trying to catch up.
                started = Instant::now() - Duration::from_secs_f32((step + 1) as f32 * dt);
            }
        }
    }
    let mut summaries = Vec::with_capacity(players.len());
    for p in players.iter() {
        let text = summary_markdown(p, &p.env.gait_report(), seconds);
        rec.log_static(
            format!("summary/{}", p.entry.label),
            &TextDocument::new(text.clone()).with_media_type(rerun::MediaType::markdown()),
        )
        .map_err(rec_err)?;
        summaries.push(text);
    }
    Ok((steps, summaries))
}

fn to_task_command(c: VelocityCommand) -> Command {
    Command {
        vx: c.vx,
        vy: c.vy,
        wz: c.wz,
        heading: 0.0,
        heading_mode: false,
        standing: c.vx == 0.0 && c.vy == 0.0 && c.wz == 0.0,
        // Held until the schedule changes it: the task must not resample it back.
        time_left: f32::INFINITY,
    }
}

/// Entity-safe body names, numbered where two bodies would share one.
fn unique_body_names<'a>(names: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for n in names {
        let base = sanitize(n);
        let mut name = base.clone();
        let mut k = 1;
        while out.contains(&name) {
            name = format!("{base}_{k}");
            k += 1;
        }
        out.push(name);
    }
    out
}

/// A rapier pose as a Rerun transform.
fn transform(pose: &l3p_robot::model::Pose) -> Transform3D {
    let (t, q) = pose_arrays(pose);
    Transform3D::from_translation_rotation(t, rerun::Quaternion::from_xyzw(q))
}

fn body_color(name: &str, is_foot: bool, is_root: bool) -> Color {
    if is_foot {
        Color::from_rgb(230, 140, 40)
    } else if is_root {
        Color::from_rgb(60, 110, 200)
    } else if name.to_ascii_lowercase().contains("calf") || name.contains("SHANK") {
        Color::from_rgb(120, 120, 130)
    } else {
        Color::from_rgb(165, 165, 175)
    }
}

fn log_robot_static(rec: &RecordingStream, p: &Player) -> anyhow::Result<()> {
    let root = format!("world/{}", p.entry.label);
    let half = 0.5 * p.offset.yaw;
    let yaw = rerun::Quaternion::from_xyzw([0.0, 0.0, half.sin(), half.cos()]);
    rec.log_static(
        root.as_str(),
        &Transform3D::from_translation_rotation(p.offset.translation, yaw),
    )
    .map_err(rec_err)?;
    let model = p.env.model();
    for (b, body) in model.bodies.iter().enumerate() {
        for (k, c) in body.colliders.iter().enumerate() {
            let is_foot = p.spec.foot_links.contains(&c.link.as_str());
            let color = body_color(&c.link, is_foot, b == 0);
            let path = format!("{root}/{}/shape{k}", p.body_names[b]);
            rec.log_static(path.as_str(), &transform(&c.pose))
                .map_err(rec_err)?;
            match c.shape {
                ShapeSpec::Cuboid { half } => rec.log_static(
                    path.as_str(),
                    &Boxes3D::from_half_sizes([(half.x, half.y, half.z)])
                        .with_colors([color])
                        .with_fill_mode(rerun::FillMode::Solid),
                ),
                ShapeSpec::Sphere { radius } => rec.log_static(
                    path.as_str(),
                    &Ellipsoids3D::from_radii([radius])
                        .with_colors([color])
                        .with_fill_mode(rerun::FillMode::Solid),
                ),
                ShapeSpec::Capsule {
                    half_length,
                    radius,
                } => rec.log_static(
                    path.as_str(),
                    // Rerun's capsule runs from the origin along +z; ours is centred.
                    &Capsules3D::from_lengths_and_radii([2.0 * half_length], [radius])
                        .with_translations([(0.0, 0.0, -half_length)])
                        .with_colors([color]),
                ),
                ShapeSpec::Cylinder {
                    half_length,
                    radius,
                } => rec.log_static(
                    path.as_str(),
                    &Cylinders3D::from_lengths_and_radii([2.0 * half_length], [radius])
                        .with_colors([color])
                        .with_fill_mode(rerun::FillMode::Solid),
                ),
                ShapeSpec::ConvexHull { ref points } => {
                    // The loader only keeps points with volume; should they make no hull, the
                    // points themselves are drawn.
                    match l3p_sim::world::convex_hull_mesh(points) {
                        Some((vertices, triangles)) => rec.log_static(
                            path.as_str(),
                            &Mesh3D::new(vertices.iter().map(|v| [v.x, v.y, v.z]))
                                .with_triangle_indices(triangles)
                                .with_vertex_colors(std::iter::repeat_n(color, vertices.len())),
                        ),
                        None => rec.log_static(
                            path.as_str(),
                            &rerun::Points3D::new(points.iter().map(|v| [v.x, v.y, v.z]))
                                .with_colors([color]),
                        ),
                    }
                }
            }
            .map_err(rec_err)?;
        }
    }
    Ok(())
}

/// The default layout: the 3D scene beside velocity, gait-diagram and base-height plots and the
/// gait summaries (the viewer's own heuristics scatter the ~50 series per robot).
fn send_layout(rec: &RecordingStream, players: &[Player]) -> anyhow::Result<()> {
    use rerun::blueprint::{
        Blueprint, BlueprintActivation, Horizontal, Spatial3DView, Tabs, TextDocumentView,
        TimeSeriesView, Vertical,
    };
    let series = |name: &str, sub: &str| {
        TimeSeriesView::new(name).with_contents(
            players
                .iter()
                .map(|p| format!("/plots/{}/{sub}/**", p.entry.label))
                .collect::<Vec<_>>(),
        )
    };
    let plots = Vertical::new([
        series("velocity: command vs measured", "velocity").into(),
        series("gait diagram (raised = foot down)", "gait_diagram").into(),
        Tabs::new([
            series("joint targets vs positions", "joints").into(),
            series("torques", "torque").into(),
            TimeSeriesView::new("base height")
                .with_contents(
                    players
                        .iter()
                        .map(|p| format!("/plots/{}/base_height", p.entry.label))
                        .collect::<Vec<_>>(),
                )
                .into(),
        ])
        .into(),
        TextDocumentView::new("gait summary")
            .with_contents(["/summary/**"])
            .into(),
    ]);
    let root = Horizontal::new([
        Spatial3DView::new("scene").with_origin("/world").into(),
        plots.into(),
    ])
    .with_column_shares([3.0, 2.0]);
    Blueprint::new(root)
        .send(rec, BlueprintActivation::default())
        .map_err(rec_err)
}

/// Flat ground: a thin box around where the robots can walk in the play (`reach` m). Rough
/// terrain: each robot's window of the height grid.
fn log_ground(
    rec: &RecordingStream,
    players: &[Player],
    reach: f32,
    straight: bool,
) -> anyhow::Result<()> {
    let terrain = players[0].env.terrain();
    if terrain.is_flat() {
        let lanes = 0.5 * (players.len() - 1) as f32 * SPACING;
        let (half_x, half_y, centre_x, centre_y) = if straight {
            (0.5 * reach + 1.5, 1.5 + lanes, 0.5 * reach, lanes)
        } else {
            (reach + 1.5, reach + 1.5 + lanes, 0.0, lanes)
        };
        return rec
            .log_static(
                "world/ground",
                &Boxes3D::from_centers_and_half_sizes(
                    [(centre_x, centre_y, -0.01)],
                    [(half_x, half_y, 0.01)],
                )
                .with_colors([Color::from_rgb(200, 205, 195)])
                .with_fill_mode(rerun::FillMode::Solid),
            )
            .map_err(rec_err);
    }
    for p in players {
        let Some(snap) = p.env.snapshot(0) else {
            continue;
        };
        let t = p.env.terrain();
        let (cx, cy) = (snap.origin[0], snap.origin[1]);
        let n = (2.0 * TERRAIN_WINDOW / t.resolution).round() as usize + 1;
        let mut positions = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let x = cx - TERRAIN_WINDOW + i as f32 * t.resolution;
                let y = cy - TERRAIN_WINDOW + j as f32 * t.resolution;
                positions.push((x, y, t.height_at(x, y)));
            }
        }
        let mut triangles = Vec::with_capacity(2 * (n - 1) * (n - 1));
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = (j * n + i) as u32;
                let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
                triangles.push((a, b, d));
                triangles.push((a, d, c));
            }
        }
        rec.log_static(
            format!("world/{}/terrain", p.entry.label),
            &Mesh3D::new(positions)
                .with_triangle_indices(triangles)
                .with_albedo_factor(rerun::Rgba32::from_rgb(190, 195, 185)),
        )
        .map_err(rec_err)?;
    }
    Ok(())
}

fn log_step(rec: &RecordingStream, p: &mut Player) -> anyhow::Result<()> {
    let Some(snap) = p.env.snapshot(0) else {
        return Ok(());
    };
    let root = format!("world/{}", p.entry.label);
    for (name, pose) in p.body_names.iter().zip(&snap.body_poses) {
        rec.log(format!("{root}/{name}"), &transform(pose))
            .map_err(rec_err)?;
    }
    let s = snap.state;
    let threshold = p.env.task().spec.reward_params.contact_threshold;
    let (mut origins, mut vectors) = (Vec::new(), Vec::new());
    for f in 0..NUM_FEET {
        if s.foot_force[f] > threshold {
            origins.push(snap.foot_positions[f]);
            let len = FORCE_ARROW_PER_WEIGHT * s.foot_force[f] / p.weight.max(1e-3);
            vectors.push([0.0, 0.0, len]);
        }
    }
    rec.log(
        format!("{root}/contacts"),
        &Arrows3D::from_vectors(vectors)
            .with_origins(origins)
            .with_colors([Color::from_rgb(220, 60, 50)]),
    )
    .map_err(rec_err)?;
    // Velocities in the heading frame (the command's frame).
    let yaw = yaw_of(s.base_quat);
    let (c, sn) = (yaw.cos(), yaw.sin());
    let v = s.base_lin_vel_w;
    let measured = [
        c * v[0] + sn * v[1],
        -sn * v[0] + c * v[1],
        s.base_ang_vel_w[2],
    ];
    let cmd = snap.command;
    let to_world = |x: f32, y: f32| [c * x - sn * y, sn * x + c * y, 0.0];
    let above = [s.base_pos[0], s.base_pos[1], s.base_pos[2] + 0.15];
    rec.log(
        format!("{root}/velocity/command"),
        &Arrows3D::from_vectors([to_world(cmd.vx, cmd.vy)])
            .with_origins([above])
            .with_colors([Color::from_rgb(40, 170, 80)]),
    )
    .map_err(rec_err)?;
    rec.log(
        format!("{root}/velocity/measured"),
        &Arrows3D::from_vectors([to_world(measured[0], measured[1])])
            .with_origins([above])
            .with_colors([Color::from_rgb(200, 60, 160)]),
    )
    .map_err(rec_err)?;

    let plots = format!("plots/{}", p.entry.label);
    let scalar = |path: String, value: f32| -> anyhow::Result<()> {
        rec.log(path, &Scalars::single(value as f64))
            .map_err(rec_err)
    };
    for (name, want, got) in [
        ("vx", cmd.vx, measured[0]),
        ("vy", cmd.vy, measured[1]),
        ("wz", cmd.wz, measured[2]),
    ] {
        scalar(format!("{plots}/velocity/{name}_command"), want)?;
        scalar(format!("{plots}/velocity/{name}_measured"), got)?;
    }
    let ground = p.env.terrain().height_at(s.base_pos[0], s.base_pos[1]);
    scalar(format!("{plots}/base_height"), s.base_pos[2] - ground)?;
    for (j, joint) in p.spec.joint_names.iter().enumerate() {
        let joint = sanitize(joint);
        scalar(
            format!("{plots}/joints/{joint}/target"),
            snap.joint_targets[j],
        )?;
        scalar(format!("{plots}/joints/{joint}/position"), s.joint_pos[j])?;
        scalar(format!("{plots}/torque/{joint}"), s.joint_torque[j])?;
    }
    for (f, foot) in p.spec.foot_links.iter().enumerate() {
        let down = if s.foot_force[f] > threshold {
            0.6
        } else {
            0.0
        };
        scalar(
            format!("{plots}/gait_diagram/{}", sanitize(foot)),
            (NUM_FEET - f) as f32 + down,
        )?;
    }
    let change = match p.prev_targets {
        Some(prev) => {
            let sq: f32 = prev
                .iter()
                .zip(&snap.joint_targets)
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            (sq / NUM_JOINTS as f32).sqrt()
        }
        None => 0.0,
    };
    p.prev_targets = Some(snap.joint_targets);
    scalar(format!("{plots}/target_change_rms"), change)?;
    let power: f32 = s
        .joint_torque
        .iter()
        .zip(&s.joint_vel)
        .map(|(t, w)| (t * w).abs())
        .sum();
    scalar(format!("{plots}/power_w"), power)?;
    Ok(())
}

fn summary_markdown(p: &Player, g: &GaitReport, seconds: f32) -> String {
    let pct = |x: f32| format!("{:.0}%", 100.0 * x);
    let feet = |v: &[f32; NUM_FEET], f: &dyn Fn(f32) -> String| {
        v.iter().map(|x| f(*x)).collect::<Vec<_>>().join(" / ")
    };
    format!(
        "# {label}: {robot} under {policy}\n\n\
         {seconds:.1} s played, {steps} control steps.\n\n\
         | measure | value |\n|---|---|\n\
         | base height mean / min | {hm:.3} / {hmin:.3} m ({hp:.0}% of standing {hs:.3} m) |\n\
         | mean velocity fwd / left | {vf:.2} / {vl:.2} m/s |\n\
         | swing share FL / FR / RL / RR | {swing} |\n\
         | touchdowns per s | {td} |\n\
         | non-foot contact share | {nf} |\n\
         | joint-target change per step (RMS) | {tc:.3} rad |\n\
         | second difference (RMS) | {sd:.3} rad |\n\
         | mean abs torque / power | {tq:.2} N·m / {pw:.1} W |\n\
         | heading drift | {hd:.1}° |\n",
        label = p.entry.label,
        robot = p.spec.name,
        policy = p.entry.policy,
        steps = g.steps,
        hm = g.base_height_mean,
        hmin = g.base_height_min,
        hp = g.base_height_pct,
        hs = g.standing_height,
        vf = g.mean_heading_velocity[0],
        vl = g.mean_heading_velocity[1],
        swing = feet(&g.swing_share, &pct),
        td = feet(&g.touchdown_hz, &|x| format!("{x:.1}")),
        nf = pct(g.non_foot_contact_share),
        tc = g.target_change_rms,
        sd = g.target_second_diff_rms,
        tq = g.mean_abs_torque,
        pw = g.mean_power,
        hd = g.heading_drift_rad.to_degrees(),
    )
}

/// `l3p train --rerun`: a training run's Rerun stream. Every metric of every iteration as
/// `metrics/<name>` on the `iteration` timeline, and now and then a rollout of the latest policy
/// with the `l3p play` layout ([`log_training_rollout`]).
#[derive(Clone)]
pub struct TrainStream {
    rec: RecordingStream,
}

impl std::fmt::Debug for TrainStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TrainStream")
    }
}

impl TrainStream {
    /// Streams to a viewer when `target` is a URL (`rerun+http://…`), else saves to the file
    /// `target` (a `.rrd`).
    pub fn open(run: &str, target: &str) -> anyhow::Result<Self> {
        let app = rerun::ApplicationId::try_new(format!("l3p-train-{run}")).map_err(rec_err)?;
        let builder = rerun::RecordingStreamBuilder::new(app);
        let rec = if target.contains("://") {
            builder.connect_grpc_opts(target.to_string())
        } else {
            builder.save(target)
        }
        .map_err(rec_err)?;
        Ok(Self { rec })
    }

    /// Logs one metrics record's finite values at its iteration.
    pub fn log_metrics(
        &self,
        iteration: u64,
        values: &std::collections::BTreeMap<String, f64>,
    ) -> anyhow::Result<()> {
        self.rec.set_time_sequence("iteration", iteration as i64);
        for (name, v) in values.iter().filter(|(_, v)| v.is_finite()) {
            let path: Vec<String> = name.split('/').map(sanitize).collect();
            self.rec
                .log(format!("metrics/{}", path.join("/")), &Scalars::single(*v))
                .map_err(rec_err)?;
        }
        Ok(())
    }

    /// A short rollout of `policy` on `robot` at a constant `command` with the `l3p play` entity
    /// layout, at `iteration` on the `iteration` timeline; each rollout overwrites the previous
    /// one's entities.
    pub fn log_rollout(
        &self,
        env: &l3p_task::config::EnvConfig,
        robot: &str,
        policy: DeployPolicy,
        iteration: u64,
        command: VelocityCommand,
        seconds: f32,
    ) -> anyhow::Result<()> {
        let entry = SceneEntry {
            robot: robot.to_string(),
            policy: format!("iteration {iteration}"),
            label: sanitize(robot),
        };
        let mut players = build_players(env, vec![(entry, policy)], command, iteration)?;
        self.rec.set_time_sequence("iteration", iteration as i64);
        let schedule = CommandSchedule::constant(command);
        record(&self.rec, &mut players, &schedule, seconds, false)?;
        Ok(())
    }

    /// Waits until everything logged has reached the viewer or the file.
    pub fn flush(&self) -> anyhow::Result<()> {
        self.rec.flush_blocking().map_err(rec_err)
    }
}
