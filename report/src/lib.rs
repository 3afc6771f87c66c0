//! Training reports from a run's metrics file: curves as SVG and PNG, the paper-style convergence
//! row, radar charts, and TensorBoard event files.
//!
//! Main items: [`load_learner_records`], [`series`], [`smooth`], [`convergence_iteration`],
//! [`ReportRow`] (`ReportRow::from_records`), [`svg_chart`], [`svg_bands`] (curves over seeds), and
//! their PNG twins [`png_chart`], [`png_bands`] (drawn by [`crate::raster`]); [`svg_radar`] /
//! [`png_radar`] (one polygon per method over several axes, e.g. terrain types);
//! [`tensorboard::EventWriter`] (the learner's metrics as TensorBoard scalars) and
//! [`tensorboard::read_events`].
//!
//! Architecture invariant: reads and writes metrics and pictures only — no burn, no Zenoh, no
//! simulator; the learner writes its TensorBoard file through this crate, `l3p report` and
//! `l3p experiment report` draw with it.
//!
//! Convergence (DESIGN §6): the first iteration at which the smoothed curve reaches a fraction of its
//! final value. Rewards can be negative, so "85% of the final value" is measured over the range the
//! curve travelled: the first iteration where `smoothed ≥ start + 0.85 · (final − start)`, with
//! `start` and `final` the means of the first and last 5% of the smoothed curve.

pub mod raster;
pub mod tensorboard;

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

/// Episodes that must have ended inside a window of [`reward_for_bars`] before it counts: early in
/// a run few episodes end per iteration, and one lucky episode is not a level reached.
pub const BAR_MIN_EPISODES: f64 = 20.0;

/// `(iteration, reward)`: the episode reward over the trailing `window` iterations, weighted by
/// the episodes that ended in each; iterations whose window holds fewer than
/// [`BAR_MIN_EPISODES`] ended episodes are left out. For "when did this arm reach a bar".
pub fn reward_for_bars(records: &[MetricsRecord], window: usize) -> Vec<(f64, f64)> {
    let window = window.max(1);
    let per_iteration: Vec<(f64, f64, f64)> = records
        .iter()
        .map(|r| {
            let episodes = r.values.get("episodes").copied().unwrap_or(0.0);
            match r.values.get("episode_return") {
                Some(&v) if v.is_finite() && episodes > 0.0 => (r.iteration as f64, v, episodes),
                _ => (r.iteration as f64, 0.0, 0.0),
            }
        })
        .collect();
    let mut out = Vec::new();
    for (i, &(iteration, _, _)) in per_iteration.iter().enumerate() {
        let w = &per_iteration[(i + 1).saturating_sub(window)..=i];
        let episodes: f64 = w.iter().map(|p| p.2).sum();
        if episodes >= BAR_MIN_EPISODES {
            out.push((
                iteration,
                w.iter().map(|p| p.1 * p.2).sum::<f64>() / episodes,
            ));
        }
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

/// The plot area of a chart: pixel geometry and the data range it maps.
struct Frame {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

const W: f64 = 720.0;
const H: f64 = 360.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 50.0;

impl Frame {
    /// The range of the finite points (a unit range where there are none or they coincide).
    fn around(points: impl Iterator<Item = (f64, f64)>) -> Self {
        let mut f = Frame {
            x0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y0: f64::INFINITY,
            y1: f64::NEG_INFINITY,
        };
        for (x, y) in points.filter(|p| p.0.is_finite() && p.1.is_finite()) {
            f.x0 = f.x0.min(x);
            f.x1 = f.x1.max(x);
            f.y0 = f.y0.min(y);
            f.y1 = f.y1.max(y);
        }
        if !f.x0.is_finite() {
            (f.x0, f.x1, f.y0, f.y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if f.x1 - f.x0 < 1e-9 {
            f.x1 = f.x0 + 1.0;
        }
        if f.y1 - f.y0 < 1e-9 {
            f.y1 = f.y0 + 1.0;
        }
        f
    }

    fn sx(&self, x: f64) -> f64 {
        LEFT + (x - self.x0) / (self.x1 - self.x0) * (W - LEFT - RIGHT)
    }

    fn sy(&self, y: f64) -> f64 {
        TOP + (1.0 - (y - self.y0) / (self.y1 - self.y0)) * (H - TOP - BOTTOM)
    }

    /// SVG `points` of the finite points.
    fn path(&self, points: impl Iterator<Item = (f64, f64)>) -> String {
        points
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|p| format!("{:.1},{:.1}", self.sx(p.0), self.sy(p.1)))
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// The document up to the plotted lines: title, box, ticks, axis labels.
    fn open(&self, title: &str, y_label: &str) -> String {
        let mut svg = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" font-family=\"sans-serif\" font-size=\"12\">\n\
             <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
             <text x=\"{}\" y=\"22\" font-size=\"15\" text-anchor=\"middle\">{}</text>\n\
             <rect x=\"{LEFT}\" y=\"{TOP}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>\n",
            W / 2.0,
            escape(title),
            W - LEFT - RIGHT,
            H - TOP - BOTTOM
        );
        for i in 0..=4 {
            let fy = self.y0 + (self.y1 - self.y0) * i as f64 / 4.0;
            let fx = self.x0 + (self.x1 - self.x0) * i as f64 / 4.0;
            svg.push_str(&format!(
                "<text x=\"{}\" y=\"{:.1}\" text-anchor=\"end\">{fy:.3}</text>\n<text x=\"{:.1}\" y=\"{}\" text-anchor=\"middle\">{fx:.0}</text>\n",
                LEFT - 6.0,
                self.sy(fy) + 4.0,
                self.sx(fx),
                H - BOTTOM + 18.0
            ));
        }
        svg.push_str(&format!(
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">iteration</text>\n\
             <text x=\"16\" y=\"{}\" transform=\"rotate(-90 16 {})\" text-anchor=\"middle\">{}</text>\n",
            (LEFT + W - RIGHT) / 2.0,
            H - 10.0,
            H / 2.0,
            H / 2.0,
            escape(y_label),
        ));
        svg
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// One thing drawn inside a chart's frame, in data coordinates.
enum Layer {
    Line {
        points: Vec<(f64, f64)>,
        colour: &'static str,
        width: f64,
    },
    /// A filled polygon (a band over seeds).
    Area {
        points: Vec<(f64, f64)>,
        colour: &'static str,
        opacity: f32,
    },
    /// A legend entry (the `k`-th).
    Legend {
        text: String,
        colour: &'static str,
        k: usize,
    },
}

/// A chart: title, axis label, data range and layers; drawn as SVG or PNG from the same layout.
struct Chart {
    title: String,
    y_label: String,
    frame: Frame,
    layers: Vec<Layer>,
}

impl Chart {
    fn svg(&self) -> String {
        let f = &self.frame;
        let mut svg = f.open(&self.title, &self.y_label);
        for layer in &self.layers {
            svg.push_str(&match layer {
                Layer::Line {
                    points,
                    colour,
                    width,
                } => format!(
                    "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"{width}\" points=\"{}\"/>\n",
                    f.path(points.iter().copied())
                ),
                Layer::Area {
                    points,
                    colour,
                    opacity,
                } => format!(
                    "<polygon fill=\"{colour}\" fill-opacity=\"{opacity}\" stroke=\"none\" points=\"{}\"/>\n",
                    f.path(points.iter().copied())
                ),
                Layer::Legend { text, colour, k } => format!(
                    "<text x=\"{}\" y=\"{}\" fill=\"{colour}\">{}</text>\n",
                    LEFT + 10.0,
                    TOP + 16.0 + 15.0 * *k as f64,
                    escape(text)
                ),
            });
        }
        svg.push_str("</svg>\n");
        svg
    }

    fn png(&self) -> Vec<u8> {
        use crate::raster::{Anchor, Canvas, parse_hex};
        let f = &self.frame;
        let mut c = Canvas::new(W as usize, H as usize);
        let grey = [0x88, 0x88, 0x88];
        let black = [0, 0, 0];
        let to_px = |points: &[(f64, f64)]| -> Vec<(f64, f64)> {
            points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .map(|p| (f.sx(p.0), f.sy(p.1)))
                .collect()
        };
        for layer in &self.layers {
            match layer {
                Layer::Area {
                    points,
                    colour,
                    opacity,
                } => c.fill_polygon(&to_px(points), parse_hex(colour), *opacity),
                Layer::Line {
                    points,
                    colour,
                    width,
                } => c.polyline(&to_px(points), parse_hex(colour), *width),
                Layer::Legend { .. } => {}
            }
        }
        let (x0, y0, x1, y1) = (LEFT, TOP, W - RIGHT, H - BOTTOM);
        for (a, b) in [
            ((x0, y0), (x1, y0)),
            ((x1, y0), (x1, y1)),
            ((x1, y1), (x0, y1)),
            ((x0, y1), (x0, y0)),
        ] {
            c.line(a, b, grey, 1.0);
        }
        c.text(W / 2.0, 20.0, &self.title, black, 1, Anchor::Middle);
        for i in 0..=4 {
            let fy = f.y0 + (f.y1 - f.y0) * i as f64 / 4.0;
            let fx = f.x0 + (f.x1 - f.x0) * i as f64 / 4.0;
            c.text(
                LEFT - 6.0,
                f.sy(fy),
                &format!("{fy:.3}"),
                black,
                1,
                Anchor::End,
            );
            c.text(
                f.sx(fx),
                H - BOTTOM + 14.0,
                &format!("{fx:.0}"),
                black,
                1,
                Anchor::Middle,
            );
        }
        c.text(
            (LEFT + W - RIGHT) / 2.0,
            H - 12.0,
            "iteration",
            black,
            1,
            Anchor::Middle,
        );
        c.text_vertical(12.0, H / 2.0, &self.y_label, black);
        for layer in &self.layers {
            if let Layer::Legend { text, colour, k } = layer {
                let y = TOP + 12.0 + 15.0 * *k as f64;
                c.text(LEFT + 10.0, y, text, parse_hex(colour), 1, Anchor::Start);
            }
        }
        c.to_png()
    }
}

fn line_chart(title: &str, y_label: &str, raw: &[(f64, f64)], smoothed: &[(f64, f64)]) -> Chart {
    Chart {
        title: title.into(),
        y_label: y_label.into(),
        frame: Frame::around(raw.iter().copied()),
        layers: vec![
            Layer::Line {
                points: raw.to_vec(),
                colour: "#9ecae1",
                width: 1.0,
            },
            Layer::Line {
                points: smoothed.to_vec(),
                colour: "#08519c",
                width: 2.0,
            },
        ],
    }
}

fn bands_chart(title: &str, y_label: &str, lines: &[(String, Vec<(f64, f64, f64, f64)>)]) -> Chart {
    let frame = Frame::around(
        lines
            .iter()
            .flat_map(|(_, p)| p.iter().flat_map(|&(x, _, lo, hi)| [(x, lo), (x, hi)])),
    );
    let mut layers = Vec::new();
    for (k, (label, points)) in lines.iter().enumerate() {
        let colour = SERIES_COLOURS[k % SERIES_COLOURS.len()];
        let band = points
            .iter()
            .map(|&(x, _, _, hi)| (x, hi))
            .chain(points.iter().rev().map(|&(x, _, lo, _)| (x, lo)))
            .collect();
        layers.push(Layer::Area {
            points: band,
            colour,
            opacity: 0.18,
        });
        layers.push(Layer::Line {
            points: points.iter().map(|&(x, m, _, _)| (x, m)).collect(),
            colour,
            width: 2.0,
        });
        layers.push(Layer::Legend {
            text: label.clone(),
            colour,
            k,
        });
    }
    Chart {
        title: title.into(),
        y_label: y_label.into(),
        frame,
        layers,
    }
}

/// A line chart as a standalone SVG document: raw values faint, smoothed values bold.
pub fn svg_chart(
    title: &str,
    y_label: &str,
    raw: &[(f64, f64)],
    smoothed: &[(f64, f64)],
) -> String {
    line_chart(title, y_label, raw, smoothed).svg()
}

/// [`svg_chart`] as a PNG image.
pub fn png_chart(
    title: &str,
    y_label: &str,
    raw: &[(f64, f64)],
    smoothed: &[(f64, f64)],
) -> Vec<u8> {
    line_chart(title, y_label, raw, smoothed).png()
}

/// Several curves with spread, overlaid: for each `(label, points)` with points `(x, mean, lo,
/// hi)`, the mean as a line over a translucent lo–hi band, and a legend.
pub fn svg_bands(
    title: &str,
    y_label: &str,
    lines: &[(String, Vec<(f64, f64, f64, f64)>)],
) -> String {
    bands_chart(title, y_label, lines).svg()
}

/// [`svg_bands`] as a PNG image.
pub fn png_bands(
    title: &str,
    y_label: &str,
    lines: &[(String, Vec<(f64, f64, f64, f64)>)],
) -> Vec<u8> {
    bands_chart(title, y_label, lines).png()
}

/// A radar chart: `axes` around a circle from the top, clockwise; each series a closed polygon
/// with `values[k]` on axis `k`, scaled so that `max` touches the outer ring (values are clamped
/// to `0..=max`; non-finite ones drawn at 0).
struct Radar<'a> {
    title: &'a str,
    axes: &'a [String],
    series: &'a [(String, Vec<f64>)],
    max: f64,
}

/// One colour per series, for the curve charts and the radar alike: ten distinct ones, so an
/// ablation's seven arms or a grid's four methods never repeat a colour.
const SERIES_COLOURS: [&str; 10] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
    "#bcbd22", "#17becf",
];
/// The chart's height without its legend, and its least width.
const RADAR_SIZE: f64 = 520.0;
/// The outer ring's radius (px); axis labels sit just outside it.
const RADAR_RADIUS: f64 = RADAR_SIZE / 2.0 - 90.0;
/// Legend line pitch (px).
const RADAR_LEGEND_LINE: f64 = 15.0;

impl Radar<'_> {
    /// Wide enough for the longest axis label on either side of the circle.
    fn width(&self) -> f64 {
        let widest = self
            .axes
            .iter()
            .map(|a| crate::raster::Canvas::text_width(a, 1))
            .max()
            .unwrap_or(0) as f64;
        (2.0 * (RADAR_RADIUS * 1.12 + widest + 12.0)).max(RADAR_SIZE)
    }

    /// The chart, then one legend line per series below it.
    fn height(&self) -> f64 {
        RADAR_SIZE + RADAR_LEGEND_LINE * self.series.len() as f64
    }

    /// Baseline of series `k`'s legend line.
    fn legend_y(&self, k: usize) -> f64 {
        RADAR_SIZE - 5.0 + RADAR_LEGEND_LINE * k as f64
    }

    fn centre(&self) -> (f64, f64, f64) {
        (self.width() / 2.0, RADAR_SIZE / 2.0 + 20.0, RADAR_RADIUS)
    }

    /// Where axis `k`'s label goes, and which of its ends is there (away from the circle).
    fn label(&self, k: usize) -> (f64, f64, crate::raster::Anchor) {
        use crate::raster::Anchor;
        let (cx, _, _) = self.centre();
        let (lx, ly) = self.at(k, self.max * 1.12);
        let anchor = if (lx - cx).abs() < 5.0 {
            Anchor::Middle
        } else if lx > cx {
            Anchor::Start
        } else {
            Anchor::End
        };
        (lx, ly, anchor)
    }

    /// Pixel position of value `v` on axis `k`.
    fn at(&self, k: usize, v: f64) -> (f64, f64) {
        let (cx, cy, r) = self.centre();
        let n = self.axes.len().max(1) as f64;
        let angle = -std::f64::consts::FRAC_PI_2 + std::f64::consts::TAU * k as f64 / n;
        let v = if v.is_finite() {
            v.clamp(0.0, self.max)
        } else {
            0.0
        };
        let rr = r * v / self.max.max(f64::MIN_POSITIVE);
        (cx + rr * angle.cos(), cy + rr * angle.sin())
    }

    fn ring(&self, fraction: f64) -> Vec<(f64, f64)> {
        (0..self.axes.len())
            .map(|k| self.at(k, fraction * self.max))
            .collect()
    }

    fn polygon(&self, values: &[f64]) -> Vec<(f64, f64)> {
        (0..self.axes.len())
            .map(|k| self.at(k, values.get(k).copied().unwrap_or(f64::NAN)))
            .collect()
    }

    fn svg(&self) -> String {
        let points = |p: &[(f64, f64)]| {
            p.iter()
                .map(|(x, y)| format!("{x:.1},{y:.1}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let mut svg = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n\
             <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
             <text x=\"{}\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">{}</text>\n",
            self.width(),
            self.height(),
            self.width() / 2.0,
            escape(self.title)
        );
        let (cx, cy, _) = self.centre();
        for i in 1..=4 {
            let f = i as f64 / 4.0;
            svg.push_str(&format!(
                "<polygon fill=\"none\" stroke=\"#cccccc\" points=\"{}\"/>\n",
                points(&self.ring(f))
            ));
            let (x, y) = self.at(0, f * self.max);
            svg.push_str(&format!(
                "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"#888888\">{:.1}</text>\n",
                x + 4.0,
                y + 12.0,
                f * self.max
            ));
        }
        for (k, axis) in self.axes.iter().enumerate() {
            let (x, y) = self.at(k, self.max);
            let (lx, ly, anchor) = self.label(k);
            let anchor = match anchor {
                crate::raster::Anchor::Start => "start",
                crate::raster::Anchor::Middle => "middle",
                crate::raster::Anchor::End => "end",
            };
            svg.push_str(&format!(
                "<line x1=\"{cx:.1}\" y1=\"{cy:.1}\" x2=\"{x:.1}\" y2=\"{y:.1}\" stroke=\"#cccccc\"/>\n\
                 <text x=\"{lx:.1}\" y=\"{:.1}\" text-anchor=\"{anchor}\">{}</text>\n",
                ly + 4.0,
                escape(axis)
            ));
        }
        for (k, (label, values)) in self.series.iter().enumerate() {
            let colour = SERIES_COLOURS[k % SERIES_COLOURS.len()];
            svg.push_str(&format!(
                "<polygon fill=\"{colour}\" fill-opacity=\"0.15\" stroke=\"{colour}\" stroke-width=\"2\" points=\"{}\"/>\n\
                 <text x=\"10\" y=\"{}\" fill=\"{colour}\">{}</text>\n",
                points(&self.polygon(values)),
                self.legend_y(k),
                escape(label)
            ));
        }
        svg.push_str("</svg>\n");
        svg
    }

    fn png(&self) -> Vec<u8> {
        use crate::raster::{Anchor, Canvas, parse_hex};
        let mut c = Canvas::new(self.width() as usize, self.height() as usize);
        let grey = [0xcc, 0xcc, 0xcc];
        let black = [0, 0, 0];
        let (cx, cy, _) = self.centre();
        for i in 1..=4 {
            let mut ring = self.ring(i as f64 / 4.0);
            ring.push(ring[0]);
            c.polyline(&ring, grey, 1.0);
        }
        for (k, axis) in self.axes.iter().enumerate() {
            c.line((cx, cy), self.at(k, self.max), grey, 1.0);
            let (lx, ly, anchor) = self.label(k);
            c.text(lx, ly, axis, black, 1, anchor);
        }
        for (k, (label, values)) in self.series.iter().enumerate() {
            let rgb = parse_hex(SERIES_COLOURS[k % SERIES_COLOURS.len()]);
            let mut polygon = self.polygon(values);
            c.fill_polygon(&polygon, rgb, 0.15);
            polygon.push(polygon[0]);
            c.polyline(&polygon, rgb, 2.0);
            c.text(10.0, self.legend_y(k) - 4.0, label, rgb, 1, Anchor::Start);
        }
        c.text(
            self.width() / 2.0,
            16.0,
            self.title,
            black,
            1,
            Anchor::Middle,
        );
        c.to_png()
    }
}

/// A radar chart as a standalone SVG document (see [`png_radar`] for the PNG twin): `axes` around
/// the circle clockwise from the top, one closed polygon per `(label, values)` series, `max` on
/// the outer ring.
pub fn svg_radar(title: &str, axes: &[String], series: &[(String, Vec<f64>)], max: f64) -> String {
    Radar {
        title,
        axes,
        series,
        max,
    }
    .svg()
}

/// [`svg_radar`] as a PNG image.
pub fn png_radar(title: &str, axes: &[String], series: &[(String, Vec<f64>)], max: f64) -> Vec<u8> {
    Radar {
        title,
        axes,
        series,
        max,
    }
    .png()
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

    #[test]
    fn png_bands_draw_each_mean_in_its_colour_inside_the_frame() {
        let line = |offset: f64| -> Vec<(f64, f64, f64, f64)> {
            (0..50)
                .map(|i| {
                    let m = offset + i as f64;
                    (i as f64, m, m - 2.0, m + 2.0)
                })
                .collect()
        };
        let png = png_bands(
            "go1 — reward",
            "reward",
            &[("mlp".into(), line(0.0)), ("l3p".into(), line(20.0))],
        );
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width as f64, info.height as f64), (W, H));
        let count = |rgb: [u8; 3]| buf.chunks(3).filter(|p| *p == rgb).count();
        // Both means are drawn (2 px wide over ~600 px), the band is tinted, text is black.
        assert!(count([0x1f, 0x77, 0xb4]) > 600, "first mean");
        assert!(count([0xff, 0x7f, 0x0e]) > 600, "second mean");
        assert!(count([0, 0, 0]) > 200, "labels");
        assert!(
            buf.chunks(3).any(|p| p[2] > p[0] && p[0] > 200),
            "a light blue band"
        );
    }

    #[test]
    fn bar_rewards_weight_by_episodes_and_wait_for_enough_of_them() {
        let record = |iteration: u64, reward: Option<f64>, episodes: f64| {
            let mut r = MetricsRecord::new("run", "learner", iteration, 0);
            if let Some(v) = reward {
                r.values.insert("episode_return".into(), v);
            }
            r.values.insert("episodes".into(), episodes);
            r
        };
        let records = [
            record(1, Some(100.0), 1.0), // one lucky early episode: not enough to count
            record(2, None, 0.0),
            record(3, Some(10.0), 19.0), // 20 episodes in the window from here
            record(4, Some(40.0), 20.0),
        ];
        let bars = reward_for_bars(&records, 3);
        assert_eq!(bars.len(), 2, "{bars:?}");
        assert_eq!(bars[0].0, 3.0);
        assert!((bars[0].1 - (100.0 + 190.0) / 20.0).abs() < 1e-9);
        // The window of 3 drops iteration 1: (19·10 + 20·40) / 39.
        assert_eq!(bars[1].0, 4.0);
        assert!((bars[1].1 - (190.0 + 800.0) / 39.0).abs() < 1e-9);
    }

    #[test]
    fn a_radar_puts_each_value_on_its_axis() {
        let axes: Vec<String> = ["flat", "stairs", "slope", "rough"]
            .map(String::from)
            .to_vec();
        let series = vec![
            ("l3p-transfer".to_string(), vec![8.0, 4.0, 8.0, 0.0]),
            ("mlp-transfer".to_string(), vec![2.0, f64::NAN, 20.0, 1.0]),
        ];
        let radar = Radar {
            title: "go1",
            axes: &axes,
            series: &series,
            max: 8.0,
        };
        let (cx, cy, r) = radar.centre();
        // Axis 0 points up, axis 1 right (clockwise); max on the outer ring, 0 at the centre.
        let close =
            |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9;
        assert!(close(radar.at(0, 8.0), (cx, cy - r)));
        assert!(close(radar.at(1, 4.0), (cx + r / 2.0, cy)));
        assert!(close(radar.at(3, 0.0), (cx, cy)));
        // Out-of-range values are clamped, missing ones drawn at the centre.
        assert!(close(radar.at(2, 20.0), radar.at(2, 8.0)));
        assert!(close(radar.at(1, f64::NAN), (cx, cy)));
        let svg = svg_radar("go1", &axes, &series, 8.0);
        assert_eq!(
            svg.matches("fill-opacity").count(),
            2,
            "one polygon per series"
        );
        assert!(svg.contains(">stairs</text>") && svg.contains(">mlp-transfer</text>"));
        let png = png_radar("go1", &axes, &series, 8.0);
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buf).unwrap();
        let count = |rgb: [u8; 3]| buf.chunks(3).filter(|p| *p == rgb).count();
        assert!(count([0x1f, 0x77, 0xb4]) > 300, "first polygon's outline");
        assert!(count([0xff, 0x7f, 0x0e]) > 300, "second polygon's outline");

        // Long axis labels (the terrain types) fit inside the image on both sides, and every
        // legend line lies below the chart and inside the image.
        let long: Vec<String> = [
            "flat",
            "random rough",
            "pyramid slope",
            "inverted pyramid slope",
            "boxes",
            "pyramid stairs",
            "inverted pyramid stairs",
        ]
        .map(String::from)
        .to_vec();
        let five: Vec<(String, Vec<f64>)> =
            (0..5).map(|k| (format!("m{k}"), vec![1.0; 7])).collect();
        let wide = Radar {
            title: "go1",
            axes: &long,
            series: &five,
            max: 9.0,
        };
        for (k, axis) in long.iter().enumerate() {
            let (x, _, anchor) = wide.label(k);
            let w = crate::raster::Canvas::text_width(axis, 1) as f64;
            let (x0, x1) = match anchor {
                crate::raster::Anchor::Start => (x, x + w),
                crate::raster::Anchor::Middle => (x - w / 2.0, x + w / 2.0),
                crate::raster::Anchor::End => (x - w, x),
            };
            assert!(x0 >= 0.0 && x1 <= wide.width(), "{axis}: {x0}..{x1}");
        }
        let lowest_label = (0..long.len()).map(|k| wide.label(k).1).fold(0.0, f64::max);
        assert!(wide.legend_y(0) - 12.0 > lowest_label);
        assert!(wide.legend_y(4) < wide.height());
    }
}
