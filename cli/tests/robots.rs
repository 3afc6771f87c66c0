//! `l3p robots add` through the binary: a user's URDF becomes a robot file that `robots list`,
//! `robots check` and a training config know by name; adding it twice needs `--replace`; a file
//! that is not a quadruped is a clear error.

use std::path::Path;
use std::process::Command;

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
    let urdf = l3p_robots::catalog::RobotSpec::by_name("a1")
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
