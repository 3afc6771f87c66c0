//! The Zenoh configs under `deploy/zenoh/` (DESIGN §8–9): every file parses with the Zenoh version
//! we build against, the ACL denies by default and gives the robot-command key to the deploy
//! controller alone, and — when `openssl` is installed — a router started from `router-acl.json5`
//! with generated certificates really enforces that over mutual TLS, for clients set up by
//! `client-tls.json5` and by an l3p config's `[zenoh.tls]` alike.
//!
//! `zenoh::Config::from_file` checks the JSON5 syntax and the schema (unknown keys, types, enum
//! values) but does not open the TLS files it names: they are read when a TLS link is set up. The
//! configs point at `/etc/l3p/certs/...`, which does not exist here, so the parse tests use the files
//! as they are and the enforcement test replaces the paths with certificates made in a temp dir.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use zenoh::key_expr::KeyExpr;
use zenoh::{Config, Session, Wait};

fn deploy_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn zenoh_file(name: &str) -> PathBuf {
    deploy_dir().join("zenoh").join(name)
}

fn load(path: &Path) -> Config {
    Config::from_file(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn get(config: &Config, key: &str) -> Value {
    let text = config
        .get_json(key)
        .unwrap_or_else(|e| panic!("{key}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{key}: {e}: {text}"))
}

/// Every `deploy/zenoh/*.json5`, sorted.
fn json5_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(deploy_dir().join("zenoh"))
        .expect("deploy/zenoh exists")
        .map(|entry| entry.expect("readable dir entry").path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "json5"))
        .collect();
    files.sort();
    files
}

#[test]
fn every_zenoh_config_parses() {
    let files = json5_files();
    let names: BTreeSet<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for expected in [
        "router.json5",
        "router-tls.json5",
        "router-acl.json5",
        "client-tls.json5",
        "peer-tls.json5",
    ] {
        assert!(
            names.contains(expected),
            "deploy/zenoh/{expected} is missing"
        );
    }
    for file in &files {
        let config = load(file);
        let mode = get(&config, "mode");
        assert!(
            ["router", "peer", "client"].contains(&mode.as_str().unwrap_or("")),
            "{}: mode {mode}",
            file.display()
        );
    }
}

/// Zenoh allocates `transport/link/rx/buffer_size` of receive buffers up front for every link: a
/// router with 16 MiB there grew by megabytes per client reconnect, +109 MiB/h in the one-hour soak
/// (BENCHMARKS.md). Every shipped file keeps Zenoh's default, one batch; `l3p router` warns about
/// more.
#[test]
fn no_config_allocates_more_than_one_batch_per_link() {
    for file in json5_files() {
        let size = get(&load(&file), "transport/link/rx/buffer_size");
        assert!(
            size.as_u64()
                .is_some_and(|bytes| bytes <= l3p_net::DEFAULT_RX_BUFFER_SIZE),
            "{}: rx buffer_size {size}",
            file.display()
        );
    }
}

#[test]
fn tls_configs_use_mutual_tls_and_verify_names() {
    for (name, mode, side) in [
        ("router-tls.json5", "router", "listen"),
        ("router-acl.json5", "router", "listen"),
        ("client-tls.json5", "client", "connect"),
        ("peer-tls.json5", "peer", "connect"),
    ] {
        let config = load(&zenoh_file(name));
        assert_eq!(get(&config, "mode"), mode, "{name}");
        let tls = get(&config, "transport/link/tls");
        for key in [
            "root_ca_certificate",
            &format!("{side}_certificate"),
            &format!("{side}_private_key"),
        ] {
            assert!(
                tls[key].is_string(),
                "{name}: transport/link/tls/{key} is not set"
            );
        }
        assert_eq!(tls["verify_name_on_connect"], true, "{name}");
        if mode == "router" {
            assert_eq!(
                tls["enable_mtls"], true,
                "{name}: routers must require client certificates"
            );
            let listen = get(&config, "listen/endpoints");
            let endpoints = listen.as_array().expect("listen endpoints list");
            assert!(
                !endpoints.is_empty()
                    && endpoints
                        .iter()
                        .all(|e| e.as_str().unwrap().starts_with("quic/")),
                "{name}: routers with certificates listen on QUIC (TLS 1.3) only: {listen}"
            );
        }
    }
}

/// One access-control rule of the config, as JSON.
struct Rule<'a>(&'a Value);

impl Rule<'_> {
    fn has(&self, field: &str, item: &str) -> bool {
        self.0[field]
            .as_array()
            .is_some_and(|items| items.iter().any(|v| v == item))
    }

    /// Whether this rule decides `permission` for a put sent by a client (ingress) on `key`.
    fn decides_put(&self, permission: &str, key: &str) -> bool {
        let key = KeyExpr::new(key).unwrap();
        let ingress =
            self.0.get("flows").is_none_or(Value::is_null) || self.has("flows", "ingress");
        self.0["permission"] == permission
            && self.has("messages", "put")
            && ingress
            && self.0["key_exprs"].as_array().unwrap().iter().any(|k| {
                KeyExpr::new(k.as_str().unwrap().to_string())
                    .unwrap()
                    .includes(&key)
            })
    }
}

/// The subjects (by id) whose policies let them put on `key`, following Zenoh's rule: deny rules
/// of the subject win, then an allow rule is needed (default permission: deny).
fn writers(acl: &Value, key: &str) -> BTreeSet<String> {
    let rules = acl["rules"].as_array().unwrap();
    let rule = |id: &Value| {
        Rule(
            rules
                .iter()
                .find(|r| r["id"] == *id)
                .unwrap_or_else(|| panic!("policy names unknown rule {id}")),
        )
    };
    let mut out = BTreeSet::new();
    let subjects: Vec<&Value> = acl["subjects"].as_array().unwrap().iter().collect();
    for subject in subjects {
        let id = &subject["id"];
        let policies: Vec<&Value> = acl["policies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["subjects"].as_array().unwrap().contains(id))
            .collect();
        let rule_ids: Vec<&Value> = policies
            .iter()
            .flat_map(|p| p["rules"].as_array().unwrap())
            .collect();
        let denied = rule_ids.iter().any(|r| rule(r).decides_put("deny", key));
        let allowed = rule_ids.iter().any(|r| rule(r).decides_put("allow", key));
        if allowed && !denied {
            out.insert(id.as_str().unwrap().to_string());
        }
    }
    out
}

#[test]
fn acl_denies_by_default_and_only_deploy_commands_robots() {
    let config = load(&zenoh_file("router-acl.json5"));
    let acl = get(&config, "access_control");
    assert_eq!(acl["enabled"], true);
    assert_eq!(acl["default_permission"], "deny");

    let rules = acl["rules"].as_array().unwrap();
    assert!(
        rules.iter().any(|r| r["key_exprs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|k| k == "l3p/robot/*/command")),
        "no rule names l3p/robot/*/command"
    );

    let set = |ids: &[&str]| ids.iter().map(|s| s.to_string()).collect::<BTreeSet<_>>();
    assert_eq!(writers(&acl, "l3p/robot/go1-01/command"), set(&["deploy"]));
    assert_eq!(
        writers(&acl, "l3p/robot/go1-01/deploy/status"),
        set(&["deploy"])
    );
    assert_eq!(
        writers(&acl, "l3p/robot/go1-01/state"),
        set(&["robot-bridge"])
    );
    assert_eq!(
        writers(&acl, "l3p/robot/go1-01/operator"),
        set(&["operator"])
    );
    assert_eq!(
        writers(&acl, "l3p/a1-flat/rollout/a1/a1-1234"),
        set(&["actor", "learner", "registry"])
    );

    // Subjects are authenticated identities: certificate common names, never bare Zenoh ids.
    let readme = std::fs::read_to_string(deploy_dir().join("certs/README.md"))
        .expect("deploy/certs/README.md");
    for subject in acl["subjects"].as_array().unwrap() {
        assert!(subject.get("zids").is_none_or(Value::is_null), "{subject}");
        let names = subject["cert_common_names"]
            .as_array()
            .unwrap_or_else(|| panic!("subject without cert_common_names: {subject}"));
        for name in names {
            let name = name.as_str().unwrap();
            assert!(
                readme.contains(&format!("CN={name}")) || readme.contains(name),
                "deploy/certs/README.md does not say how to make the certificate for {name}"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------------
// Enforcement over mutual TLS: a router from router-acl.json5, clients from client-tls.json5.

/// A temp dir removed on drop.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run openssl");
    assert!(
        out.status.success(),
        "openssl {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// CA and certificates as in deploy/certs/README.md (P-256 keys, names for 127.0.0.1).
fn make_certs(dir: &Path, clients: &[&str]) {
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-keyout",
            "ca-key.pem",
            "-out",
            "ca.pem",
            "-days",
            "3650",
            "-subj",
            "/CN=l3p-ca",
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
        ],
    );
    let sign = |file: &str, cn: &str, ext: &str| {
        std::fs::write(dir.join(format!("{file}.ext")), ext).unwrap();
        openssl(
            dir,
            &[
                "req",
                "-new",
                "-newkey",
                "ec",
                "-pkeyopt",
                "ec_paramgen_curve:prime256v1",
                "-nodes",
                "-keyout",
                &format!("{file}-key.pem"),
                "-out",
                &format!("{file}.csr"),
                "-subj",
                &format!("/CN={cn}"),
            ],
        );
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &format!("{file}.csr"),
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca-key.pem",
                "-CAcreateserial",
                "-days",
                "825",
                "-sha256",
                "-extfile",
                &format!("{file}.ext"),
                "-out",
                &format!("{file}.pem"),
            ],
        );
    };
    sign(
        "router",
        "l3p-router",
        "basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n\
         extendedKeyUsage=serverAuth,clientAuth\nsubjectAltName=DNS:localhost,IP:127.0.0.1\n",
    );
    for cn in clients {
        sign(
            cn,
            cn,
            "basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n\
             extendedKeyUsage=clientAuth\n",
        );
    }
}

fn set(config: &mut Config, key: &str, value: &str) {
    config
        .insert_json5(key, value)
        .unwrap_or_else(|e| panic!("{key} = {value}: {e}"));
}

fn path_json(path: PathBuf) -> String {
    serde_json::to_string(&path.to_string_lossy()).unwrap()
}

fn open_router(dir: &Path, port: u16) -> Session {
    let mut config = load(&zenoh_file("router-acl.json5"));
    set(
        &mut config,
        "listen/endpoints",
        &format!(r#"["quic/127.0.0.1:{port}"]"#),
    );
    let tls = "transport/link/tls";
    set(
        &mut config,
        &format!("{tls}/root_ca_certificate"),
        &path_json(dir.join("ca.pem")),
    );
    for side in ["listen", "connect"] {
        set(
            &mut config,
            &format!("{tls}/{side}_certificate"),
            &path_json(dir.join("router.pem")),
        );
        set(
            &mut config,
            &format!("{tls}/{side}_private_key"),
            &path_json(dir.join("router-key.pem")),
        );
    }
    zenoh::open(config).wait().expect("open the ACL router")
}

fn open_client(dir: &Path, port: u16, cn: &str) -> Session {
    let mut config = load(&zenoh_file("client-tls.json5"));
    set(
        &mut config,
        "connect/endpoints",
        &format!(r#"["quic/127.0.0.1:{port}"]"#),
    );
    // The file retries the router forever (right for a service); a test fails instead.
    set(&mut config, "connect/timeout_ms", "5000");
    set(&mut config, "connect/exit_on_failure", "true");
    let tls = "transport/link/tls";
    set(
        &mut config,
        &format!("{tls}/root_ca_certificate"),
        &path_json(dir.join("ca.pem")),
    );
    set(
        &mut config,
        &format!("{tls}/connect_certificate"),
        &path_json(dir.join(format!("{cn}.pem"))),
    );
    set(
        &mut config,
        &format!("{tls}/connect_private_key"),
        &path_json(dir.join(format!("{cn}-key.pem"))),
    );
    zenoh::open(config)
        .wait()
        .unwrap_or_else(|e| panic!("open client {cn}: {e}"))
}

/// A client set up the way an l3p config does it: `[zenoh.tls]` ([`l3p_net::TlsSettings`]), no
/// Zenoh file.
fn open_client_with_tls_settings(dir: &Path, port: u16, cn: &str) -> Session {
    let settings = l3p_net::ZenohSettings {
        mode: "client".into(),
        connect: vec![format!("quic/127.0.0.1:{port}")],
        tls: Some(l3p_net::TlsSettings {
            ca: dir.join("ca.pem"),
            cert: dir.join(format!("{cn}.pem")),
            key: dir.join(format!("{cn}-key.pem")),
        }),
        ..l3p_net::ZenohSettings::default()
    };
    let mut config = settings
        .to_zenoh_config()
        .unwrap_or_else(|e| panic!("[zenoh.tls] for {cn}: {e}"));
    set(&mut config, "connect/timeout_ms", "5000");
    set(&mut config, "connect/exit_on_failure", "true");
    zenoh::open(config)
        .wait()
        .unwrap_or_else(|e| panic!("open client {cn} with [zenoh.tls]: {e}"))
}

type Sub = zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// Payloads received until `expect` arrives (or `deadline` passes), plus a short grace period for
/// anything that should not have been delivered.
fn received(sub: &Sub, expect: &str, deadline: Duration) -> BTreeSet<String> {
    let mut got = BTreeSet::new();
    let start = Instant::now();
    while !got.contains(expect) && start.elapsed() < deadline {
        if let Ok(Some(sample)) = sub.recv_timeout(Duration::from_millis(100)) {
            got.insert(sample.payload().try_to_string().unwrap().into_owned());
        }
    }
    let grace = Instant::now();
    while grace.elapsed() < Duration::from_millis(500) {
        if let Ok(Some(sample)) = sub.recv_timeout(Duration::from_millis(100)) {
            got.insert(sample.payload().try_to_string().unwrap().into_owned());
        }
    }
    got
}

/// Polls `condition` every 20 ms until it holds; panics naming `what` after 10 s.
fn wait_until(what: &str, mut condition: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !condition() {
        assert!(Instant::now() < deadline, "timed out waiting until {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Number of replies a query gets.
fn replies(session: &Session, key: &str) -> usize {
    let replies = session
        .get(key)
        .timeout(Duration::from_millis(1500))
        .wait()
        .expect("send query");
    let mut n = 0;
    while let Ok(reply) = replies.recv() {
        if reply.result().is_ok() {
            n += 1;
        }
    }
    n
}

#[test]
fn acl_router_enforces_writers_over_mutual_tls() {
    if Command::new("openssl").arg("version").output().is_err() {
        eprintln!("skipped: openssl not found (needed to make test certificates)");
        return;
    }
    let dir = TempDir(std::env::temp_dir().join(format!("l3p-zenoh-acl-{}", std::process::id())));
    std::fs::create_dir_all(&dir.0).unwrap();
    let clients = [
        "l3p-deploy",
        "l3p-robot-bridge",
        "l3p-operator",
        "l3p-learner",
        "l3p-actor",
        "l3p-registry",
    ];
    zenoh::try_init_log_from_env();
    make_certs(&dir.0, &clients);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();

    let _router = open_router(&dir.0, port);
    // The deploy controller and an actor join as an l3p config makes them ([zenoh.tls]); the
    // others through client-tls.json5. Both ways must get the same rights.
    let deploy = open_client_with_tls_settings(&dir.0, port, "l3p-deploy");
    let bridge = open_client(&dir.0, port, "l3p-robot-bridge");
    let operator = open_client(&dir.0, port, "l3p-operator");
    let learner = open_client(&dir.0, port, "l3p-learner");
    let actor = open_client_with_tls_settings(&dir.0, port, "l3p-actor");
    let registry = open_client(&dir.0, port, "l3p-registry");

    let command = "l3p/robot/go1-01/command";
    let state = "l3p/robot/go1-01/state";
    let op_key = "l3p/robot/go1-01/operator";
    let commands = bridge.declare_subscriber(command).wait().unwrap();
    let states = deploy.declare_subscriber(state).wait().unwrap();
    let operator_requests = deploy.declare_subscriber(op_key).wait().unwrap();
    let metrics = operator
        .declare_subscriber("l3p/a1-flat/metrics/**")
        .wait()
        .unwrap();
    let _registry_service = registry
        .declare_queryable("l3p/registry/**")
        .callback(|query| {
            let key = query.key_expr().clone();
            query.reply(key, "ok").wait().unwrap();
        })
        .wait()
        .unwrap();
    // Wait until the declarations reached every client through the router: each writer below
    // knows a subscriber (or the queryable) for its key, allowed or not — the router decides.
    for (session, key) in [
        (&operator, command),
        (&learner, command),
        (&actor, command),
        (&registry, command),
        (&deploy, command),
        (&operator, state),
        (&learner, state),
        (&actor, state),
        (&bridge, state),
        (&learner, op_key),
        (&bridge, op_key),
        (&actor, op_key),
        (&operator, op_key),
        (&learner, "l3p/a1-flat/metrics/learner"),
    ] {
        let publisher = session.declare_publisher(key).wait().unwrap();
        wait_until(
            &format!("a subscriber for {key} reaches {}", session.zid()),
            || publisher.matching_status().wait().unwrap().matching(),
        );
    }
    for (session, key) in [
        (&deploy, "l3p/registry/pull"),
        (&operator, "l3p/registry/list"),
        (&actor, "l3p/registry/show"),
        (&learner, "l3p/registry/put"),
        (&actor, "l3p/registry/put"),
        (&operator, "l3p/registry/tag"),
        (&deploy, "l3p/registry/put"),
    ] {
        let querier = session.declare_querier(key).wait().unwrap();
        wait_until(
            &format!("the registry's queryable reaches {}", session.zid()),
            || querier.matching_status().wait().unwrap().matching(),
        );
    }
    // A session delivers its own puts to its own subscribers without the router, so the
    // subscribing session is never among the writers tried below.

    // Robot commands: the deploy controller only.
    for (session, who) in [
        (&operator, "operator"),
        (&learner, "learner"),
        (&actor, "actor"),
        (&registry, "registry"),
    ] {
        session.put(command, who).wait().unwrap();
    }
    deploy.put(command, "deploy").wait().unwrap();
    let got = received(&commands, "deploy", Duration::from_secs(5));
    assert_eq!(
        got,
        BTreeSet::from(["deploy".to_string()]),
        "command writers"
    );

    // Robot state: the bridge only.
    for (session, who) in [
        (&operator, "operator"),
        (&learner, "learner"),
        (&actor, "actor"),
    ] {
        session.put(state, who).wait().unwrap();
    }
    bridge.put(state, "bridge").wait().unwrap();
    let got = received(&states, "bridge", Duration::from_secs(5));
    assert_eq!(got, BTreeSet::from(["bridge".to_string()]), "state writers");

    // Operator requests: operators only.
    for (session, who) in [
        (&learner, "learner"),
        (&bridge, "bridge"),
        (&actor, "actor"),
    ] {
        session.put(op_key, who).wait().unwrap();
    }
    operator.put(op_key, "operator").wait().unwrap();
    let got = received(&operator_requests, "operator", Duration::from_secs(5));
    assert_eq!(
        got,
        BTreeSet::from(["operator".to_string()]),
        "operator writers"
    );

    // Training traffic flows, and observers can read it.
    learner
        .put("l3p/a1-flat/metrics/learner", "learner")
        .wait()
        .unwrap();
    let got = received(&metrics, "learner", Duration::from_secs(5));
    assert_eq!(
        got,
        BTreeSet::from(["learner".to_string()]),
        "metrics readers"
    );

    // Registry: everyone with a role may read, only the learner may write.
    assert_eq!(
        replies(&deploy, "l3p/registry/pull"),
        1,
        "deploy pulls policies"
    );
    assert_eq!(
        replies(&operator, "l3p/registry/list"),
        1,
        "operators list the registry"
    );
    assert_eq!(
        replies(&actor, "l3p/registry/show"),
        1,
        "actors read the registry"
    );
    assert_eq!(
        replies(&learner, "l3p/registry/put"),
        1,
        "the learner writes the registry"
    );
    assert_eq!(
        replies(&actor, "l3p/registry/put"),
        0,
        "actors must not write the registry"
    );
    assert_eq!(
        replies(&operator, "l3p/registry/tag"),
        0,
        "operators must not move aliases"
    );
    assert_eq!(
        replies(&deploy, "l3p/registry/put"),
        0,
        "deploy must not write the registry"
    );
}
