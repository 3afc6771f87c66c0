//! `l3p play`: run one or more policies in the simulator and log what happens to **Rerun**
//! (`--save run.rrd`, `--connect`, `--spawn`): the robots' collision shapes every control step, the
//! terrain, foot contacts and their forces, commanded vs measured velocity, joint targets vs
//! positions, torques, a gait diagram and the gait diagnostics of `l3p eval`.
//!
//! Main types: [`PlayArgs`], [`CommandSchedule`] (pure, tested here), [`Scene`] (which policy
//! drives which robot, and where it is drawn). The Rerun half lives in `play_rerun` behind the
//! default-on `rerun` cargo feature; without it `l3p play` says how to get it.

use std::path::PathBuf;

use clap::Args;

use crate::eval_cmd::PhysicsPins;

/// The Rerun SDK version `l3p play` writes with; open its files with the same viewer version
/// (`pip install rerun-sdk==0.36.3`, then `rerun run.rrd`).
pub const RERUN_VERSION: &str = "0.36.3";

/// Where a viewer listens by default (`rerun` started with no arguments).
pub const DEFAULT_VIEWER_URL: &str = "rerun+http://127.0.0.1:9876/proxy";

#[derive(Debug, Args)]
pub struct PlayArgs {
    /// Policies: export files/directories or registry refs (`name@version|alias`), comma-separated;
    /// one per robot, or one for all.
    #[arg(long, value_delimiter = ',', required = true)]
    pub policy: Vec<String>,
    /// Robots, comma-separated (e.g. `a1,go1`); one per policy, or one for all (the same robot
    /// under two policies, side by side).
    #[arg(long, value_delimiter = ',', required = true)]
    pub robot: Vec<String>,
    /// Terrain preset: flat, simple-rough, curriculum, paper.
    #[arg(long, default_value = "flat")]
    pub terrain: String,
    /// Constant command `vx,vy,wz` (m/s, m/s, rad/s; base frame). Default: 0.5,0,0.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        value_name = "VX,VY,WZ"
    )]
    pub command: Option<Vec<f32>>,
    /// Command schedule `t:vx,vy,wz;t:vx,vy,wz;…` (t in seconds from the start, increasing), e.g.
    /// `0:0.5,0,0;4:1.0,0,0;8:0,0,1.0`.
    #[arg(long, conflicts_with = "command", allow_hyphen_values = true)]
    pub commands: Option<String>,
    /// Simulated seconds to play.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f32,
    /// Config whose [env] section to use (defaults otherwise).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Data directory holding the registry (for registry refs) and added robots.
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// Seed (randomised physics, spawn).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    #[command(flatten)]
    pub pins: PhysicsPins,
    /// Write the recording to this `.rrd` file.
    #[arg(long, group = "sink")]
    pub save: Option<PathBuf>,
    /// Stream to a running viewer (default address: a local `rerun`).
    #[arg(long, group = "sink", num_args = 0..=1, default_missing_value = DEFAULT_VIEWER_URL)]
    pub connect: Option<String>,
    /// Start a viewer (`rerun` on PATH) and stream to it.
    #[arg(long, group = "sink")]
    pub spawn: bool,
    /// Pace the simulation to wall-clock time (for a live viewer).
    #[arg(long)]
    pub realtime: bool,
}

/// Where the recording goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Sink {
    Save(PathBuf),
    Connect(String),
    Spawn,
}

impl PlayArgs {
    /// The one sink the arguments name.
    pub fn sink(&self) -> anyhow::Result<Sink> {
        match (&self.save, &self.connect, self.spawn) {
            (Some(p), None, false) => Ok(Sink::Save(p.clone())),
            (None, Some(u), false) => Ok(Sink::Connect(u.clone())),
            (None, None, true) => Ok(Sink::Spawn),
            _ => anyhow::bail!(
                "say where the recording goes: --save run.rrd, --connect [URL] or --spawn"
            ),
        }
    }
}

/// One robot of the scene: its policy, and its label (the Rerun entity name).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneEntry {
    pub robot: String,
    pub policy: String,
    pub label: String,
}

/// Pairs robots with policies (a list of one applies to all) and names each entry: the robot's
/// name, numbered when a robot appears twice.
pub fn scene(robots: &[String], policies: &[String]) -> anyhow::Result<Vec<SceneEntry>> {
    let n = robots.len().max(policies.len());
    if robots.is_empty() || policies.is_empty() {
        anyhow::bail!("give at least one --robot and one --policy");
    }
    for (what, len) in [("--robot", robots.len()), ("--policy", policies.len())] {
        if len != 1 && len != n {
            anyhow::bail!(
                "{what} has {len} entries but the scene has {n}: give one for all, or one per robot"
            );
        }
    }
    let pick = |v: &[String], i: usize| v[if v.len() == 1 { 0 } else { i }].clone();
    let mut out: Vec<SceneEntry> = (0..n)
        .map(|i| SceneEntry {
            robot: pick(robots, i),
            policy: pick(policies, i),
            label: sanitize(&pick(robots, i)),
        })
        .collect();
    let base: Vec<String> = out.iter().map(|e| e.label.clone()).collect();
    for (i, entry) in out.iter_mut().enumerate() {
        if base.iter().filter(|b| **b == base[i]).count() > 1 {
            let k = base[..i].iter().filter(|b| **b == base[i]).count();
            entry.label = format!("{}_{k}", base[i]);
        }
    }
    Ok(out)
}

/// A Rerun entity-path segment: letters, digits, `_` and `-` kept, anything else `_`.
pub fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A velocity command in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityCommand {
    pub vx: f32,
    pub vy: f32,
    pub wz: f32,
}

/// Commands that change at given times: `(t, command)` with `t` increasing from 0.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandSchedule(pub Vec<(f32, VelocityCommand)>);

impl CommandSchedule {
    /// One command for the whole play.
    pub fn constant(c: VelocityCommand) -> Self {
        Self(vec![(0.0, c)])
    }

    /// Parses `t:vx,vy,wz;t:vx,vy,wz;…`; the first time must be 0 and times must increase.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let mut out: Vec<(f32, VelocityCommand)> = Vec::new();
        for (i, item) in text.split(';').map(str::trim).enumerate() {
            if item.is_empty() {
                continue;
            }
            let (t, c) = item.split_once(':').ok_or_else(|| {
                anyhow::anyhow!("--commands entry {i} ({item:?}) is not `t:vx,vy,wz`")
            })?;
            let t: f32 = t
                .trim()
                .parse()
                .map_err(|_| anyhow::anyhow!("--commands entry {i}: time {t:?} is not a number"))?;
            let c = parse_command(c).map_err(|e| anyhow::anyhow!("--commands entry {i}: {e}"))?;
            if !t.is_finite() || t < 0.0 {
                anyhow::bail!("--commands entry {i}: time {t} must be finite and >= 0");
            }
            if let Some((prev, _)) = out.last()
                && t <= *prev
            {
                anyhow::bail!("--commands entry {i}: time {t} does not come after {prev}");
            }
            out.push((t, c));
        }
        match out.first() {
            None => anyhow::bail!("--commands is empty"),
            Some((t, _)) if *t != 0.0 => {
                anyhow::bail!("--commands must start at time 0, not {t}")
            }
            _ => Ok(Self(out)),
        }
    }

    /// The command in force at time `t`.
    pub fn at(&self, t: f32) -> VelocityCommand {
        self.0
            .iter()
            .take_while(|(start, _)| *start <= t)
            .last()
            .map(|(_, c)| *c)
            .unwrap_or(self.0[0].1)
    }
}

/// Parses `vx,vy,wz` (finite numbers).
pub fn parse_command(text: &str) -> anyhow::Result<VelocityCommand> {
    let v: Vec<f32> = text
        .split(',')
        .map(|s| s.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("command {text:?} is not `vx,vy,wz`"))?;
    command_from(&v)
}

fn command_from(v: &[f32]) -> anyhow::Result<VelocityCommand> {
    match v {
        [vx, vy, wz] if v.iter().all(|x| x.is_finite()) => Ok(VelocityCommand {
            vx: *vx,
            vy: *vy,
            wz: *wz,
        }),
        _ => anyhow::bail!("a command is three finite numbers vx,vy,wz; got {v:?}"),
    }
}

impl PlayArgs {
    /// The schedule the arguments describe (`--command`, `--commands`, or 0.5 m/s forward).
    pub fn schedule(&self) -> anyhow::Result<CommandSchedule> {
        match (&self.command, &self.commands) {
            (Some(v), _) => Ok(CommandSchedule::constant(command_from(v)?)),
            (None, Some(text)) => CommandSchedule::parse(text),
            (None, None) => Ok(CommandSchedule::constant(VelocityCommand {
                vx: 0.5,
                vy: 0.0,
                wz: 0.0,
            })),
        }
    }
}

pub fn run(args: PlayArgs) -> anyhow::Result<()> {
    // Check everything that needs no simulator first, so a typo fails at once.
    args.sink()?;
    args.schedule()?;
    scene(&args.robot, &args.policy)?;
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive, got {}", args.seconds);
    }
    #[cfg(feature = "rerun")]
    {
        crate::play_rerun::play(&args)
    }
    #[cfg(not(feature = "rerun"))]
    {
        anyhow::bail!(
            "this l3p was built without the `rerun` feature\nhint: cargo build --release -p l3p-cli \
             (the feature is on by default)"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_schedule_parses_and_holds_each_command_until_the_next() {
        let s = CommandSchedule::parse("0:0.5,0,0; 4:1.0,0,0;8:0,0,-1").unwrap();
        assert_eq!(s.0.len(), 3);
        assert_eq!(s.at(0.0).vx, 0.5);
        assert_eq!(s.at(3.99).vx, 0.5);
        assert_eq!(s.at(4.0).vx, 1.0);
        assert_eq!(s.at(100.0).wz, -1.0);
    }

    #[test]
    fn bad_schedules_are_refused_with_the_entry_named() {
        for (text, needle) in [
            ("", "empty"),
            ("1:0.5,0,0", "start at time 0"),
            ("0:0.5,0,0;0:1,0,0", "does not come after"),
            ("0:0.5,0", "three finite numbers"),
            ("0:0.5,0,nan", "three finite numbers"),
            ("0:x,0,0", "entry 0"),
            ("0:1,0,0;zz", "entry 1"),
        ] {
            let e = CommandSchedule::parse(text).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn robots_and_policies_pair_up_and_duplicates_get_numbered() {
        let s = scene(&strings(&["a1", "go1"]), &strings(&["p"])).unwrap();
        assert_eq!(
            s.iter().map(|e| e.label.as_str()).collect::<Vec<_>>(),
            ["a1", "go1"]
        );
        assert!(s.iter().all(|e| e.policy == "p"));
        let s = scene(&strings(&["a1"]), &strings(&["p", "q"])).unwrap();
        assert_eq!(
            s.iter().map(|e| e.label.as_str()).collect::<Vec<_>>(),
            ["a1_0", "a1_1"]
        );
        assert_eq!(s[1].policy, "q");
        let e = scene(&strings(&["a1", "go1", "spot"]), &strings(&["p", "q"])).unwrap_err();
        assert!(e.to_string().contains("--policy has 2 entries"), "{e}");
        assert_eq!(sanitize("my robot/v2"), "my_robot_v2");
    }
}
