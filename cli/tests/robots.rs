//! `l3p robots add` through the binary: a user's URDF becomes a robot file that `robots list`,
//! `robots check` and a training config know by name; adding it twice needs `--replace`; a file
//! that is not a quadruped is a clear error. `l3p transfer` fine-tunes a registry checkpoint on
//! it with the core frozen, and the registry records where the new policy came from; a policy
//! trained for an added robot deploys to a simulated one through `l3p deploy` and `l3p sim-robot`.

use std::path::Path;
use std::process::Command;

mod common;
use common::{Procs, TINY_FLAT_TASK, deploy_endpoint, log_tails, wait_for_port};

fn l3p(args: &[&str], cwd: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .current_dir(cwd)
        .env_remove("L3P_ROBOTS_DIR")
        .output()
        .unwrap();
    (
        out.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
    )
}

#[test]
fn an_added_urdf_is_listed_checked_and_trainable_by_name() {
    let dir = std::env::temp_dir().join(format!("l3p-robots-add-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A1's own URDF under a user's name.
    let urdf = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .replacen("name=\"a1\"", "name=\"Lab Dog\"", 1);
    std::fs::write(dir.join("lab_dog.urdf"), urdf).unwrap();

    let (ok, out) = l3p(&["robots", "add", "lab_dog.urdf"], &dir);
    assert!(ok, "{out}");
    assert!(
        out.contains("FL_calf_joint") && out.contains("stands:"),
        "{out}"
    );
    let file = dir.join("l3p-data/robots/lab_dog.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(
        text.contains("name = \"lab_dog\"") && text.contains("kp = "),
        "{text}"
    );
    assert!(dir.join("l3p-data/robots/lab_dog.urdf").exists());

    let (ok, out) = l3p(&["robots", "add", "lab_dog.urdf"], &dir);
    assert!(!ok && out.contains("--replace"), "{out}");
    let (ok, out) = l3p(
        &["robots", "add", "lab_dog.urdf", "--replace", "--kp", "70"],
        &dir,
    );
    assert!(ok, "{out}");
    assert!(std::fs::read_to_string(&file).unwrap().contains("kp = 70"));

    let (ok, out) = l3p(&["robots", "list"], &dir);
    assert!(ok && out.contains("lab_dog"), "{out}");
    let (ok, out) = l3p(&["robots", "check", "lab_dog", "--training-gains"], &dir);
    assert!(ok && out.contains("settled base height"), "{out}");

    // A training config names it like a built-in robot.
    let config =
        "[run]\nname = \"dog\"\n\n[[actors]]\nrobot = \"lab_dog\"\nenvs = 4\nthreads = 1\n";
    std::fs::write(dir.join("dog.toml"), config).unwrap();
    let (ok, out) = l3p(&["config", "dog.toml"], &dir);
    assert!(ok, "{out}");
    let unknown = config.replace("lab_dog", "lab_cat");
    std::fs::write(dir.join("cat.toml"), unknown).unwrap();
    let (ok, out) = l3p(&["config", "cat.toml"], &dir);
    assert!(
        !ok && out.contains("lab_cat") && out.contains("lab_dog"),
        "{out}"
    );

    // Not a quadruped: refused, naming why, nothing written.
    std::fs::write(
        dir.join("stick.urdf"),
        "<robot name=\"stick\"><link name=\"base\"/></robot>",
    )
    .unwrap();
    let (ok, out) = l3p(&["robots", "add", "stick.urdf"], &dir);
    assert!(!ok && !out.contains("panicked"), "{out}");
    assert!(!dir.join("l3p-data/robots/stick.toml").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn transfer_fine_tunes_a_registry_checkpoint_on_an_added_robot_with_lineage() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    let urdf = l3p_robot::catalog::RobotSpec::by_name("go1")
        .unwrap()
        .urdf
        .replacen("name=\"go1\"", "name=\"field_dog\"", 1);
    std::fs::write(cwd.join("field_dog.urdf"), urdf).unwrap();
    let (ok, out) = l3p(&["robots", "add", "field_dog.urdf"], cwd);
    assert!(ok, "{out}");
    // Pretrain a (tiny) A1 policy; its checkpoint goes to the registry under l3p-data.
    let base = format!("[run]\nname = \"pre\"\n{TINY_FLAT_TASK}")
        + "[learner]\nmax_iterations = 2\n[rollout]\nsteps_per_env = 8\n[[actors]]\nrobot = \"a1\"\nenvs = 4\nthreads = 1\n";
    std::fs::write(cwd.join("base.toml"), base).unwrap();
    let (ok, out) = l3p(&["train", "base.toml", "--quiet"], cwd);
    assert!(ok, "{out}");
    let (ok, out) = l3p(
        &[
            "transfer",
            "--robot",
            "field_dog",
            "--from",
            "pre-checkpoint@latest",
            "--config",
            "base.toml",
            "--iterations",
            "2",
            "--quiet",
        ],
        cwd,
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("l3p-transfer") && out.contains("stopped at iteration 2"),
        "{out}"
    );
    let written =
        std::fs::read_to_string(cwd.join("l3p-data/field_dog-transfer/transfer.toml")).unwrap();
    assert!(
        written.contains("mode = \"l3p-transfer\"") && written.contains("robot = \"field_dog\""),
        "{written}"
    );
    let (ok, out) = l3p(
        &[
            "registry",
            "lineage",
            "field_dog-transfer-field_dog@latest",
            "--data",
            "l3p-data",
        ],
        cwd,
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("--from_checkpoint--> pre-checkpoint@"),
        "{out}"
    );
    // A deploy artifact is not a checkpoint to start from.
    let (ok, out) = l3p(
        &[
            "transfer",
            "--robot",
            "go1",
            "--from",
            "pre-a1@latest",
            "--config",
            "base.toml",
        ],
        cwd,
    );
    assert!(!ok && out.contains("checkpoint"), "{out}");
}

/// `l3p robots add` also stores the robot in the data directory's registry; an actor on another
/// machine (another data directory, no robot files) that is asked for it fetches it from the
/// registry over Zenoh and simulates it. A robot nobody added is a clear error naming both places.
#[test]
fn an_actor_elsewhere_fetches_an_added_robot_from_the_registry() {
    let dir = tempfile::tempdir().unwrap();
    let home = dir.path().join("home");
    let far = dir.path().join("far");
    std::fs::create_dir_all(&home).unwrap();
    std::fs::create_dir_all(&far).unwrap();
    let urdf = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .replacen("name=\"a1\"", "name=\"Yard Dog\"", 1);
    std::fs::write(home.join("yard_dog.urdf"), urdf).unwrap();
    let (ok, out) = l3p(&["robots", "add", "yard_dog.urdf"], &home);
    assert!(ok && out.contains("registry: robot-yard_dog@1"), "{out}");

    let port = l3p_net::free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let logs = dir.path();
    let mut procs = Procs(Vec::new());
    let data = home.join("l3p-data");
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            data.to_str().unwrap(),
            "--listen",
            &endpoint,
        ],
        logs,
    );
    wait_for_port(
        port,
        std::time::Duration::from_secs(60),
        "the registry",
        logs,
    );

    let far_data = far.join("l3p-data");
    let config = far.join("actor.toml");
    std::fs::write(
        &config,
        format!(
            "[run]\nname = \"far\"\ndata_dir = \"{}\"\n{TINY_FLAT_TASK}",
            far_data.display()
        ),
    )
    .unwrap();
    let actor_args = |robot: &'static str| {
        vec![
            "actor".to_string(),
            "--config".into(),
            config.to_str().unwrap().into(),
            "--robot".into(),
            robot.into(),
            "--envs".into(),
            "2".into(),
            "--connect".into(),
            endpoint.clone(),
        ]
    };
    let args = actor_args("yard_dog");
    procs.spawn(
        "actor",
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        logs,
    );
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    loop {
        let log = std::fs::read_to_string(logs.join("actor.log")).unwrap_or_default();
        if log.contains("waiting for a policy") {
            assert!(log.contains("robot fetched from the registry"), "{log}");
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the actor never got ready{}",
            log_tails(logs)
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    procs.kill("actor");
    let fetched = std::fs::read_to_string(far_data.join("robots/yard_dog.toml")).unwrap();
    let added = std::fs::read_to_string(data.join("robots/yard_dog.toml")).unwrap();
    assert_eq!(fetched, added);

    let args = actor_args("yard_cat");
    procs.spawn(
        "stray",
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        logs,
    );
    let status = procs
        .wait_exit("stray", std::time::Duration::from_secs(120))
        .expect("an actor for an unknown robot exits");
    assert!(!status.success());
    let log = std::fs::read_to_string(logs.join("stray.log")).unwrap();
    assert!(
        log.contains("yard_cat") && log.contains("robot-yard_cat@latest"),
        "{log}"
    );
}

/// Binary STL of the box with half extents `h`: 12 triangles (normals left zero).
fn box_stl(h: [f32; 3]) -> Vec<u8> {
    let corner = |i: usize| [0, 1, 2].map(|a| if (i >> a) & 1 == 0 { -h[a] } else { h[a] });
    let faces = [
        [0, 2, 6, 4],
        [1, 5, 7, 3],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 1, 3, 2],
        [4, 6, 7, 5],
    ];
    let mut out = vec![b' '; 80];
    out.extend(12u32.to_le_bytes());
    for f in faces {
        for t in [[f[0], f[1], f[2]], [f[0], f[2], f[3]]] {
            out.extend([0u8; 12]);
            for c in t.map(corner).as_flattened() {
                out.extend(c.to_le_bytes());
            }
            out.extend([0u8; 2]);
        }
    }
    out
}

/// `l3p robots add` on a URDF whose calves are STL meshes records their hulls in the description;
/// the robot registered from it — `robots check` in a new process, and the registry artifact an
/// actor elsewhere installs — has the hulls with the mesh files gone.
#[test]
fn an_added_robots_mesh_hulls_travel_in_its_description_and_registry_artifact() {
    let dir = tempfile::tempdir().unwrap();
    let home = dir.path().join("home");
    let capsule = r#"<geometry><capsule radius="0.012" length="0.176"/></geometry>"#;
    let urdf = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .replacen("name=\"a1\"", "name=\"Hull Dog\"", 1)
        .replace(
            capsule,
            r#"<geometry><mesh filename="../meshes/calf.stl" scale="0.001 0.001 0.001"/></geometry>"#,
        );
    let package = home.join("hull_dog_description");
    std::fs::create_dir_all(package.join("urdf")).unwrap();
    std::fs::create_dir_all(package.join("meshes")).unwrap();
    std::fs::write(package.join("urdf/hull_dog.urdf"), urdf).unwrap();
    // The calf capsule's straight part as a box in millimetres.
    std::fs::write(package.join("meshes/calf.stl"), box_stl([12.0, 12.0, 88.0])).unwrap();

    let (ok, out) = l3p(
        &["robots", "add", "hull_dog_description/urdf/hull_dog.urdf"],
        &home,
    );
    assert!(ok, "{out}");
    assert!(out.contains("../meshes/calf.stl (8 points)"), "{out}");
    let text = std::fs::read_to_string(home.join("l3p-data/robots/hull_dog.toml")).unwrap();
    assert!(
        text.contains("[[mesh_hulls]]") && text.contains("file = \"../meshes/calf.stl\""),
        "{text}"
    );
    std::fs::remove_dir_all(&package).unwrap();

    // A new process registers it from the description and the copied URDF's text.
    let (ok, out) = l3p(&["robots", "check", "hull_dog"], &home);
    assert!(ok, "{out}");
    for leg in ["FL", "FR", "RL", "RR"] {
        assert!(
            out.contains(&format!(
                "link `{leg}_calf`: mesh `../meshes/calf.stl` used as a convex hull of 8 points"
            )),
            "{out}"
        );
    }

    // The registry artifact, installed where neither the meshes nor the home directory are.
    let registry = l3p_registry::Registry::open(&home.join("l3p-data")).unwrap();
    let (_, bytes) = registry.get_blob("robot-hull_dog@latest").unwrap();
    let far = dir.path().join("far/robots");
    let spec = l3p_cli::robots_cmd::install_robot_artifact(&bytes, "hull_dog", &far).unwrap();
    assert!(
        std::fs::read_to_string(far.join("hull_dog.toml"))
            .unwrap()
            .contains("[[mesh_hulls]]")
    );
    assert_eq!(spec.mesh_hulls.len(), 1);
    let model = spec.model().unwrap();
    let calf_hulls = model
        .bodies
        .iter()
        .flat_map(|b| &b.colliders)
        .filter(|c| c.link.ends_with("_calf"))
        .filter(|c| {
            matches!(&c.shape, l3p_robot::model::ShapeSpec::ConvexHull { points } if points.len() == 8)
        })
        .count();
    assert_eq!(calf_hulls, 4, "{:#?}", model.warnings);
}

/// `l3p deploy` and `l3p sim-robot` know an added robot as they know a catalog one: a policy
/// trained for it (here 2 iterations: the test is the deploy path, not the gait) is served by the
/// registry, loaded by the controller for that robot and sent to a simulated robot built from the
/// added description, at the control rate, until the sim-robot's run ends; an A1 policy is refused
/// for it.
#[test]
fn a_policy_trained_for_an_added_robot_deploys_to_its_simulated_robot() {
    let dir = tempfile::tempdir().unwrap();
    let cwd = dir.path();
    let urdf = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .replacen("name=\"a1\"", "name=\"Porch Dog\"", 1);
    std::fs::write(cwd.join("porch_dog.urdf"), urdf).unwrap();
    let (ok, out) = l3p(&["robots", "add", "porch_dog.urdf"], cwd);
    assert!(ok, "{out}");
    let config = format!("[run]\nname = \"porch\"\n{TINY_FLAT_TASK}")
        + "[learner]\nmax_iterations = 2\n[rollout]\nsteps_per_env = 8\n\
           [[actors]]\nrobot = \"porch_dog\"\nenvs = 4\nthreads = 1\n\
           [[actors]]\nrobot = \"a1\"\nenvs = 4\nthreads = 1\n";
    std::fs::write(cwd.join("porch.toml"), config).unwrap();
    let (ok, out) = l3p(&["train", "porch.toml", "--quiet"], cwd);
    assert!(ok, "{out}");

    let port = l3p_net::free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut procs = Procs(Vec::new());
    let data = cwd.join("l3p-data");
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            data.to_str().unwrap(),
            "--listen",
            &endpoint,
        ],
        cwd,
    );
    let second = std::time::Duration::from_secs(1);
    wait_for_port(port, 60 * second, "the registry", cwd);

    // The A1 policy of the same run is refused for the added robot, before anything is sent.
    let (ok, out) = l3p(
        &[
            "deploy",
            "--robot",
            "porch_dog",
            "--robot-id",
            "porch",
            "--policy",
            "porch-a1@latest",
            "--connect",
            &endpoint,
        ],
        cwd,
    );
    assert!(
        !ok && out.contains("policy for a1") && out.contains("porch_dog"),
        "{out}"
    );
    assert!(!out.contains("panicked"), "{out}");

    let (deploy_port, deploy_ep) = deploy_endpoint(port);
    // Staleness bound 10 periods instead of 3: on a loaded machine states arrive 60-70 ms late and
    // the controller would rightly damp; this test is about the added robot, not that rule
    // (cli/tests/deploy.rs tests it).
    let config = cwd.join("deploy.toml");
    std::fs::write(&config, "[deploy]\nstale_periods = 10.0\n").unwrap();
    procs.spawn_split_in_dir(
        "deploy",
        &[
            "deploy",
            "--robot",
            "porch_dog",
            "--robot-id",
            "porch",
            "--policy",
            "porch-porch_dog@latest",
            "--config",
            config.to_str().unwrap(),
            "--connect",
            &endpoint,
            "--listen",
            &deploy_ep,
        ],
        cwd,
    );
    wait_for_port(deploy_port, 60 * second, "the controller", cwd);
    procs.spawn_split_in_dir(
        "sim",
        &[
            "sim-robot",
            "--robot",
            "porch_dog",
            "--robot-id",
            "porch",
            "--duration",
            "8",
            // The robot side's own watchdog at 300 ms instead of 100: a loaded machine delays
            // commands by more than 100 ms now and then, and the summary must not count that as
            // the policy's damping.
            "--command-timeout",
            "0.3",
            "--connect",
            &deploy_ep,
        ],
        cwd,
    );
    let exit = procs.wait_exit("sim", 90 * second);
    assert!(
        exit.is_some_and(|s| s.success()),
        "sim-robot failed{}",
        log_tails(cwd)
    );
    let summary: serde_json::Value =
        serde_json::from_str(std::fs::read_to_string(cwd.join("sim.out")).unwrap().trim()).unwrap();
    eprintln!("sim-robot summary: {summary}");
    let f = |k: &str| {
        summary[k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k} in {summary}"))
    };
    assert_eq!(summary["robot"], "porch_dog");
    // The simulated robot is the added description (its inferred pose stands at 0.290 m), not
    // the catalog A1 whose URDF it came from (0.302 m).
    let a1 = l3p_robot::catalog::RobotSpec::by_name("a1")
        .unwrap()
        .nominal_standing_height()
        .unwrap() as f64;
    let nominal = f("nominal_base_height");
    assert!((nominal - a1).abs() > 0.005, "{nominal} vs A1 {a1}");
    assert!(
        f("policy_seconds") >= 2.0,
        "too little time under the policy{}",
        log_tails(cwd)
    );
    // 50 Hz commands while under the policy, none rejected, and a near-zero policy keeps the
    // robot standing (no fall, no damping).
    assert!(
        f("commands_received") >= 40.0 * f("policy_seconds"),
        "{summary}"
    );
    assert_eq!(f("commands_rejected"), 0.0, "{summary}");
    assert_eq!(f("steps_damping"), 0.0, "{summary}");
    assert!(
        f("policy_min_base_height") > 0.75 * nominal && f("policy_max_tilt_deg") < 20.0,
        "{summary}"
    );
}
