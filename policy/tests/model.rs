//! Policy modules: distribution maths, ELU, parameter budgets, multi-robot batching, diffusion
//! recovery, checkpoints and exports (including a reload in a fresh process).

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Tensor, TensorData};
use l3p_policy::diffusion::ObsDiffusionConfig;
use l3p_policy::nets::MlpConfig;
use l3p_policy::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn t2(v: Vec<f32>, r: usize, c: usize, d: &burn::tensor::Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(v, [r, c]), d)
}

fn small() -> PolicyConfig {
    PolicyConfig {
        d_h: 8,
        d_z: 4,
        encoder_hidden: vec![16],
        core_hidden: vec![16],
        decoder_hidden: vec![8],
        mlp_hidden: vec![16, 16],
        critic_hidden: vec![16],
        recovery: RecoveryConfig {
            diffusion_steps: 5,
            obs_hidden: vec![16],
            act_hidden: vec![8],
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn gaussian_log_prob_and_entropy_match_hand_values() {
    let d = cpu_device();
    // a = [1, 0], μ = [0, 0], σ = [1, 2]:
    // log p = −½(1² + 0²) − ln 1 − ln 2 − ln 2π = −0.5 − 0.693147 − 1.837877 = −3.031024
    let lp = gaussian_log_prob(
        t2(vec![1.0, 0.0], 1, 2, &d),
        t2(vec![0.0, 0.0], 1, 2, &d),
        Tensor::from_data(TensorData::new(vec![1.0f32, 2.0], [2]), &d),
    );
    let lp = tensor_to_vec(lp).unwrap();
    assert!((lp[0] + 3.031_024).abs() < 1e-5, "{lp:?}");
    // H = Σ ½ + ½ ln 2π + ln σ = 2·1.418939 + ln 2 = 3.531024
    let h = tensor_to_vec(gaussian_entropy(Tensor::from_data(
        TensorData::new(vec![1.0f32, 2.0], [2]),
        &d,
    )))
    .unwrap();
    assert!((h[0] - 3.531_024).abs() < 1e-5, "{h:?}");
}

#[test]
fn elu_rewrite_matches_definition_and_gradient() {
    let d = train_device();
    let xs = vec![-3.0f32, -0.5, 0.0, 0.5, 2.0];
    let x = Tensor::<1>::from_data(TensorData::new(xs.clone(), [5]), &d).require_grad();
    let y = elu(x.clone());
    let grads = y.clone().sum().backward();
    let g = tensor_to_vec(x.grad(&grads).unwrap()).unwrap();
    let y = tensor_to_vec(y).unwrap();
    for (i, &v) in xs.iter().enumerate() {
        let want = if v > 0.0 { v } else { v.exp() - 1.0 };
        let want_g = if v > 0.0 { 1.0 } else { v.exp() };
        assert!((y[i] - want).abs() < 1e-6, "elu({v}) = {}", y[i]);
        if v != 0.0 {
            assert!((g[i] - want_g).abs() < 1e-6, "elu'({v}) = {}", g[i]);
        }
    }
}

#[test]
fn parameter_counts_and_matched_mlp_budget() {
    let d = cpu_device();
    let cfg = PolicyConfig::default();
    let model = PolicyModel::new(cfg.clone(), vec![PolicyRobot::new("a1", 48, 12)], &d).unwrap();
    let report = model.param_report();
    assert!(
        report.contains("core") && report.contains("a1.r_obs"),
        "{report}"
    );
    // Counted from sizes = counted from the module.
    let counts = model.param_counts();
    let get = |n: &str| counts.iter().find(|(k, _)| k == n).unwrap().1;
    assert_eq!(
        get("core") + get("a1.encoder") + get("a1.decoder") + get("a1.std"),
        cfg.actor_params(48, 12)
    );
    assert_eq!(get("a1.encoder"), mlp_params(48, &[512], 64));
    // Matched MLP budget within 1%.
    let hidden = cfg.matched_mlp_hidden(48, 12);
    let mlp = PolicyConfig {
        arch: Arch::Mlp,
        mlp_hidden: hidden.clone(),
        ..cfg.clone()
    };
    let (a, b) = (
        mlp.actor_params(48, 12) as f64,
        cfg.actor_params(48, 12) as f64,
    );
    assert!((a - b).abs() / b < 0.01, "mlp {hidden:?}: {a} vs l3p {b}");
}

#[test]
fn config_toml_is_strict_and_defaults_fill_in() {
    let cfg: PolicyConfig = toml::from_str("d_h = 32\n[recovery]\nlambda = 0.5\n").unwrap();
    assert_eq!(cfg.d_h, 32);
    assert_eq!(cfg.d_z, 16);
    assert_eq!(cfg.recovery.lambda, 0.5);
    let err = toml::from_str::<PolicyConfig>("d_hh = 32\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("d_hh"), "{err}");
    assert!(
        PolicyConfig {
            d_h: 0,
            ..Default::default()
        }
        .validate()
        .is_err()
    );
}

#[test]
fn several_robots_share_the_core_in_one_batch() {
    let d = cpu_device();
    let robots = vec![PolicyRobot::new("a1", 6, 3), PolicyRobot::new("spot", 5, 2)];
    let model = PolicyModel::new(small(), robots, &d).unwrap();
    let mut rng = StdRng::seed_from_u64(1);
    let oa: Vec<f32> = (0..4 * 6).map(|_| rng.random_range(-1.0..1.0)).collect();
    let ob: Vec<f32> = (0..3 * 5).map(|_| rng.random_range(-1.0..1.0)).collect();
    let outs = model.net.actors(vec![
        Some(t2(oa.clone(), 4, 6, &d)),
        Some(t2(ob.clone(), 3, 5, &d)),
    ]);
    let ma = tensor_to_vec(outs[0].clone().unwrap().mean).unwrap();
    let mb = tensor_to_vec(outs[1].clone().unwrap().mean).unwrap();
    assert_eq!((ma.len(), mb.len()), (12, 6));
    // Same as running each robot alone.
    let sa = model.act_mean_host(0, &oa).unwrap();
    let sb = model.act_mean_host(1, &ob).unwrap();
    for (x, y) in ma.iter().zip(&sa).chain(mb.iter().zip(&sb)) {
        assert!((x - y).abs() < 1e-5);
    }
    assert!(model.act_mean_host(0, &oa[..5]).is_err());
    assert!(
        model
            .robot_index("go2")
            .unwrap_err()
            .to_string()
            .contains("a1, spot")
    );
}

/// Observations that are a nonlinear function of a 2-D latent factor.
fn synthetic_obs(rng: &mut StdRng, n: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(n * 6);
    for _ in 0..n {
        let (u, w): (f32, f32) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        v.extend_from_slice(&[
            u,
            w,
            (2.0 * u).sin(),
            u * w,
            w.abs() - 0.5,
            (u + w).cos() - 0.5,
        ]);
    }
    v
}

#[test]
fn diffusion_recovery_beats_the_mean_predictor() {
    let d = train_device();
    let mut rng = StdRng::seed_from_u64(5);
    let recovery = RecoveryConfig {
        diffusion_steps: 20,
        obs_hidden: vec![128, 128],
        ..Default::default()
    };
    let mut enc = MlpConfig::new(6, &[64], 8).init(&d);
    let mut diff = ObsDiffusionConfig {
        obs_dim: 6,
        cond_dim: 8,
        recovery,
    }
    .init(&d);
    let mut opt_e = AdamConfig::new().init();
    let mut opt_d = AdamConfig::new().init();
    for _ in 0..1500 {
        let x = t2(synthetic_obs(&mut rng, 128), 128, 6, &d);
        let h = enc.forward(x.clone());
        let loss = diff.loss(x, h, &mut rng);
        let mut grads = loss.backward();
        let ge = GradientsParams::from_module(&mut grads, &enc);
        let gd = GradientsParams::from_module(&mut grads, &diff);
        enc = opt_e.step(2e-3, enc, ge);
        diff = opt_d.step(2e-3, diff, gd);
    }
    let test = synthetic_obs(&mut rng, 512);
    let x = t2(test.clone(), 512, 6, &d).inner();
    let (enc, diff) = (enc.valid(), diff.valid());
    let rec = tensor_to_vec(diff.sample(enc.forward(x), &mut rng)).unwrap();
    let mse: f32 = test
        .iter()
        .zip(&rec)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f32>()
        / test.len() as f32;
    let mut mean = [0f32; 6];
    for row in test.chunks_exact(6) {
        for k in 0..6 {
            mean[k] += row[k] / 512.0;
        }
    }
    let base: f32 = test
        .iter()
        .enumerate()
        .map(|(i, a)| (a - mean[i % 6]).powi(2))
        .sum::<f32>()
        / test.len() as f32;
    eprintln!("diffusion recon mse {mse:.4}, mean-predictor mse {base:.4}");
    assert!(
        mse < 0.2 * base,
        "reconstruction {mse} is not well below the mean predictor {base}"
    );
}

#[test]
fn checkpoint_round_trip_gives_identical_actions() {
    let d = train_device();
    let model = PolicyModel::new(small(), vec![PolicyRobot::new("go1", 6, 3)], &d).unwrap();
    let obs: Vec<f32> = (0..5 * 6).map(|i| (i as f32 * 0.37).sin()).collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ck.bin");
    save_checkpoint(
        &path,
        &model,
        &[],
        42,
        serde_json::json!({"learning_rate": 0.001}),
    )
    .unwrap();
    let ck = load_checkpoint(&path, &d).unwrap();
    assert_eq!(ck.iteration, 42);
    assert_eq!(ck.model.robots, model.robots);
    assert_eq!(
        ck.model.act_mean_host(0, &obs).unwrap(),
        model.act_mean_host(0, &obs).unwrap()
    );
    // Corrupt input is an error, not a panic.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() / 2);
    assert!(checkpoint_from_bytes(&bytes, &d).is_err());
    assert!(
        checkpoint_from_bytes(b"garbage", &d)
            .unwrap_err()
            .to_string()
            .contains("magic")
    );
}

const CHILD_ENV: &str = "L3P_EXPORT_CHILD_DIR";

fn export_obs() -> Vec<f32> {
    (0..7 * 6).map(|i| (i as f32 * 0.61).cos() * 1.5).collect()
}

/// Helper run by `export_reloads_in_a_fresh_process` in a child process.
#[test]
#[ignore = "run by export_reloads_in_a_fresh_process in a child process"]
fn export_child_process() {
    let dir = std::path::PathBuf::from(std::env::var(CHILD_ENV).expect("set by the parent test"));
    let policy = DeployPolicy::load(&dir).unwrap();
    let actions = policy.act(&export_obs()).unwrap();
    let bytes: Vec<u8> = actions.iter().flat_map(|a| a.to_le_bytes()).collect();
    std::fs::write(dir.join("child_actions.bin"), bytes).unwrap();
}

#[test]
fn export_reloads_in_a_fresh_process() {
    let d = cpu_device();
    for arch in [Arch::L3p, Arch::Mlp] {
        let model = PolicyModel::new(
            PolicyConfig { arch, ..small() },
            vec![PolicyRobot::new("go1", 6, 3)],
            &d,
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let cfg = export_to_dir(&model, "go1", dir.path()).unwrap();
        assert_eq!(cfg.layers.last().unwrap().output, 3);
        assert_eq!(cfg.core_sha256.is_some(), arch == Arch::L3p);
        let status = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--ignored",
                "--exact",
                "export_child_process",
                "--test-threads",
                "1",
            ])
            .env(CHILD_ENV, dir.path())
            .status()
            .unwrap();
        assert!(status.success());
        let child: Vec<f32> = std::fs::read(dir.path().join("child_actions.bin"))
            .unwrap()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        // Bit-identical to the in-process pure-Rust path on the same export …
        let (bytes, _) = export_bytes(&model, "go1").unwrap();
        let here = DeployPolicy::from_bytes(&bytes)
            .unwrap()
            .act(&export_obs())
            .unwrap();
        assert_eq!(child, here);
        // … and equal to burn's forward up to float rounding.
        let burn = model.act_mean_host(0, &export_obs()).unwrap();
        for (a, b) in child.iter().zip(&burn) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // The JSON beside the weights is the same config.
        assert_eq!(
            l3p_policy::export::read_export_json(dir.path()).unwrap(),
            cfg
        );
    }
}

#[test]
fn bad_exports_are_errors() {
    assert!(DeployPolicy::from_bytes(b"not safetensors").is_err());
    let d = cpu_device();
    let model = PolicyModel::new(small(), vec![PolicyRobot::new("go1", 6, 3)], &d).unwrap();
    let (bytes, _) = export_bytes(&model, "go1").unwrap();
    let p = DeployPolicy::from_bytes(&bytes).unwrap();
    assert!(
        p.act(&[0.0; 5])
            .unwrap_err()
            .to_string()
            .contains("obs_dim 6")
    );
    assert!(export_bytes(&model, "spot").is_err());
}

/// A large batch runs in parallel row blocks; every row must equal the same row run alone.
#[test]
fn parallel_batch_inference_equals_row_by_row() {
    let d = cpu_device();
    let model = PolicyModel::new(small(), vec![PolicyRobot::new("go1", 6, 3)], &d).unwrap();
    let (bytes, _) = export_bytes(&model, "go1").unwrap();
    let p = DeployPolicy::from_bytes(&bytes).unwrap();
    let n = 301; // not a multiple of the block size
    let obs: Vec<f32> = (0..n * 6).map(|i| (i as f32 * 0.37).sin() * 2.0).collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let batch = pool.install(|| p.act(&obs).unwrap());
    assert_eq!(batch.len(), n * 3);
    for r in [0, 1, 63, 64, 127, 128, 200, 300] {
        let alone = p.act(&obs[r * 6..(r + 1) * 6]).unwrap();
        assert_eq!(&batch[r * 3..(r + 1) * 3], alone.as_slice(), "row {r}");
    }
}
