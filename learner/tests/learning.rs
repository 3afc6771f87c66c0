//! PPO learns the point-mass task (tests/common) in both architectures: the mean return of the
//! policy mean moves from its initial value to within 10% of the initial gap to the optimum.

mod common;

use common::*;
use l3p_learner::{Mode, Ppo, PpoConfig, TransferHeads, init_model};
use l3p_policy::{PolicyConfig, PolicyRobot, RecoveryConfig, train_device};
use rand::SeedableRng;
use rand::rngs::StdRng;

pub fn small_config() -> PolicyConfig {
    PolicyConfig {
        d_h: 16,
        d_z: 8,
        encoder_hidden: vec![64],
        core_hidden: vec![64],
        decoder_hidden: vec![32],
        mlp_hidden: vec![64, 64],
        critic_hidden: vec![64, 64],
        init_std: 1.0,
        recovery: RecoveryConfig {
            diffusion_steps: 10,
            obs_hidden: vec![64],
            act_hidden: vec![32],
            eval_samples: 64,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn learns(mode: Mode) {
    let device = train_device();
    let model = init_model(
        mode,
        small_config(),
        vec![PolicyRobot::new("pm", OBS, ACT)],
        None,
        TransferHeads::Fresh,
        &[],
        &device,
    )
    .unwrap();
    let cfg = PpoConfig {
        mode,
        seed: 3,
        ..Default::default()
    };
    let mut ppo = Ppo::new(cfg, model, device).unwrap();
    let mut env = PointMass::new(64, 7);
    let mut rng = StdRng::seed_from_u64(11);
    let optimum = optimal_return();
    let initial = eval_return(ppo.model());
    let gap = optimum - initial;
    assert!(
        gap > 2.0,
        "the task must leave room to learn: initial {initial}, optimum {optimum}"
    );
    let max_updates = 150;
    let mut last = initial;
    for it in 0..max_updates {
        let batch = collect(ppo.model(), &mut env, 16, &mut rng);
        let m = ppo.update(&batch).unwrap();
        assert!(m.approx_kl.is_finite() && m.value_loss.is_finite());
        if it % 10 == 9 {
            last = eval_return(ppo.model());
            eprintln!(
                "{mode:?} update {}: return {last:.3} (initial {initial:.3}, optimum {optimum:.3}) lr {:.2e} kl {:.4} std {:.3} ev {:.3} rec_obs {:.3} recon {:.3}/{:.3}",
                it + 1,
                m.learning_rate,
                m.approx_kl,
                m.mean_std,
                m.explained_variance,
                m.rec_obs_loss,
                m.recon_mse,
                m.recon_baseline_mse
            );
            if optimum - last < 0.10 * gap {
                return;
            }
        }
    }
    panic!(
        "{mode:?}: return {last} after {max_updates} updates, not within 10% of the gap ({gap}) to the optimum {optimum}"
    );
}

#[test]
fn mlp_ppo_reaches_near_optimal_return() {
    learns(Mode::Mlp);
}

#[test]
fn l3p_ppo_reaches_near_optimal_return() {
    learns(Mode::L3p);
}
