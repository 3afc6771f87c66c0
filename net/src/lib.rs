//! How every l3p process joins the Zenoh network: [`ZenohSettings`] (the `[zenoh]` config section)
//! → [`open_session`], and the project's two publisher profiles ([`declare_control_publisher`],
//! [`declare_rollout_publisher`]). A crate of its own so that the actor and the deploy controller
//! speak Zenoh without linking the registry's SQLite store.
//!
//! Architecture invariant: depends on no other project crate.

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
    /// Optional Zenoh JSON5 config file loaded first (TLS, ACL, ...); the fields above override it.
    pub config_file: Option<PathBuf>,
}

impl Default for ZenohSettings {
    fn default() -> Self {
        Self {
            mode: "peer".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            config_file: None,
        }
    }
}

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
            multicast_scouting: false,
            config_file: None,
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
        Ok(config)
    }
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

    /// A connect-only session (what actors and one-shot commands open) listens on no port.
    #[cfg(target_os = "linux")]
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_connect_only_session_listens_nowhere() {
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
