//! The data path of one training iteration without the network: a real rapier VecEnv stepped by the
//! actor's collector under an exported policy, the chunk through the wire codec and validation, then a
//! PPO update that changes the policy.

use l3p_actor::{Collector, RolloutEnv, sim_env};
use l3p_learner::{Mode, Ppo, PpoConfig, RolloutBatch, TransferHeads, init_model};
use l3p_policy::{DeployPolicy, PolicyConfig};
use l3p_proto::{RolloutChunk, codec};
use l3p_robot::catalog::RobotSpec;
use l3p_task::config::{EnvConfig, TerrainPreset};

#[test]
fn one_iteration_from_simulator_to_updated_policy() {
    let robot = RobotSpec::by_name("a1").unwrap();
    let mut env_config = EnvConfig::default();
    env_config.height_scan = false;
    env_config.terrain.preset = TerrainPreset::Flat;
    let env = sim_env(robot, &env_config, 4, 1, 3).unwrap();
    let (obs_dim, action_dim) = (env.obs_dim(), env.action_dim());
    assert_eq!((obs_dim, action_dim), (48, 12));

    let mut policy_config = PolicyConfig::default();
    policy_config.encoder_hidden = vec![32];
    policy_config.core_hidden = vec![32];
    policy_config.critic_hidden = vec![32];
    let spec = l3p_policy::PolicyRobot {
        name: "a1".into(),
        obs_dim,
        action_dim,
        action_scale: robot.action_scale,
        io: None,
    };
    let device = l3p_policy::train_device();
    let model = init_model(
        Mode::L3p,
        policy_config,
        vec![spec],
        None,
        TransferHeads::Fresh,
        &[],
        &device,
    )
    .unwrap();
    let mut ppo = Ppo::new(PpoConfig::default(), model, device).unwrap();
    let (export, _) = ppo.export("a1").unwrap();
    let policy = DeployPolicy::from_bytes(&export).unwrap();

    let mut collector = Collector::new(env, 11);
    let mut chunk = RolloutChunk::zeros(
        "run",
        "a1",
        "a1-0",
        ppo.iteration(),
        4,
        16,
        obs_dim,
        action_dim,
    );
    collector.collect(&policy, &mut chunk).unwrap();
    chunk.validate_dims(obs_dim, action_dim).unwrap();
    assert!(
        chunk.rewards.iter().any(|r| *r != 0.0),
        "the task pays rewards"
    );
    assert!(chunk.observations.iter().any(|o| *o != 0.0));
    // Behaviour log-probs match the policy's std: log N(a; μ, σ) summed over 12 dims.
    let std = policy.std();
    let expected: f32 = (0..action_dim)
        .map(|j| {
            let z = (chunk.actions[j] - chunk.action_means[j]) / std[j];
            -0.5 * z * z - std[j].ln() - 0.5 * (2.0 * std::f32::consts::PI).ln()
        })
        .sum();
    assert!(
        (chunk.log_probs[0] - expected).abs() < 1e-3,
        "{} vs {expected}",
        chunk.log_probs[0]
    );

    let decoded: RolloutChunk = codec::decode(&codec::encode(&chunk).unwrap()).unwrap();
    assert_eq!(decoded, chunk);
    let batch = RolloutBatch::from_chunks([&decoded]).unwrap();
    let metrics = ppo.update(&batch).unwrap();
    assert_eq!(ppo.iteration(), 1);
    assert!(
        metrics.approx_kl.is_finite() && metrics.total_loss.is_finite(),
        "{metrics:?}"
    );
    let updated = DeployPolicy::from_bytes(&ppo.export("a1").unwrap().0).unwrap();
    let obs = &chunk.observations[..obs_dim];
    assert_ne!(
        policy.act(obs).unwrap(),
        updated.act(obs).unwrap(),
        "the update changed the policy"
    );
}
