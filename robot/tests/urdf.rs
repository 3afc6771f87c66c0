//! URDF loading: the built-in models, every vendor file in `$L3P_SHARED_DIR/urdf`, and error messages.

use std::path::PathBuf;

use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::urdf::{UrdfError, load_urdf_file, load_urdf_str};

fn shared_urdf_dir() -> Option<PathBuf> {
    match std::env::var_os("L3P_SHARED_DIR") {
        Some(d) => Some(PathBuf::from(d).join("urdf")),
        None => {
            eprintln!("skipped: L3P_SHARED_DIR not set");
            None
        }
    }
}

#[test]
fn builtin_models_load_with_twelve_joints_feet_and_base() {
    for spec in RobotSpec::all() {
        let model = spec
            .model()
            .unwrap_or_else(|e| panic!("{}: {e}", spec.name));
        assert_eq!(model.num_actuated(), NUM_JOINTS, "{}", spec.name);
        for j in spec.joint_names {
            assert!(
                model.body_of_joint(j).is_some(),
                "{}: joint {j} missing",
                spec.name
            );
        }
        for l in spec
            .foot_links
            .iter()
            .chain(spec.penalised_links)
            .chain(spec.termination_links)
        {
            assert!(
                model.body_of_link(l).is_some(),
                "{}: link {l} missing",
                spec.name
            );
        }
        // Feet are merged into the calves (fixed joints), so there are 13 bodies.
        assert_eq!(model.bodies.len(), 13, "{}", spec.name);
        let rel = (model.total_mass() - spec.published_mass).abs() / spec.published_mass;
        assert!(
            rel < 0.05,
            "{}: mass {} vs published {}",
            spec.name,
            model.total_mass(),
            spec.published_mass
        );
        let h = spec.nominal_standing_height().unwrap();
        assert!(h > 0.2 && h < 0.8, "{}: standing height {h}", spec.name);
    }
}

/// Which vendor file corresponds to which built-in robot.
const VENDOR: [(&str, &str); 7] = [
    ("a1", "a1/a1.urdf"),
    ("go1", "go1/go1.urdf"),
    ("go2", "go2/go2_description.urdf"),
    ("anymal_b", "anymal_b/anymal.urdf"),
    ("anymal_c", "anymal_c/anymal.urdf"),
    ("anymal_d", "anymal_d/anymal.urdf"),
    ("spot", "spot/model.urdf"),
];

#[test]
fn every_vendor_file_loads() {
    let Some(dir) = shared_urdf_dir() else { return };
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let sub = entry.unwrap().path();
        if !sub.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&sub).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|e| e == "urdf") {
                let m = load_urdf_file(&p).unwrap_or_else(|e| panic!("{e}"));
                assert!(
                    m.num_actuated() >= 12,
                    "{}: {} joints",
                    p.display(),
                    m.num_actuated()
                );
                n += 1;
            }
        }
    }
    assert!(n >= 8, "found only {n} vendor files");
}

#[test]
fn project_models_match_vendor_mass_and_joint_count() {
    let Some(dir) = shared_urdf_dir() else { return };
    for (name, file) in VENDOR {
        let spec = RobotSpec::by_name(name).unwrap();
        let ours = spec.model().unwrap();
        let vendor = load_urdf_file(dir.join(file)).unwrap();
        let mut vendor_joints = vendor.num_actuated();
        if name == "anymal_d" {
            // The vendor file adds two payload pan/tilt joints; ours fixes them into the base.
            assert_eq!(vendor_joints, 14);
            vendor_joints -= 2;
        }
        assert_eq!(ours.num_actuated(), vendor_joints, "{name}");
        for j in spec.joint_names {
            let vendor_name = if name == "spot" {
                j.replace('_', ".")
            } else {
                j.to_string()
            };
            assert!(
                vendor.body_of_joint(&vendor_name).is_some(),
                "{name}: vendor has no joint {vendor_name}"
            );
        }
        let ours_mass = ours.total_mass();
        if name == "spot" {
            // The Spot SDK URDF is kinematics-only (no <inertial>): every body gets the placeholder
            // mass. Ours is checked against Boston Dynamics' published 32.7 kg instead.
            assert!(vendor.total_mass() < 0.2);
            assert!((ours_mass - 32.7).abs() / 32.7 < 0.05);
        } else {
            let vm = vendor.total_mass();
            assert!(
                (ours_mass - vm).abs() / vm < 0.05,
                "{name}: ours {ours_mass} vs vendor {vm}"
            );
        }
    }
}

#[test]
fn duplicate_materials_in_a_visual_are_tolerated() {
    let text = r#"<robot name="r">
      <link name="base"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
        <visual><geometry><box size="1 1 1"/></geometry><material name="a"/><material name="灰色"/></visual>
        <collision><geometry><mesh filename="package://nowhere/base.dae"/></geometry></collision>
      </link>
      <link name="leg"><inertial><mass value="0.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
      <link name="frame"/>
      <joint name="j" type="continuous"><parent link="base"/><child link="leg"/><axis xyz="0 1 0"/></joint>
      <joint name="f" type="fixed"><parent link="leg"/><child link="frame"/><origin xyz="0 0 -0.2"/></joint>
      <gazebo><anything/></gazebo>
    </robot>"#;
    let m = load_urdf_str(text, "dup.urdf").unwrap();
    assert_eq!(m.num_actuated(), 1);
    assert!(
        m.bodies[1].joint.as_ref().unwrap().limits.is_none(),
        "continuous joint has no limits"
    );
    // The mesh collider became a box stand-in.
    assert_eq!(m.bodies[0].colliders.len(), 1);
    assert!(m.bodies[0].colliders[0].stand_in);
    assert!(
        m.body_of_link("frame")
            .is_some_and(|(b, p)| b == 1 && (p.translation.z + 0.2).abs() < 1e-6)
    );
}

#[test]
fn fixed_joint_merge_combines_mass_and_inertia() {
    // Two 1 kg point-like links 0.2 m apart on a fixed joint: merged mass 2, com in the middle,
    // inertia about y gains 2 * 1 * 0.1^2.
    let text = r#"<robot name="r">
      <link name="a"><inertial><mass value="1"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
      <link name="b"><inertial><mass value="1"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
      <joint name="f" type="fixed"><parent link="a"/><child link="b"/><origin xyz="0.2 0 0" rpy="0 0 1.0"/></joint>
    </robot>"#;
    let m = load_urdf_str(text, "merge.urdf").unwrap();
    assert_eq!(m.bodies.len(), 1);
    let b = &m.bodies[0];
    assert!((b.mass - 2.0).abs() < 1e-6);
    assert!((b.com.x - 0.1).abs() < 1e-6);
    assert!(
        (b.inertia.y_axis.y - (0.002 + 0.02)).abs() < 1e-5,
        "{:?}",
        b.inertia
    );
    assert!((b.inertia.x_axis.x - 0.002).abs() < 1e-5);
}

#[test]
fn broken_files_name_file_element_and_line() {
    let bad_number = "<robot name=\"r\">\n<link name=\"a\">\n<inertial>\n<mass value=\"heavy\"/>\n</inertial>\n</link>\n</robot>";
    let e = load_urdf_str(bad_number, "bad.urdf").unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, UrdfError::Invalid { line: 4, .. }), "{msg}");
    assert!(
        msg.contains("bad.urdf:4") && msg.contains("<mass>") && msg.contains("heavy"),
        "{msg}"
    );

    let bad_xml = "<robot name=\"r\">\n<link name=\"a\">\n</robot>";
    let e = load_urdf_str(bad_xml, "x.urdf").unwrap_err();
    assert!(matches!(e, UrdfError::Xml { line: 3, .. }), "{e}");

    let bad_vec = "<robot name=\"r\">\n<link name=\"a\"/>\n<link name=\"b\"/>\n<joint name=\"j\" type=\"revolute\">\n<origin xyz=\"0 0\"/>\n<parent link=\"a\"/><child link=\"b\"/></joint>\n</robot>";
    let e = load_urdf_str(bad_vec, "v.urdf").unwrap_err();
    assert!(e.to_string().contains("v.urdf:5: <origin>"), "{e}");

    let two_roots = "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/></robot>";
    let e = load_urdf_str(two_roots, "t.urdf").unwrap_err();
    assert!(e.to_string().contains("several root links"), "{e}");

    let e = load_urdf_file("/nonexistent/robot.urdf").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/robot.urdf"), "{e}");
}

/// Hostile or absurd files (each accepted or crashing the loader before): a clear error naming
/// the element, never an abort.
#[test]
fn absurd_values_and_deep_nesting_are_refused_with_the_element_named() {
    let link = |inertial: &str| {
        format!(
            "<robot name=\"r\">\n<link name=\"a\">\n<inertial>\n{inertial}\n</inertial>\n</link>\n</robot>"
        )
    };
    let inertia = |ixx: &str, iyy: &str, izz: &str, ixy: &str| {
        link(&format!(
            "<mass value=\"1\"/><inertia ixx=\"{ixx}\" ixy=\"{ixy}\" ixz=\"0\" iyy=\"{iyy}\" iyz=\"0\" izz=\"{izz}\"/>"
        ))
    };
    let cases = [
        (link("<mass value=\"1e300\"/>"), "<mass>"),
        (inertia("1e38", "1", "1", "0"), "<inertia>"),
        (inertia("-0.1", "0.1", "0.1", "0"), "negative moment"),
        (inertia("0.1", "0.1", "0.5", "0"), "triangle inequality"),
        (inertia("0.1", "0.1", "0.1", "0.5"), "positive semi-definite"),
        (
            "<robot name=\"r\"><link name=\"a\"><visual><geometry><sphere radius=\"-1\"/></geometry></visual></link></robot>".to_string(),
            "negative radius",
        ),
        (
            "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/><joint name=\"j\" type=\"revolute\"><parent link=\"a\"/><child link=\"b\"/><axis xyz=\"0 0 1\"/><limit lower=\"1\" upper=\"-1\" effort=\"1\" velocity=\"1\"/></joint></robot>".to_string(),
            "above upper",
        ),
    ];
    for (text, want) in cases {
        let e = load_urdf_str(&text, "odd.urdf").unwrap_err().to_string();
        assert!(e.contains(want) && e.contains("odd.urdf"), "{want}: {e}");
    }
    // 20,000 nested elements (the serde parser behind urdf-rs overflowed its stack on these).
    let deep = format!(
        "<robot name=\"r\"><link name=\"a\">{}{}</link></robot>",
        "<x>".repeat(20_000),
        "</x>".repeat(20_000)
    );
    let e = load_urdf_str(&deep, "deep.urdf").unwrap_err().to_string();
    assert!(e.contains("nested more than"), "{e}");
    // A plausible body still loads.
    load_urdf_str(&inertia("0.1", "0.1", "0.1", "0.01"), "ok.urdf").unwrap();
}
