//! Deploy end to end over real processes on loopback Zenoh: `l3p registry serve`, `l3p sim-robot`
//! and `l3p deploy`. A policy trained by `l3p train configs/a1-flat.toml --until-walks` (session 13:
//! 20 ms physics, seed 2, meets the walk criterion in 5 ms physics at iteration 140; exported under
//! docs/a1-flat-session31/policy) walks the simulated A1, stepping at 5 ms, at a normal height; when
//! the state stream stops the controller damps within 3 periods and stays damped until `l3p operate resume`; a NaN-producing policy is damped;
//! a policy for another robot is refused before any command is sent.

mod common;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{Procs, deploy_endpoint, log_tails, wait_for_port};
use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_proto::{ControlMode, DeployStatus, RobotCommand, codec, keys};

/// `[deploy] stale_periods` of the walking test's controller.
const STALE_PERIODS: f64 = 10.0;

/// A `[deploy]` config with a staleness bound of [`STALE_PERIODS`] (200 ms) instead of the default
/// 3: on a loaded machine a state can arrive 60-70 ms late, and the controller then rightly damps
/// before what a test measures. The rules under test are the same, counted in these periods.
fn tolerant_deploy_config(dir: &Path) -> PathBuf {
    let config = dir.join("deploy.toml");
    std::fs::write(
        &config,
        format!("[deploy]\nstale_periods = {STALE_PERIODS:.1}\n"),
    )
    .unwrap();
    config
}

fn trained_policy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs/a1-flat-session31/policy/policy.safetensors")
}

/// What the test saw on the robot's keys, in arrival order.
#[derive(Debug, Clone, PartialEq)]
enum Seen {
    State,
    Command(ControlMode),
}

struct Tap {
    events: Arc<Mutex<Vec<(Instant, Seen)>>>,
    status: Arc<Mutex<Option<DeployStatus>>>,
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl Tap {
    async fn new(session: &zenoh::Session, robot_id: &str) -> Self {
        let events = Arc::new(Mutex::new(Vec::new()));
        let status = Arc::new(Mutex::new(None));
        let e1 = events.clone();
        let state = session
            .declare_subscriber(keys::robot_state(robot_id))
            .callback(move |_| e1.lock().unwrap().push((Instant::now(), Seen::State)))
            .await
            .unwrap();
        let e2 = events.clone();
        let command = session
            .declare_subscriber(keys::robot_command(robot_id))
            .callback(move |s| {
                let cmd: RobotCommand = codec::decode(&s.payload().to_bytes()).unwrap();
                e2.lock()
                    .unwrap()
                    .push((Instant::now(), Seen::Command(cmd.mode)));
            })
            .await
            .unwrap();
        let st = status.clone();
        let status_sub = session
            .declare_subscriber(keys::robot_deploy_status(robot_id))
            .callback(move |s| {
                *st.lock().unwrap() = codec::decode_json(&s.payload().to_bytes()).ok();
            })
            .await
            .unwrap();
        Self {
            events,
            status,
            _subs: vec![state, command, status_sub],
        }
    }

    /// Waits until the controller's status reaches the tap (it publishes one every second).
    async fn wait_for_route(&self, dir: &Path) {
        self.wait_for(
            "the controller's status",
            Duration::from_secs(20),
            dir,
            |t| t.status().is_some(),
        )
        .await;
    }

    fn events(&self) -> Vec<(Instant, Seen)> {
        self.events.lock().unwrap().clone()
    }

    fn commands_since(&self, t: Instant) -> Vec<ControlMode> {
        self.events()
            .into_iter()
            .filter_map(|(at, e)| match e {
                Seen::Command(m) if at >= t => Some(m),
                _ => None,
            })
            .collect()
    }

    fn status(&self) -> Option<DeployStatus> {
        self.status.lock().unwrap().clone()
    }

    async fn wait_for(
        &self,
        what: &str,
        timeout: Duration,
        dir: &Path,
        pred: impl Fn(&Self) -> bool,
    ) {
        let deadline = Instant::now() + timeout;
        while !pred(self) {
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}; status {:?}{}",
                self.status(),
                log_tails(dir)
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
}

fn l3p(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .output()
        .unwrap()
}

/// Registry service on a fresh port with `policy` stored as `<name>` (kind deploy, robot a1).
fn start_registry(procs: &mut Procs, dir: &Path, artifacts: &[(&str, &Path)]) -> String {
    let port = free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    // Stored before the service starts: direct database access, no race with its start-up.
    for (name, file) in artifacts {
        let out = l3p(&[
            "registry",
            "put",
            file.to_str().unwrap(),
            "--name",
            name,
            "--kind",
            "deploy",
            "--robot",
            "a1",
            "--data",
            dir.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            dir.to_str().unwrap(),
            "--listen",
            &endpoint,
        ],
        dir,
    );
    endpoint
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trained_policy_walks_the_sim_robot_and_stale_state_damps_until_resume() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut procs = Procs(Vec::new());
    let endpoint = start_registry(&mut procs, d, &[("a1-walk", &trained_policy())]);
    let port: u16 = endpoint.rsplit(':').next().unwrap().parse().unwrap();
    // The controller listens (nothing listens unless told to); the robot, the operator and this
    // test connect to it.
    let (deploy_port, deploy_ep) = deploy_endpoint(port);
    let config = tolerant_deploy_config(d);
    procs.spawn(
        "deploy",
        &[
            "deploy",
            "--robot",
            "a1",
            "--robot-id",
            "dog",
            "--policy",
            "a1-walk@latest",
            "--config",
            config.to_str().unwrap(),
            "--connect",
            &endpoint,
            "--listen",
            &deploy_ep,
        ],
        d,
    );
    wait_for_port(deploy_port, Duration::from_secs(60), "the controller", d);
    let session = open_session(&ZenohSettings::loopback(None, &[port, deploy_port]))
        .await
        .unwrap();
    let tap = Tap::new(&session, "dog").await;
    // The controller publishes its status every second from its first tick: once the tap has one,
    // the route from the controller to the tap is live (no guessed propagation delay).
    tap.wait_for_route(d).await;

    let sim_args = [
        "sim-robot",
        "--robot",
        "a1",
        "--robot-id",
        "dog",
        "--command",
        "0.5,0,0",
        "--duration",
        "12",
        "--connect",
        &deploy_ep,
    ];
    procs.spawn_split("sim", &sim_args, d);

    // The sim-robot runs 12 s of wall-clock and exits (on a loaded machine it steps slower than
    // real time: 12 s leaves ≥ 4 s under the policy after zero-torque and the ramp); its summary
    // says how the robot moved under the policy.
    let exit = tokio::task::block_in_place(|| procs.wait_exit("sim", Duration::from_secs(60)));
    assert!(
        exit.is_some_and(|s| s.success()),
        "sim-robot failed{}",
        log_tails(d)
    );
    let summary: serde_json::Value =
        serde_json::from_str(std::fs::read_to_string(d.join("sim.out")).unwrap().trim()).unwrap();
    let f = |k: &str| {
        summary[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} in {summary}"))
    };
    assert!(
        f("policy_seconds") >= 4.0,
        "too little time under the policy: {summary}{}",
        log_tails(d)
    );
    eprintln!("sim-robot summary: {summary}");
    // A normal-height trot (≈ 85% of the 0.30 m nominal in l3p eval); the session-1 policy it
    // replaced walked crouched at 0.14 m. Falling puts the trunk on the ground (≈ 0.06 m).
    assert!(
        f("policy_min_base_height") > 0.75 * f("nominal_base_height"),
        "the robot did not stay up: {summary}"
    );
    assert!(f("policy_max_tilt_deg") < 30.0, "{summary}");
    let forward = summary["policy_displacement"][0].as_f64().unwrap();
    assert!(
        forward > 0.6 * 0.5 * f("policy_seconds"),
        "did not walk forward at the 0.5 m/s command: {summary}"
    );
    assert_eq!(f("commands_rejected"), 0.0);

    // The state stream stopped with the sim-robot: damping within STALE_PERIODS periods (at most
    // that many policy commands after the last state), then the fault is reported.
    let last_state = tap
        .events()
        .iter()
        .rev()
        .find(|(_, e)| *e == Seen::State)
        .map(|(t, _)| *t)
        .unwrap();
    tap.wait_for(
        "damping after the state stopped",
        Duration::from_secs(10),
        d,
        |t| t.commands_since(last_state).contains(&ControlMode::Damping),
    )
    .await;
    let after = tap.commands_since(last_state);
    let first_damping = after
        .iter()
        .position(|m| *m == ControlMode::Damping)
        .unwrap();
    assert!(
        after[..first_damping]
            .iter()
            .all(|m| *m == ControlMode::Policy)
            && first_damping <= STALE_PERIODS as usize + 1,
        "commands after the last state: {after:?}"
    );
    // No wall-clock bound: the count above (at most STALE_PERIODS policy periods, then damping)
    // is the timing rule, and it holds on a slow machine too.
    let damping_at = tap
        .events()
        .into_iter()
        .find(|(t, e)| *t >= last_state && *e == Seen::Command(ControlMode::Damping))
        .unwrap()
        .0;
    tap.wait_for(
        "the stale-state fault in the status",
        Duration::from_secs(5),
        d,
        |t| {
            t.status()
                .is_some_and(|s| s.fault.is_some_and(|f| f.contains("stale")))
        },
    )
    .await;

    // States come back: still damping (latched) ...
    procs.spawn_split("sim2", &sim_args, d);
    tap.wait_for("states again", Duration::from_secs(20), d, |t| {
        t.events()
            .iter()
            .any(|(at, e)| *at > damping_at && *e == Seen::State)
    })
    .await;
    let back = Instant::now();
    // Count commands rather than sleep: a slow machine sends them later, not differently.
    tap.wait_for(
        "11 commands after the states came back",
        Duration::from_secs(20),
        d,
        |t| t.commands_since(back).len() > 10,
    )
    .await;
    let latched = tap.commands_since(back);
    assert!(
        latched.iter().all(|m| *m == ControlMode::Damping),
        "{latched:?}"
    );
    // ... until the operator resumes: ramp, then policy.
    let resumed = Instant::now();
    let out = tokio::task::block_in_place(|| {
        l3p(&[
            "operate",
            "--robot-id",
            "dog",
            "resume",
            "--connect",
            &deploy_ep,
        ])
    });
    assert!(
        out.status.success(),
        "operate: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    tap.wait_for("policy after resume", Duration::from_secs(10), d, |t| {
        t.commands_since(resumed).contains(&ControlMode::Policy)
    })
    .await;
    let modes = tap.commands_since(resumed);
    let first_ramp = modes.iter().position(|m| *m == ControlMode::Ramp).unwrap();
    let first_policy = modes
        .iter()
        .position(|m| *m == ControlMode::Policy)
        .unwrap();
    assert!(first_ramp < first_policy, "{modes:?}");
}

/// A copy of the trained export whose first encoder and first core layers are scaled by 1e30: finite
/// weights (so the file loads) whose activations overflow to ±inf and then NaN.
fn nan_policy(dir: &Path) -> PathBuf {
    use safetensors::SafeTensors;
    let bytes = std::fs::read(trained_policy()).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let (_, meta) = SafeTensors::read_metadata(&bytes).unwrap();
    let mut data: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    for (name, view) in st.tensors() {
        let mut raw = view.data().to_vec();
        if name == "encoder.0.weight" || name == "core.0.weight" {
            for c in raw.chunks_exact_mut(4) {
                let v = f32::from_le_bytes([c[0], c[1], c[2], c[3]]) * 1e30;
                c.copy_from_slice(&v.to_le_bytes());
            }
        }
        data.push((name, raw, view.shape().to_vec()));
    }
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = data
        .iter()
        .map(|(n, b, s)| {
            let v = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b);
            (n.clone(), v.unwrap())
        })
        .collect();
    let out = safetensors::serialize(views, meta.metadata().clone()).unwrap();
    let path = dir.join("nan.safetensors");
    std::fs::write(&path, out).unwrap();
    path
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nan_policy_is_damped_and_wrong_robot_is_refused_before_any_command() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let nan = nan_policy(d);
    let mut procs = Procs(Vec::new());
    let endpoint = start_registry(
        &mut procs,
        d,
        &[("a1-walk", &trained_policy()), ("a1-nan", &nan)],
    );
    let port: u16 = endpoint.rsplit(':').next().unwrap().parse().unwrap();
    let session = open_session(&ZenohSettings::loopback(None, &[port]))
        .await
        .unwrap();
    let wrong = Tap::new(&session, "other").await;
    // Nothing will publish on these keys, so there is no route to wait for: this settling time and
    // the 300 ms window below can only make the "nothing published" check pass vacuously on a slow
    // machine, never fail it.
    tokio::time::sleep(Duration::from_millis(500)).await;

    // An A1 policy on a Go1: refused, nothing published.
    let out = tokio::task::block_in_place(|| {
        l3p(&[
            "deploy",
            "--robot",
            "go1",
            "--robot-id",
            "other",
            "--policy",
            "a1-walk@latest",
            "--connect",
            &endpoint,
        ])
    });
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("policy for a1") && stderr.contains("go1"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(wrong.events().is_empty(), "{:?}", wrong.events());

    // The NaN policy: start-up as usual, then damping on its first policy tick.
    let (deploy_port, deploy_ep) = deploy_endpoint(port);
    let nan_config = tolerant_deploy_config(d);
    procs.spawn(
        "deploy",
        &[
            "deploy",
            "--robot",
            "a1",
            "--robot-id",
            "pup",
            "--policy",
            "a1-nan@latest",
            "--config",
            nan_config.to_str().unwrap(),
            "--connect",
            &endpoint,
            "--listen",
            &deploy_ep,
        ],
        d,
    );
    wait_for_port(deploy_port, Duration::from_secs(60), "the controller", d);
    let robot_side = open_session(&ZenohSettings::loopback(None, &[deploy_port]))
        .await
        .unwrap();
    let tap = Tap::new(&robot_side, "pup").await;
    tap.wait_for_route(d).await;
    procs.spawn(
        "sim",
        &[
            "sim-robot",
            "--robot",
            "a1",
            "--robot-id",
            "pup",
            "--connect",
            &deploy_ep,
        ],
        d,
    );
    let start = Instant::now();
    tap.wait_for(
        "damping from the NaN policy",
        Duration::from_secs(30),
        d,
        |t| t.commands_since(start).contains(&ControlMode::Damping),
    )
    .await;
    let modes = tap.commands_since(start);
    assert!(modes.contains(&ControlMode::Ramp), "{modes:?}");
    assert!(
        !modes.contains(&ControlMode::Policy),
        "a NaN policy command went out: {modes:?}"
    );
    tap.wait_for(
        "the non-finite fault in the status",
        Duration::from_secs(5),
        d,
        |t| {
            t.status()
                .is_some_and(|s| s.fault.is_some_and(|f| f.contains("non-finite")))
        },
    )
    .await;
}

/// Off loopback without mutual TLS `l3p deploy` refuses to start, before it opens a session or reads
/// a policy; `--insecure` gets it past that check with a warning (here it then fails on the policy
/// file, as it would on loopback).
#[test]
fn deploy_refuses_unauthenticated_links_off_loopback_unless_insecure() {
    let dir = tempfile::tempdir().unwrap();
    let policy = dir.path().join("policy.safetensors");
    std::fs::write(&policy, b"not a policy").unwrap();
    let policy = policy.display().to_string();
    // Every interface: reachable from the network.
    let listen = format!("tcp/0.0.0.0:{}", free_loopback_port().unwrap());
    let deploy = |extra: &[&str]| {
        let mut args = vec![
            "deploy",
            "--robot",
            "a1",
            "--robot-id",
            "dog",
            "--policy",
            &policy,
            "--listen",
            &listen,
        ];
        args.extend_from_slice(extra);
        let out = l3p(&args);
        (
            out.status,
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };

    let (status, stderr) = deploy(&[]);
    assert!(!status.success(), "{stderr}");
    assert!(
        stderr.contains("refusing to command a robot over unauthenticated links")
            && stderr.contains(&listen)
            && stderr.contains("--insecure"),
        "{stderr}"
    );
    assert!(
        !stderr.contains(&policy),
        "refused before the policy is read: {stderr}"
    );

    let (status, stderr) = deploy(&["--insecure"]);
    assert!(!status.success(), "{stderr}");
    assert!(!stderr.contains("refusing"), "{stderr}");
    assert!(
        stderr.contains("--insecure:") && stderr.contains(&listen),
        "{stderr}"
    );
    assert!(
        stderr.contains(&policy),
        "the policy file is what fails: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// `l3p-deploy` (the lean binary, `deploy-bin/`) takes exactly the flags of `l3p deploy` and reads
/// the same `[zenoh]` and `[deploy]` from a config file with the same flags: the robot runs what was
/// rehearsed with `l3p deploy`. (Its behaviour end to end: `deploy-bin/tests/lean.rs`.)
#[test]
fn the_lean_binary_takes_the_flags_and_settings_of_l3p_deploy() {
    use clap::{Args, CommandFactory};
    let longs = |cmd: &clap::Command| -> std::collections::BTreeSet<String> {
        cmd.get_arguments()
            .filter_map(|a| a.get_long())
            .filter(|l| !["help", "version", "verbose"].contains(l))
            .map(str::to_string)
            .collect()
    };
    let l3p = l3p_cli::deploy_cmd::DeployArgs::augment_args(clap::Command::new("deploy"));
    let lean = l3p_deploy_bin::Cli::command();
    assert_eq!(longs(&l3p), longs(&lean));
    // clap's own checks (unique ids and groups), which a parse in a debug build would run
    l3p.clone().debug_assert();
    lean.clone().debug_assert();
    assert!(
        lean.get_arguments()
            .any(|a| a.get_long() == Some("verbose"))
    );

    let reference = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/reference.toml");
    let connect = vec!["tcp/127.0.0.1:7999".to_string()];
    let (config, zenoh) = l3p_cli::runtime::NetArgs {
        config: Some(reference.clone()),
        connect: connect.clone(),
        listen: Vec::new(),
    }
    .load()
    .unwrap();
    let (safety, lean_zenoh) = l3p_deploy_bin::NetFlags {
        config: Some(reference),
        connect,
        listen: Vec::new(),
    }
    .load()
    .unwrap();
    assert_eq!((safety, lean_zenoh), (config.deploy, zenoh));
}
