//! Training reports from a run's metrics file: curves as SVG and the paper-style convergence row.
//!
//! Main items: [`load_learner_records`], [`series`], [`smooth`], [`convergence_iteration`],
//! [`ReportRow`] (`ReportRow::from_records`), [`svg_chart`].
//!
//! Convergence (DESIGN §6): the first iteration at which the smoothed curve reaches a fraction of its
//! final value. Rewards can be negative, so "85% of the final value" is measured over the range the
//! curve travelled: the first iteration where `smoothed ≥ start + 0.85 · (final − start)`, with
//! `start` and `final` the means of the first and last 5% of the smoothed curve.

use std::io::BufRead;
use std::path::Path;

use l3p_proto::{MetricsRecord, codec};

/// Learner records of a metrics file, in file order; lines that do not parse are skipped.
pub fn load_learner_records(path: &Path) -> std::io::Result<Vec<MetricsRecord>> {
    let file = std::fs::File::open(path)?;
    let mut records = Vec::new();
    for line in std::io::BufReader::new(file).lines() {
        if let Ok(record) = codec::decode_json::<MetricsRecord>(line?.as_bytes())
            && record.source == "learner"
        {
            records.push(record);
        }
    }
    Ok(records)
}

/// `(iteration, value)` of every record that has `key`.
pub fn series(records: &[MetricsRecord], key: &str) -> Vec<(f64, f64)> {
    records
        .iter()
        .filter_map(|r| r.values.get(key).map(|v| (r.iteration as f64, *v)))
        .collect()
}

/// Trailing moving average over `window` points.
pub fn smooth(points: &[(f64, f64)], window: usize) -> Vec<(f64, f64)> {
    let window = window.max(1);
    let mut out = Vec::with_capacity(points.len());
    let mut sum = 0.0;
    for (i, &(x, y)) in points.iter().enumerate() {
        sum += y;
        if i >= window {
            sum -= points[i - window].1;
        }
        out.push((x, sum / (i + 1).min(window) as f64));
    }
    out
}

fn mean_of(points: &[(f64, f64)]) -> f64 {
    points.iter().map(|p| p.1).sum::<f64>() / points.len().max(1) as f64
}

/// First iteration where the (already smoothed) curve reaches `fraction` of the way from its start
/// to its final value; `None` for an empty or flat curve.
pub fn convergence_iteration(smoothed: &[(f64, f64)], fraction: f64) -> Option<u64> {
    if smoothed.len() < 2 {
        return None;
    }
    let edge = (smoothed.len() / 20).max(1);
    let start = mean_of(&smoothed[..edge]);
    let end = mean_of(&smoothed[smoothed.len() - edge..]);
    if (end - start).abs() < 1e-12 {
        return None;
    }
    let threshold = start + fraction * (end - start);
    let rising = end > start;
    smoothed
        .iter()
        .find(|&&(_, y)| {
            if rising {
                y >= threshold
            } else {
                y <= threshold
            }
        })
        .map(|&(x, _)| x as u64)
}

/// The paper-style summary of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportRow {
    pub iterations: u64,
    pub level_85: Option<u64>,
    pub level_95: Option<u64>,
    pub reward_85: Option<u64>,
    pub reward_95: Option<u64>,
    pub final_level: f64,
    pub final_reward: f64,
    pub lin_vel_error: f64,
    pub yaw_rate_error: f64,
}

impl ReportRow {
    /// Summarise learner records; "final" values are means over the last 5% of iterations (≥ 1).
    pub fn from_records(records: &[MetricsRecord], window: usize) -> Self {
        let last = |key: &str| {
            let s = series(records, key);
            let edge = (s.len() / 20).max(1).min(s.len());
            if s.is_empty() {
                f64::NAN
            } else {
                mean_of(&s[s.len() - edge..])
            }
        };
        let level = smooth(&series(records, "terrain_level"), window);
        let reward = smooth(&series(records, "episode_return"), window);
        Self {
            iterations: records.last().map(|r| r.iteration).unwrap_or(0),
            level_85: convergence_iteration(&level, 0.85),
            level_95: convergence_iteration(&level, 0.95),
            reward_85: convergence_iteration(&reward, 0.85),
            reward_95: convergence_iteration(&reward, 0.95),
            final_level: last("terrain_level"),
            final_reward: last("episode_return"),
            lin_vel_error: last("lin_vel_error"),
            yaw_rate_error: last("yaw_rate_error"),
        }
    }
}

/// A line chart as a standalone SVG document: raw values faint, smoothed values bold.
pub fn svg_chart(
    title: &str,
    y_label: &str,
    raw: &[(f64, f64)],
    smoothed: &[(f64, f64)],
) -> String {
    let (w, h, left, right, top, bottom) = (720.0, 360.0, 70.0, 20.0, 40.0, 50.0);
    let finite: Vec<&(f64, f64)> = raw
        .iter()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (0.0f64, 1.0f64, 0.0f64, 1.0f64);
    if let Some(first) = finite.first() {
        (x0, x1, y0, y1) = (first.0, first.0, first.1, first.1);
        for p in &finite {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
    }
    if x1 - x0 < 1e-9 {
        x1 = x0 + 1.0;
    }
    if y1 - y0 < 1e-9 {
        y1 = y0 + 1.0;
    }
    let sx = |x: f64| left + (x - x0) / (x1 - x0) * (w - left - right);
    let sy = |y: f64| top + (1.0 - (y - y0) / (y1 - y0)) * (h - top - bottom);
    let path = |points: &[(f64, f64)]| {
        points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|p| format!("{:.1},{:.1}", sx(p.0), sy(p.1)))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let escape = |s: &str| {
        s.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
    };
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{}\" y=\"22\" font-size=\"15\" text-anchor=\"middle\">{}</text>\n\
         <rect x=\"{left}\" y=\"{top}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>\n",
        w / 2.0,
        escape(title),
        w - left - right,
        h - top - bottom
    );
    for i in 0..=4 {
        let fy = y0 + (y1 - y0) * i as f64 / 4.0;
        let fx = x0 + (x1 - x0) * i as f64 / 4.0;
        svg.push_str(&format!(
            "<text x=\"{}\" y=\"{:.1}\" text-anchor=\"end\">{fy:.3}</text>\n<text x=\"{:.1}\" y=\"{}\" text-anchor=\"middle\">{fx:.0}</text>\n",
            left - 6.0,
            sy(fy) + 4.0,
            sx(fx),
            h - bottom + 18.0
        ));
    }
    svg.push_str(&format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">iteration</text>\n\
         <text x=\"16\" y=\"{}\" transform=\"rotate(-90 16 {})\" text-anchor=\"middle\">{}</text>\n\
         <polyline fill=\"none\" stroke=\"#9ecae1\" stroke-width=\"1\" points=\"{}\"/>\n\
         <polyline fill=\"none\" stroke=\"#08519c\" stroke-width=\"2\" points=\"{}\"/>\n</svg>\n",
        (left + w - right) / 2.0,
        h - 10.0,
        h / 2.0,
        h / 2.0,
        escape(y_label),
        path(raw),
        path(smoothed)
    ));
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(iteration: u64, reward: f64, level: f64) -> MetricsRecord {
        let mut r = MetricsRecord::new("run", "learner", iteration, 0);
        r.insert("episode_return", reward);
        r.insert("terrain_level", level);
        r.insert("lin_vel_error", 0.1);
        r
    }

    #[test]
    fn smoothing_is_a_trailing_mean() {
        let s = smooth(&[(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)], 2);
        assert_eq!(s, vec![(0.0, 1.0), (1.0, 2.0), (2.0, 4.0)]);
    }

    #[test]
    fn convergence_finds_the_first_crossing_of_a_linear_ramp() {
        // 0..=100 rising linearly to 10 then flat at 10 for 100 iterations.
        let points: Vec<(f64, f64)> = (0..=200)
            .map(|i| (i as f64, if i <= 100 { i as f64 / 10.0 } else { 10.0 }))
            .collect();
        // start ≈ mean of the first 10 points (0.45), end 10: threshold 0.45 + 0.85·9.55 ≈ 8.57.
        assert_eq!(convergence_iteration(&points, 0.85), Some(86));
        assert_eq!(convergence_iteration(&points, 0.95), Some(96));
        // Falling curves (e.g. tracking error) work too.
        let falling: Vec<(f64, f64)> = points.iter().map(|&(x, y)| (x, -y)).collect();
        assert_eq!(convergence_iteration(&falling, 0.85), Some(86));
        assert_eq!(convergence_iteration(&[(0.0, 1.0), (1.0, 1.0)], 0.85), None);
    }

    #[test]
    fn report_row_takes_final_values_from_the_tail() {
        let records: Vec<_> = (1..=40)
            .map(|i| record(i, i as f64, (i as f64 / 8.0).min(4.0)))
            .collect();
        let row = ReportRow::from_records(&records, 1);
        assert_eq!(row.iterations, 40);
        assert!((row.final_reward - 39.5).abs() < 1e-9, "{row:?}"); // mean of the last 2 of 40
        assert!((row.final_level - 4.0).abs() < 1e-9);
        assert!(
            row.level_95.unwrap() <= 32 && row.level_95.unwrap() >= 30,
            "{row:?}"
        );
        assert!((row.lin_vel_error - 0.1).abs() < 1e-12);
    }

    #[test]
    fn svg_chart_is_well_formed() {
        let raw: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, (i * i) as f64)).collect();
        let svg = svg_chart("reward <A1>", "reward", &raw, &smooth(&raw, 3));
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("reward &lt;A1&gt;"));
        assert_eq!(svg.matches("<polyline").count(), 2);
    }
}
