//! Bring your own robot: a URDF becomes a robot description (legs, standing pose checked in
//! simulation, gains from the load), registers beside the catalog and trains in the task like a
//! built-in robot. Vendor files come from `$L3P_SHARED_DIR/urdf` (skipped without it).

use std::path::PathBuf;

use l3p_robot::added::{self, AddError, Overrides, RobotDescription};
use l3p_robot::catalog::RobotSpec;
use l3p_robot::urdf::{load_urdf_file, load_urdf_str};
use l3p_sim::describe::describe;
use l3p_sim::vecenv::VecEnv;
use l3p_task::config::{EnvConfig, TerrainConfig, TerrainPreset};

fn vendor_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(std::env::var_os("L3P_SHARED_DIR")?).join("urdf");
    dir.is_dir().then_some(dir)
}

fn named(name: &str) -> Overrides {
    Overrides {
        name: Some(name.into()),
        ..Default::default()
    }
}

/// A1's own URDF under another robot name, as a user's file.
fn renamed_a1() -> String {
    RobotSpec::by_name("a1")
        .unwrap()
        .urdf
        .replacen("name=\"a1\"", "name=\"my_quad\"", 1)
}

#[test]
fn every_vendor_urdf_with_dynamics_is_added_unedited_and_stands() {
    let Some(dir) = vendor_dir() else {
        eprintln!("skipped: L3P_SHARED_DIR not set");
        return;
    };
    let mut rows = Vec::new();
    for catalog in [
        "a1", "go1", "go2", "anymal_b", "anymal_c", "anymal_d", "spot",
    ] {
        let sub = dir.join(catalog);
        let Some(file) = std::fs::read_dir(&sub)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .find(|p| p.extension().is_some_and(|x| x == "urdf"))
        else {
            panic!("no URDF in {}", sub.display());
        };
        let model = load_urdf_file(&file).unwrap();
        if catalog == "spot" {
            // Boston Dynamics' SDK file is kinematics only (no inertia, no collision shapes):
            // refused, naming the first body without mass.
            let err = describe(&model, "robot.urdf", &named("vendor_spot"), false)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("= base:") && err.contains("no <inertial>"),
                "{err}"
            );
            rows.push(format!("{catalog:9} refused: {err}"));
            continue;
        }
        let inferred = describe(
            &model,
            "robot.urdf",
            &named(&format!("vendor_{catalog}")),
            false,
        )
        .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let d = &inferred.description;
        let spec = RobotSpec::by_name(catalog).unwrap();
        assert_eq!(
            d.joint_names.iter().map(String::as_str).collect::<Vec<_>>(),
            spec.joint_names.to_vec(),
            "{catalog}: joint order"
        );
        let pose_diff = d
            .default_pose
            .iter()
            .zip(&spec.default_pose)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        rows.push(format!(
            "{catalog:9} pose {:?}\n          catalog {:?}",
            d.default_pose.map(|v| (v * 100.0).round() / 100.0),
            spec.default_pose
        ));
        rows.push(format!(
            "{catalog:9} mass {:6.2} kg (catalog {:6.2})  standing {:.3} m (catalog {:.3}) settled {:.3}  max pose diff {pose_diff:.2} rad  kp {:6.1} kd {:4.2} (catalog {} / {})",
            d.mass,
            spec.published_mass,
            inferred.standing_height,
            spec.nominal_standing_height().unwrap(),
            inferred.settled_height,
            d.kp,
            d.kd,
            spec.training_gains.kp,
            spec.training_gains.kd,
        ));
        assert!(
            inferred.settled_height > 0.85 * inferred.standing_height,
            "{catalog} sank"
        );
        // Knees bend the way the vendor's own default pose bends them (ANYmal's "X" included),
        // within 0.7 rad of it.
        for leg in 0..4 {
            let k = 3 * leg + 2;
            assert_eq!(
                d.default_pose[k].signum(),
                spec.default_pose[k].signum(),
                "{catalog}: knee {k}"
            );
        }
        assert!(pose_diff < 0.7, "{catalog}: {pose_diff}");
    }
    eprintln!("{}", rows.join("\n"));
}

#[test]
fn an_added_robot_is_found_by_name_and_stands_in_the_task() {
    let text = renamed_a1();
    let model = load_urdf_str(&text, "my_quad.urdf").unwrap();
    let inferred = describe(&model, "my_quad.urdf", &Overrides::default(), false).unwrap();
    let d = &inferred.description;
    assert_eq!(d.name, "my_quad");
    // The same leg structure as A1, a pose with feet under the hips and A1-like gains.
    let a1 = RobotSpec::by_name("a1").unwrap();
    assert_eq!(
        d.joint_names.iter().map(String::as_str).collect::<Vec<_>>(),
        a1.joint_names.to_vec()
    );
    assert!(d.kp > 30.0 && d.kp < 120.0, "kp {}", d.kp);
    for leg in 0..4 {
        assert!(d.default_pose[3 * leg + 2] < -0.5, "knees bend backwards");
    }
    // The description survives its TOML and registers.
    let back: RobotDescription = toml::from_str(&d.to_toml()).unwrap();
    assert_eq!(&back, d);
    let spec = added::register(&back, text).unwrap();
    assert_eq!(RobotSpec::by_name("My-Quad").unwrap().name, spec.name);
    // Trains like a built-in robot: zero actions, nobody falls for 2 s.
    let env_cfg = EnvConfig {
        terrain: TerrainConfig::with_preset(TerrainPreset::Flat),
        height_scan: false,
        ..Default::default()
    };
    let mut env = VecEnv::new(spec, &env_cfg, 4, 2, 1).unwrap();
    env.reset_all();
    let actions = vec![0.0; 4 * env.action_dim()];
    let mut ended = 0;
    for _ in 0..100 {
        ended += env
            .step(&actions)
            .unwrap()
            .terminated
            .iter()
            .filter(|t| **t)
            .count();
    }
    assert_eq!(ended, 0);
    let standing = spec.nominal_standing_height().unwrap();
    for e in 0..4 {
        let h = env.robot_state(e).unwrap().base_pos[2];
        assert!(h > 0.8 * standing, "env {e}: {h} of {standing}");
    }
}

#[test]
fn bad_input_is_an_error_naming_the_element() {
    // A leg joint without an effort limit.
    let text = renamed_a1().replacen("effort=\"33.5\"", "", 1);
    let model = load_urdf_str(&text, "my_quad.urdf").unwrap();
    let err = describe(&model, "x.urdf", &Overrides::default(), false).unwrap_err();
    assert!(
        matches!(&err, AddError::MissingLimits { effort, .. } if !effort.is_empty()),
        "{err}"
    );
    assert!(err.to_string().contains("_joint"), "{err}");
    // ... unless the caller fills it in.
    let filled = Overrides {
        effort: Some(30.0),
        ..Default::default()
    };
    assert!(describe(&model, "x.urdf", &filled, false).is_ok());
    // A catalog robot's name.
    let a1 = RobotSpec::by_name("a1").unwrap().model().unwrap();
    let err = describe(&a1, "a1.urdf", &Overrides::default(), false).unwrap_err();
    assert!(err.to_string().contains("built-in"), "{err}");
    // Edited descriptions: a bad number or a link the URDF does not have.
    let model = load_urdf_str(&renamed_a1(), "my_quad.urdf").unwrap();
    let good = describe(&model, "x.urdf", &Overrides::default(), false)
        .unwrap()
        .description;
    let mut neg = good.clone();
    neg.kp = -3.0;
    assert!(neg.validate().unwrap_err().to_string().contains("kp"));
    let mut nan = good.clone();
    nan.default_pose[4] = f32::NAN;
    assert!(
        nan.validate()
            .unwrap_err()
            .to_string()
            .contains("default_pose[4]")
    );
    let mut wrong_foot = good.clone();
    wrong_foot.foot_links[2] = "RL_toe".into();
    let err = added::register(&wrong_foot, renamed_a1()).unwrap_err();
    assert!(err.to_string().contains("RL_toe"), "{err}");
    // A file that is not a quadruped.
    let biped = "<robot name=\"b\"><link name=\"base\"/></robot>";
    let model = load_urdf_str(biped, "b.urdf").unwrap();
    assert!(matches!(
        describe(&model, "b.urdf", &Overrides::default(), false),
        Err(AddError::Infer(_))
    ));
}

#[test]
fn a_robots_directory_loads_and_a_bad_file_is_named() {
    let dir = std::env::temp_dir().join(format!("l3p-added-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = renamed_a1().replacen("name=\"my_quad\"", "name=\"dir_quad\"", 1);
    std::fs::write(dir.join("dir_quad.urdf"), &text).unwrap();
    let model = load_urdf_str(&text, "dir_quad.urdf").unwrap();
    let d = describe(&model, "dir_quad.urdf", &Overrides::default(), false)
        .unwrap()
        .description;
    std::fs::write(dir.join("dir_quad.toml"), d.to_toml()).unwrap();
    let loaded = added::load_dir(&dir).unwrap();
    assert_eq!(loaded.len(), 1);
    assert!(RobotSpec::by_name("dir_quad").is_ok());
    std::fs::write(
        dir.join("zz_broken.toml"),
        "name = \"zz\"\nkp = \"stiff\"\n",
    )
    .unwrap();
    let err = added::load_dir(&dir).unwrap_err().to_string();
    assert!(err.contains("zz_broken.toml"), "{err}");
    assert!(added::load_dir(&dir.join("missing")).unwrap().is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}
