//! `l3p router`: processes that reach each other only through it (a registry service in client mode
//! and a one-shot client) work, and a listener that would leave the machine without mutual TLS is
//! refused unless `--insecure`. The same router under mutual TLS and the ACL, across network
//! namespaces: `soak.rs`.

use std::time::Duration;

mod common;

use common::{Procs, log_tails, wait_for_port};
use l3p_net::free_loopback_port;

#[test]
fn clients_reach_each_other_only_through_the_router() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_loopback_port().unwrap();
    let router = format!("tcp/127.0.0.1:{port}");
    let mut procs = Procs(Vec::new());
    procs.spawn("router", &["router", "--listen", &router], dir.path());
    wait_for_port(port, Duration::from_secs(60), "the router", dir.path());

    // The registry service as a client: it opens no port of its own, so only the router can carry
    // the query to it.
    let config = dir.path().join("client.toml");
    std::fs::write(
        &config,
        format!("[zenoh]\nmode = \"client\"\nconnect = [\"{router}\"]\n"),
    )
    .unwrap();
    let data = dir.path().join("data");
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            data.to_str().unwrap(),
            "--config",
            config.to_str().unwrap(),
        ],
        dir.path(),
    );
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    loop {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_l3p"))
            .args(["registry", "list", "--json", "--config"])
            .arg(&config)
            .output()
            .unwrap();
        if out.status.success() {
            let listed: serde_json::Value = serde_json::from_slice(&out.stdout)
                .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
            assert!(listed.is_array(), "{listed}");
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no registry answered through the router: {}{}",
            String::from_utf8_lossy(&out.stderr),
            log_tails(dir.path())
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

#[test]
fn a_router_open_to_the_network_without_mutual_tls_is_refused_unless_insecure() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(["router", "--listen", "tcp/0.0.0.0:0"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("refusing to route") && stderr.contains("tcp/0.0.0.0:0"),
        "{stderr}"
    );

    // With --insecure it starts (and says why it should not); stopped with SIGTERM.
    let dir = tempfile::tempdir().unwrap();
    let mut procs = Procs(Vec::new());
    procs.spawn(
        "router",
        &["router", "--insecure", "--listen", "tcp/0.0.0.0:0"],
        dir.path(),
    );
    let log = dir.path().join("router.log");
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while !std::fs::read_to_string(&log)
        .unwrap_or_default()
        .contains("listening on")
    {
        assert!(
            std::time::Instant::now() < deadline,
            "{}",
            log_tails(dir.path())
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        text.contains("unauthenticated links (--insecure)"),
        "{text}"
    );
}
