//! `l3p-deploy`, the binary, end to end: against a stand-in robot on loopback Zenoh it runs the
//! trained A1 policy through the start-up sequence (zero torque → ramp → policy → damping on stop)
//! and prints its final status; off loopback without mutual TLS it refuses to start, as `l3p deploy`
//! does (`cli/tests/deploy.rs` runs the same checks on `l3p deploy` with the simulator as the robot).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_proto::{ControlMode, DeployStatus, RobotCommand, codec, keys};
use l3p_robot::catalog::RobotSpec;

fn trained_policy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs/a1-flat-session31/policy/policy.safetensors")
}

fn lean() -> Command {
    Command::new(env!("CARGO_BIN_EXE_l3p-deploy"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_lean_binary_runs_a_policy_through_start_up_and_stops_through_damping() {
    let dir = tempfile::tempdir().unwrap();
    // A file of `l3p`'s config: the sections the controller does not read are accepted unread.
    let config = dir.path().join("deploy.toml");
    std::fs::write(
        &config,
        "[run]\nname = \"lean\"\n[deploy]\nstale_periods = 10.0\nzero_torque_s = 0.2\nramp_s = 0.5\n\
         stop_damping_s = 0.5\n",
    )
    .unwrap();
    let port = free_loopback_port().unwrap();
    let stderr = std::fs::File::create(dir.path().join("deploy.log")).unwrap();
    let policy = trained_policy();
    let mut child = lean()
        .args(["--robot", "a1", "--robot-id", "lean-dog", "--duration", "6"])
        .arg("--policy")
        .arg(&policy)
        .arg("--config")
        .arg(&config)
        .args(["--listen", &format!("tcp/127.0.0.1:{port}")])
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap();

    // The stand-in robot: a standing A1 at 50 Hz; it records the controller's command modes.
    let io = l3p_deploy::read_policy_file(&policy, RobotSpec::by_name("a1").unwrap())
        .unwrap()
        .io;
    let mut settings = ZenohSettings::loopback(None, &[port]);
    settings.connect_retry_s = 20;
    let session = open_session(&settings).await.unwrap();
    let modes = Arc::new(Mutex::new(Vec::<ControlMode>::new()));
    let seen = modes.clone();
    let _commands = session
        .declare_subscriber(keys::robot_command("lean-dog"))
        .callback(move |s| {
            let cmd: RobotCommand = codec::decode(&s.payload().to_bytes()).unwrap();
            let mut modes = seen.lock().unwrap();
            if modes.last() != Some(&cmd.mode) {
                modes.push(cmd.mode);
            }
        })
        .await
        .unwrap();
    let publisher = session
        .declare_publisher(keys::robot_state("lean-dog"))
        .await
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut state = l3p_deploy::observation::standing_state(&io, "lean-dog");
    let exit = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "l3p-deploy did not stop after --duration 6: {}",
            std::fs::read_to_string(dir.path().join("deploy.log")).unwrap_or_default()
        );
        state.seq += 1;
        state.stamp_ns = l3p_deploy::latest::now_unix_ns();
        publisher.put(codec::encode(&state).unwrap()).await.unwrap();
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    let log = std::fs::read_to_string(dir.path().join("deploy.log")).unwrap_or_default();
    assert!(exit.success(), "{exit}: {log}");
    let mut stdout = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut stdout).unwrap();
    let status: DeployStatus = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(
        (status.robot.as_str(), status.robot_id.as_str()),
        ("a1", "lean-dog")
    );
    assert_eq!(status.mode, ControlMode::Damping, "stops through damping");
    assert_eq!(
        *modes.lock().unwrap(),
        [
            ControlMode::ZeroTorque,
            ControlMode::Ramp,
            ControlMode::Policy,
            ControlMode::Damping
        ],
        "{log}"
    );
    let _ = session.close().await;
}

/// Off loopback without mutual TLS `l3p-deploy` refuses to start before it reads the policy;
/// `--insecure` gets it past that check with a warning (here it then fails on the policy file).
#[test]
fn the_lean_binary_refuses_unauthenticated_links_off_loopback_unless_insecure() {
    let dir = tempfile::tempdir().unwrap();
    let policy = dir.path().join("policy.safetensors");
    std::fs::write(&policy, b"not a policy").unwrap();
    let listen = format!("tcp/0.0.0.0:{}", free_loopback_port().unwrap());
    let deploy = |extra: &[&str]| {
        let out = lean()
            .args(["--robot", "a1", "--robot-id", "dog", "--listen", &listen])
            .arg("--policy")
            .arg(&policy)
            .args(extra)
            .output()
            .unwrap();
        (
            out.status,
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let policy_name = policy.display().to_string();

    let (status, stderr) = deploy(&[]);
    assert!(!status.success(), "{stderr}");
    assert!(
        stderr.contains("refusing to command a robot over unauthenticated links")
            && stderr.contains(&listen)
            && stderr.contains("--insecure")
            && !stderr.contains(&policy_name),
        "{stderr}"
    );

    let (status, stderr) = deploy(&["--insecure"]);
    assert!(!status.success(), "{stderr}");
    assert!(
        !stderr.contains("refusing")
            && stderr.contains("--insecure:")
            && stderr.contains(&policy_name)
            && !stderr.contains("panicked"),
        "{stderr}"
    );
}

/// A robot added with `l3p robots add` (here: A1's URDF and catalog values under another name, in
/// the config's `[run] data_dir`) is known to the lean binary, which has no simulator: it gets as
/// far as refusing the A1 policy for that robot.
#[test]
fn the_lean_binary_knows_robots_added_under_the_configs_data_dir() {
    let dir = tempfile::tempdir().unwrap();
    let robots = dir.path().join("data").join("robots");
    std::fs::create_dir_all(&robots).unwrap();
    let a1 = RobotSpec::by_name("a1").unwrap();
    let urdf = a1.urdf.replacen("name=\"a1\"", "name=\"lean_quad\"", 1);
    std::fs::write(robots.join("lean_quad.urdf"), urdf).unwrap();
    let strings = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let description = l3p_robot::added::RobotDescription {
        name: "lean_quad".into(),
        display_name: "A1 under another name".into(),
        urdf: "lean_quad.urdf".into(),
        joint_names: a1.joint_names.map(str::to_string),
        axis_signs: [1.0; 12],
        default_pose: a1.default_pose,
        base_link: a1.base_link.into(),
        foot_links: a1.foot_links.map(str::to_string),
        penalised_links: strings(a1.penalised_links),
        termination_links: strings(a1.termination_links),
        kp: a1.training_gains.kp,
        kd: a1.training_gains.kd,
        effort_limit: a1.effort_limit,
        velocity_limit: a1.velocity_limit,
        action_scale: a1.action_scale,
        spawn_height: a1.spawn_height,
        mass: a1.published_mass,
        mesh_hulls: Vec::new(),
    };
    std::fs::write(robots.join("lean_quad.toml"), description.to_toml()).unwrap();
    let config = dir.path().join("deploy.toml");
    std::fs::write(
        &config,
        format!("[run]\ndata_dir = {:?}\n", dir.path().join("data")),
    )
    .unwrap();
    let port = free_loopback_port().unwrap();
    let out = lean()
        .args(["--robot", "lean_quad", "--robot-id", "dog"])
        .arg("--policy")
        .arg(trained_policy())
        .arg("--config")
        .arg(&config)
        .args(["--listen", &format!("tcp/127.0.0.1:{port}")])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("this robot is lean_quad") && !stderr.contains("unknown robot"),
        "{stderr}"
    );
}
