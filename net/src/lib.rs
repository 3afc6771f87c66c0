//! How every l3p process joins the Zenoh network: [`ZenohSettings`] (the `[zenoh]` config section,
//! with mutual TLS from [`TlsSettings`]) → [`open_session`], what a session's links expose
//! ([`Exposure`], which `l3p deploy` checks before it will command a robot), and the project's two
//! publisher profiles ([`declare_control_publisher`], [`declare_rollout_publisher`]). A crate of its
//! own so that the actor and the deploy controller speak Zenoh without linking the registry's SQLite
//! store.
//!
//! Architecture invariant: depends on no other project crate.

use std::net::IpAddr;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// How a process joins the Zenoh network (`[zenoh]` in the config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohSettings {
    /// `peer` (LAN, default) or `client` (through a `zenohd` router).
    pub mode: String,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447`. Empty: no listener (a process that only
    /// connects opens no port); Zenoh's own default would listen on every interface.
    pub listen: Vec<String>,
    /// Endpoints to connect to (routers or peers).
    pub connect: Vec<String>,
    /// Multicast scouting (automatic discovery on the LAN). Off by default: processes find each other
    /// through `listen`/`connect` only, so nothing joins a LAN unless configured to.
    pub multicast_scouting: bool,
    /// Client mode: how long opening a session keeps retrying `connect` (backing off from 1 to 4 s)
    /// before it fails, so that a daemon started before its router, or while the router restarts,
    /// waits for it instead of exiting. 0: one try. Peers and routers always retry in the
    /// background (Zenoh's default). A `connect.timeout_ms` set in `config_file` wins.
    pub connect_retry_s: u64,
    /// Optional Zenoh JSON5 config file loaded first (TLS, ACL, ...); the fields above override it.
    pub config_file: Option<PathBuf>,
    /// Mutual TLS on every TLS link this process opens or accepts (`[zenoh.tls]`).
    pub tls: Option<TlsSettings>,
}

/// Mutual TLS (`[zenoh.tls]`): the process proves its role with a certificate from the run's private
/// CA and accepts only peers that do the same. The certificate's common name is the role the router's
/// ACL grants (`deploy/zenoh/router-acl.json5`; how to make them: `deploy/certs/README.md`). Only
/// `quic/<host>:<port>` and `tls/<host>:<port>` endpoints use it; a `tcp/` endpoint stays plain.
/// Prefer `quic/` between machines: Zenoh 1.10's `tls/` link reads and writes one rustls stream from
/// two tasks at once (eclipse-zenoh/zenoh#2557), which the multi-host soak saw crash a router with
/// SIGILL when a peer was killed; QUIC keeps each direction on its own stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsSettings {
    /// The CA certificate (PEM) every peer's certificate must chain to.
    pub ca: PathBuf,
    /// This process's certificate (PEM), used both to connect and to listen.
    pub cert: PathBuf,
    /// Its private key (PEM).
    pub key: PathBuf,
}

/// What a session's links expose, judged from its final Zenoh config ([`ZenohSettings::exposure`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Exposure {
    /// Every endpoint is on this machine (loopback or a Unix socket) and nothing scouts the LAN.
    Local,
    /// Every endpoint that leaves this machine is TLS with mutual authentication.
    Authenticated,
    /// Something reaches the network without mutual TLS; the text says what.
    Unauthenticated(String),
}

impl Default for ZenohSettings {
    fn default() -> Self {
        Self {
            mode: "peer".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            connect_retry_s: DEFAULT_CONNECT_RETRY_S,
            config_file: None,
            tls: None,
        }
    }
}

/// [`ZenohSettings::connect_retry_s`] by default: a router restart (a few seconds), not so long that
/// a one-shot command with a wrong endpoint seems to hang.
pub const DEFAULT_CONNECT_RETRY_S: u64 = 10;

/// Zenoh's default `transport/link/rx/buffer_size`: one batch (see
/// [`ZenohSettings::oversized_rx_buffer`]).
pub const DEFAULT_RX_BUFFER_SIZE: u64 = 65_535;

impl ZenohSettings {
    /// Loopback-only peer: listens on 127.0.0.1 (port `listen`, or any free one — never Zenoh's
    /// default of every interface), connects to `connect`, no scouting.
    pub fn loopback(listen: Option<u16>, connect: &[u16]) -> Self {
        Self {
            mode: "peer".into(),
            listen: vec![format!("tcp/127.0.0.1:{}", listen.unwrap_or(0))],
            connect: connect
                .iter()
                .map(|p| format!("tcp/127.0.0.1:{p}"))
                .collect(),
            ..Self::default()
        }
    }

    /// The Zenoh config these settings describe.
    pub fn to_zenoh_config(&self) -> Result<zenoh::Config, NetError> {
        let mut config = match &self.config_file {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| NetError::Config(format!("{}: {e}", path.display())))?,
            None => zenoh::Config::default(),
        };
        let mut set = |key: &str, value: String| {
            config
                .insert_json5(key, &value)
                .map_err(|e| NetError::Config(format!("{key}: {e}")))
        };
        set("mode", json(&self.mode))?;
        // Always set: an empty list means no listener, where Zenoh's default is every interface.
        set("listen/endpoints", json(&self.listen))?;
        if !self.connect.is_empty() {
            set("connect/endpoints", json(&self.connect))?;
        }
        set("scouting/multicast/enabled", json(&self.multicast_scouting))?;
        if let Some(tls) = &self.tls {
            // Zenoh reads these files only when a TLS link is set up, and then fails with a
            // handshake error that does not name them: check them here.
            let named = [("ca", &tls.ca), ("cert", &tls.cert), ("key", &tls.key)];
            for (name, path) in named {
                std::fs::metadata(path).map_err(|e| {
                    NetError::Config(format!("[zenoh.tls] {name} = {}: {e}", path.display()))
                })?;
            }
            let path = |p: &PathBuf| json(&p.to_string_lossy());
            let link = "transport/link/tls";
            set(&format!("{link}/root_ca_certificate"), path(&tls.ca))?;
            set(&format!("{link}/enable_mtls"), "true".into())?;
            set(&format!("{link}/verify_name_on_connect"), "true".into())?;
            for side in ["connect", "listen"] {
                set(&format!("{link}/{side}_certificate"), path(&tls.cert))?;
                set(&format!("{link}/{side}_private_key"), path(&tls.key))?;
            }
        }
        // Zenoh's client default is a single try: a router that is restarting when a daemon starts
        // would make the daemon exit (the multi-host soak saw a learner refused this way).
        let configured = config
            .get_json("connect/timeout_ms")
            .is_ok_and(|text| text.trim() != "null");
        if !configured {
            let millis = self
                .connect_retry_s
                .saturating_mul(1000)
                .min(i64::MAX as u64);
            config
                .insert_json5("connect/timeout_ms", &format!("{{ client: {millis} }}"))
                .map_err(|e| NetError::Config(format!("connect/timeout_ms: {e}")))?;
        }
        Ok(config)
    }

    /// What a session opened with these settings would expose (see [`Exposure`]), from the final
    /// config, so that endpoints and TLS set in `config_file` count too.
    pub fn exposure(&self) -> Result<Exposure, NetError> {
        let config = self.to_zenoh_config()?;
        let value = |key: &str| -> serde_json::Value {
            config
                .get_json(key)
                .ok()
                .and_then(|text| serde_json::from_str(&text).ok())
                .unwrap_or(serde_json::Value::Null)
        };
        if value("scouting/multicast/enabled") == serde_json::Value::Bool(true) {
            return Ok(Exposure::Unauthenticated(
                "multicast scouting is on: it announces this process to the whole LAN".into(),
            ));
        }
        let mutual_tls = value("transport/link/tls/enable_mtls") == serde_json::Value::Bool(true)
            && value("transport/link/tls/root_ca_certificate").is_string();
        let mut endpoints = Vec::new();
        collect_strings(&value("listen/endpoints"), &mut endpoints);
        collect_strings(&value("connect/endpoints"), &mut endpoints);
        let mut remote = false;
        for endpoint in &endpoints {
            if endpoint_is_local(endpoint) {
                continue;
            }
            remote = true;
            // QUIC is TLS 1.3 underneath and reads the same `transport/link/tls` settings.
            let tls = matches!(endpoint.split('/').next(), Some("tls" | "quic"));
            if !(tls && mutual_tls) {
                let why = if tls {
                    "TLS without client certificates (give [zenoh.tls])"
                } else {
                    "not TLS"
                };
                return Ok(Exposure::Unauthenticated(format!(
                    "endpoint `{endpoint}` leaves this machine and is {why}"
                )));
            }
        }
        Ok(if remote {
            Exposure::Authenticated
        } else {
            Exposure::Local
        })
    }

    /// The receive buffers Zenoh would allocate up front for every link of a session opened with
    /// these settings (`transport/link/rx/buffer_size` of the final config), in bytes, when that is
    /// more than Zenoh's default of one batch ([`DEFAULT_RX_BUFFER_SIZE`]); `None` otherwise. A
    /// router allocates them again for every link a client opens, and the allocator keeps much of
    /// what a closed link frees: at 16 MiB, a router whose clients reconnect every few seconds grew
    /// by megabytes per reconnect (BENCHMARKS.md, the one-hour soak). Large messages need no larger
    /// value: Zenoh allocates receive buffers beyond the pool as it needs them.
    pub fn oversized_rx_buffer(&self) -> Result<Option<u64>, NetError> {
        let size = self
            .to_zenoh_config()?
            .get_json("transport/link/rx/buffer_size")
            .ok()
            .and_then(|text| text.trim().parse::<u64>().ok());
        Ok(size.filter(|&bytes| bytes > DEFAULT_RX_BUFFER_SIZE))
    }
}

/// Every string in a config value (endpoint lists are arrays, or maps from mode to arrays).
fn collect_strings(value: &serde_json::Value, out: &mut Vec<String>) {
    match value {
        serde_json::Value::String(s) => out.push(s.clone()),
        serde_json::Value::Array(items) => items.iter().for_each(|v| collect_strings(v, out)),
        serde_json::Value::Object(map) => map.values().for_each(|v| collect_strings(v, out)),
        _ => {}
    }
}

/// `true` for an endpoint that cannot leave this machine: a Unix socket, or a loopback address
/// (`tcp/127.0.0.1:7447`, `tls/[::1]:7447`, `tcp/localhost:7447`). `0.0.0.0` and `[::]` listen on
/// every interface, so they are not local.
pub fn endpoint_is_local(endpoint: &str) -> bool {
    let Some((protocol, rest)) = endpoint.split_once('/') else {
        return false;
    };
    if protocol.starts_with("unixsock") || protocol == "unixpipe" {
        return true;
    }
    // Zenoh endpoints may carry `?metadata` and `#config` after the address.
    let address = rest.split(['?', '#']).next().unwrap_or_default();
    let host = match address.strip_prefix('[') {
        Some(bracketed) => bracketed.split(']').next().unwrap_or_default(),
        None => address.rsplit_once(':').map_or(address, |(host, _)| host),
    };
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// JSON text of a config value (strings quoted, lists as arrays).
fn json<T: Serialize>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_default()
}

/// A Zenoh session could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    #[error("invalid zenoh config: {0}")]
    Config(String),
    #[error(
        "cannot open zenoh session: {0}\nhint: check the listen/connect endpoints and that the port is free"
    )]
    Open(String),
}

/// Open a Zenoh session with these settings.
pub async fn open_session(settings: &ZenohSettings) -> Result<zenoh::Session, NetError> {
    let config = settings.to_zenoh_config()?;
    zenoh::open(config)
        .await
        .map_err(|e| NetError::Open(e.to_string()))
}

/// The project's two publisher profiles, declared in one place.
///
/// - Control (`robot/<id>/command`, `robot/<id>/state`): real-time priority, express, and `Drop`
///   under congestion — a late command or state is worse than none, the next one replaces it.
/// - Rollouts (`<run>/rollout/...`): `Block` under congestion — training data is never dropped on
///   the way; a slow learner slows the actors instead.
pub async fn declare_control_publisher(
    session: &zenoh::Session,
    key: String,
) -> zenoh::Result<zenoh::pubsub::Publisher<'static>> {
    use zenoh::qos::{CongestionControl, Priority};
    session
        .declare_publisher(key)
        .priority(Priority::RealTime)
        .express(true)
        .congestion_control(CongestionControl::Drop)
        .await
}

/// See [`declare_control_publisher`]: the rollout profile.
pub async fn declare_rollout_publisher(
    session: &zenoh::Session,
    key: String,
) -> zenoh::Result<zenoh::pubsub::Publisher<'static>> {
    session
        .declare_publisher(key)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
}

/// A TCP port on 127.0.0.1 that was free a moment ago (for loopback sessions in local mode and tests).
pub fn free_loopback_port() -> std::io::Result<u16> {
    let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
    Ok(listener.local_addr()?.port())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_sessions_never_listen_beyond_loopback() {
        assert_eq!(
            ZenohSettings::loopback(None, &[7447]).listen,
            ["tcp/127.0.0.1:0"]
        );
        assert_eq!(
            ZenohSettings::loopback(Some(9000), &[]).listen,
            ["tcp/127.0.0.1:9000"]
        );
        let config = ZenohSettings::loopback(None, &[7447])
            .to_zenoh_config()
            .unwrap();
        let listen = config.get_json("listen/endpoints").unwrap();
        assert!(listen.contains("127.0.0.1:0"), "{listen}");
    }

    #[test]
    fn default_settings_open_no_listener_and_do_not_scout() {
        let config = ZenohSettings::default().to_zenoh_config().unwrap();
        let listen = config.get_json("listen/endpoints").unwrap();
        assert!(!listen.contains("tcp"), "{listen}");
        let scouting = config.get_json("scouting/multicast/enabled").unwrap();
        assert_eq!(scouting, "false");
    }

    #[test]
    fn endpoints_on_this_machine_are_local() {
        for local in [
            "tcp/127.0.0.1:7447",
            "tcp/127.8.9.1:7447",
            "tls/[::1]:7447",
            "tcp/localhost:7447",
            "tcp/LOCALHOST:7447#rel=1",
            "tcp/127.0.0.1:7447?iface=lo",
            "unixsock-stream//tmp/l3p.sock",
        ] {
            assert!(endpoint_is_local(local), "{local}");
        }
        for remote in [
            "tcp/0.0.0.0:7447",
            "tcp/[::]:7447",
            "tcp/192.0.2.7:7447",
            "tls/router.example.com:7447",
            "udp/10.0.0.1:7447",
            "tcp/localhost.example.com:7447",
            "garbage",
        ] {
            assert!(!endpoint_is_local(remote), "{remote}");
        }
    }

    fn exposure(settings: &ZenohSettings) -> Exposure {
        settings.exposure().unwrap()
    }

    /// Three empty files standing in for the CA, certificate and key (Zenoh reads them only when
    /// a TLS link is set up).
    fn tls_files(dir: &std::path::Path) -> TlsSettings {
        let file = |name: &str| {
            let path = dir.join(name);
            std::fs::write(&path, "").unwrap();
            path
        };
        TlsSettings {
            ca: file("ca.pem"),
            cert: file("deploy.pem"),
            key: file("deploy-key.pem"),
        }
    }

    #[test]
    fn exposure_tells_local_authenticated_and_open_links_apart() {
        assert_eq!(exposure(&ZenohSettings::default()), Exposure::Local);
        assert_eq!(
            exposure(&ZenohSettings::loopback(None, &[7447])),
            Exposure::Local
        );
        let open = |listen: &[&str], connect: &[&str]| ZenohSettings {
            listen: listen.iter().map(|s| s.to_string()).collect(),
            connect: connect.iter().map(|s| s.to_string()).collect(),
            ..ZenohSettings::default()
        };
        let Exposure::Unauthenticated(why) = exposure(&open(&[], &["tcp/192.0.2.7:7447"])) else {
            panic!("a plain TCP link off the machine is unauthenticated");
        };
        assert!(
            why.contains("tcp/192.0.2.7:7447") && why.contains("not TLS"),
            "{why}"
        );
        assert!(matches!(
            exposure(&open(&["tcp/0.0.0.0:7447"], &[])),
            Exposure::Unauthenticated(_)
        ));
        let Exposure::Unauthenticated(why) = exposure(&open(&[], &["tls/router.example.com:7447"]))
        else {
            panic!("TLS without client certificates proves nobody's role");
        };
        assert!(why.contains("[zenoh.tls]"), "{why}");
        let scouting = ZenohSettings {
            multicast_scouting: true,
            ..ZenohSettings::default()
        };
        let Exposure::Unauthenticated(why) = exposure(&scouting) else {
            panic!("multicast scouting announces the process to the LAN");
        };
        assert!(why.contains("multicast"), "{why}");

        let dir = tempfile::tempdir().unwrap();
        let tls = ZenohSettings {
            tls: Some(tls_files(dir.path())),
            ..open(&["tcp/127.0.0.1:7449"], &["tls/router.example.com:7447"])
        };
        assert_eq!(exposure(&tls), Exposure::Authenticated);
        let quic = ZenohSettings {
            tls: Some(tls_files(dir.path())),
            ..open(&[], &["quic/router.example.com:7447"])
        };
        assert_eq!(exposure(&quic), Exposure::Authenticated);
        let quic_without_certificates = open(&[], &["quic/router.example.com:7447"]);
        assert!(matches!(
            exposure(&quic_without_certificates),
            Exposure::Unauthenticated(_)
        ));
        // One plain link off the machine is enough to be open, certificates or not.
        let mixed = ZenohSettings {
            connect: vec![
                "tls/router.example.com:7447".into(),
                "tcp/192.0.2.7:7447".into(),
            ],
            ..tls.clone()
        };
        assert!(matches!(exposure(&mixed), Exposure::Unauthenticated(_)));
    }

    #[test]
    fn tls_settings_become_zenoh_mutual_tls_and_missing_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let tls = tls_files(dir.path());
        let settings = ZenohSettings {
            connect: vec!["tls/router.example.com:7447".into()],
            tls: Some(tls.clone()),
            ..ZenohSettings::default()
        };
        let config = settings.to_zenoh_config().unwrap();
        let get = |key: &str| {
            config
                .get_json(&format!("transport/link/tls/{key}"))
                .unwrap()
        };
        assert_eq!(get("enable_mtls"), "true");
        assert_eq!(get("verify_name_on_connect"), "true");
        assert!(get("root_ca_certificate").contains("ca.pem"));
        for side in ["connect", "listen"] {
            assert!(get(&format!("{side}_certificate")).contains("deploy.pem"));
            assert!(get(&format!("{side}_private_key")).contains("deploy-key.pem"));
        }
        let missing = ZenohSettings {
            tls: Some(TlsSettings {
                key: dir.path().join("nope-key.pem"),
                ..tls
            }),
            ..settings
        };
        let err = missing.to_zenoh_config().unwrap_err().to_string();
        assert!(
            err.contains("[zenoh.tls] key") && err.contains("nope-key.pem"),
            "{err}"
        );
    }

    /// TLS set up in a Zenoh config file counts as much as `[zenoh.tls]`.
    #[test]
    fn exposure_reads_tls_from_the_config_file() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("client.json5");
        std::fs::write(
            &file,
            r#"{ transport: { link: { tls: { root_ca_certificate: "/etc/l3p/certs/ca.pem",
                 enable_mtls: true } } } }"#,
        )
        .unwrap();
        let settings = ZenohSettings {
            connect: vec!["tls/router.example.com:7447".into()],
            config_file: Some(file),
            ..ZenohSettings::default()
        };
        assert_eq!(exposure(&settings), Exposure::Authenticated);
    }

    /// A receive buffer above one batch, set in a Zenoh config file, is reported; the default is not.
    #[test]
    fn an_oversized_receive_buffer_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("router.json5");
        std::fs::write(
            &file,
            "{ transport: { link: { rx: { buffer_size: 16777216 } } } }",
        )
        .unwrap();
        let mut settings = ZenohSettings {
            mode: "router".into(),
            config_file: Some(file),
            ..ZenohSettings::default()
        };
        assert_eq!(settings.oversized_rx_buffer().unwrap(), Some(16_777_216));
        settings.config_file = None;
        assert_eq!(settings.oversized_rx_buffer().unwrap(), None);
    }

    /// A client started before its router waits for it (`connect_retry_s`); with 0 it fails at once.
    /// Judged by order, not by a clock: the patient client starts first, the one-try client fails
    /// with no router anywhere, and only then does the router start — so the patient client, which
    /// gives up after `DEFAULT_CONNECT_RETRY_S`, can only connect if the one-try client did not wait.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_waits_for_a_router_that_starts_late() {
        // Its router listens in this process: not while the listener probe below looks.
        let _sockets = SOCKETS.lock().await;
        let port = free_loopback_port().unwrap();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let once = ZenohSettings {
            mode: "client".into(),
            connect: vec![endpoint.clone()],
            connect_retry_s: 0,
            ..ZenohSettings::default()
        };
        let patient = ZenohSettings {
            connect_retry_s: DEFAULT_CONNECT_RETRY_S,
            ..once.clone()
        };
        let patient = tokio::spawn(async move { open_session(&patient).await });
        assert!(matches!(open_session(&once).await, Err(NetError::Open(_))));
        // The router is late: the patient client's first tries find nothing either.
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        assert!(!patient.is_finished(), "the patient client gave up at once");
        let router_settings = ZenohSettings {
            mode: "router".into(),
            listen: vec![endpoint],
            ..ZenohSettings::default()
        };
        let router = open_session(&router_settings).await.unwrap();
        let client = patient
            .await
            .unwrap()
            .expect("the client gave up before the router started");
        let routers: Vec<_> = client.info().routers_zid().await.collect();
        assert_eq!(routers, vec![router.zid()]);
        client.close().await.unwrap();
        router.close().await.unwrap();
    }

    /// A `connect.timeout_ms` from the Zenoh file is kept; otherwise `connect_retry_s` sets it.
    #[test]
    fn connect_retry_sets_the_client_timeout_unless_the_file_does() {
        let timeout = |settings: &ZenohSettings| {
            settings
                .to_zenoh_config()
                .unwrap()
                .get_json("connect/timeout_ms")
                .unwrap()
        };
        let settings = ZenohSettings {
            connect_retry_s: 7,
            ..ZenohSettings::default()
        };
        assert!(
            timeout(&settings).contains("7000"),
            "{}",
            timeout(&settings)
        );
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("zenoh.json5");
        std::fs::write(&file, "{ connect: { timeout_ms: { client: 1234 } } }").unwrap();
        let from_file = ZenohSettings {
            config_file: Some(file),
            ..settings
        };
        let text = timeout(&from_file);
        assert!(text.contains("1234") && !text.contains("7000"), "{text}");
    }

    /// Held by the tests that open listening sessions or probe this process's listeners (tests run
    /// in parallel threads of one process, so a router one opens is a listener the other sees).
    static SOCKETS: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

    /// A connect-only session (what actors and one-shot commands open) listens on no port.
    #[cfg(target_os = "linux")]
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_connect_only_session_listens_nowhere() {
        let _sockets = SOCKETS.lock().await;
        let before = listening_inodes();
        let settings = ZenohSettings {
            connect: vec![format!("tcp/127.0.0.1:{}", free_loopback_port().unwrap())],
            ..ZenohSettings::default()
        };
        let session = open_session(&settings).await.unwrap();
        let mine = own_socket_inodes();
        let new_listeners: Vec<_> = listening_inodes()
            .into_iter()
            .filter(|i| !before.contains(i) && mine.contains(i))
            .collect();
        assert!(new_listeners.is_empty(), "{new_listeners:?}");
        session.close().await.unwrap();
        // The probe does see a listener when there is one.
        let before = listening_inodes();
        let listening = open_session(&ZenohSettings::loopback(None, &[]))
            .await
            .unwrap();
        let mine = own_socket_inodes();
        assert!(
            listening_inodes()
                .iter()
                .any(|i| !before.contains(i) && mine.contains(i))
        );
        listening.close().await.unwrap();
    }

    /// Socket inodes in LISTEN state (TCP, v4 and v6).
    #[cfg(target_os = "linux")]
    fn listening_inodes() -> Vec<String> {
        ["/proc/net/tcp", "/proc/net/tcp6"]
            .iter()
            .filter_map(|p| std::fs::read_to_string(p).ok())
            .flat_map(|t| {
                t.lines()
                    .skip(1)
                    .filter_map(|l| {
                        let f: Vec<&str> = l.split_whitespace().collect();
                        (f.get(3) == Some(&"0A")).then(|| f.get(9).map(|s| s.to_string()))?
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// Inodes of this process's sockets.
    #[cfg(target_os = "linux")]
    fn own_socket_inodes() -> Vec<String> {
        std::fs::read_dir("/proc/self/fd")
            .map(|d| {
                d.flatten()
                    .filter_map(|e| std::fs::read_link(e.path()).ok())
                    .filter_map(|l| {
                        let l = l.to_string_lossy().to_string();
                        l.strip_prefix("socket:[")
                            .and_then(|r| r.strip_suffix(']'))
                            .map(str::to_string)
                    })
                    .collect()
            })
            .unwrap_or_default()
    }
}
