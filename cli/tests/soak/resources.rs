//! Resource sampling for the soak: resident memory, open file descriptors and threads of every
//! named process (by its current pid, so a restarted process starts a new *incarnation*), and the
//! bytes of the data directories and files, every `every` seconds on a background thread. [`Growth`]
//! fits a least-squares slope to each series; [`Limits`] says how much growth per hour is allowed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One process at one time.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProcSample {
    pub t_s: f64,
    pub name: String,
    pub pid: u32,
    pub rss_mib: f64,
    pub fds: f64,
    pub threads: f64,
}

/// The directories' sizes at one time.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DiskSample {
    pub t_s: f64,
    /// Bytes under each watched directory, by label.
    pub bytes: BTreeMap<String, u64>,
}

/// Resident memory (MiB), open descriptors and threads of `pid`, or `None` when it is gone.
pub fn process_resources(pid: u32) -> Option<(f64, f64, f64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |key: &str| -> Option<f64> {
        status
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|rest| rest.split_whitespace().next())
            .and_then(|v| v.parse().ok())
    };
    let rss_kib = field("VmRSS:")?;
    let threads = field("Threads:")?;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count() as f64;
    Some((rss_kib / 1024.0, fds, threads))
}

/// Bytes of `path`: a file's length, or the sum over the regular files under a directory (0 when
/// it does not exist).
pub fn path_bytes(path: &Path) -> u64 {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => m.len(),
        Ok(m) if m.is_dir() => std::fs::read_dir(path)
            .map(|entries| entries.flatten().map(|e| path_bytes(&e.path())).sum())
            .unwrap_or(0),
        _ => 0,
    }
}

/// The current pid of each named process; the soak updates it on every (re)start.
pub type Pids = Arc<Mutex<BTreeMap<String, u32>>>;

/// Samples on a background thread until [`Sampler::finish`].
pub struct Sampler {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<(Vec<ProcSample>, Vec<DiskSample>)>,
}

impl Sampler {
    pub fn start(pids: Pids, dirs: Vec<(String, PathBuf)>, every: Duration) -> Sampler {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let thread = std::thread::spawn(move || {
            let start = Instant::now();
            let (mut procs, mut disk) = (Vec::new(), Vec::new());
            let mut next = start;
            while !stopped.load(Ordering::Relaxed) {
                if Instant::now() >= next {
                    let t_s = start.elapsed().as_secs_f64();
                    let current = pids.lock().unwrap().clone();
                    for (name, pid) in current {
                        if let Some((rss_mib, fds, threads)) = process_resources(pid) {
                            procs.push(ProcSample {
                                t_s,
                                name,
                                pid,
                                rss_mib,
                                fds,
                                threads,
                            });
                        }
                    }
                    let bytes = dirs
                        .iter()
                        .map(|(label, path)| (label.clone(), path_bytes(path)))
                        .collect();
                    disk.push(DiskSample { t_s, bytes });
                    next += every;
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            (procs, disk)
        });
        Sampler { stop, thread }
    }

    pub fn finish(self) -> (Vec<ProcSample>, Vec<DiskSample>) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().expect("the sampler thread")
    }
}

/// Least-squares slope of `y` over `t` (per second); 0 with fewer than two distinct times.
pub fn slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    if points.len() < 2 {
        return 0.0;
    }
    let (mt, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, y)| (a + t / n, b + y / n));
    let (cov, var) = points.iter().fold((0.0, 0.0), |(c, v), (t, y)| {
        (c + (t - mt) * (y - my), v + (t - mt) * (t - mt))
    });
    if var > 0.0 { cov / var } else { 0.0 }
}

/// One resource of one incarnation of a process: its first and last value and the growth per hour
/// fitted over the incarnation's second half (after start-up).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Growth {
    pub name: String,
    pub pid: u32,
    pub resource: &'static str,
    pub samples: usize,
    pub span_s: f64,
    pub first: f64,
    pub last: f64,
    pub median: f64,
    pub per_hour: f64,
}

/// The growth of every resource of every incarnation with at least `min_samples` samples.
pub fn growth(samples: &[ProcSample], min_samples: usize) -> Vec<Growth> {
    let mut by_incarnation: BTreeMap<(String, u32), Vec<&ProcSample>> = BTreeMap::new();
    for s in samples {
        by_incarnation
            .entry((s.name.clone(), s.pid))
            .or_default()
            .push(s);
    }
    let mut out = Vec::new();
    for ((name, pid), series) in by_incarnation {
        if series.len() < min_samples {
            continue;
        }
        let resources: [(&'static str, fn(&ProcSample) -> f64); 3] = [
            ("rss_mib", |s| s.rss_mib),
            ("fds", |s| s.fds),
            ("threads", |s| s.threads),
        ];
        for (resource, value) in resources {
            let half = &series[series.len() / 2..];
            let points: Vec<(f64, f64)> = half.iter().map(|s| (s.t_s, value(s))).collect();
            let mut values: Vec<f64> = series.iter().map(|s| value(s)).collect();
            values.sort_by(f64::total_cmp);
            out.push(Growth {
                name: name.clone(),
                pid,
                resource,
                samples: series.len(),
                span_s: series.last().unwrap().t_s - series[0].t_s,
                first: value(series[0]),
                last: value(series.last().unwrap()),
                median: values[values.len() / 2],
                per_hour: slope(&points) * 3600.0,
            });
        }
    }
    out
}

/// Growth per hour allowed of an incarnation that lived at least `min_span_s`: resident memory
/// `max(rss_floor_mib, rss_share × median)`, descriptors and threads a fixed count (a leak of one
/// per reconnect, every 20 s, is 180 an hour).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub min_span_s: f64,
    pub rss_floor_mib: f64,
    pub rss_share: f64,
    pub fds: f64,
    pub threads: f64,
}

impl Limits {
    /// What an hour-long soak asserts. Twenty minutes: a fresh process's memory warms up for about
    /// ten (an actor: 40 → 49.5 MiB, then flat), so a shorter life's second half still climbs.
    pub const SOAK: Limits = Limits {
        min_span_s: 1200.0,
        rss_floor_mib: 64.0,
        rss_share: 0.25,
        fds: 24.0,
        threads: 12.0,
    };

    /// The growths that break the limits (only incarnations that lived `min_span_s`).
    pub fn breaches<'a>(&self, growths: &'a [Growth]) -> Vec<&'a Growth> {
        growths
            .iter()
            .filter(|g| g.span_s >= self.min_span_s)
            .filter(|g| {
                let limit = match g.resource {
                    "rss_mib" => self.rss_floor_mib.max(self.rss_share * g.median),
                    "fds" => self.fds,
                    _ => self.threads,
                };
                g.per_hour > limit
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(name: &str, pid: u32, rss: impl Fn(f64) -> f64) -> Vec<ProcSample> {
        (0..61)
            .map(|i| {
                let t_s = i as f64 * 60.0;
                ProcSample {
                    t_s,
                    name: name.into(),
                    pid,
                    rss_mib: rss(t_s),
                    fds: 40.0,
                    threads: 20.0,
                }
            })
            .collect()
    }

    #[test]
    fn a_leak_breaks_the_limits_and_a_steady_process_does_not() {
        // A steady router; a learner that gains 120 MiB an hour (over max(64, a quarter of its
        // ~330 MiB median)); an actor that keeps one more descriptor every minute.
        let mut samples = series("router", 1, |t| 100.0 + (t / 300.0).sin());
        samples.extend(series("learner", 2, |t| 300.0 + t / 30.0));
        let mut actor = series("actor", 3, |_| 80.0);
        for (i, s) in actor.iter_mut().enumerate() {
            s.fds = 30.0 + i as f64; // one descriptor a minute: 60 an hour
        }
        samples.extend(actor);
        let growths = growth(&samples, 6);
        let breaches: Vec<(String, &str)> = Limits::SOAK
            .breaches(&growths)
            .iter()
            .map(|g| (g.name.clone(), g.resource))
            .collect();
        assert_eq!(
            breaches,
            [
                ("actor".to_string(), "fds"),
                ("learner".to_string(), "rss_mib")
            ]
        );
        let learner_rss = growths
            .iter()
            .find(|g| g.name == "learner" && g.resource == "rss_mib")
            .unwrap();
        assert!((learner_rss.per_hour - 120.0).abs() < 1e-6);
    }

    #[test]
    fn short_incarnations_are_not_judged() {
        let samples: Vec<ProcSample> = series("learner", 7, |t| 100.0 + t)
            .into_iter()
            .take(8)
            .collect();
        let growths = growth(&samples, 6);
        assert!(!growths.is_empty());
        assert!(Limits::SOAK.breaches(&growths).is_empty(), "7 minutes");
    }

    #[test]
    fn this_process_reads_its_own_resources() {
        let (rss, fds, threads) = process_resources(std::process::id()).unwrap();
        assert!(rss > 1.0 && fds >= 3.0 && threads >= 1.0);
        assert!(process_resources(u32::MAX).is_none());
    }
}
