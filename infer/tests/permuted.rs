//! `DeployPolicy::permuted` folds signed permutations of observations and actions into the export
//! exactly: `π'(o) = M_a π(M_o o)`, twice the mirror is the policy itself, bad maps are refused.
//! `DeployPolicy::averaged` is the mean of two policies as one wider MLP; with the mirror image it
//! is exactly equivariant.

use std::path::Path;

use l3p_infer::DeployPolicy;

const EXPORT_DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../docs/a1-flat-session27/policy"
);

/// A signed permutation that is its own inverse: pairs swapped, every other sign flipped.
fn involution(n: usize) -> (Vec<usize>, Vec<f32>) {
    let index = (0..n)
        .map(|i| {
            if i + 1 < n && i % 2 == 0 {
                i + 1
            } else if i % 2 == 1 {
                i - 1
            } else {
                i
            }
        })
        .collect();
    let sign = (0..n).map(|i| if i % 4 < 2 { -1.0 } else { 1.0 }).collect();
    (index, sign)
}

fn apply(index: &[usize], sign: &[f32], x: &[f32]) -> Vec<f32> {
    x.chunks(index.len())
        .flat_map(|row| {
            index
                .iter()
                .zip(sign)
                .map(|(&j, s)| s * row[j])
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn a_permuted_policy_acts_as_the_maps_say_and_twice_is_the_original() {
    let policy = DeployPolicy::load(Path::new(EXPORT_DIR)).unwrap();
    let (d, a) = (policy.obs_dim(), policy.action_dim());
    let (oi, os) = involution(d);
    let (ai, asg) = involution(a);
    let mirrored = policy.permuted(&oi, &os, &ai, &asg).unwrap();
    let obs: Vec<f32> = (0..3 * d).map(|i| (i as f32 * 0.61).sin()).collect();
    let want = apply(&ai, &asg, &policy.act(&apply(&oi, &os, &obs)).unwrap());
    let got = mirrored.act(&obs).unwrap();
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-5, "{g} vs {w}");
    }
    let twice = mirrored.permuted(&oi, &os, &ai, &asg).unwrap();
    assert_eq!(twice.act(&obs).unwrap(), policy.act(&obs).unwrap());
    let std: Vec<f32> = ai.iter().map(|&j| policy.std()[j]).collect();
    assert_eq!(mirrored.std(), &std[..]);
    // Not a permutation, or the wrong size: refused with the size named.
    let mut repeated = oi.clone();
    repeated[1] = repeated[0];
    let err = policy
        .permuted(&repeated, &os, &ai, &asg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a permutation"), "{err}");
    assert!(policy.permuted(&oi, &os, &ai[..a - 1], &asg).is_err());
}

#[test]
fn a_policy_averaged_with_its_mirror_is_exactly_symmetric() {
    let policy = DeployPolicy::load(Path::new(EXPORT_DIR)).unwrap();
    let (d, a) = (policy.obs_dim(), policy.action_dim());
    let (oi, os) = involution(d);
    let (ai, asg) = involution(a);
    let mirrored = policy.permuted(&oi, &os, &ai, &asg).unwrap();
    let both = policy.averaged(&mirrored).unwrap();
    let obs: Vec<f32> = (0..3 * d).map(|i| (i as f32 * 0.37).cos()).collect();
    // The mean of the two, from one network.
    let (p, m) = (policy.act(&obs).unwrap(), mirrored.act(&obs).unwrap());
    for ((g, x), y) in both.act(&obs).unwrap().iter().zip(&p).zip(&m) {
        assert!(
            (g - 0.5 * (x + y)).abs() < 1e-5,
            "{g} vs mean of {x} and {y}"
        );
    }
    // Equivariant: acting on the mirrored observation gives the mirrored action.
    let want = apply(&ai, &asg, &both.act(&obs).unwrap());
    let got = both.act(&apply(&oi, &os, &obs)).unwrap();
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-5, "{g} vs {w}");
    }
    // The original is not.
    let want = apply(&ai, &asg, &p);
    let got = policy.act(&apply(&oi, &os, &obs)).unwrap();
    assert!(got.iter().zip(&want).any(|(g, w)| (g - w).abs() > 1e-3));
    // It writes as an export and reads back the same.
    let back = DeployPolicy::from_bytes(&both.to_bytes().unwrap()).unwrap();
    assert_eq!(back.act(&obs).unwrap(), both.act(&obs).unwrap());
    assert_eq!(
        back.config.layers[0].output,
        2 * policy.config.layers[0].output
    );
    // Shapes must match.
    let wider = both.averaged(&both).unwrap();
    assert!(policy.averaged(&wider).is_err());
}
