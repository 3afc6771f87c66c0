//! `l3p registry serve|list|show|pull|put|tag|history|lineage|gc`: the artifact registry from the
//! command line. `serve` runs the Zenoh service on a local database; `gc` removes old checkpoint
//! versions from one (always the database itself, never through a service); the other commands talk
//! to a running service through Zenoh (`--connect`, default `tcp/127.0.0.1:7447`, or `--config` for
//! a config's `[zenoh]` with its TLS), or, with `--data <dir>`,
//! open `<dir>/registry.db` directly without any service (SQLite locking keeps that safe next to a
//! running service).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use clap::{Args, Subcommand};
use l3p_net::{ZenohSettings, open_session};
use l3p_registry::{
    ArtifactKind, ArtifactMeta, DEFAULT_KEEP_LAST, GcReport, KeepReason, LineageRole, ListFilter,
    PutRequest, Registry, RegistryAccess, RegistryClient, RetentionPolicy,
};

use crate::runtime::NetArgs;

#[derive(Debug, Args)]
pub struct RegistryArgs {
    #[command(subcommand)]
    pub command: RegistryCommand,
}

/// Where client commands find the registry: a service over Zenoh (the network flags every command
/// shares), or the database itself.
#[derive(Debug, Clone, Args)]
pub struct Target {
    #[command(flatten)]
    pub net: NetArgs,
    /// Read and write `<dir>/registry.db` directly instead of asking a service.
    #[arg(long, visible_alias = "data-dir")]
    pub data: Option<PathBuf>,
}

#[derive(Debug, Subcommand)]
pub enum RegistryCommand {
    /// Serve the registry over Zenoh until Ctrl-C.
    Serve {
        /// Data directory holding registry.db.
        #[arg(long, visible_alias = "data-dir", default_value = "l3p-data")]
        data: PathBuf,
        /// Endpoints to listen on (repeatable); default tcp/127.0.0.1:7447 without --config.
        #[arg(long)]
        listen: Vec<String>,
        /// Endpoints (routers or peers) to connect to (repeatable).
        #[arg(long)]
        connect: Vec<String>,
        /// Enable multicast scouting (LAN discovery); off by default.
        #[arg(long)]
        scouting: bool,
        /// Zenoh JSON5 config file (TLS, ACL, ...), loaded before the flags above.
        #[arg(long)]
        zenoh_config: Option<PathBuf>,
        /// An l3p config whose `[zenoh]` section (mode, endpoints, `[zenoh.tls]`) the service
        /// uses, as the learner and actors do; the flags above override it.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Keep the database bounded while serving: at start and every --gc-every-s seconds,
        /// remove what `l3p registry gc --keep <N>` would (off without this flag). A failed pass
        /// is logged and the service goes on.
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
        gc_keep: Option<u64>,
        /// Seconds between the service's gc passes (with --gc-keep).
        #[arg(long, default_value_t = 3600, value_parser = clap::value_parser!(u64).range(1..))]
        gc_every_s: u64,
    },
    /// List stored versions.
    List {
        #[arg(long)]
        kind: Option<ArtifactKind>,
        #[arg(long)]
        name: Option<String>,
        #[arg(long)]
        robot: Option<String>,
        /// Print the JSON reply instead of a table.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        target: Target,
    },
    /// Show one version's metadata: `<name>@<version|alias>`.
    Show {
        artifact: String,
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        target: Target,
    },
    /// Download a version's blob (hash checked) to a file.
    Pull {
        artifact: String,
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        target: Target,
    },
    /// Store a file as the next version of a name.
    Put {
        file: PathBuf,
        #[arg(long)]
        name: String,
        #[arg(long)]
        kind: ArtifactKind,
        #[arg(long)]
        robot: Option<String>,
        /// Producer recorded with the version.
        #[arg(long, default_value = "cli")]
        producer: String,
        /// Free JSON metadata (`extra`).
        #[arg(long)]
        extra: Option<String>,
        /// Lineage edge `role=name@version|alias` (repeatable), e.g. `trained_against=a1-core@3`.
        #[arg(long)]
        lineage: Vec<String>,
        /// Alias to point at the new version (repeatable).
        #[arg(long)]
        alias: Vec<String>,
        #[command(flatten)]
        target: Target,
    },
    /// Point an alias at a version: `tag a1-core@3 prod`.
    Tag {
        artifact: String,
        alias: String,
        #[command(flatten)]
        target: Target,
    },
    /// Show how a name's aliases moved.
    History {
        name: String,
        #[arg(long)]
        alias: Option<String>,
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        target: Target,
    },
    /// Show what a version depends on and what depends on it.
    Lineage {
        artifact: String,
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        target: Target,
    },
    /// Remove old checkpoint versions: keep the newest --keep of each checkpoint, every aliased
    /// version, every lineage parent of a kept version and every version of other kinds. A deploy
    /// artifact's edge to the checkpoint it was exported from does not keep that checkpoint (the
    /// edge goes with it).
    Gc {
        /// Data directory holding registry.db (opened directly; safe next to a running service).
        #[arg(long, visible_alias = "data-dir", default_value = "l3p-data")]
        data: PathBuf,
        /// Newest versions kept of each checkpoint artifact (at least 1).
        #[arg(long, default_value_t = DEFAULT_KEEP_LAST, value_parser = clap::value_parser!(u64).range(1..))]
        keep: u64,
        /// Print what would be removed and change nothing.
        #[arg(long)]
        dry_run: bool,
        /// Print the JSON report instead of text.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(args: RegistryArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    runtime.block_on(run_async(args.command))
}

/// The registry a client command talks to: `--data`'s database, else a service over Zenoh.
async fn connect(target: &Target) -> anyhow::Result<RegistryAccess> {
    if let Some(dir) = &target.data {
        return Ok(RegistryAccess::Local(Registry::open(dir)?));
    }
    let (_, settings) = target.net.load()?;
    let session = open_session(&settings).await?;
    Ok(RegistryAccess::Remote(RegistryClient::new(&session)))
}

async fn run_async(command: RegistryCommand) -> anyhow::Result<()> {
    match command {
        RegistryCommand::Serve {
            data,
            listen,
            connect,
            scouting,
            zenoh_config,
            config,
            gc_keep,
            gc_every_s,
        } => {
            let mut settings = match &config {
                Some(path) => crate::config::Config::load(path)?.zenoh,
                None => ZenohSettings {
                    listen: vec!["tcp/127.0.0.1:7447".into()],
                    ..ZenohSettings::default()
                },
            };
            if !listen.is_empty() {
                settings.listen = listen;
            }
            if !connect.is_empty() {
                settings.connect = connect;
            }
            settings.multicast_scouting |= scouting;
            if zenoh_config.is_some() {
                settings.config_file = zenoh_config;
            }
            let gc = gc_keep.map(|keep| ServiceGc {
                keep,
                every: std::time::Duration::from_secs(gc_every_s),
            });
            serve(&data, settings, gc).await
        }
        RegistryCommand::List {
            kind,
            name,
            robot,
            json,
            target,
        } => {
            let registry = connect(&target).await?;
            let artifacts = registry.list(&ListFilter { kind, name, robot }).await?;
            if json {
                println!("{}", serde_json::to_string_pretty(&artifacts)?);
            } else {
                print_table(&artifacts);
            }
            Ok(())
        }
        RegistryCommand::Show {
            artifact,
            json,
            target,
        } => {
            let registry = connect(&target).await?;
            let meta = registry.get_meta(&artifact).await?;
            if json {
                println!("{}", serde_json::to_string_pretty(&meta)?);
            } else {
                print_meta(&meta)?;
            }
            Ok(())
        }
        RegistryCommand::Pull {
            artifact,
            output,
            target,
        } => {
            let registry = connect(&target).await?;
            let (meta, bytes) = registry.get_blob(&artifact).await?;
            l3p_policy::write_atomic(&output, &bytes)
                .with_context(|| format!("cannot write {}", output.display()))?;
            println!(
                "{} -> {} ({} bytes, sha256 {})",
                meta.reference(),
                output.display(),
                meta.size,
                meta.sha256
            );
            Ok(())
        }
        RegistryCommand::Put {
            file,
            name,
            kind,
            robot,
            producer,
            extra,
            lineage,
            alias,
            target,
        } => {
            let bytes =
                std::fs::read(&file).with_context(|| format!("cannot read {}", file.display()))?;
            let mut req = PutRequest::new(&name, kind, bytes).producer(&producer);
            if let Some(robot) = robot {
                req = req.robot(&robot);
            }
            if let Some(extra) = extra {
                req = req.extra(serde_json::from_str(&extra).context("--extra is not valid JSON")?);
            }
            for edge in &lineage {
                let (role, artifact) = edge
                    .split_once('=')
                    .with_context(|| format!("--lineage {edge:?}: expected role=name@version"))?;
                req = req.lineage(role.parse::<LineageRole>()?, artifact);
            }
            for alias in &alias {
                req = req.alias(alias);
            }
            let registry = connect(&target).await?;
            let outcome = registry.put(req).await?;
            let what = if outcome.created {
                "stored"
            } else {
                "already stored (identical content)"
            };
            println!(
                "{} {what}, sha256 {}",
                outcome.meta.reference(),
                outcome.meta.sha256
            );
            Ok(())
        }
        RegistryCommand::Tag {
            artifact,
            alias,
            target,
        } => {
            let registry = connect(&target).await?;
            let outcome = registry.tag(&artifact, &alias).await?;
            let e = &outcome.event;
            match (outcome.moved, e.previous) {
                (false, _) => println!(
                    "{}@{} already points at version {}",
                    e.name, e.alias, e.version
                ),
                (true, Some(previous)) => {
                    println!("{}@{}: {previous} -> {}", e.name, e.alias, e.version)
                }
                (true, None) => println!("{}@{}: new -> {}", e.name, e.alias, e.version),
            }
            Ok(())
        }
        RegistryCommand::History {
            name,
            alias,
            json,
            target,
        } => {
            let registry = connect(&target).await?;
            let events = registry.alias_history(&name, alias.as_deref()).await?;
            if json {
                println!("{}", serde_json::to_string_pretty(&events)?);
            } else {
                println!(
                    "{:<14} {:<12} {:>8} {:>8}",
                    "UNIX_MS", "ALIAS", "FROM", "TO"
                );
                for e in &events {
                    let from = e
                        .previous
                        .map(|p| p.to_string())
                        .unwrap_or_else(|| "-".into());
                    println!(
                        "{:<14} {:<12} {:>8} {:>8}",
                        e.unix_ms, e.alias, from, e.version
                    );
                }
            }
            Ok(())
        }
        RegistryCommand::Lineage {
            artifact,
            json,
            target,
        } => {
            let registry = connect(&target).await?;
            let graph = registry.lineage(&artifact).await?;
            if json {
                println!("{}", serde_json::to_string_pretty(&graph)?);
            } else {
                println!("{} ({})", graph.artifact.reference(), graph.artifact.kind);
                println!("depends on:");
                for link in &graph.upstream {
                    println!("  {} --{}--> {}", link.child, link.role, link.parent);
                }
                println!("used by:");
                for link in &graph.downstream {
                    println!("  {} --{}--> {}", link.child, link.role, link.parent);
                }
            }
            Ok(())
        }
        // Local and synchronous: the database itself, no Zenoh.
        RegistryCommand::Gc {
            data,
            keep,
            dry_run,
            json,
        } => gc(&data, keep, dry_run, json),
    }
}

fn gc(data: &Path, keep: u64, dry_run: bool, json: bool) -> anyhow::Result<()> {
    let registry = Registry::open_existing(data)?;
    let report = registry.gc(&RetentionPolicy { keep_last: keep }, dry_run)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_gc(registry.path(), &report);
    }
    Ok(())
}

fn print_gc(path: &Path, r: &GcReport) {
    let verb = if r.dry_run { "would remove" } else { "removed" };
    println!(
        "registry gc of {}{}: keep the newest {} versions of each checkpoint",
        path.display(),
        if r.dry_run { " (dry run)" } else { "" },
        r.keep_last
    );
    println!(
        "{:<24} {:<10} {:>6} {:>8}  REMOVED VERSIONS",
        "NAME", "KIND", "KEPT", "REMOVED"
    );
    for a in &r.artifacts {
        let removed: Vec<String> = a.removed.iter().map(u64::to_string).collect();
        println!(
            "{:<24} {:<10} {:>6} {:>8}  {}",
            a.name,
            a.kind,
            a.kept.len(),
            a.removed.len(),
            if removed.is_empty() {
                "-".to_string()
            } else {
                removed.join(",")
            }
        );
    }
    if !r.kept_because.is_empty() {
        println!("kept beyond the newest {}:", r.keep_last);
        for k in &r.kept_because {
            match &k.reason {
                KeepReason::Alias { alias } => println!("  {:<24} alias {alias}", k.reference),
                KeepReason::Lineage { child, role } => {
                    println!("  {:<24} lineage: {child} --{role}--> it", k.reference)
                }
            }
        }
    }
    println!(
        "{verb} {} versions, {} lineage rows, {} blobs ({} bytes of blobs)",
        r.versions_removed, r.lineage_removed, r.blobs_removed, r.blob_bytes_removed
    );
    if r.lineage_cut > 0 {
        println!(
            "({} of those lineage rows are kept deploy artifacts' edges to the checkpoints they \
             were exported from)",
            r.lineage_cut
        );
    }
    if r.dry_run {
        println!("database file: {} bytes (unchanged)", r.file_bytes_before);
    } else {
        println!(
            "database file: {} -> {} bytes",
            r.file_bytes_before, r.file_bytes_after
        );
    }
}

/// `registry serve --gc-keep`: the retention the service applies, and how often.
#[derive(Debug, Clone, Copy)]
struct ServiceGc {
    keep: u64,
    every: std::time::Duration,
}

/// Applies `gc` at once and then every `gc.every` until `cancel`; each pass on the blocking pool
/// (SQLite's locking keeps it safe beside the service's own requests), its outcome logged.
async fn gc_periodically(
    registry: Arc<Registry>,
    gc: ServiceGc,
    cancel: tokio_util::sync::CancellationToken,
) {
    let mut ticks = tokio::time::interval(gc.every);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = cancel.cancelled() => return,
            _ = ticks.tick() => {}
        }
        let r = registry.clone();
        let policy = RetentionPolicy { keep_last: gc.keep };
        match tokio::task::spawn_blocking(move || r.gc(&policy, false)).await {
            Ok(Ok(report)) => tracing::info!(
                keep = gc.keep,
                versions_removed = report.versions_removed,
                blob_bytes_removed = report.blob_bytes_removed,
                file_bytes_after = report.file_bytes_after,
                "registry gc"
            ),
            Ok(Err(e)) => tracing::warn!("registry gc failed (the service goes on): {e:#}"),
            Err(e) => tracing::warn!("registry gc task failed (the service goes on): {e}"),
        }
    }
}

async fn serve(data: &Path, settings: ZenohSettings, gc: Option<ServiceGc>) -> anyhow::Result<()> {
    let registry = Arc::new(Registry::open(data)?);
    let session = open_session(&settings).await?;
    // Ctrl-C or SIGTERM (systemd, a supervisor) stop the service cleanly.
    let cancel = crate::runtime::cancel_on_signal();
    if let Some(gc) = gc {
        tokio::spawn(gc_periodically(registry.clone(), gc, cancel.clone()));
    }
    eprintln!(
        "registry {} serving on {:?} (connected to {:?})",
        registry.path().display(),
        settings.listen,
        settings.connect
    );
    l3p_registry::serve(&session, registry, cancel).await?;
    session
        .close()
        .await
        .map_err(|e| anyhow::anyhow!("closing the zenoh session: {e}"))?;
    Ok(())
}

fn print_table(artifacts: &[ArtifactMeta]) {
    println!(
        "{:<24} {:>4} {:<10} {:<10} {:>10} {:<12} ALIASES",
        "NAME", "VER", "KIND", "ROBOT", "SIZE", "SHA256"
    );
    for m in artifacts {
        println!(
            "{:<24} {:>4} {:<10} {:<10} {:>10} {:<12} {}",
            m.name,
            m.version,
            m.kind,
            m.robot.as_deref().unwrap_or("-"),
            m.size,
            &m.sha256[..m.sha256.len().min(12)],
            m.aliases.join(",")
        );
    }
}

fn print_meta(m: &ArtifactMeta) -> anyhow::Result<()> {
    println!("artifact:  {}", m.reference());
    println!("kind:      {}", m.kind);
    println!("robot:     {}", m.robot.as_deref().unwrap_or("-"));
    println!("size:      {} bytes", m.size);
    println!("sha256:    {}", m.sha256);
    println!("created:   {} (unix ms)", m.created_unix_ms);
    println!(
        "producer:  {}",
        if m.producer.is_empty() {
            "-"
        } else {
            &m.producer
        }
    );
    println!(
        "aliases:   {}",
        if m.aliases.is_empty() {
            "-".to_string()
        } else {
            m.aliases.join(", ")
        }
    );
    for (key, value) in &m.dims {
        println!("dim:       {key} = {value}");
    }
    for (key, value) in &m.metrics {
        println!("metric:    {key} = {value}");
    }
    for edge in &m.lineage {
        println!(
            "lineage:   {} {} (sha256 {})",
            edge.role,
            edge.reference(),
            &edge.sha256[..edge.sha256.len().min(12)]
        );
    }
    if !m.config.is_null() {
        println!("config:    {}", serde_json::to_string(&m.config)?);
    }
    if !m.extra.is_null() {
        println!("extra:     {}", serde_json::to_string(&m.extra)?);
    }
    Ok(())
}
