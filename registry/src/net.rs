//! Zenoh session set-up shared by every l3p process ([`ZenohSettings`] → [`open_session`]). It lives in
//! the registry crate because that is the lowest crate that speaks Zenoh and every daemon (learner,
//! actor, deploy) already depends on the registry client.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// How a process joins the Zenoh network (`[zenoh]` in the config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohSettings {
    /// `peer` (LAN, default) or `client` (through a `zenohd` router).
    pub mode: String,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447`. Empty: Zenoh's default.
    pub listen: Vec<String>,
    /// Endpoints to connect to (routers or peers).
    pub connect: Vec<String>,
    /// Multicast scouting (automatic discovery on the LAN). Off in local mode and tests, which connect
    /// explicitly over loopback so that two runs on one machine never see each other.
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
            multicast_scouting: true,
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
        if !self.listen.is_empty() {
            set("listen/endpoints", json(&self.listen))?;
        }
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
}
