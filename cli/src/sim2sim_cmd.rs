//! `l3p sim2sim --policy <ref|export> [--model <mjcf|urdf>]`: plays a policy in MuJoCo, a second
//! simulator, through the export's `io` contract alone, and reports the gait diagnostics of
//! `l3p eval` (tracking, height, swing and touchdowns, non-foot contact, chatter, heading change,
//! falls) with a walk verdict.
//!
//! The simulation is `deploy/examples/sim2sim.py` (MuJoCo's Python package is the field's
//! convention; it loads URDF as well as MJCF, so every catalog and added robot works without a
//! hand-made model). Both it and `numpy_policy.py` are compiled into the binary and written to a
//! temporary directory per call, so the command works from any directory. Main items:
//! [`Sim2SimArgs`], [`run_sim2sim`] (one variant, parsed JSON back), [`Variant`].

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::Context;
use clap::Args;

const SCRIPT: &str = include_str!("../../deploy/examples/sim2sim.py");
const NUMPY_POLICY: &str = include_str!("../../deploy/examples/numpy_policy.py");

/// The script's exit code when `import mujoco` fails.
const EXIT_NO_MUJOCO: i32 = 3;

#[derive(Debug, Clone, Args)]
pub struct Sim2SimArgs {
    /// A deployable policy: an export directory or file, or a registry ref `name@version|alias`
    /// read from the local registry under --data-dir.
    #[arg(long)]
    pub policy: String,
    /// The robot model: a URDF or a MuJoCo MJCF file. Default: the robot's own URDF (catalog or
    /// added robot), the one the policy trained on.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Forward speeds (m/s), one row each; lateral and yaw commands are zero.
    #[arg(long, value_delimiter = ',', num_args = 1, default_value = "0.5,1.0")]
    pub forward: Vec<f32>,
    /// Simulated seconds per episode.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f32,
    /// Episodes per speed, each from a slightly perturbed start.
    #[arg(long, default_value_t = 3)]
    pub seeds: u32,
    /// Hold the initial heading: yaw rate = clip(0.5 · heading error, ±1), as the task's heading
    /// mode (off by default: the verdict's heading bound is about walking straight unaided).
    #[arg(long)]
    pub heading_hold: bool,
    /// Physics step (s); the control period is the export's.
    #[arg(long, default_value_t = 0.005)]
    pub physics_dt: f32,
    /// Run the standard variants one after the other: the model as given, without passive joint
    /// terms, and with damping 1 N·m·s/rad + Coulomb friction 0.2 N·m on every joint (a real
    /// motor's order of magnitude), each also at 20 ms action latency and at 80% motor strength.
    #[arg(long)]
    pub variants: bool,
    /// Zero the model's passive joint damping, friction and armature.
    #[arg(long)]
    pub no_passive: bool,
    /// Passive joint damping on every policy joint (N·m·s/rad).
    #[arg(long)]
    pub joint_damping: Option<f32>,
    /// Coulomb joint friction on every policy joint (N·m).
    #[arg(long)]
    pub joint_friction: Option<f32>,
    /// Action latency (ms).
    #[arg(long)]
    pub latency_ms: Option<f32>,
    /// Motor strength (torque scale).
    #[arg(long)]
    pub motor_strength: Option<f32>,
    /// Print everything as JSON (one object per variant) instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Exit with an error when any variant's verdict fails.
    #[arg(long)]
    pub require_pass: bool,
    /// Data directory holding the registry (for registry refs).
    #[arg(long, default_value = "l3p-data")]
    pub data_dir: PathBuf,
    /// The Python interpreter (needs numpy and mujoco).
    #[arg(long, env = "L3P_PYTHON", default_value = "python3")]
    pub python: String,
    /// Further arguments for the script, after `--` (e.g. `-- --max-xy-error 0.15 --pd explicit`;
    /// `python3 deploy/examples/sim2sim.py --help` lists them).
    #[arg(last = true)]
    pub script_args: Vec<String>,
}

impl Sim2SimArgs {
    /// The walk criterion's check in MuJoCo (`l3p train --until-walks --sim2sim`): the export in
    /// `policy_dir` on its robot's own URDF, 3 × 20 s at 0.5 and 1.0 m/s, joint damping
    /// `joint_damping` (the rapier check's pin), the script's default bounds.
    pub fn walk_check(policy_dir: &Path, joint_damping: f32) -> Sim2SimArgs {
        Sim2SimArgs {
            policy: policy_dir.display().to_string(),
            model: None,
            forward: vec![0.5, 1.0],
            seconds: 20.0,
            seeds: 3,
            heading_hold: false,
            physics_dt: 0.005,
            variants: false,
            no_passive: false,
            joint_damping: Some(joint_damping),
            joint_friction: None,
            latency_ms: None,
            motor_strength: None,
            json: true,
            require_pass: false,
            data_dir: PathBuf::from("l3p-data"),
            python: python_interpreter(),
            script_args: Vec::new(),
        }
    }
}

/// One physics setting a policy is played under.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    pub no_passive: bool,
    pub joint_damping: Option<f32>,
    pub joint_friction: Option<f32>,
    pub latency_ms: Option<f32>,
    pub motor_strength: Option<f32>,
}

impl Variant {
    /// The variant the flags ask for.
    fn from_args(args: &Sim2SimArgs) -> Variant {
        Variant {
            name: "as given".into(),
            no_passive: args.no_passive,
            joint_damping: args.joint_damping,
            joint_friction: args.joint_friction,
            latency_ms: args.latency_ms,
            motor_strength: args.motor_strength,
        }
    }

    /// `--variants`: passive joint terms as the model has them, off, and a real motor's; the last
    /// two also with 20 ms of latency and with 80% motor strength.
    pub fn standard() -> Vec<Variant> {
        let plain = Variant {
            name: "model's passive terms".into(),
            no_passive: false,
            joint_damping: None,
            joint_friction: None,
            latency_ms: None,
            motor_strength: None,
        };
        let none = Variant {
            name: "no passive terms".into(),
            no_passive: true,
            ..plain.clone()
        };
        let motor = Variant {
            name: "damping 1 + friction 0.2".into(),
            joint_damping: Some(1.0),
            joint_friction: Some(0.2),
            ..plain.clone()
        };
        let mut out = vec![plain, none.clone(), motor.clone()];
        for base in [none, motor] {
            out.push(Variant {
                name: format!("{}, latency 20 ms", base.name),
                latency_ms: Some(20.0),
                ..base.clone()
            });
            out.push(Variant {
                name: format!("{}, motor strength 0.8", base.name),
                motor_strength: Some(0.8),
                ..base
            });
        }
        out
    }

    fn script_args(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.no_passive {
            out.push("--no-passive".to_string());
        }
        let mut value = |flag: &str, v: Option<f32>| {
            if let Some(v) = v {
                out.push(flag.to_string());
                out.push(v.to_string());
            }
        };
        value("--joint-damping", self.joint_damping);
        value("--joint-friction", self.joint_friction);
        value("--latency-ms", self.latency_ms);
        value("--motor-strength", self.motor_strength);
        out
    }
}

/// What one script run printed: the table (stderr with `--json -`) and its JSON.
#[derive(Debug, Clone)]
pub struct Sim2SimRun {
    pub variant: Variant,
    pub table: String,
    pub json: serde_json::Value,
}

impl Sim2SimRun {
    /// Whether every bound held (the script's `verdict.pass`).
    pub fn passed(&self) -> bool {
        self.json
            .pointer("/verdict/pass")
            .and_then(|v| v.as_bool())
            .unwrap_or(false)
    }

    /// The failing bounds as readable lines (empty: it walks); a verdict without its pass flag
    /// counts as one failure.
    pub fn failures(&self) -> Vec<String> {
        if self.passed() {
            return Vec::new();
        }
        let listed: Vec<String> = self
            .json
            .pointer("/verdict/failures")
            .and_then(|f| f.as_array())
            .map(|f| {
                f.iter()
                    .filter_map(|x| x.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default();
        if listed.is_empty() {
            vec!["sim2sim gave no verdict".into()]
        } else {
            listed
        }
    }
}

/// Where the script, the policy and the model are written for one call.
struct Workspace {
    dir: tempfile::TempDir,
    policy: PathBuf,
    model: PathBuf,
}

impl Workspace {
    fn new(args: &Sim2SimArgs) -> anyhow::Result<Workspace> {
        let dir = tempfile::Builder::new().prefix("l3p-sim2sim").tempdir()?;
        std::fs::write(dir.path().join("sim2sim.py"), SCRIPT)?;
        std::fs::write(dir.path().join("numpy_policy.py"), NUMPY_POLICY)?;
        let (bytes, policy) = crate::eval_cmd::load_policy_bytes(&args.policy, &args.data_dir)
            .with_context(|| format!("loading the policy {}", args.policy))?;
        let policy_dir = dir.path().join("policy");
        std::fs::create_dir(&policy_dir)?;
        std::fs::write(policy_dir.join("policy.safetensors"), bytes)?;
        let model = match &args.model {
            Some(m) => m
                .canonicalize()
                .with_context(|| format!("the model {}", m.display()))?,
            None => {
                let robot = l3p_robot::catalog::RobotSpec::by_name(&policy.config.robot)?;
                let path = dir.path().join(format!("{}.urdf", robot.name));
                std::fs::write(&path, robot.urdf)?;
                path
            }
        };
        Ok(Workspace {
            dir,
            policy: policy_dir,
            model,
        })
    }
}

/// Plays the policy under one variant and returns the script's table and JSON.
fn run_variant(
    args: &Sim2SimArgs,
    ws: &Workspace,
    variant: &Variant,
) -> anyhow::Result<Sim2SimRun> {
    let forward = args
        .forward
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let mut cmd = Command::new(&args.python);
    cmd.arg(ws.dir.path().join("sim2sim.py"))
        .arg(&ws.policy)
        .arg("--model")
        .arg(&ws.model)
        .args(["--forward", &forward])
        .args(["--seconds", &args.seconds.to_string()])
        .args(["--seeds", &args.seeds.to_string()])
        .args(["--physics-dt", &args.physics_dt.to_string()])
        .args(["--json", "-"]);
    if args.heading_hold {
        cmd.arg("--heading-hold");
    }
    cmd.args(variant.script_args()).args(&args.script_args);
    let out = cmd.output().map_err(|e| {
        anyhow::anyhow!(
            "cannot run {}: {e}\nhint: sim2sim needs Python 3 with numpy and mujoco \
             (pip install numpy mujoco), or --python <interpreter>",
            args.python
        )
    })?;
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    match out.status.code() {
        Some(0) | Some(1) => {}
        Some(EXIT_NO_MUJOCO) => anyhow::bail!(
            "{}\nhint: sim2sim needs the Python package mujoco: {} -m pip install mujoco",
            stderr.trim(),
            args.python
        ),
        _ => anyhow::bail!("sim2sim ({}) failed: {}", variant.name, stderr.trim()),
    }
    let json: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("sim2sim printed no JSON; its log:\n{stderr}"))?;
    Ok(Sim2SimRun {
        variant: variant.clone(),
        table: stderr,
        json,
    })
}

/// The Python interpreter sim2sim runs: `$L3P_PYTHON`, else `python3` (`--python`'s default).
pub fn python_interpreter() -> String {
    std::env::var("L3P_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Fails with the install hint unless `python` imports numpy and mujoco.
pub fn check_python(python: &str) -> anyhow::Result<()> {
    let ok = Command::new(python)
        .args(["-c", "import numpy, mujoco"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        anyhow::bail!(
            "sim2sim needs {python} with numpy and mujoco\nhint: {python} -m pip install numpy mujoco \
             (or L3P_PYTHON=<interpreter>)"
        );
    }
    Ok(())
}

/// Plays the policy under each variant (the flags' one, or the standard set with `--variants`).
pub fn run_sim2sim(args: &Sim2SimArgs) -> anyhow::Result<Vec<Sim2SimRun>> {
    let ws = Workspace::new(args)?;
    let variants = if args.variants {
        Variant::standard()
    } else {
        vec![Variant::from_args(args)]
    };
    variants.iter().map(|v| run_variant(args, &ws, v)).collect()
}

pub fn run(args: Sim2SimArgs) -> anyhow::Result<()> {
    let runs = run_sim2sim(&args)?;
    if args.json {
        let out: Vec<_> = runs
            .iter()
            .map(|r| serde_json::json!({"variant": r.variant.name, "result": r.json}))
            .collect();
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for r in &runs {
            println!("== {}", r.variant.name);
            println!("{}", r.table.trim_end());
            println!();
        }
    }
    let failed: Vec<_> = runs
        .iter()
        .filter(|r| !r.passed())
        .map(|r| r.variant.name.as_str())
        .collect();
    if args.require_pass && !failed.is_empty() {
        anyhow::bail!("the walk verdict fails in MuJoCo: {}", failed.join("; "));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_variants_cover_passive_terms_latency_and_strength() {
        let v = Variant::standard();
        assert_eq!(v.len(), 7);
        assert!(v.iter().any(|v| v.no_passive && v.latency_ms == Some(20.0)));
        assert!(
            v.iter()
                .any(|v| v.joint_damping == Some(1.0) && v.motor_strength == Some(0.8))
        );
        assert_eq!(
            v[2].script_args(),
            ["--joint-damping", "1", "--joint-friction", "0.2"]
        );
        assert_eq!(v[1].script_args(), ["--no-passive"]);
    }

    fn run_with(json: serde_json::Value) -> Sim2SimRun {
        Sim2SimRun {
            variant: Variant::standard().remove(0),
            table: String::new(),
            json,
        }
    }

    #[test]
    fn the_verdict_decides_and_a_missing_one_fails() {
        let pass = run_with(serde_json::json!({"verdict": {"pass": true, "failures": []}}));
        assert!(pass.passed() && pass.failures().is_empty());
        let fail = run_with(serde_json::json!({"verdict": {
            "pass": false,
            "failures": ["1.00 m/s: heading change 43 > 15 deg"]
        }}));
        assert!(!fail.passed());
        assert_eq!(fail.failures(), ["1.00 m/s: heading change 43 > 15 deg"]);
        let garbled = run_with(serde_json::json!({"commands": []}));
        assert_eq!(garbled.failures(), ["sim2sim gave no verdict"]);
    }
}
