//! Workspace tidiness, read from the manifests and sources (in the spirit of rust-analyzer's `tidy`):
//! project crates depend on each other only along the allowed graph below (ARCHITECTURE.md
//! "Dependency graph" shows the same list), every normal dependency is used by its crate's sources,
//! so an unused one (compile time on two cores) cannot creep back, and the crates that reach the
//! registry only over Zenoh do not link SQLite through another project crate.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Project crate → the project crates its `[dependencies]` may name.
const ALLOWED: &[(&str, &[&str])] = &[
    ("l3p-proto", &[]),
    ("l3p-net", &[]),
    ("l3p-robots", &[]),
    ("l3p-policy", &[]),
    ("l3p-registry-client", &["l3p-proto"]),
    ("l3p-registry", &["l3p-proto", "l3p-registry-client"]),
    (
        "l3p-learner",
        &["l3p-proto", "l3p-policy", "l3p-registry-client"],
    ),
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
            "l3p-registry-client",
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

/// Crates that must not link SQLite (`rusqlite`), not even through other project crates: they talk
/// to the registry over Zenoh with `l3p-registry-client`; only `l3p-registry` holds the store.
const WITHOUT_SQLITE: &[&str] = &[
    "l3p-registry-client",
    "l3p-learner",
    "l3p-actor",
    "l3p-deploy",
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

/// The project crates `start` links (itself included), following `[dependencies]` only: dev- and
/// build-dependencies do not end up in its library or binaries.
fn linked_project_crates<'a>(members: &'a [Member], start: &str) -> Vec<&'a Member> {
    let by_name: BTreeMap<&str, &Member> = members.iter().map(|m| (m.name.as_str(), m)).collect();
    let mut seen = BTreeSet::from([start]);
    let mut stack = vec![start];
    let mut linked = Vec::new();
    while let Some(name) = stack.pop() {
        let member = by_name
            .get(name)
            .unwrap_or_else(|| panic!("{name} is not a workspace member"));
        linked.push(*member);
        for dep in &member.dependencies {
            if by_name.contains_key(dep.as_str()) && seen.insert(dep.as_str()) {
                stack.push(dep.as_str());
            }
        }
    }
    linked
}

#[test]
fn zenoh_only_registry_users_do_not_link_sqlite() {
    let members = members();
    let sqlite_through = |start: &str| -> Vec<String> {
        linked_project_crates(&members, start)
            .into_iter()
            .filter(|m| m.dependencies.iter().any(|d| d == "rusqlite"))
            .map(|m| m.name.clone())
            .collect()
    };
    // The walk finds SQLite where it is: the CLI holds the store through `l3p-registry`.
    assert_eq!(sqlite_through("l3p-cli"), ["l3p-registry"]);
    let offenders: Vec<String> = WITHOUT_SQLITE
        .iter()
        .filter_map(|krate| {
            let through = sqlite_through(krate);
            (!through.is_empty()).then(|| format!("{krate} links rusqlite through {through:?}"))
        })
        .collect();
    assert!(
        offenders.is_empty(),
        "{offenders:#?}\nhint: depend on l3p-registry-client (the Zenoh client), not l3p-registry"
    );
}
