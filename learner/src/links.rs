//! The learner daemon's Zenoh links, each a task feeding or serving the loop in [`crate::daemon`]:
//! the weights server ([`spawn_weights_server`], replies from [`weights_reply`]), the rollout intake
//! ([`spawn_chunk_intake`], which admits only chunks within the run's [`ChunkContract`]) and the
//! actor liveliness watch ([`spawn_liveliness_watch`]).

use std::collections::HashMap;
use std::sync::{Arc, RwLock};
use std::time::Instant;

use l3p_proto::{RolloutChunk, codec, keys};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tracing::warn;
use zenoh::Session;
use zenoh::sample::SampleKind;

use crate::daemon::{DaemonError, Event, LearnerOptions, zerr};

/// Weights of the current policy version, shared with the queryable task.
#[derive(Default)]
pub(crate) struct Published {
    pub(crate) version: u64,
    /// Encoded [`l3p_proto::WeightsBlob`] per robot.
    pub(crate) blobs: HashMap<String, Vec<u8>>,
}

/// Answers `l3p/<run>/policy/weights/<robot>/<version>` queries from `published` until `cancel`.
pub(crate) async fn spawn_weights_server(
    session: &Session,
    run: &str,
    published: Arc<RwLock<Published>>,
    cancel: CancellationToken,
) -> Result<tokio::task::JoinHandle<()>, DaemonError> {
    let queryable = session
        .declare_queryable(keys::policy_weights_all(run))
        .await
        .map_err(zerr)?;
    let run = run.to_string();
    Ok(tokio::spawn(async move {
        loop {
            let query = tokio::select! {
                _ = cancel.cancelled() => break,
                q = queryable.recv_async() => match q { Ok(q) => q, Err(_) => break },
            };
            let key = query.key_expr().as_str().to_string();
            let reply = match published.read() {
                Ok(p) => weights_reply(&p, &key, &run),
                Err(_) => Err(format!("bad weights key {key}")),
            };
            let sent = match reply {
                Ok(bytes) => query.reply(key.clone(), bytes).await,
                Err(message) => query.reply_err(message.into_bytes()).await,
            };
            if let Err(e) = sent {
                warn!("cannot answer weights query {key}: {e}");
            }
        }
    }))
}

/// The reply to a weights query `…/<robot>/<version>`: the robot's blob when `version` is the
/// one served, otherwise an error message for the querier.
pub(crate) fn weights_reply(
    published: &Published,
    key: &str,
    run: &str,
) -> Result<Vec<u8>, String> {
    let parsed = key.rsplitn(3, '/').collect::<Vec<_>>();
    let [version, robot, _] = parsed.as_slice() else {
        return Err(format!("bad weights key {key}"));
    };
    match version.parse::<u64>() {
        Ok(v) if v == published.version => published
            .blobs
            .get(*robot)
            .cloned()
            .ok_or_else(|| format!("unknown robot {robot} in run {run}")),
        Ok(v) => Err(format!(
            "policy version {v} is not served (current {})",
            published.version
        )),
        Err(_) => Err(format!("bad weights key {key}")),
    }
}

/// What a rollout chunk must be to reach the gather: this run, a robot it trains with that robot's
/// observation and action sizes, `steps_per_env` steps and observations within the clip.
pub(crate) struct ChunkContract {
    run: String,
    dims: HashMap<String, (usize, usize)>,
    steps_per_env: usize,
    obs_clip: f32,
}

/// Why a chunk was turned away (logged, counted, never fatal).
#[derive(Debug)]
pub(crate) struct Rejection {
    /// The sender, when the chunk decoded far enough to name it.
    actor: Option<String>,
    reason: String,
}

impl ChunkContract {
    pub(crate) fn of(opts: &LearnerOptions) -> Self {
        ChunkContract {
            run: opts.run.clone(),
            dims: opts
                .robots
                .iter()
                .map(|r| (r.name.clone(), (r.obs_dim, r.action_dim)))
                .collect(),
            steps_per_env: opts.steps_per_env,
            obs_clip: opts.obs_clip,
        }
    }

    /// Decodes and checks one chunk payload.
    pub(crate) fn admit(&self, bytes: &[u8]) -> Result<RolloutChunk, Rejection> {
        let chunk = codec::decode::<RolloutChunk>(bytes).map_err(|e| Rejection {
            actor: None,
            reason: e.to_string(),
        })?;
        let checked = match self.dims.get(&chunk.robot) {
            None => Err(format!(
                "unknown robot {} (run trains {:?})",
                chunk.robot,
                self.dims.keys()
            )),
            Some(_) if chunk.run != self.run => Err(format!("chunk of run {}", chunk.run)),
            Some(&(obs, act)) => chunk
                .validate_contract(obs, act, self.steps_per_env, self.obs_clip)
                .map_err(|e| e.to_string()),
        };
        match checked {
            Ok(()) => Ok(chunk),
            Err(reason) => Err(Rejection {
                actor: Some(chunk.actor_id.clone()),
                reason,
            }),
        }
    }
}

/// Subscribes to the run's rollout chunks and forwards each as [`Event::Chunk`] or
/// [`Event::Rejected`], adding its decode time to `decode_seconds`.
pub(crate) async fn spawn_chunk_intake(
    session: &Session,
    contract: ChunkContract,
    tx: mpsc::Sender<Event>,
    decode_seconds: Arc<std::sync::Mutex<f64>>,
) -> Result<tokio::task::JoinHandle<()>, DaemonError> {
    let rollouts = session
        .declare_subscriber(keys::rollout_all(&contract.run))
        .await
        .map_err(zerr)?;
    Ok(tokio::spawn(async move {
        while let Ok(sample) = rollouts.recv_async().await {
            let start = Instant::now();
            let event = match contract.admit(&sample.payload().to_bytes()) {
                Ok(chunk) => Event::Chunk(Box::new(chunk)),
                Err(Rejection { actor, reason }) => {
                    let actor = actor.unwrap_or_default();
                    warn!(key = %sample.key_expr(), %actor, "rejected chunk: {reason}");
                    Event::Rejected
                }
            };
            if let Ok(mut acc) = decode_seconds.lock() {
                *acc += start.elapsed().as_secs_f64();
            }
            if tx.send(event).await.is_err() {
                break;
            }
        }
    }))
}

/// Watches the run's actor liveliness tokens (with history) and forwards joins and leaves.
pub(crate) async fn spawn_liveliness_watch(
    session: &Session,
    run: &str,
    tx: mpsc::Sender<Event>,
) -> Result<tokio::task::JoinHandle<()>, DaemonError> {
    let liveliness = session
        .liveliness()
        .declare_subscriber(keys::actors_all(run))
        .history(true)
        .await
        .map_err(zerr)?;
    let run = run.to_string();
    Ok(tokio::spawn(async move {
        while let Ok(sample) = liveliness.recv_async().await {
            let Some((robot, actor)) =
                keys::parse_actor_liveliness(&run, sample.key_expr().as_str())
            else {
                continue;
            };
            let id = format!("{robot}/{actor}");
            let event = match sample.kind() {
                SampleKind::Put => Event::ActorUp(id),
                SampleKind::Delete => Event::ActorDown(id),
            };
            if tx.send(event).await.is_err() {
                break;
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_served_for_the_current_version_only() {
        let published = Published {
            version: 7,
            blobs: HashMap::from([("a1".to_string(), vec![1, 2, 3])]),
        };
        let key = |robot: &str, version: &str| format!("l3p/run/policy/weights/{robot}/{version}");
        assert_eq!(
            weights_reply(&published, &key("a1", "7"), "run"),
            Ok(vec![1, 2, 3])
        );
        let stale = weights_reply(&published, &key("a1", "6"), "run").unwrap_err();
        assert!(
            stale.contains("version 6 is not served (current 7)"),
            "{stale}"
        );
        let unknown = weights_reply(&published, &key("go1", "7"), "run").unwrap_err();
        assert!(unknown.contains("unknown robot go1"), "{unknown}");
        let bad = weights_reply(&published, &key("a1", "latest"), "run").unwrap_err();
        assert!(bad.contains("bad weights key"), "{bad}");
        assert!(weights_reply(&published, "x", "run").is_err());
    }

    fn contract() -> ChunkContract {
        ChunkContract {
            run: "run".into(),
            dims: HashMap::from([("a1".to_string(), (2, 1))]),
            steps_per_env: 3,
            obs_clip: 100.0,
        }
    }

    fn chunk_bytes(chunk: &RolloutChunk) -> Vec<u8> {
        codec::encode(chunk).unwrap()
    }

    /// A chunk that passes every value check (positive action stds).
    fn chunk(run: &str, robot: &str, steps: usize, obs: usize) -> RolloutChunk {
        let mut c = RolloutChunk::zeros(run, robot, "x", 0, 4, steps, obs, 1);
        c.action_stds.fill(1.0);
        c
    }

    #[test]
    fn only_chunks_within_the_run_contract_are_admitted() {
        let c = contract();
        let good = chunk("run", "a1", 3, 2);
        assert_eq!(c.admit(&chunk_bytes(&good)).unwrap().actor_id, "x");

        let garbage = c.admit(&[1, 2, 3]).unwrap_err();
        assert_eq!(garbage.actor, None);
        let cases = [
            (chunk("other", "a1", 3, 2), "chunk of run other"),
            (chunk("run", "go1", 3, 2), "unknown robot go1"),
            (chunk("run", "a1", 1, 2), "steps"),
            (chunk("run", "a1", 3, 5), "obs"),
            (
                RolloutChunk::zeros("run", "a1", "x", 0, 4, 3, 2, 1),
                "action_stds",
            ),
        ];
        for (chunk, why) in cases {
            let r = c.admit(&chunk_bytes(&chunk)).unwrap_err();
            assert_eq!(r.actor.as_deref(), Some("x"));
            assert!(r.reason.contains(why), "{why}: {}", r.reason);
        }
        let mut huge = good.clone();
        huge.observations[0] = 1e30;
        assert!(
            c.admit(&chunk_bytes(&huge)).is_err(),
            "observation outside the clip"
        );
    }
}
