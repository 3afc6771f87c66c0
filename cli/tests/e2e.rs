//! End-to-end over real processes on loopback Zenoh: `l3p registry serve`, `l3p learner` and two
//! `l3p actor`s (two robots, one shared core). Checks that policy versions advance and metrics reach
//! an outside subscriber, that malformed chunks are rejected and counted while training goes on, that
//! killing an actor does not stall training, that a killed learner resumes from its checkpoint, and
//! that training goes on while the registry is down (uploads wait in a backlog).
//!
//! (Process-level tests live in the `cli` crate because Cargo tells only this package's tests where
//! the `l3p` binary is.)

use std::path::Path;
use std::time::{Duration, Instant};

mod common;

use common::{Procs, log_tails, wait_for_port};
use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_proto::{MetricsRecord, RolloutChunk, codec, keys};

const RUN: &str = "e2e";

fn write_config(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("e2e.toml");
    let text = format!(
        r#"
[run]
name = "{RUN}"
data_dir = "{data}"

[env]
height_scan = false
[env.terrain]
preset = "flat"

[model]
encoder_hidden = [32]
core_hidden = [32]
decoder_hidden = [32]
critic_hidden = [32, 32]
[model.recovery]
obs_hidden = [32]
diffusion_steps = 10
eval_samples = 32

[learner]
min_actors = 2
gather_timeout_s = 30.0
checkpoint_every = 2
registry_checkpoint_every = 2
max_iterations = 0

[rollout]
steps_per_env = 8

[[actors]]
robot = "a1"
envs = 4

[[actors]]
robot = "go1"
envs = 4
"#,
        data = dir.join("data").display()
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// Learner records received so far.
struct Watcher {
    rx: tokio::sync::mpsc::UnboundedReceiver<MetricsRecord>,
    seen: Vec<MetricsRecord>,
    log_dir: std::path::PathBuf,
}

impl Watcher {
    /// Wait for a learner record satisfying `pred`; panics with the logs' location on timeout.
    async fn until(
        &mut self,
        what: &str,
        timeout: Duration,
        pred: impl Fn(&MetricsRecord) -> bool,
    ) -> MetricsRecord {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.rx.recv()).await {
                Ok(Some(record)) => {
                    self.seen.push(record.clone());
                    if pred(&record) {
                        return record;
                    }
                }
                _ => panic!(
                    "timed out waiting for {what}; learner records seen: {:?}{}",
                    self.seen
                        .iter()
                        .filter(|r| r.source == "learner")
                        .map(|r| r.iteration)
                        .collect::<Vec<_>>(),
                    log_tails(&self.log_dir)
                ),
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn distributed_training_survives_bad_input_and_dead_processes() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let config_arg = config.to_str().unwrap();
    let registry_port = free_loopback_port().unwrap();
    let learner_port = loop {
        let port = free_loopback_port().unwrap();
        if port != registry_port {
            break port;
        }
    };
    let registry_ep = format!("tcp/127.0.0.1:{registry_port}");
    let learner_ep = format!("tcp/127.0.0.1:{learner_port}");
    let data = dir.path().join("data");
    let mut procs = Procs(Vec::new());
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            data.to_str().unwrap(),
            "--listen",
            &registry_ep,
        ],
        dir.path(),
    );
    wait_for_port(
        registry_port,
        Duration::from_secs(60),
        "the registry",
        dir.path(),
    );
    let learner_args = [
        "learner",
        "--config",
        config_arg,
        "--listen",
        &learner_ep,
        "--connect",
        &registry_ep,
        "--registry",
    ];
    procs.spawn("learner", &learner_args, dir.path());
    wait_for_port(
        learner_port,
        Duration::from_secs(60),
        "the learner",
        dir.path(),
    );
    for (robot, id) in [("a1", "a1-0"), ("go1", "go1-0")] {
        let args = [
            "actor",
            "--config",
            config_arg,
            "--robot",
            robot,
            "--id",
            id,
            "--connect",
            &registry_ep,
            "--connect",
            &learner_ep,
        ];
        procs.spawn(id, &args, dir.path());
    }

    // An outside subscriber, as a user would run `l3p metrics --follow`.
    let session = open_session(&ZenohSettings::loopback(
        None,
        &[registry_port, learner_port],
    ))
    .await
    .unwrap();
    let subscriber = session
        .declare_subscriber(keys::metrics_all(RUN))
        .await
        .unwrap();
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    tokio::spawn(async move {
        while let Ok(sample) = subscriber.recv_async().await {
            if let Ok(record) = codec::decode_json::<MetricsRecord>(&sample.payload().to_bytes()) {
                let _ = tx.send(record);
            }
        }
    });
    let mut watch = Watcher {
        rx,
        seen: Vec::new(),
        log_dir: dir.path().to_path_buf(),
    };

    // 1. Versions advance with both robots contributing samples.
    let first = watch
        .until("iteration 3", Duration::from_secs(180), |r| {
            r.source == "learner" && r.iteration >= 3
        })
        .await;
    assert_eq!(first.values["actors"], 2.0, "{first:?}");
    assert_eq!(
        first.values["samples"],
        (2 * 4 * 8) as f64,
        "both actors' chunks in one update"
    );
    watch
        .until("actor metrics", Duration::from_secs(60), |r| {
            r.source.starts_with("actor-a1")
        })
        .await;

    // 2. Malformed bytes, a chunk holding NaN, one of an unknown robot, one of the wrong step count
    // and one of huge values are rejected and counted; training continues.
    let publisher = session
        .declare_publisher(keys::rollout(RUN, "a1", "intruder"))
        .await
        .unwrap();
    publisher.put(b"not a chunk".to_vec()).await.unwrap();
    let mut chunk = RolloutChunk::zeros(RUN, "a1", "intruder", first.iteration, 4, 8, 48, 12);
    chunk.action_stds.fill(1.0);
    chunk.rewards[5] = f32::NAN;
    publisher.put(codec::encode(&chunk).unwrap()).await.unwrap();
    let mut unknown =
        RolloutChunk::zeros(RUN, "cheetah", "intruder", first.iteration, 4, 8, 48, 12);
    unknown.action_stds.fill(1.0);
    publisher
        .put(codec::encode(&unknown).unwrap())
        .await
        .unwrap();
    // Well-formed but odd (these used to end `l3p train`): one step instead of the run's 8, and
    // finite values large enough to overflow the loss.
    let mut one_step = RolloutChunk::zeros(RUN, "a1", "intruder", first.iteration, 4, 1, 48, 12);
    one_step.action_stds.fill(1.0);
    publisher
        .put(codec::encode(&one_step).unwrap())
        .await
        .unwrap();
    let mut huge = RolloutChunk::zeros(RUN, "a1", "intruder", first.iteration, 4, 8, 48, 12);
    huge.action_stds.fill(1.0);
    huge.observations.fill(3e38);
    publisher.put(codec::encode(&huge).unwrap()).await.unwrap();
    let after_bad = watch
        .until(
            "rejected chunks to be counted",
            Duration::from_secs(120),
            |r| {
                r.source == "learner"
                    && r.values.get("rejected_chunks").copied().unwrap_or(0.0) >= 5.0
            },
        )
        .await;

    // 3. Kill one actor: training continues with the other.
    procs.kill("go1-0");
    let target = after_bad.iteration + 3;
    let alone = watch
        .until("progress without go1", Duration::from_secs(180), |r| {
            r.source == "learner" && r.iteration >= target
        })
        .await;
    assert_eq!(alone.values["actors"], 1.0, "{alone:?}");
    assert_eq!(alone.values["samples"], (4 * 8) as f64);

    // 4. Kill the learner and restart it: it resumes from its last checkpoint, not from zero.
    let before_kill = watch
        .seen
        .iter()
        .filter(|r| r.source == "learner")
        .map(|r| r.iteration)
        .max()
        .unwrap();
    procs.kill("learner");
    let killed_at = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as u64;
    procs.spawn("learner-2", &learner_args, dir.path());
    let resumed = watch
        .until("the restarted learner", Duration::from_secs(180), |r| {
            r.source == "learner" && r.unix_ms > killed_at
        })
        .await;
    assert!(
        resumed.iteration <= before_kill + 1,
        "{} after {before_kill}",
        resumed.iteration
    );
    // Checkpoints every 2 iterations, written after the iteration's metrics: the kill may land
    // between the two, so the newest checkpoint is at least `before_kill − 2`.
    let oldest_allowed = before_kill.saturating_sub(2);
    assert!(
        resumed.iteration > oldest_allowed && resumed.iteration >= 3,
        "resumed at {} after reaching {before_kill}",
        resumed.iteration
    );

    // 5. Kill the registry: training goes on past several registry checkpoints (every 2
    // iterations), the uploads wait in the backlog and the failed attempts are counted (an upload
    // sent within the client's discovery window after the learner started waits for that window
    // to pass before it counts as failed).
    procs.kill("registry");
    let target = resumed.iteration + 6;
    let outage = watch
        .until(
            "progress without the registry, failed uploads counted",
            Duration::from_secs(180),
            |r| {
                r.source == "learner"
                    && r.iteration >= target
                    && r.values
                        .get("registry_failed_attempts")
                        .copied()
                        .unwrap_or(0.0)
                        >= 1.0
            },
        )
        .await;
    assert!(
        outage.values["registry_backlog"] >= 1.0
            && outage.values["registry_failed_attempts"] >= 1.0,
        "{outage:?}"
    );

    // 6. A forged liveliness token (an "actor" that never sends) costs one short wait (at most as
    // long again as the real actors' chunks took, never the 30 s gather timeout), once.
    let _forged = session
        .liveliness()
        .declare_token(keys::actor_liveliness(RUN, "a1", "ghost"))
        .await
        .unwrap();
    let target = outage.iteration + 4;
    let after_ghost = watch
        .until(
            "progress past a silent actor",
            Duration::from_secs(65),
            |r| r.source == "learner" && r.iteration >= target,
        )
        .await;
    assert_eq!(after_ghost.values["silent_actors"], 1.0, "{after_ghost:?}");
    let waits: Vec<f64> = watch
        .seen
        .iter()
        .filter(|r| r.source == "learner" && r.iteration > outage.iteration)
        .map(|r| r.values["gather_wait_seconds"])
        .collect();
    assert!(
        waits.iter().all(|&w| w < 15.0),
        "a ghost must not cost a gather timeout: waits {waits:?}"
    );
    eprintln!("gather waits after a forged liveliness token: {waits:?}");
}
