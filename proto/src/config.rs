//! Strict TOML loading shared by every config section: unknown or misspelt keys are errors that name
//! the key, the line and the file.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A config file that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid config {path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("invalid config {path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// Read and strictly parse a TOML file into `T` (whose structs use `deny_unknown_fields`).
pub fn load_toml<T: DeserializeOwned>(path: &Path) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_toml(&text, path)
}

/// Strictly parse TOML text; `path` only labels errors.
pub fn parse_toml<T: DeserializeOwned>(text: &str, path: &Path) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|err| {
        // toml's message names the unknown key and shows the offending line; prefix the line number.
        let line = err.span().map(|span| {
            text.as_bytes()[..span.start.min(text.len())]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1
        });
        let message = match line {
            Some(line) => format!("line {line}: {}", err.message()),
            None => err.message().to_string(),
        };
        ConfigError::Parse {
            path: path.to_path_buf(),
            message,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, Default)]
    #[serde(deny_unknown_fields, default)]
    struct Section {
        envs: usize,
        name: String,
    }

    #[derive(Debug, serde::Deserialize, Default)]
    #[serde(deny_unknown_fields, default)]
    struct File {
        actor: Section,
    }

    #[test]
    fn misspelt_key_is_named_with_file_and_line() {
        let text = "[actor]\nenvs = 4\nnmae = \"x\"\n";
        let err = parse_toml::<File>(text, Path::new("configs/x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("configs/x.toml"), "{err}");
        assert!(err.contains("nmae"), "{err}");
        assert!(err.contains("line 3"), "{err}");
    }

    #[test]
    fn defaults_fill_missing_keys() {
        let file: File = parse_toml("[actor]\nenvs = 4\n", Path::new("x.toml")).unwrap();
        assert_eq!(file.actor.envs, 4);
        assert_eq!(file.actor.name, "");
    }
}
