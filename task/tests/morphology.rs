//! The morphology map carries a joint motion of one robot to another as the same foot motion.

use l3p_robot::catalog::{NUM_JOINTS, RobotSpec};
use l3p_robot::math::Vec3;
use l3p_task::morphology::{TransferMap, foot_jacobians};

/// Foot positions (base frame) of `robot` at its default pose plus `delta` (canonical order).
fn feet(robot: &RobotSpec, delta: &[f32; NUM_JOINTS]) -> [Vec3; 4] {
    let model = robot.model().unwrap();
    let mut q = vec![0.0; model.bodies.len()];
    for (k, name) in robot.joint_names.iter().enumerate() {
        q[model.body_of_joint(name).unwrap()] = robot.default_pose[k] + delta[k];
    }
    let poses = model.body_poses(&q);
    robot.foot_links.map(|f| {
        let (b, offset) = model.body_of_link(f).unwrap();
        (poses[b] * offset).translation
    })
}

fn mat_vec(m: &[f32], v: &[f32]) -> Vec<f32> {
    let n = v.len();
    (0..m.len() / n)
        .map(|r| (0..n).map(|c| m[r * n + c] * v[c]).sum())
        .collect()
}

#[test]
fn a_robot_maps_to_itself_as_the_identity() {
    let a1 = RobotSpec::by_name("a1").unwrap();
    let map = TransferMap::new(a1, a1, false, true).unwrap();
    assert_eq!(map.obs_dim, 50);
    for r in 0..map.obs_dim {
        for c in 0..map.obs_dim {
            let want = if r == c { 1.0 } else { 0.0 };
            assert!(
                (map.observation[r * 50 + c] - want).abs() < 1e-3,
                "obs[{r},{c}]"
            );
        }
    }
    for r in 0..NUM_JOINTS {
        for c in 0..NUM_JOINTS {
            let want = if r == c { 1.0 } else { 0.0 };
            assert!(
                (map.action[r * NUM_JOINTS + c] - want).abs() < 1e-3,
                "act[{r},{c}]"
            );
        }
    }
}

/// The defining property on the pair that differs most (A1's knees all point backwards, ANYmal's
/// hind knees forwards; ANYmal's legs are twice as long): a small A1 joint motion, mapped, moves
/// each ANYmal foot as the A1 foot moved.
#[test]
fn a_mapped_joint_motion_moves_the_feet_alike() {
    let a1 = RobotSpec::by_name("a1").unwrap();
    for target in ["anymal_c", "spot", "go1"] {
        let target = RobotSpec::by_name(target).unwrap();
        let map = TransferMap::new(a1, target, false, true).unwrap();
        let ratio = target.action_scale / a1.action_scale;
        let delta_a1: [f32; NUM_JOINTS] = std::array::from_fn(|k| {
            0.02 * [1.0, -0.7, 0.5][k % 3] * if k < 6 { 1.0 } else { -1.0 }
        });
        // action map = (s_s / s_t) P, so P Δq = ratio · action · Δq.
        let mapped = mat_vec(&map.action, &delta_a1);
        let delta_target: [f32; NUM_JOINTS] = std::array::from_fn(|k| ratio * mapped[k]);
        let (a1_0, a1_1) = (feet(a1, &[0.0; NUM_JOINTS]), feet(a1, &delta_a1));
        let (t_0, t_1) = (
            feet(target, &[0.0; NUM_JOINTS]),
            feet(target, &delta_target),
        );
        for leg in 0..4 {
            let moved_a1 = a1_1[leg] - a1_0[leg];
            let moved_t = t_1[leg] - t_0[leg];
            assert!(moved_a1.length() > 0.003, "the A1 foot moves");
            assert!(
                (moved_a1 - moved_t).length() < 0.1 * moved_a1.length(),
                "{} leg {leg}: A1 foot moved {moved_a1:?}, mapped foot {moved_t:?}",
                target.name
            );
        }
        // The observation's joint blocks invert it: a target joint state reads as the A1 one.
        let n = map.obs_dim;
        let mut obs = vec![0.0; n];
        obs[12..24].copy_from_slice(&delta_target);
        let seen = mat_vec(&map.observation, &obs);
        for k in 0..NUM_JOINTS {
            assert!(
                (seen[12 + k] - delta_a1[k]).abs() < 1e-4,
                "{} joint {k}",
                target.name
            );
        }
    }
}

#[test]
fn anymal_hind_knees_run_the_other_way() {
    let anymal = RobotSpec::by_name("anymal_c").unwrap();
    let a1 = RobotSpec::by_name("a1").unwrap();
    let map = TransferMap::new(a1, anymal, false, false).unwrap();
    let knee = |leg: usize| map.action[(3 * leg + 2) * NUM_JOINTS + 3 * leg + 2];
    // Front knees bend the same way as A1's, hind knees the opposite way.
    assert!(
        knee(0) > 0.0 && knee(1) > 0.0,
        "front {} {}",
        knee(0),
        knee(1)
    );
    assert!(
        knee(2) < 0.0 && knee(3) < 0.0,
        "hind {} {}",
        knee(2),
        knee(3)
    );
    let j = foot_jacobians(anymal, &anymal.model().unwrap()).unwrap();
    assert!(j.iter().all(|m| m.determinant().abs() > 1e-4));
}
