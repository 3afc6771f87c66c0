//! TensorBoard event files: framing and CRCs read back, tags and steps as written, and — where
//! Python's `tensorboard` package is installed — TensorBoard's own reader agrees.

use l3p_proto::MetricsRecord;
use l3p_report::tensorboard::{EventWriter, read_events, tfrecord};

fn record(iteration: u64, reward: f64) -> MetricsRecord {
    let mut r = MetricsRecord::new("run", "learner", iteration, 1_700_000_000_000 + iteration);
    r.insert("episode_return", reward);
    r.insert("surrogate_loss", -0.01 * iteration as f64);
    r.insert("Episode_Reward/gait_clock", 0.5);
    r.insert("episode_length", f64::NAN);
    r
}

#[test]
fn scalars_read_back_with_their_tags_and_steps() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = EventWriter::create(dir.path()).unwrap();
    for it in 1..=3 {
        w.write(&record(it, 10.0 * it as f64)).unwrap();
    }
    let events = read_events(w.path()).unwrap();
    assert_eq!(events.len(), 4, "file version + 3 records");
    assert_eq!(events[0].file_version.as_deref(), Some("brain.Event:2"));
    assert!(events[0].scalars.is_empty());
    for (k, e) in events[1..].iter().enumerate() {
        let it = k as i64 + 1;
        assert_eq!(e.step, it);
        assert!((e.wall_time - (1_700_000_000.0 + 0.001 * it as f64)).abs() < 1e-6);
        let get = |tag: &str| e.scalars.iter().find(|(t, _)| t == tag).map(|(_, v)| *v);
        assert_eq!(get("Train/mean_reward"), Some(10.0 * it as f32));
        assert_eq!(get("Loss/surrogate"), Some(-0.01 * it as f32));
        assert_eq!(get("Episode_Reward/gait_clock"), Some(0.5));
        // NaN ("no finished episode yet") is left out, not written as a value.
        assert_eq!(get("Train/mean_episode_length"), None);
        assert_eq!(e.scalars.len(), 3);
    }
}

#[test]
fn a_corrupt_or_truncated_file_is_an_error_naming_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = EventWriter::create(dir.path()).unwrap();
    w.write(&record(1, 1.0)).unwrap();
    let good = std::fs::read(w.path()).unwrap();
    let path = dir.path().join("bad");
    let mut flipped = good.clone();
    let last = flipped.len() - 6;
    flipped[last] ^= 0x40;
    std::fs::write(&path, &flipped).unwrap();
    let err = read_events(&path).unwrap_err().to_string();
    assert!(err.contains("record 1") && err.contains("CRC"), "{err}");
    std::fs::write(&path, &good[..good.len() - 3]).unwrap();
    let err = read_events(&path).unwrap_err().to_string();
    assert!(err.contains("record 1"), "{err}");
    // A length that claims more than the file holds.
    let mut huge = tfrecord(b"x");
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let crc = l3p_report::tensorboard::masked_crc32c(&huge[..8]);
    huge[8..12].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&path, &huge).unwrap();
    let err = read_events(&path).unwrap_err().to_string();
    assert!(err.contains("runs past the file"), "{err}");
}

#[test]
fn tensorboards_own_reader_sees_the_same_scalars() {
    let probe = std::process::Command::new("python3")
        .args([
            "-c",
            "import tensorboard.backend.event_processing.event_accumulator",
        ])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!(
            "skipped: Python's tensorboard package is not installed (pip install tensorboard)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut w = EventWriter::create(dir.path()).unwrap();
    for it in 1..=4 {
        w.write(&record(it, it as f64)).unwrap();
    }
    let script = r#"
import sys
from tensorboard.backend.event_processing import event_accumulator as ea
acc = ea.EventAccumulator(sys.argv[1], size_guidance={ea.SCALARS: 0})
acc.Reload()
for tag in sorted(acc.Tags()["scalars"]):
    print(tag, ",".join(f"{e.step}:{e.value:g}" for e in acc.Scalars(tag)))
"#;
    let out = std::process::Command::new("python3")
        .args(["-c", script, dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Train/mean_reward 1:1,2:2,3:3,4:4"),
        "{stdout}"
    );
    assert!(
        stdout.contains("Loss/surrogate 1:-0.01,2:-0.02,3:-0.03,4:-0.04"),
        "{stdout}"
    );
    assert!(
        stdout.contains("Episode_Reward/gait_clock 1:0.5"),
        "{stdout}"
    );
    assert_eq!(stdout.lines().count(), 3, "{stdout}");
}
