//! Workspace tidiness, read from the manifests and sources (in the spirit of rust-analyzer's `tidy`):
//! project crates depend on each other only along the allowed graph (read from ARCHITECTURE.md
//! "Dependency graph", the one place it is written), every normal dependency is used by its crate's sources,
//! so an unused one (compile time on two cores) cannot creep back, and the crates that reach the
//! registry only over Zenoh do not link SQLite through another project crate, and the deploy
//! controller links neither the simulator nor the training stack — nor does `l3p-deploy`, the lean
//! binary that runs it on the robot (no viewer either).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Project crate → the project crates its `[dependencies]` may name, read from the one place the
/// graph is written: the indented block under ARCHITECTURE.md's "Dependency graph" heading, one
/// `crate → dep, dep` line per crate (short names: `robot` is `l3p-robot`; `(none…)` for none).
fn allowed_graph() -> Vec<(String, Vec<String>)> {
    let architecture = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let after = architecture
        .split_once("### Dependency graph")
        .expect("ARCHITECTURE.md has a \"### Dependency graph\" section")
        .1;
    let full = |short: &str| format!("l3p-{}", short.trim());
    let graph: Vec<(String, Vec<String>)> = after
        .lines()
        .skip_while(|l| !l.starts_with("    "))
        .take_while(|l| l.starts_with("    "))
        .map(|line| {
            let (krate, deps) = line
                .split_once('→')
                .unwrap_or_else(|| panic!("ARCHITECTURE.md graph line without `→`: {line:?}"));
            let deps = deps.trim();
            let deps = if deps.starts_with("(none") {
                Vec::new()
            } else {
                deps.split(',').map(full).collect()
            };
            (full(krate), deps)
        })
        .collect();
    assert!(graph.len() > 3, "ARCHITECTURE.md's graph block not found");
    graph
}

/// Crates that must not link SQLite (`rusqlite`), not even through other project crates: they talk
/// to the registry over Zenoh with `l3p-registry-client`; only `l3p-registry` holds the store.
const WITHOUT_SQLITE: &[&str] = &[
    "l3p-registry-client",
    "l3p-learner",
    "l3p-actor",
    "l3p-deploy",
    "l3p-deploy-bin",
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
    let graph = allowed_graph();
    let allowed: BTreeMap<&str, &[String]> = graph
        .iter()
        .map(|(k, deps)| (k.as_str(), deps.as_slice()))
        .collect();
    let members = members();
    let mut violations = Vec::new();
    for m in &members {
        let Some(may) = allowed.get(m.name.as_str()) else {
            violations.push(format!("{} is not in the allowed graph", m.name));
            continue;
        };
        for dep in m.dependencies.iter().filter(|d| d.starts_with("l3p-")) {
            if !may.contains(dep) {
                violations.push(format!("{} → {dep} is not an allowed edge", m.name));
            }
        }
    }
    assert_eq!(
        members.len(),
        graph.len(),
        "ARCHITECTURE.md's graph names a crate that is not a workspace member"
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

/// One `[dependencies]` entry with what decides whether and how it is linked.
struct DepSpec {
    name: String,
    optional: bool,
    default_features: bool,
    features: Vec<String>,
}

/// A crate's `[dependencies]`, `workspace = true` entries resolved against the workspace's table
/// (a member can add features to an inherited dependency, not turn its default features back on).
fn dependency_specs(manifest_dir: &Path) -> (Vec<DepSpec>, toml::Table) {
    let workspace: toml::Table = std::fs::read_to_string(root().join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let inherited = workspace["workspace"]["dependencies"]
        .as_table()
        .unwrap()
        .clone();
    let manifest: toml::Table = std::fs::read_to_string(manifest_dir.join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let strings = |v: Option<&toml::Value>| -> Vec<String> {
        v.and_then(|v| v.as_array())
            .map(|a| {
                a.iter()
                    .filter_map(|s| s.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default()
    };
    let specs = manifest
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|table| {
            table
                .iter()
                .map(|(name, entry)| {
                    let entry = entry.as_table().cloned().unwrap_or_default();
                    let base = if entry.get("workspace").and_then(|w| w.as_bool()) == Some(true) {
                        inherited
                            .get(name)
                            .and_then(|v| v.as_table())
                            .cloned()
                            .unwrap_or_default()
                    } else {
                        entry.clone()
                    };
                    let mut features = strings(base.get("features"));
                    features.extend(strings(entry.get("features")));
                    DepSpec {
                        name: name.clone(),
                        optional: entry.get("optional").and_then(|o| o.as_bool()) == Some(true),
                        default_features: base
                            .get("default-features")
                            .and_then(|d| d.as_bool())
                            .unwrap_or(true),
                        features,
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    (specs, manifest)
}

/// `requested` features of a crate closed over its `[features]` table (items such as `dep:x` and
/// other features' names included).
fn features_on(manifest: &toml::Table, requested: &BTreeSet<String>) -> BTreeSet<String> {
    let table = manifest
        .get("features")
        .and_then(|f| f.as_table())
        .cloned()
        .unwrap_or_default();
    let mut on = requested.clone();
    let mut stack: Vec<String> = on.iter().cloned().collect();
    while let Some(feature) = stack.pop() {
        let items = table.get(&feature).and_then(|v| v.as_array());
        for item in items.into_iter().flatten().filter_map(|i| i.as_str()) {
            if on.insert(item.to_string()) {
                stack.push(item.to_string());
            }
        }
    }
    on
}

/// `true` when `dep` is linked with these features on.
fn is_linked(dep: &DepSpec, on: &BTreeSet<String>) -> bool {
    !dep.optional || on.contains(&format!("dep:{}", dep.name))
}

/// Every package `start` links through project crates, with each project crate's features resolved
/// as cargo does for a build of `start` alone (the features every edge asks for, unified).
fn linked_packages(start: &str) -> BTreeSet<String> {
    let members = members();
    let dir_of: BTreeMap<&str, &Path> = members
        .iter()
        .map(|m| (m.name.as_str(), m.dir.as_path()))
        .collect();
    // Project crate → the features asked of it ("default" while its default features are on).
    let mut requested: BTreeMap<String, BTreeSet<String>> =
        BTreeMap::from([(start.to_string(), BTreeSet::from(["default".to_string()]))]);
    let mut grew = true;
    while grew {
        grew = false;
        for (krate, features) in requested.clone() {
            let (specs, manifest) = dependency_specs(dir_of[krate.as_str()]);
            let on = features_on(&manifest, &features);
            let project_deps = specs
                .iter()
                .filter(|d| dir_of.contains_key(d.name.as_str()));
            for dep in project_deps.filter(|d| is_linked(d, &on)) {
                let mut wanted: BTreeSet<String> = dep.features.iter().cloned().collect();
                if dep.default_features {
                    wanted.insert("default".into());
                }
                let entry = requested.entry(dep.name.clone()).or_default();
                let before = entry.len();
                entry.extend(wanted);
                grew |= entry.len() != before;
            }
        }
    }
    let mut linked = BTreeSet::new();
    for (krate, features) in &requested {
        let (specs, manifest) = dependency_specs(dir_of[krate.as_str()]);
        let on = features_on(&manifest, features);
        linked.insert(krate.clone());
        linked.extend(
            specs
                .iter()
                .filter(|d| is_linked(d, &on))
                .map(|d| d.name.clone()),
        );
    }
    linked
}

#[test]
fn robot_models_and_the_task_link_no_simulator() {
    for krate in ["l3p-robot", "l3p-task"] {
        let linked = linked_packages(krate);
        assert!(
            !linked.contains("rapier3d") && !linked.contains("l3p-sim"),
            "{krate} links the simulator: {linked:?}"
        );
    }
}

#[test]
fn the_deploy_controller_links_no_simulator_and_no_training_stack() {
    // The walk finds the simulator and burn where they are.
    let cli = linked_packages("l3p-cli");
    assert!(cli.contains("rapier3d") && cli.contains("burn"), "{cli:?}");
    let actor = linked_packages("l3p-actor");
    assert!(actor.contains("rapier3d"), "the actor simulates: {actor:?}");
    let deploy = linked_packages("l3p-deploy");
    let offenders: Vec<&str> = [
        "rapier3d",
        "burn",
        "rusqlite",
        "l3p-sim",
        "l3p-policy",
        "l3p-registry",
    ]
    .into_iter()
    .filter(|p| deploy.contains(*p))
    .collect();
    assert!(
        offenders.is_empty(),
        "l3p-deploy links {offenders:?} (through {deploy:?})\nhint: depend on l3p-infer (not \
         l3p-policy), on l3p-robot and l3p-task (not l3p-sim), and on l3p-registry-client"
    );
}

/// What `l3p-deploy` (package `l3p-deploy-bin`), the binary the robot computer runs, may not link:
/// the simulator, the tensor and training stack, the registry store, the viewer.
const NOT_IN_THE_LEAN_BINARY: &[&str] = &[
    "rapier3d",
    "l3p-sim",
    "burn",
    "rusqlite",
    "rerun",
    "l3p-policy",
    "l3p-learner",
    "l3p-actor",
    "l3p-registry",
];

#[test]
fn the_lean_deploy_binary_links_no_physics_learner_sqlite_or_viewer() {
    // The walk finds each of them where it is: `l3p` links them all (Rerun by default).
    let cli = linked_packages("l3p-cli");
    let missing: Vec<&str> = NOT_IN_THE_LEAN_BINARY
        .iter()
        .copied()
        .filter(|p| !cli.contains(*p))
        .collect();
    assert!(
        missing.is_empty(),
        "l3p-cli should link {missing:?}: {cli:?}"
    );
    let lean = linked_packages("l3p-deploy-bin");
    let offenders: Vec<&str> = NOT_IN_THE_LEAN_BINARY
        .iter()
        .copied()
        .filter(|p| lean.contains(*p))
        .collect();
    assert!(
        offenders.is_empty(),
        "l3p-deploy links {offenders:?} (through {lean:?})\nhint: the lean binary depends on \
         l3p-deploy, l3p-infer (not l3p-policy), l3p-robot (not l3p-sim) and l3p-registry-client; \
         what only `l3p` needs goes in l3p-cli"
    );
    // And it is a binary of that package: the one that `cargo build -p l3p-deploy-bin` makes.
    let manifest: toml::Table =
        std::fs::read_to_string(root().join("deploy-bin").join("Cargo.toml"))
            .unwrap()
            .parse()
            .unwrap();
    let bins: Vec<&str> = manifest["bin"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|b| b["name"].as_str())
        .collect();
    assert_eq!(bins, ["l3p-deploy"]);
}
