//! Leg-structure inference (`l3p_robot::legs`): every vendor URDF of the shared corpus, every
//! catalog robot, and synthetic quadrupeds (renamed, shuffled, mirrored, mesh-only) and
//! non-quadrupeds (hexapod, biped, 2-joint leg, 4-joint leg, prismatic leg, disconnected link).
//! No simulation.
//!
//! The vendor files are read where they lie (never copied): `$L3P_SHARED_DIR/urdf`, else
//! `../shared/urdf` beside the workspace; without a corpus these tests print `skipped` and pass (as
//! `tests/urdf.rs`), a file missing from it fails.

use std::path::PathBuf;

use l3p_robot::catalog::RobotSpec;
use l3p_robot::legs::{InferError, InferredLegs, JointRole, LegId, infer_quadruped};
use l3p_robot::urdf::{UrdfError, load_urdf_file, load_urdf_str};

// ---------------------------------------------------------------------------------------------
// Vendor files

/// The vendor corpus: `$L3P_SHARED_DIR/urdf`, else `../shared/urdf` beside the workspace; `None`
/// (the vendor tests print `skipped` and pass, as README says) when neither exists. A file missing
/// from a corpus that exists still fails.
fn shared_urdf_dir() -> Option<PathBuf> {
    let candidates: Vec<PathBuf> = match std::env::var_os("L3P_SHARED_DIR") {
        Some(d) => vec![PathBuf::from(d).join("urdf")],
        None => vec![PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/urdf")],
    };
    let found = candidates
        .iter()
        .find(|d| d.is_dir())
        .map(|d| d.canonicalize().unwrap_or_else(|_| d.clone()));
    if found.is_none() {
        eprintln!(
            "skipped: vendor URDF corpus not found at {}",
            candidates[0].display()
        );
    }
    found
}

/// Vendor file, catalog robot it corresponds to, and how its names relate to the catalog's.
const VENDOR: [(&str, &str); 8] = [
    ("a1/a1.urdf", "a1"),
    ("go1/go1.urdf", "go1"),
    ("go2/go2_description.urdf", "go2"),
    ("go2/go2_description_2024-11.urdf", "go2"),
    ("anymal_b/anymal.urdf", "anymal_b"),
    ("anymal_c/anymal.urdf", "anymal_c"),
    ("anymal_d/anymal.urdf", "anymal_d"),
    ("spot/model.urdf", "spot"),
];

fn infer_file(path: &std::path::Path) -> InferredLegs {
    assert!(
        path.is_file(),
        "vendor URDF {} is missing\nhint: the shared corpus must hold every file listed in robots/tests/infer.rs",
        path.display()
    );
    let model = load_urdf_file(path).unwrap_or_else(|e| panic!("{e}"));
    infer_quadruped(&model).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn every_vendor_urdf_is_inferred_in_the_catalog_order() {
    let Some(dir) = shared_urdf_dir() else {
        return;
    };
    for (file, robot) in VENDOR {
        let legs = infer_file(&dir.join(file));
        println!("{file}\n{legs}");
        let spec = RobotSpec::by_name(robot).unwrap();
        if robot == "spot" {
            // The catalog's Spot URDF was written by hand with `_` names (`fl_hx`, links `body`,
            // `fl_foot`); the SDK file uses `fl.hx`, has root `base` and no foot links, so its feet
            // are the lower legs. The catalog's own URDF is compared exactly in the next test.
            let expected: Vec<String> = spec
                .joint_names
                .iter()
                .map(|j| j.replace('_', "."))
                .collect();
            assert_eq!(legs.joint_names(), expected, "{file}");
            assert_eq!(
                legs.foot_links(),
                ["fl.lleg", "fr.lleg", "hl.lleg", "hr.lleg"]
            );
            assert_eq!(legs.base_link, "base");
            // Kinematics-only file: every trunk and leg body got the loader's placeholder mass.
            let masses = legs
                .warnings
                .iter()
                .filter(|w| w.contains("has no mass"))
                .count();
            assert_eq!(masses, 13, "{:#?}", legs.warnings);
        } else {
            assert_eq!(legs.joint_names(), spec.joint_names, "{file}");
            assert_eq!(legs.foot_links(), spec.foot_links, "{file}");
            assert_eq!(legs.base_link, spec.base_link, "{file}");
        }
        assert!(
            legs.axis_signs().iter().all(|s| *s == 1.0),
            "{file}: {legs}"
        );
        if robot == "anymal_d" {
            assert_eq!(
                legs.extra_joints,
                [
                    "inspection_payload_mount_to_pan",
                    "inspection_payload_pan_to_tilt"
                ]
            );
        } else {
            assert!(
                legs.extra_joints.is_empty(),
                "{file}: {:?}",
                legs.extra_joints
            );
        }
        // Geometry agrees with the names: front hips ahead, left hips to the left.
        let h: Vec<_> = legs.legs.iter().map(|l| l.hip_position()).collect();
        assert!(
            h[0].x > 0.0 && h[1].x > 0.0 && h[2].x < 0.0 && h[3].x < 0.0,
            "{file}"
        );
        assert!(
            h[0].y > 0.0 && h[1].y < 0.0 && h[2].y > 0.0 && h[3].y < 0.0,
            "{file}"
        );
    }
}

#[test]
fn every_urdf_in_the_corpus_is_a_quadruped() {
    // Files added to the corpus later are inferred too (they need not be in `VENDOR`).
    let Some(dir) = shared_urdf_dir() else {
        return;
    };
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let sub = entry.unwrap().path();
        if !sub.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&sub).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|e| e == "urdf") {
                infer_file(&p);
                n += 1;
            }
        }
    }
    assert!(
        n >= VENDOR.len(),
        "found only {n} vendor files in {}",
        dir.display()
    );
}

#[test]
fn every_catalog_urdf_matches_its_spec() {
    for spec in RobotSpec::all() {
        let model = load_urdf_str(spec.urdf, spec.name).unwrap();
        let legs = infer_quadruped(&model).unwrap_or_else(|e| panic!("{}: {e}", spec.name));
        assert_eq!(legs.joint_names(), spec.joint_names, "{}", spec.name);
        assert_eq!(legs.foot_links(), spec.foot_links, "{}", spec.name);
        assert_eq!(legs.base_link, spec.base_link, "{}", spec.name);
        assert!(
            legs.warnings.is_empty(),
            "{}: {:?}",
            spec.name,
            legs.warnings
        );
        for (k, j) in legs.joints().enumerate() {
            assert_eq!(j.role, JointRole::ALL[k % 3]);
            assert_eq!(j.sign, 1.0, "{}: {}", spec.name, j.name);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Synthetic robots

/// One joint of a synthetic leg.
#[derive(Clone)]
struct J {
    name: String,
    /// Child link name.
    link: String,
    kind: &'static str,
    axis: [f32; 3],
    /// Origin in the parent link frame.
    xyz: [f32; 3],
}

/// A synthetic leg: joints from the trunk down, then an optional foot link on a fixed joint.
#[derive(Clone)]
struct Leg {
    joints: Vec<J>,
    foot: Option<String>,
    /// Collision of every link in this leg given as a mesh only.
    mesh_only: bool,
    /// Mass of every moving link in this leg.
    mass: f32,
}

/// A standard 3-joint leg at hip position (x, y): abduction about x, hip and knee about y,
/// thigh and calf 0.2 m; names `<p>_haa`, `<p>_hfe`, `<p>_kfe`, links `<p>_hip` … `<p>_foot`.
fn leg(p: &str, x: f32, y: f32) -> Leg {
    let side = y.signum();
    let j = |n: &str, l: &str, axis, xyz| J {
        name: format!("{p}_{n}"),
        link: format!("{p}_{l}"),
        kind: "revolute",
        axis,
        xyz,
    };
    Leg {
        joints: vec![
            j("haa", "hip", [1.0, 0.0, 0.0], [x, y, 0.0]),
            j("hfe", "thigh", [0.0, 1.0, 0.0], [0.0, 0.06 * side, 0.0]),
            j("kfe", "calf", [0.0, 1.0, 0.0], [0.0, 0.0, -0.2]),
        ],
        foot: Some(format!("{p}_foot")),
        mesh_only: false,
        mass: 0.5,
    }
}

/// The four standard legs FL, FR, RL, RR (prefixes `fl`, `fr`, `rl`, `rr`).
fn quad() -> Vec<Leg> {
    vec![
        leg("fl", 0.2, 0.05),
        leg("fr", 0.2, -0.05),
        leg("rl", -0.2, 0.05),
        leg("rr", -0.2, -0.05),
    ]
}

fn inertial(m: f32) -> String {
    format!(
        r#"<inertial><mass value="{m}"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>"#
    )
}

fn link_xml(name: &str, mass: f32, geometry: &str, mesh_only: bool) -> String {
    let geometry = if mesh_only {
        format!(r#"<mesh filename="package://synthetic/meshes/{name}.stl"/>"#)
    } else {
        geometry.to_string()
    };
    format!(
        r#"<link name="{name}">{}<collision><geometry>{geometry}</geometry></collision></link>"#,
        inertial(mass)
    )
}

/// A URDF with a 0.5 × 0.2 × 0.1 m box trunk `trunk` and the given legs; `shuffle` lists the
/// elements (links and joints) in a scrambled but fixed order.
fn robot_xml(legs: &[Leg], shuffle: bool) -> String {
    let mut elements = vec![link_xml(
        "trunk",
        5.0,
        r#"<box size="0.5 0.2 0.1"/>"#,
        false,
    )];
    for l in legs {
        let mut parent = "trunk".to_string();
        for j in &l.joints {
            elements.push(link_xml(
                &j.link,
                l.mass,
                r#"<cylinder radius="0.02" length="0.2"/>"#,
                l.mesh_only,
            ));
            let [ax, ay, az] = j.axis;
            let [x, y, z] = j.xyz;
            let limit = if j.kind == "continuous" {
                String::new()
            } else {
                r#"<limit lower="-2" upper="2" effort="30" velocity="20"/>"#.to_string()
            };
            elements.push(format!(
                r#"<joint name="{}" type="{}"><parent link="{parent}"/><child link="{}"/><origin xyz="{x} {y} {z}" rpy="0 0 0"/><axis xyz="{ax} {ay} {az}"/>{limit}</joint>"#,
                j.name, j.kind, j.link
            ));
            parent = j.link.clone();
        }
        if let Some(foot) = &l.foot {
            elements.push(link_xml(
                foot,
                0.05,
                r#"<sphere radius="0.02"/>"#,
                l.mesh_only,
            ));
            elements.push(format!(
                r#"<joint name="{foot}_fixed" type="fixed"><parent link="{parent}"/><child link="{foot}"/><origin xyz="0 0 -0.2"/></joint>"#
            ));
        }
    }
    if shuffle {
        // A fixed scramble: stride 7 through the list (coprime with its length unless 7 divides it).
        let n = elements.len();
        let stride = if n % 7 == 0 { 5 } else { 7 };
        elements = (0..n)
            .map(|i| elements[(i * stride + 3) % n].clone())
            .collect();
    }
    format!(
        "<robot name=\"synthetic\">\n{}\n</robot>\n",
        elements.join("\n")
    )
}

fn infer_xml(xml: &str) -> Result<InferredLegs, InferError> {
    let model = load_urdf_str(xml, "synthetic.urdf").unwrap_or_else(|e| panic!("{e}\n{xml}"));
    infer_quadruped(&model)
}

fn expect_err(xml: &str) -> String {
    match infer_xml(xml) {
        Ok(legs) => panic!("expected an error, got\n{legs}"),
        Err(e) => {
            println!("{e}\n");
            e.to_string()
        }
    }
}

const STANDARD: [&str; 12] = [
    "fl_haa", "fl_hfe", "fl_kfe", "fr_haa", "fr_hfe", "fr_kfe", "rl_haa", "rl_hfe", "rl_kfe",
    "rr_haa", "rr_hfe", "rr_kfe",
];

#[test]
fn synthetic_quadruped_is_inferred() {
    let legs = infer_xml(&robot_xml(&quad(), false)).unwrap();
    assert_eq!(legs.joint_names(), STANDARD);
    assert_eq!(
        legs.foot_links(),
        ["fl_foot", "fr_foot", "rl_foot", "rr_foot"]
    );
    assert_eq!(legs.base_link, "trunk");
    assert!(legs.warnings.is_empty(), "{:?}", legs.warnings);
    let ids: Vec<LegId> = legs.legs.iter().map(|l| l.id).collect();
    assert_eq!(ids, LegId::ALL);
    // Feet 0.4 m below the hip axes at the zero pose.
    for l in &legs.legs {
        assert!((l.foot_position.z + 0.4).abs() < 1e-5, "{legs}");
    }
    let s = legs.summary();
    assert!(s.contains("fl_haa +x") && s.contains("rr_kfe +y"), "{s}");
}

#[test]
fn renamed_joints_in_shuffled_order_are_assigned_by_geometry() {
    // Legs listed RR, FL, RL, FR; joints named j1..j12 in that listing order, links l1..l12, feet
    // f1..f4: no name says which leg is which. Continuous knees.
    let order = [3usize, 0, 2, 1];
    let base = quad();
    let mut legs = Vec::new();
    let mut k = 0;
    for (n, &i) in order.iter().enumerate() {
        let mut l = base[i].clone();
        for j in &mut l.joints {
            k += 1;
            j.name = format!("j{k}");
            j.link = format!("l{k}");
        }
        l.joints[2].kind = "continuous";
        l.foot = Some(format!("f{}", n + 1));
        legs.push(l);
    }
    let xml = robot_xml(&legs, true);
    // The scramble really scrambles: the first joint element is not j1.
    let first = xml.find("<joint name=\"").unwrap();
    assert!(!xml[first..].starts_with("<joint name=\"j1\""), "{xml}");
    let inferred = infer_xml(&xml).unwrap();
    // FL is listed 2nd (j4..j6), FR 4th (j10..j12), RL 3rd (j7..j9), RR 1st (j1..j3).
    let expected = [
        "j4", "j5", "j6", "j10", "j11", "j12", "j7", "j8", "j9", "j1", "j2", "j3",
    ];
    assert_eq!(inferred.joint_names(), expected, "{inferred}");
    assert_eq!(inferred.foot_links(), ["f2", "f4", "f3", "f1"]);
}

#[test]
fn mirrored_axes_are_reported_as_negative_signs() {
    // Right legs with every axis flipped, as some vendors mirror them.
    let mut legs = quad();
    for i in [1, 3] {
        for j in &mut legs[i].joints {
            j.axis = j.axis.map(|a| -a);
        }
    }
    // And a front-left knee about -y.
    legs[0].joints[2].axis = [0.0, -1.0, 0.0];
    let inferred = infer_xml(&robot_xml(&legs, false)).unwrap();
    assert_eq!(inferred.joint_names(), STANDARD);
    let signs = inferred.axis_signs();
    assert_eq!(
        signs,
        [
            1.0, 1.0, -1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, -1.0
        ]
    );
    assert!(inferred.summary().contains("fr_haa -x"), "{inferred}");
}

#[test]
fn rotated_joint_frames_are_judged_in_the_trunk_frame() {
    // The hip joint frame is rotated 90° about x (rpy), with its axis written as z: in the trunk
    // frame it is about -y, so the leg is accepted with a negative hip sign. The knee below it,
    // written in the rotated thigh frame (axis -z, origin -y), is about +y in the trunk frame.
    let xml = robot_xml(&quad(), false)
        .replace(
            r#"<child link="fl_thigh"/><origin xyz="0 0.06 0" rpy="0 0 0"/><axis xyz="0 1 0"/>"#,
            r#"<child link="fl_thigh"/><origin xyz="0 0.06 0" rpy="1.5707963 0 0"/><axis xyz="0 0 1"/>"#,
        )
        .replace(
            r#"<child link="fl_calf"/><origin xyz="0 0 -0.2" rpy="0 0 0"/><axis xyz="0 1 0"/>"#,
            r#"<child link="fl_calf"/><origin xyz="0 -0.2 0" rpy="0 0 0"/><axis xyz="0 0 -1"/>"#,
        );
    assert!(
        xml.contains("rpy=\"1.5707963") && xml.contains("0 -0.2 0"),
        "replacements did not apply"
    );
    let inferred = infer_xml(&xml).unwrap();
    assert_eq!(inferred.joint_names(), STANDARD);
    let fl = &inferred.legs[0];
    assert_eq!(
        [fl.joints[1].sign, fl.joints[2].sign],
        [-1.0, 1.0],
        "{inferred}"
    );
    assert!((fl.joints[2].position.z + 0.2).abs() < 1e-5, "{inferred}");
}

#[test]
fn mesh_only_collision_leg_is_inferred_with_a_warning() {
    let mut legs = quad();
    legs[2].mesh_only = true;
    let inferred = infer_xml(&robot_xml(&legs, false)).unwrap();
    assert_eq!(inferred.joint_names(), STANDARD);
    assert_eq!(inferred.foot_links()[2], "rl_foot");
    assert!(
        inferred
            .warnings
            .iter()
            .any(|w| w.contains("`rl_calf`") && w.contains("replaced by")),
        "{:?}",
        inferred.warnings
    );
}

#[test]
fn massless_leg_link_is_a_warning_and_a_bad_mass_an_error() {
    let xml = robot_xml(&quad(), false).replace(
        &format!("<link name=\"fr_thigh\">{}", inertial(0.5)),
        "<link name=\"fr_thigh\">",
    );
    let inferred = infer_xml(&xml).unwrap();
    assert!(
        inferred
            .warnings
            .iter()
            .any(|w| w.contains("`fr_thigh`") && w.contains("no mass")),
        "{:?}",
        inferred.warnings
    );
    // Negative masses never get past the loader (file, element and line).
    let neg =
        robot_xml(&quad(), false).replacen("<mass value=\"0.5\"/>", "<mass value=\"-0.5\"/>", 1);
    let e = load_urdf_str(&neg, "neg.urdf").unwrap_err();
    assert!(
        matches!(e, UrdfError::Invalid { .. }) && e.to_string().contains("negative mass"),
        "{e}"
    );
    // A model built by other means with a NaN or zero mass in a leg is refused naming the link.
    for bad in [f32::NAN, 0.0, -1.0] {
        let mut model = load_urdf_str(&robot_xml(&quad(), false), "m.urdf").unwrap();
        let b = model.body_of_joint("rl_kfe").unwrap();
        model.bodies[b].mass = bad;
        let e = infer_quadruped(&model).unwrap_err();
        assert!(matches!(e, InferError::Mass { .. }), "{e}");
        assert!(e.to_string().contains("`rl_calf`"), "{e}");
    }
}

#[test]
fn hexapod_is_refused_with_the_leg_count() {
    let mut legs = quad();
    legs.push(leg("ml", 0.0, 0.05));
    legs.push(leg("mr", 0.0, -0.05));
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(
        msg.contains("expected 4 legs") && msg.contains("found 6"),
        "{msg}"
    );
    assert!(
        msg.contains("`ml_haa`") && msg.contains("`mr_haa`"),
        "{msg}"
    );
}

#[test]
fn biped_is_refused() {
    let legs = vec![leg("l", 0.0, 0.1), leg("r", 0.0, -0.1)];
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(msg.contains("found 2") && msg.contains("`l_haa`"), "{msg}");
    assert!(msg.contains("hint:"), "{msg}");
}

#[test]
fn leg_with_two_joints_is_refused_naming_it() {
    let mut legs = quad();
    legs[3].joints.pop();
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(msg.contains("found 3"), "{msg}");
    assert!(
        msg.contains(
            "chain starting at joint `rr_haa` has 2 joint(s) instead of 3: rr_haa, rr_hfe"
        ),
        "{msg}"
    );
}

#[test]
fn leg_with_four_joints_is_refused_naming_it() {
    let mut legs = quad();
    let mut extra = legs[0].joints[2].clone();
    extra.name = "fl_ankle".into();
    extra.link = "fl_shin".into();
    legs[0].joints.push(extra);
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(
        msg.contains("`fl_haa` has 4 joint(s)") && msg.contains("fl_ankle"),
        "{msg}"
    );
}

#[test]
fn prismatic_joint_in_a_leg_is_refused_naming_it() {
    let mut legs = quad();
    legs[1].joints[2].kind = "prismatic";
    legs[1].joints[2].axis = [0.0, 0.0, 1.0];
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(msg.contains("prismatic joint `fr_kfe`"), "{msg}");
}

#[test]
fn branching_leg_is_refused_naming_the_body() {
    let xml = robot_xml(&quad(), false).replace(
        "</robot>",
        &format!(
            "{}<joint name=\"fl_toe\" type=\"revolute\"><parent link=\"fl_thigh\"/><child link=\"fl_toe_link\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n</robot>",
            link_xml("fl_toe_link", 0.1, "<sphere radius=\"0.01\"/>", false)
        ),
    );
    let msg = expect_err(&xml);
    assert!(
        msg.contains("branches at body `fl_thigh`") && msg.contains("`fl_toe`"),
        "{msg}"
    );
}

#[test]
fn disconnected_link_is_refused() {
    // In a file: the loader refuses the second root, naming it.
    let xml = robot_xml(&quad(), false).replace(
        "</robot>",
        &format!(
            "{}\n</robot>",
            link_xml("stray", 0.1, "<sphere radius=\"0.01\"/>", false)
        ),
    );
    let e = load_urdf_str(&xml, "stray.urdf").unwrap_err();
    assert!(
        matches!(e, UrdfError::Structure { .. }) && e.to_string().contains("stray"),
        "{e}"
    );
    // In a model built by other means: inference refuses the body without a parent.
    let mut model = load_urdf_str(&robot_xml(&quad(), false), "m.urdf").unwrap();
    let b = model.body_of_joint("rr_hfe").unwrap();
    model.bodies[b].parent = None;
    let e = infer_quadruped(&model).unwrap_err();
    assert!(matches!(e, InferError::Tree { .. }), "{e}");
    assert!(e.to_string().contains("`rr_thigh` is not connected"), "{e}");
}

#[test]
fn hip_pitch_first_legs_are_refused_naming_the_joint() {
    // A leg whose first joint turns about y (hip flexion first, abduction second): its first
    // joint cannot be the abduction.
    let mut legs = quad();
    legs[2].joints[0].axis = [0.0, 1.0, 0.0];
    legs[2].joints[1].axis = [1.0, 0.0, 0.0];
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(
        msg.contains("leg RL: joint `rl_haa` (the abduction joint, number 1") && msg.contains("±x"),
        "{msg}"
    );
    // A knee about z.
    let mut legs = quad();
    legs[0].joints[2].axis = [0.0, 0.0, 1.0];
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(msg.contains("joint `fl_kfe` (the knee joint"), "{msg}");
}

#[test]
fn ambiguous_geometry_is_refused() {
    // Four hips on one line across the trunk: no front or rear.
    let legs = vec![
        leg("a", 0.0, 0.15),
        leg("b", 0.0, 0.05),
        leg("c", 0.0, -0.05),
        leg("d", 0.0, -0.15),
    ];
    let msg = expect_err(&robot_xml(&legs, false));
    assert!(msg.contains("cannot tell front from rear"), "{msg}");
}

#[test]
fn extra_chain_beside_four_legs_is_a_warning() {
    // A 2-joint pan/tilt head on top of the trunk, like ANYmal D's payload.
    let mut legs = quad();
    let mut head = leg("head", 0.25, 0.0);
    head.joints.truncate(2);
    head.joints[0].axis = [0.0, 0.0, 1.0];
    head.joints[0].xyz = [0.25, 0.0, 0.1];
    head.foot = None;
    legs.push(head);
    let inferred = infer_xml(&robot_xml(&legs, false)).unwrap();
    assert_eq!(inferred.joint_names(), STANDARD);
    assert_eq!(inferred.extra_joints, ["head_haa", "head_hfe"]);
    assert!(
        inferred
            .warnings
            .iter()
            .any(|w| w.contains("`head_haa` is not a leg")),
        "{:?}",
        inferred.warnings
    );
}

#[test]
fn root_with_a_single_moving_child_is_refused() {
    let xml = robot_xml(&quad(), false)
        .replace("<parent link=\"trunk\"/>", "<parent link=\"body\"/>")
        .replace(
            "</robot>",
            &format!(
                "{}<joint name=\"slide\" type=\"prismatic\"><parent link=\"trunk\"/><child link=\"body\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n</robot>",
                link_xml("body", 1.0, "<box size=\"0.1 0.1 0.1\"/>", false)
            ),
        );
    let msg = expect_err(&xml);
    assert!(
        msg.contains("single moving child `body` (joint `slide`)"),
        "{msg}"
    );
}
