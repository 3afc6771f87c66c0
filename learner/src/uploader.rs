//! Registry uploads in the background: the learner's local checkpoint is the source of truth, and
//! storing it (with the run's deploy artifacts) in the registry must never stop training.
//!
//! Main type: [`RegistryUploader`]. [`RegistryUploader::submit`] queues an [`Upload`]; one task
//! stores uploads in order, retrying each with exponential backoff while the registry is away.
//! The backlog and the failed attempts are counters the learner logs as metrics.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use l3p_registry_client::{LineageRole, PutRequest, RegistryClient};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::{info, warn};

/// Uploads waiting beyond this many are dropped (newest first): during a long outage the local
/// checkpoint keeps the state, and the registry gets the next upload after it.
pub const MAX_BACKLOG: usize = 8;

const FIRST_RETRY: Duration = Duration::from_secs(1);
const MAX_RETRY: Duration = Duration::from_secs(30);

/// One registry checkpoint: the checkpoint, then each robot's deploy artifact with a lineage edge
/// to the checkpoint version the registry assigned.
#[derive(Debug, Clone)]
pub struct Upload {
    pub iteration: u64,
    pub checkpoint: PutRequest,
    pub deploys: Vec<PutRequest>,
}

/// Counters shared between the learner loop and the upload task.
#[derive(Debug, Clone, Default)]
pub struct UploadStats {
    backlog: Arc<AtomicU64>,
    failed_attempts: Arc<AtomicU64>,
    dropped: Arc<AtomicU64>,
}

impl UploadStats {
    /// Uploads queued or in progress.
    pub fn backlog(&self) -> u64 {
        self.backlog.load(Ordering::Relaxed)
    }
    /// Put attempts that failed (each is retried).
    pub fn failed_attempts(&self) -> u64 {
        self.failed_attempts.load(Ordering::Relaxed)
    }
    /// Uploads dropped because the backlog was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// The background upload task and its queue.
pub struct RegistryUploader {
    tx: mpsc::Sender<Upload>,
    stats: UploadStats,
    task: JoinHandle<()>,
}

impl RegistryUploader {
    /// Starts the upload task on the current Tokio runtime.
    pub fn spawn(client: RegistryClient) -> Self {
        let (tx, mut rx) = mpsc::channel::<Upload>(MAX_BACKLOG);
        let stats = UploadStats::default();
        let task_stats = stats.clone();
        let task = tokio::spawn(async move {
            while let Some(upload) = rx.recv().await {
                store_with_retries(&client, upload, &task_stats).await;
                task_stats.backlog.fetch_sub(1, Ordering::Relaxed);
            }
        });
        Self { tx, stats, task }
    }

    /// Queues `upload`; never waits. A full backlog drops it with a warning.
    pub fn submit(&self, upload: Upload) {
        let iteration = upload.iteration;
        self.stats.backlog.fetch_add(1, Ordering::Relaxed);
        if self.tx.try_send(upload).is_err() {
            self.stats.backlog.fetch_sub(1, Ordering::Relaxed);
            self.stats.dropped.fetch_add(1, Ordering::Relaxed);
            warn!(
                iteration,
                backlog = MAX_BACKLOG,
                "registry upload backlog full: this checkpoint stays local only"
            );
        }
    }

    pub fn stats(&self) -> &UploadStats {
        &self.stats
    }

    /// Waits up to `deadline` for the queued uploads; returns how many were not stored.
    pub async fn finish(self, deadline: Duration) -> u64 {
        let Self { tx, stats, task } = self;
        drop(tx);
        let abort = task.abort_handle();
        if tokio::time::timeout(deadline, task).await.is_err() {
            abort.abort();
        }
        stats.backlog()
    }
}

async fn store_with_retries(client: &RegistryClient, mut upload: Upload, stats: &UploadStats) {
    let mut checkpoint_ref: Option<String> = None;
    let mut delay = FIRST_RETRY;
    let mut failures = 0u32;
    loop {
        match store(client, &mut upload, &mut checkpoint_ref).await {
            Ok(()) => {
                if failures > 0 {
                    info!(
                        iteration = upload.iteration,
                        failures, "registry upload stored after retries"
                    );
                }
                return;
            }
            Err(e) => {
                failures += 1;
                stats.failed_attempts.fetch_add(1, Ordering::Relaxed);
                warn!(
                    iteration = upload.iteration,
                    retry_in_s = delay.as_secs(),
                    "registry upload failed (training continues): {e}"
                );
                tokio::time::sleep(delay).await;
                delay = (delay * 2).min(MAX_RETRY);
            }
        }
    }
}

/// Stores what is left of `upload`: the checkpoint once, then the deploy artifacts one by one, so
/// a retry never stores a part twice.
async fn store(
    client: &RegistryClient,
    upload: &mut Upload,
    checkpoint_ref: &mut Option<String>,
) -> Result<(), l3p_registry_client::RegistryError> {
    let reference = match checkpoint_ref {
        Some(r) => r.clone(),
        None => {
            let stored = client.put(upload.checkpoint.clone()).await?;
            let r = format!("{}@{}", stored.meta.name, stored.meta.version);
            *checkpoint_ref = Some(r.clone());
            r
        }
    };
    while let Some(deploy) = upload.deploys.first() {
        let req = deploy
            .clone()
            .lineage(LineageRole::FromCheckpoint, &reference);
        client.put(req).await?;
        upload.deploys.remove(0);
    }
    Ok(())
}
