//! The shipped configs parse strictly; a misspelt key is an error naming it and the file; every
//! shipped experiment plans into arms whose configs are valid.

use std::path::{Path, PathBuf};

use l3p_cli::config::Config;

fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

#[test]
fn every_shipped_config_parses() {
    let mut count = 0;
    for entry in std::fs::read_dir(configs_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            Config::load(&path).unwrap_or_else(|e| panic!("{e}"));
            count += 1;
        }
    }
    assert!(count >= 1, "no configs found");
}

#[test]
fn every_shipped_experiment_plans() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut count = 0;
    for entry in std::fs::read_dir(root.join("experiments")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let spec = l3p_cli::experiment::ExperimentSpec::load(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let base = Config::load(&root.join(&spec.experiment.base_config)).unwrap();
            let arms = l3p_cli::experiment::plan(&spec, &base)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(!arms.is_empty(), "{}", path.display());
            count += 1;
        }
    }
    assert!(count >= 4, "experiments not found");
}

#[test]
fn reference_config_equals_the_defaults() {
    // The reference documents the defaults: if they drift apart, one of them is wrong.
    let reference = Config::load(&configs_dir().join("reference.toml")).unwrap();
    let defaults = Config {
        actors: reference.actors.clone(),
        ..Config::default()
    };
    assert_eq!(reference, defaults);
}

#[test]
fn misspelt_key_names_key_and_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, "[run]\nname = \"x\"\nsede = 3\n").unwrap();
    let err = Config::load(&path).unwrap_err().to_string();
    assert!(err.contains("sede"), "{err}");
    assert!(err.contains("bad.toml"), "{err}");
    assert!(err.contains("line 3"), "{err}");

    std::fs::write(&path, "[runn]\nname = \"x\"\n").unwrap();
    let err = Config::load(&path).unwrap_err().to_string();
    assert!(err.contains("runn"), "{err}");
}

#[test]
fn missing_file_is_a_clear_error() {
    let err = Config::load(Path::new("/nonexistent/l3p.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cannot read config /nonexistent/l3p.toml"),
        "{err}"
    );
}

/// Values that parse but used to hang `l3p train` (zero sizes, a zero physics step) or fail it only
/// after the actors had started (NaN rate, no minibatches, a negative discount): each is refused at
/// load with the key and the value.
#[test]
fn values_that_would_hang_or_fail_a_run_are_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.toml");
    let base = "[run]\nname = \"x\"\n";
    let actor = |envs: &str, threads: &str| {
        format!("[[actors]]\nrobot = \"a1\"\nenvs = {envs}\nthreads = {threads}\n")
    };
    let cases = [
        (actor("0", "1"), "actors[0].envs = 0"),
        (actor("4", "0"), "actors[0].threads = 0"),
        (
            format!("[env]\nsim_dt = 0.0\n{}", actor("4", "1")),
            "sim_dt",
        ),
        (
            format!("[env]\ndecimation = 0\n{}", actor("4", "1")),
            "decimation",
        ),
        (
            format!("[env]\naction_filter_alpha = 0.0\n{}", actor("4", "1")),
            "action_filter_alpha",
        ),
        (
            format!("[rollout]\nsteps_per_env = 0\n{}", actor("4", "1")),
            "rollout.steps_per_env = 0",
        ),
        (
            "[ppo]\nlearning_rate = nan\n".to_string(),
            "ppo.learning_rate = NaN",
        ),
        (
            "[ppo]\nnum_mini_batches = 0\n".to_string(),
            "ppo.num_mini_batches = 0",
        ),
        ("[ppo]\ngamma = -1.0\n".to_string(), "ppo.gamma = -1"),
        (
            format!("[ppo]\nnum_mini_batches = 64\n{}", actor("2", "1")),
            "ppo.num_mini_batches = 64",
        ),
        (
            "[learner]\ncheckpoint_every = 0\n".to_string(),
            "learner.checkpoint_every = 0",
        ),
        (actor("4", "1").replace("a1", "a2"), "actors[0].robot"),
    ];
    for (body, want) in cases {
        std::fs::write(&path, format!("{base}{body}")).unwrap();
        let err = Config::load(&path).unwrap_err().to_string();
        assert!(err.contains(want), "{body}: {err}");
        assert!(err.contains("odd.toml"), "{err}");
    }
    // The same file with sane values loads.
    std::fs::write(&path, format!("{base}{}", actor("4", "1"))).unwrap();
    Config::load(&path).unwrap();
}
