//! Workspace tidiness, read from the manifests and sources (in the spirit of rust-analyzer's `tidy`):
//! project crates depend on each other only along the allowed graph below (ARCHITECTURE.md
//! "Dependency graph" shows the same list), and every normal dependency is used by its crate's
//! sources, so an unused one (compile time on two cores) cannot creep back.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Project crate → the project crates its `[dependencies]` may name.
const ALLOWED: &[(&str, &[&str])] = &[
    ("l3p-proto", &[]),
    ("l3p-net", &[]),
    ("l3p-robots", &[]),
    ("l3p-policy", &[]),
    ("l3p-registry", &["l3p-proto"]),
    ("l3p-learner", &["l3p-proto", "l3p-policy", "l3p-registry"]),
    (
        "l3p-actor",
        &["l3p-proto", "l3p-net", "l3p-policy", "l3p-robots"],
    ),
    (
        "l3p-deploy",
        &[
            "l3p-proto",
            "l3p-net",
            "l3p-policy",
            "l3p-robots",
            "l3p-registry",
        ],
    ),
    (
        "l3p-cli",
        &[
            "l3p-proto",
            "l3p-net",
            "l3p-robots",
            "l3p-policy",
            "l3p-learner",
            "l3p-actor",
            "l3p-registry",
            "l3p-deploy",
        ],
    ),
    ("l3p-tests", &[]),
];

/// Dependencies present for their features or for a dependency's build, not named in the source.
const USED_WITHOUT_NAMING: &[(&str, &str, &str)] = &[(
    "l3p-policy",
    "gemm",
    "turns on the AVX-512 kernels of the gemm crate that burn-flex calls",
)];

/// Packages whose library name is not the package name with `-` → `_`.
const LIBRARY_NAMES: &[(&str, &str)] = &[("xml-rs", "xml")];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

struct Member {
    name: String,
    dir: PathBuf,
    dependencies: Vec<String>,
}

fn members() -> Vec<Member> {
    let workspace: toml::Table = std::fs::read_to_string(root().join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let list = workspace["workspace"]["members"].as_array().unwrap();
    list.iter()
        .map(|m| {
            let dir = root().join(m.as_str().unwrap());
            let manifest: toml::Table = std::fs::read_to_string(dir.join("Cargo.toml"))
                .unwrap()
                .parse()
                .unwrap();
            let name = manifest["package"]["name"].as_str().unwrap().to_string();
            let dependencies = manifest
                .get("dependencies")
                .and_then(|d| d.as_table())
                .map(|t| t.keys().cloned().collect())
                .unwrap_or_default();
            Member {
                name,
                dir,
                dependencies,
            }
        })
        .collect()
}

fn rust_sources(dir: &Path, out: &mut String) {
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push_str(&std::fs::read_to_string(&path).unwrap());
        }
    }
}

#[test]
fn project_crates_depend_only_along_the_allowed_graph() {
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    let members = members();
    let mut violations = Vec::new();
    for m in &members {
        let Some(may) = allowed.get(m.name.as_str()) else {
            violations.push(format!("{} is not in the allowed graph", m.name));
            continue;
        };
        for dep in m.dependencies.iter().filter(|d| d.starts_with("l3p-")) {
            if !may.contains(&dep.as_str()) {
                violations.push(format!("{} → {dep} is not an allowed edge", m.name));
            }
        }
    }
    assert_eq!(
        members.len(),
        ALLOWED.len(),
        "a crate is missing from ALLOWED"
    );
    assert!(violations.is_empty(), "{violations:#?}");
}

#[test]
fn every_normal_dependency_is_used_by_its_crate() {
    let mut unused = Vec::new();
    for m in members() {
        let mut sources = String::new();
        let src = m.dir.join("src");
        if src.exists() {
            rust_sources(&src, &mut sources);
        }
        for dep in &m.dependencies {
            if USED_WITHOUT_NAMING
                .iter()
                .any(|(c, d, _)| *c == m.name && d == dep)
            {
                continue;
            }
            let ident = LIBRARY_NAMES
                .iter()
                .find(|(package, _)| package == dep)
                .map_or_else(|| dep.replace('-', "_"), |(_, lib)| lib.to_string());
            let named = sources.match_indices(&ident).any(|(i, _)| {
                let before = sources[..i].chars().next_back();
                let after = sources[i + ident.len()..].chars().next();
                let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
                !word(before) && !word(after)
            });
            if !named {
                unused.push(format!("{}: {dep}", m.name));
            }
        }
    }
    assert!(
        unused.is_empty(),
        "dependencies not named in their crate's src/ (remove them, or move them to \
         [dev-dependencies], or list them in USED_WITHOUT_NAMING with the reason): {unused:#?}"
    );
}
