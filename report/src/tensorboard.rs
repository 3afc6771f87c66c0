//! TensorBoard event files for a run's scalar metrics, so `tensorboard --logdir l3p-data` shows
//! every run with no conversion. [`EventWriter`] appends [`MetricsRecord`]s as scalar summaries;
//! [`tag_for`] names each metric as rsl_rl/IsaacLab do (`Loss/surrogate`, `Train/mean_reward`,
//! `Episode_Reward/<term>`, `Perf/total_fps`).
//!
//! The format, written here rather than through a crate (the maintained ones pull in a protobuf
//! code generator or TensorFlow bindings): a file of TFRecords, each
//! `u64 length (LE) · u32 masked CRC-32C of the length · data · u32 masked CRC-32C of the data`,
//! where `data` is a serialised `tensorflow.Event` protobuf. Only the fields a scalar needs are
//! written: `Event { wall_time: double = 1, step: int64 = 2, file_version: string = 3,
//! summary: Summary = 5 }`, `Summary { value: repeated Value = 1 }`, `Value { tag: string = 1,
//! simple_value: float = 2 }`. The first event carries `file_version = "brain.Event:2"`.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use l3p_proto::MetricsRecord;

/// The CRC-32C (Castagnoli, reflected polynomial 0x82F63B78) lookup table.
const CRC32C_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = i as u32;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0x82F6_3B78
            } else {
                crc >> 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// CRC-32C of `data`.
pub fn crc32c(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc = CRC32C_TABLE[((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
    }
    !crc
}

/// TFRecord's masked CRC: rotated right by 15 bits plus a constant, so that a CRC stored inside
/// checksummed data does not checksum to a fixed value.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let crc = crc32c(data);
    (crc.rotate_right(15)).wrapping_add(0xa282_ead8)
}

/// One TFRecord around `data`.
pub fn tfrecord(data: &[u8]) -> Vec<u8> {
    let len = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc32c(&len).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc32c(data).to_le_bytes());
    out
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Protobuf field key: `field << 3 | wire type` (0 varint, 1 64-bit, 2 length-delimited, 5 32-bit).
fn put_key(out: &mut Vec<u8>, field: u32, wire_type: u8) {
    put_varint(out, ((field as u64) << 3) | wire_type as u64);
}

fn put_bytes(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, 2);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// A serialised `Event` with `wall_time`, `step` and either a file version or scalar values.
fn event(
    wall_time: f64,
    step: i64,
    file_version: Option<&str>,
    scalars: &[(String, f32)],
) -> Vec<u8> {
    let mut out = Vec::new();
    put_key(&mut out, 1, 1);
    out.extend_from_slice(&wall_time.to_le_bytes());
    put_key(&mut out, 2, 0);
    put_varint(&mut out, step as u64);
    if let Some(v) = file_version {
        put_bytes(&mut out, 3, v.as_bytes());
    }
    if !scalars.is_empty() {
        let mut summary = Vec::new();
        for (tag, value) in scalars {
            let mut v = Vec::new();
            put_bytes(&mut v, 1, tag.as_bytes());
            put_key(&mut v, 2, 5);
            v.extend_from_slice(&value.to_le_bytes());
            put_bytes(&mut summary, 1, &v);
        }
        put_bytes(&mut out, 5, &summary);
    }
    out
}

/// rsl_rl's names for the metrics it also logs (`rsl_rl/runners/on_policy_runner.py`), so curves
/// line up with IsaacLab runs in one TensorBoard.
const RSL_RL_TAGS: &[(&str, &str)] = &[
    ("surrogate_loss", "Loss/surrogate"),
    ("value_loss", "Loss/value_function"),
    ("entropy", "Loss/entropy"),
    ("learning_rate", "Loss/learning_rate"),
    ("mean_std", "Policy/mean_noise_std"),
    ("samples_per_second", "Perf/total_fps"),
    ("collect_seconds", "Perf/collection time"),
    ("update_seconds", "Perf/learning_time"),
    ("episode_return", "Train/mean_reward"),
    ("episode_length", "Train/mean_episode_length"),
];

/// TensorBoard tag of metric `key`: rsl_rl's name where it logs the same quantity; a key that is
/// already grouped (`Episode_Reward/<term>`, `time/<stage>_seconds`) as it is; other losses under
/// `Loss/`, everything else under `Metrics/`.
pub fn tag_for(key: &str) -> String {
    if let Some((_, tag)) = RSL_RL_TAGS.iter().find(|(k, _)| *k == key) {
        (*tag).to_string()
    } else if key.contains('/') {
        key.to_string()
    } else if key.ends_with("_loss") {
        format!("Loss/{key}")
    } else {
        format!("Metrics/{key}")
    }
}

/// Appends scalar events to one `events.out.tfevents.*` file.
pub struct EventWriter {
    file: File,
    path: PathBuf,
}

impl EventWriter {
    /// Creates a new event file in `dir` (TensorBoard reads every such file in a run's directory,
    /// so a resumed run adds a file and its curves continue).
    pub fn create(dir: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        let host = std::fs::read_to_string("/etc/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty() && h.chars().all(|c| c.is_ascii_alphanumeric() || c == '-'))
            .unwrap_or_else(|| "localhost".into());
        let path = dir.join(format!(
            "events.out.tfevents.{}.{host}.{}.l3p",
            now.as_secs(),
            std::process::id()
        ));
        let mut file = std::fs::OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(&path)?;
        file.write_all(&tfrecord(&event(
            now.as_secs_f64(),
            0,
            Some("brain.Event:2"),
            &[],
        )))?;
        Ok(EventWriter { file, path })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends every finite value of `record` at step `record.iteration` (non-finite values are
    /// left out: TensorBoard would draw them as gaps anyway, and NaN marks "no episodes yet").
    pub fn write(&mut self, record: &MetricsRecord) -> io::Result<()> {
        let scalars: Vec<(String, f32)> = record
            .values
            .iter()
            .filter(|(_, v)| v.is_finite())
            .map(|(k, v)| (tag_for(k), *v as f32))
            .collect();
        let wall_time = record.unix_ms as f64 / 1000.0;
        self.file.write_all(&tfrecord(&event(
            wall_time,
            record.iteration as i64,
            None,
            &scalars,
        )))?;
        self.file.flush()
    }
}

/// One event read back by [`read_events`].
#[derive(Debug, Clone, PartialEq)]
pub struct ReadEvent {
    pub wall_time: f64,
    pub step: i64,
    pub file_version: Option<String>,
    /// `(tag, simple_value)` of every summary value.
    pub scalars: Vec<(String, f32)>,
}

fn bad(msg: impl Into<String>) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, msg.into())
}

/// A protobuf reader over one message's bytes (only the wire types the event format uses).
struct Fields<'a> {
    data: &'a [u8],
}

enum FieldValue<'a> {
    Varint(u64),
    Fixed64([u8; 8]),
    Bytes(&'a [u8]),
    Fixed32([u8; 4]),
}

impl<'a> Fields<'a> {
    fn varint(&mut self) -> io::Result<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let (&b, rest) = self
                .data
                .split_first()
                .ok_or_else(|| bad("truncated varint"))?;
            self.data = rest;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(bad("varint longer than 10 bytes"))
    }

    fn take(&mut self, n: usize) -> io::Result<&'a [u8]> {
        if n > self.data.len() {
            return Err(bad("field runs past the message"));
        }
        let (head, rest) = self.data.split_at(n);
        self.data = rest;
        Ok(head)
    }

    fn next_field(&mut self) -> io::Result<Option<(u64, FieldValue<'a>)>> {
        if self.data.is_empty() {
            return Ok(None);
        }
        let key = self.varint()?;
        let value = match key & 7 {
            0 => FieldValue::Varint(self.varint()?),
            1 => FieldValue::Fixed64(self.take(8)?.try_into().map_err(|_| bad("fixed64"))?),
            2 => {
                let n = self.varint()?;
                FieldValue::Bytes(self.take(usize::try_from(n).map_err(|_| bad("length"))?)?)
            }
            5 => FieldValue::Fixed32(self.take(4)?.try_into().map_err(|_| bad("fixed32"))?),
            t => return Err(bad(format!("unsupported wire type {t}"))),
        };
        Ok(Some((key >> 3, value)))
    }
}

fn decode_event(data: &[u8]) -> io::Result<ReadEvent> {
    let mut e = ReadEvent {
        wall_time: 0.0,
        step: 0,
        file_version: None,
        scalars: Vec::new(),
    };
    let mut fields = Fields { data };
    while let Some((field, value)) = fields.next_field()? {
        match (field, value) {
            (1, FieldValue::Fixed64(b)) => e.wall_time = f64::from_le_bytes(b),
            (2, FieldValue::Varint(v)) => e.step = v as i64,
            (3, FieldValue::Bytes(b)) => {
                e.file_version = Some(String::from_utf8_lossy(b).into_owned());
            }
            (5, FieldValue::Bytes(summary)) => {
                let mut values = Fields { data: summary };
                while let Some((field, value)) = values.next_field()? {
                    let (1, FieldValue::Bytes(v)) = (field, value) else {
                        continue;
                    };
                    let (mut tag, mut simple) = (String::new(), None);
                    let mut vf = Fields { data: v };
                    while let Some((field, value)) = vf.next_field()? {
                        match (field, value) {
                            (1, FieldValue::Bytes(t)) => tag = String::from_utf8_lossy(t).into(),
                            (2, FieldValue::Fixed32(b)) => simple = Some(f32::from_le_bytes(b)),
                            _ => {}
                        }
                    }
                    if let Some(v) = simple {
                        e.scalars.push((tag, v));
                    }
                }
            }
            _ => {}
        }
    }
    Ok(e)
}

/// Reads an event file back, checking every record's length and data CRCs (an error names the
/// record). For tests and tools; TensorBoard itself reads these files.
pub fn read_events(path: &Path) -> io::Result<Vec<ReadEvent>> {
    let bytes = std::fs::read(path)?;
    let mut rest = bytes.as_slice();
    let mut events = Vec::new();
    while !rest.is_empty() {
        let k = events.len();
        if rest.len() < 12 {
            return Err(bad(format!("record {k}: truncated header")));
        }
        let (len_bytes, tail) = rest.split_at(8);
        let len_crc = u32::from_le_bytes(tail[..4].try_into().map_err(|_| bad("crc"))?);
        if masked_crc32c(len_bytes) != len_crc {
            return Err(bad(format!("record {k}: length CRC mismatch")));
        }
        let len = u64::from_le_bytes(len_bytes.try_into().map_err(|_| bad("length"))?);
        let tail = &tail[4..];
        let len = usize::try_from(len)
            .ok()
            .filter(|n| n.checked_add(4).is_some_and(|m| m <= tail.len()))
            .ok_or_else(|| bad(format!("record {k}: length {len} runs past the file")))?;
        let (data, tail) = tail.split_at(len);
        let data_crc = u32::from_le_bytes(tail[..4].try_into().map_err(|_| bad("crc"))?);
        if masked_crc32c(data) != data_crc {
            return Err(bad(format!("record {k}: data CRC mismatch")));
        }
        events.push(decode_event(data).map_err(|e| bad(format!("record {k}: {e}")))?);
        rest = &tail[4..];
    }
    Ok(events)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_matches_the_standard_check_values() {
        // RFC 3720 (iSCSI) B.4 and the catalogue check value for "123456789".
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(crc32c(&[0u8; 32]), 0x8A91_36AA);
        assert_eq!(crc32c(&[0xffu8; 32]), 0x62A8_AB43);
        let ascending: Vec<u8> = (0..32).collect();
        assert_eq!(crc32c(&ascending), 0x46DD_794E);
        assert_eq!(crc32c(b""), 0);
    }

    #[test]
    fn tags_follow_rsl_rl_and_keep_groups() {
        assert_eq!(tag_for("surrogate_loss"), "Loss/surrogate");
        assert_eq!(tag_for("episode_return"), "Train/mean_reward");
        assert_eq!(tag_for("samples_per_second"), "Perf/total_fps");
        assert_eq!(
            tag_for("Episode_Reward/gait_clock"),
            "Episode_Reward/gait_clock"
        );
        assert_eq!(tag_for("time/physics_seconds"), "time/physics_seconds");
        assert_eq!(tag_for("smoothness_loss"), "Loss/smoothness_loss");
        assert_eq!(tag_for("approx_kl"), "Metrics/approx_kl");
    }
}
