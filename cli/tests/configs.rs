//! The shipped configs parse strictly; a misspelt key is an error naming it and the file.

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
