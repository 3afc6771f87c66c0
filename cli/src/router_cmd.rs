//! `l3p router`: a Zenoh router from the l3p binary, for training and deployment across machines
//! without installing `zenohd`. The same library router `zenohd` runs (no plugins): with a config
//! whose `[zenoh] config_file` is `deploy/zenoh/router-acl.json5` and `[zenoh.tls]` pointing at the
//! router's certificate, it enforces the shipped ACL over mutual TLS (deploy/README.md).

use std::time::Duration;

use clap::Args;
use l3p_net::{DEFAULT_RX_BUFFER_SIZE, Exposure, open_session};

use crate::runtime::{self, NetArgs};

/// `l3p router` arguments.
#[derive(Debug, Args)]
pub struct RouterArgs {
    #[command(flatten)]
    pub net: NetArgs,
    /// Run even though a listener leaves this machine without mutual TLS.
    #[arg(long)]
    pub insecure: bool,
}

/// Runs the router until Ctrl-C or SIGTERM.
pub fn run(args: RouterArgs) -> anyhow::Result<()> {
    let (_, mut settings) = args.net.load()?;
    settings.mode = "router".into();
    if args.net.config.is_none() {
        // `NetArgs` makes a config-less process connect to 127.0.0.1:7447; a router listens there
        // and connects only to the routers it is given.
        if args.net.connect.is_empty() {
            settings.connect.clear();
        }
        if args.net.listen.is_empty() {
            settings.listen = vec!["tcp/127.0.0.1:7447".into()];
        }
    }
    if settings.listen.is_empty() {
        anyhow::bail!("a router needs an endpoint to listen on: give --listen or [zenoh] listen");
    }
    match settings.exposure()? {
        Exposure::Unauthenticated(why) if !args.insecure => anyhow::bail!(
            "refusing to route for other machines over unauthenticated links: {why}; give \
             [zenoh.tls] (deploy/README.md) or run with --insecure"
        ),
        Exposure::Unauthenticated(why) => {
            tracing::warn!("routing over unauthenticated links (--insecure): {why}");
        }
        Exposure::Local | Exposure::Authenticated => {}
    }
    if let Some(bytes) = settings.oversized_rx_buffer()? {
        tracing::warn!(
            "transport/link/rx/buffer_size is {bytes} bytes: Zenoh allocates that much for every \
             link a client opens, so a router whose clients reconnect grows by up to that much \
             each time; leave it at Zenoh's default ({DEFAULT_RX_BUFFER_SIZE})"
        );
    }
    runtime::tokio_runtime()?.block_on(async move {
        let cancel = runtime::cancel_on_signal();
        let session = open_session(&settings).await?;
        eprintln!(
            "router {} listening on {}",
            session.zid(),
            settings.listen.join(", ")
        );
        cancel.cancelled().await;
        tokio::time::timeout(Duration::from_secs(5), session.close())
            .await
            .map_err(|_| anyhow::anyhow!("closing the router's session timed out"))?
            .map_err(|e| anyhow::anyhow!("closing the router's session: {e}"))?;
        Ok(())
    })
}
