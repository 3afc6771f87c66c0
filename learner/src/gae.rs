//! Generalised advantage estimation exactly as rsl_rl (`RolloutStorage.compute_returns`), with its
//! time-out bootstrapping, plus batch advantage normalisation and explained variance.

/// GAE over a `[T, N]` rollout (row-major, step-major).
///
/// - time-out bootstrap (rsl_rl): `r_t += γ · V(s_t) · truncated_t` — the value of the state the
///   action was taken in (rsl_rl issue #20);
/// - `done_t = terminated_t || truncated_t`;
/// - `δ_t = r_t + (1 − done_t) γ V_{t+1} − V_t`, `A_t = δ_t + (1 − done_t) γ λ A_{t+1}`,
///   `R_t = A_t + V_t`, with `V_T = last_values`.
///
/// Returns `(advantages, returns)`, both `[T, N]`.
pub fn compute_gae(
    rewards: &[f32],
    values: &[f32],
    last_values: &[f32],
    terminated: &[bool],
    truncated: &[bool],
    steps: usize,
    envs: usize,
    gamma: f32,
    lam: f32,
) -> (Vec<f32>, Vec<f32>) {
    let mut adv = vec![0f32; steps * envs];
    let mut ret = vec![0f32; steps * envs];
    let mut next_adv = vec![0f32; envs];
    for t in (0..steps).rev() {
        for e in 0..envs {
            let i = t * envs + e;
            let next_value = if t + 1 == steps {
                last_values[e]
            } else {
                values[i + envs]
            };
            let r = rewards[i] + if truncated[i] { gamma * values[i] } else { 0.0 };
            let not_done = if terminated[i] || truncated[i] {
                0.0
            } else {
                1.0
            };
            let delta = r + not_done * gamma * next_value - values[i];
            let a = delta + not_done * gamma * lam * next_adv[e];
            next_adv[e] = a;
            adv[i] = a;
            ret[i] = a + values[i];
        }
    }
    (adv, ret)
}

/// `(A − mean) / (std + 1e-8)` in place, std unbiased as `torch.std`.
pub fn normalize(adv: &mut [f32]) {
    let n = adv.len();
    if n < 2 {
        return;
    }
    let mean = adv.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
    let var = adv.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let std = var.sqrt();
    for a in adv.iter_mut() {
        *a = ((*a as f64 - mean) / (std + 1e-8)) as f32;
    }
}

/// Explained variance `1 − Var(R − V) / Var(R)` (NaN-free: 0 when `Var(R)` is 0).
pub fn explained_variance(values: &[f32], returns: &[f32]) -> f32 {
    let n = returns.len().max(1) as f64;
    let mean = |v: &mut dyn Iterator<Item = f64>| v.sum::<f64>() / n;
    let mr = mean(&mut returns.iter().map(|&x| x as f64));
    let vr = mean(&mut returns.iter().map(|&x| (x as f64 - mr).powi(2)));
    let md = mean(&mut returns.iter().zip(values).map(|(&r, &v)| (r - v) as f64));
    let vd = mean(
        &mut returns
            .iter()
            .zip(values)
            .map(|(&r, &v)| ((r - v) as f64 - md).powi(2)),
    );
    if vr <= 1e-12 {
        0.0
    } else {
        (1.0 - vd / vr) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gae_matches_hand_computation() {
        // T = 3, N = 1, γ = 0.5, λ = 0.5; truncated at t = 1, no termination.
        let rewards = [1.0, 2.0, 3.0];
        let values = [0.5, 1.0, 2.0];
        let last = [4.0];
        let term = [false, false, false];
        let trunc = [false, true, false];
        let (adv, ret) = compute_gae(&rewards, &values, &last, &term, &trunc, 3, 1, 0.5, 0.5);
        // t=2: δ = 3 + 0.5*4 − 2 = 3; A2 = 3
        // t=1: r = 2 + 0.5*1.0 = 2.5 (time-out bootstrap), done → δ = 2.5 − 1 = 1.5; A1 = 1.5
        // t=0: δ = 1 + 0.5*1.0 − 0.5 = 1.0; A0 = 1.0 + 0.25*1.5 = 1.375
        let want_adv = [1.375, 1.5, 3.0];
        for i in 0..3 {
            assert!((adv[i] - want_adv[i]).abs() < 1e-6, "adv {adv:?}");
            assert!(
                (ret[i] - (want_adv[i] + values[i])).abs() < 1e-6,
                "ret {ret:?}"
            );
        }
    }

    #[test]
    fn termination_cuts_bootstrap_per_env() {
        // T = 2, N = 2; env 0 terminates at t = 0, env 1 runs on. γ = 1, λ = 1.
        let rewards = [1.0, 1.0, 1.0, 1.0];
        let values = [0.0; 4];
        let last = [10.0, 10.0];
        let term = [true, false, false, false];
        let trunc = [false; 4];
        let (adv, _) = compute_gae(&rewards, &values, &last, &term, &trunc, 2, 2, 1.0, 1.0);
        assert_eq!(adv, vec![1.0, 12.0, 11.0, 11.0]);
    }

    #[test]
    fn normalisation_and_explained_variance() {
        let mut a = vec![1.0, 2.0, 3.0, 4.0];
        normalize(&mut a);
        let mean: f32 = a.iter().sum::<f32>() / 4.0;
        assert!(mean.abs() < 1e-6);
        // unbiased std of [1,2,3,4] is 1.2910; (1 − 2.5)/1.2910 = −1.1619
        assert!((a[0] + 1.161_895).abs() < 1e-4, "{a:?}");
        assert!((explained_variance(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]) - 1.0).abs() < 1e-6);
        assert!(explained_variance(&[2.0, 2.0, 2.0], &[1.0, 2.0, 3.0]).abs() < 1e-6);
    }
}
