//! A seeded backend makes a fresh model a function of the seed (the learner daemon seeds it with
//! `[ppo] seed` before building the model; experiment arms set it to the arm's seed). Alone in its
//! own test binary: the backend's RNG is process-global, so a concurrent test drawing from it
//! between the seeding and the init would make this flaky.

use l3p_learner::{Mode, TransferHeads, init_model};
use l3p_policy::{PolicyConfig, PolicyRobot, core_sha256, train_device};

fn fresh_core_hash(seed: u64) -> String {
    let device = train_device();
    device.seed(seed);
    let model = init_model(
        Mode::L3p,
        PolicyConfig {
            d_h: 8,
            d_z: 4,
            encoder_hidden: vec![16],
            core_hidden: vec![16],
            decoder_hidden: vec![16],
            critic_hidden: vec![16],
            ..Default::default()
        },
        vec![PolicyRobot::new("pm", 6, 2)],
        None,
        TransferHeads::Fresh,
        &[],
        &device,
    )
    .unwrap();
    core_sha256(&model.net).unwrap()
}

#[test]
fn the_same_seed_builds_the_same_weights_and_another_seed_other_weights() {
    let first = fresh_core_hash(7);
    assert_eq!(first, fresh_core_hash(7));
    assert_ne!(first, fresh_core_hash(8));
}
