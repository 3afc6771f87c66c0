//! Gait diagnostics: is a policy walking, or shuffling on its knees? [`GaitMeter`] accumulates, per
//! env and control step, what a locomotion engineer looks at; [`GaitReport`] is the result and
//! [`WalkCriterion`] the pass/fail rule that `l3p eval` and `l3p bench walk` apply.
//!
//! Measures (all from the simulator snapshot [`SimState`] and the joint targets sent):
//! - base height above the ground under the base (mean, min);
//! - per foot: swing share (steps without contact) and touchdowns per second;
//! - share of steps in which any non-foot body (penalised links or the base) touches the ground;
//! - joint-target change per control step, RMS over joints and steps (rad): the chatter measure;
//! - mean |τ| (N·m) and mean mechanical power Σ|τ·q̇| (W);
//! - per episode, the heading change (rad, unwrapped), meaningful with a zero yaw command, also split
//!   into the first [`HEADING_START_SECONDS`] (the turn a standing start gives) and the rest;
//! - mean base velocity in the heading frame (forward, left): tells a robot that is too slow from
//!   one whose speed swings within each stride, which the tracking error alone cannot;
//! - how episodes ended: time-out, or which termination (base contact, tilt, too low, non-finite),
//!   and the share of steps with the base itself on the ground — *why* a policy falls;
//! - tracking errors and falls come from the episode statistics (`EpisodeSummary`).

use serde::{Deserialize, Serialize};

use crate::task::{
    DoneReason, MAX_PENALISED_BODIES, NUM_FEET, NUM_JOINTS, SimState, wrap_to_pi, yaw_of,
};

/// One control step of one env, as the meter sees it.
#[derive(Debug, Clone, Copy)]
pub struct GaitSample<'a> {
    pub state: &'a SimState,
    /// Joint position targets sent for this step (rad).
    pub targets: &'a [f32; NUM_JOINTS],
    /// Terrain height under the base (m).
    pub ground_height: f32,
    /// How many entries of `state.penalised_force` are real bodies.
    pub num_penalised: usize,
    /// Force (N) above which a body is in contact.
    pub contact_threshold: f32,
    /// Control period (s).
    pub dt: f32,
}

/// Running sums for one env (merge several with [`GaitMeter::merge`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaitMeter {
    steps: u64,
    height_sum: f64,
    height_min: f32,
    swing_steps: [u64; NUM_FEET],
    touchdowns: [u64; NUM_FEET],
    non_foot_contact_steps: u64,
    base_contact_steps: u64,
    endings: EpisodeEndings,
    target_change_sq_sum: f64,
    target_change_steps: u64,
    target_second_diff_sq_sum: f64,
    target_second_diff_steps: u64,
    /// Per joint Σ (second difference)², over `target_second_diff_steps`.
    joint_second_diff_sq_sum: [f64; NUM_JOINTS],
    abs_torque_sum: f64,
    power_sum: f64,
    /// Σ base velocity in the heading frame (forward, left).
    heading_vel_sum: [f64; 2],
    // per-episode state
    prev_targets: Option<[f32; NUM_JOINTS]>,
    prev_change: Option<[f32; NUM_JOINTS]>,
    prev_contact: Option<[bool; NUM_FEET]>,
    prev_yaw: Option<f32>,
    episode_heading_change: f32,
    /// Seconds into the current episode, and its heading change over the first
    /// [`HEADING_START_SECONDS`].
    episode_elapsed: f32,
    episode_start_heading_change: f32,
    // finished episodes
    heading_changes: Vec<f32>,
    start_heading_changes: Vec<f32>,
    episode_seconds: f64,
}

impl GaitMeter {
    /// An empty meter.
    pub fn new() -> Self {
        GaitMeter {
            height_min: f32::INFINITY,
            ..Default::default()
        }
    }

    /// Adds one control step.
    pub fn record(&mut self, s: &GaitSample<'_>) {
        let st = s.state;
        if !st.is_finite() {
            return;
        }
        self.steps += 1;
        let h = st.base_pos[2] - s.ground_height;
        self.height_sum += h as f64;
        self.height_min = self.height_min.min(h);
        let mut contact = [false; NUM_FEET];
        for f in 0..NUM_FEET {
            contact[f] = st.foot_force[f] > s.contact_threshold;
            if !contact[f] {
                self.swing_steps[f] += 1;
            }
        }
        if let Some(prev) = self.prev_contact {
            for f in 0..NUM_FEET {
                if contact[f] && !prev[f] {
                    self.touchdowns[f] += 1;
                }
            }
        }
        self.prev_contact = Some(contact);
        let n_pen = s.num_penalised.min(MAX_PENALISED_BODIES);
        if st.base_force > s.contact_threshold {
            self.base_contact_steps += 1;
        }
        if st.base_force > s.contact_threshold
            || st.penalised_force[..n_pen]
                .iter()
                .any(|f| *f > s.contact_threshold)
        {
            self.non_foot_contact_steps += 1;
        }
        if let Some(prev) = self.prev_targets {
            let change: [f32; NUM_JOINTS] = std::array::from_fn(|j| s.targets[j] - prev[j]);
            let sq: f32 = change.iter().map(|d| d * d).sum();
            self.target_change_sq_sum += (sq / NUM_JOINTS as f32) as f64;
            self.target_change_steps += 1;
            if let Some(prev_change) = self.prev_change {
                let mut sq = 0.0f32;
                for j in 0..NUM_JOINTS {
                    let d2 = (change[j] - prev_change[j]).powi(2);
                    self.joint_second_diff_sq_sum[j] += d2 as f64;
                    sq += d2;
                }
                self.target_second_diff_sq_sum += (sq / NUM_JOINTS as f32) as f64;
                self.target_second_diff_steps += 1;
            }
            self.prev_change = Some(change);
        }
        self.prev_targets = Some(*s.targets);
        let (mut tau, mut power) = (0.0f32, 0.0f32);
        for j in 0..NUM_JOINTS {
            tau += st.joint_torque[j].abs();
            power += (st.joint_torque[j] * st.joint_vel[j]).abs();
        }
        self.abs_torque_sum += (tau / NUM_JOINTS as f32) as f64;
        self.power_sum += power as f64;
        let yaw = yaw_of(st.base_quat);
        let (sin, cos) = yaw.sin_cos();
        let [vx, vy, _] = st.base_lin_vel_w;
        self.heading_vel_sum[0] += (cos * vx + sin * vy) as f64;
        self.heading_vel_sum[1] += (cos * vy - sin * vx) as f64;
        if let Some(prev) = self.prev_yaw {
            let change = wrap_to_pi(yaw - prev);
            self.episode_heading_change += change;
            if self.episode_elapsed < HEADING_START_SECONDS {
                self.episode_start_heading_change += change;
            }
        }
        self.prev_yaw = Some(yaw);
        self.episode_elapsed += s.dt;
        self.episode_seconds += s.dt as f64;
    }

    /// Ends the current episode (call on termination or time-out, before the next episode's first
    /// step): its heading change and why it ended are kept, per-episode state cleared.
    pub fn end_episode(&mut self, reason: DoneReason) {
        self.endings.count(reason);
        if self.prev_yaw.is_some() {
            self.heading_changes.push(self.episode_heading_change);
            self.start_heading_changes
                .push(self.episode_start_heading_change);
        }
        self.prev_targets = None;
        self.prev_change = None;
        self.prev_contact = None;
        self.prev_yaw = None;
        self.episode_heading_change = 0.0;
        self.episode_elapsed = 0.0;
        self.episode_start_heading_change = 0.0;
    }

    /// Adds another meter's finished sums (per-episode state of `other` is ignored).
    pub fn merge(&mut self, other: &GaitMeter) {
        self.steps += other.steps;
        self.height_sum += other.height_sum;
        self.height_min = self.height_min.min(other.height_min);
        for f in 0..NUM_FEET {
            self.swing_steps[f] += other.swing_steps[f];
            self.touchdowns[f] += other.touchdowns[f];
        }
        self.non_foot_contact_steps += other.non_foot_contact_steps;
        self.base_contact_steps += other.base_contact_steps;
        self.endings.add(&other.endings);
        self.target_change_sq_sum += other.target_change_sq_sum;
        self.target_change_steps += other.target_change_steps;
        self.target_second_diff_sq_sum += other.target_second_diff_sq_sum;
        self.target_second_diff_steps += other.target_second_diff_steps;
        for j in 0..NUM_JOINTS {
            self.joint_second_diff_sq_sum[j] += other.joint_second_diff_sq_sum[j];
        }
        self.abs_torque_sum += other.abs_torque_sum;
        self.power_sum += other.power_sum;
        for k in 0..2 {
            self.heading_vel_sum[k] += other.heading_vel_sum[k];
        }
        self.heading_changes
            .extend_from_slice(&other.heading_changes);
        self.start_heading_changes
            .extend_from_slice(&other.start_heading_changes);
        self.episode_seconds += other.episode_seconds;
    }

    /// Control steps recorded.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The diagnostics; `standing_height` is the robot's nominal standing base height (m).
    pub fn report(&self, standing_height: f32) -> GaitReport {
        let n = self.steps.max(1) as f64;
        let mean_h = (self.height_sum / n) as f32;
        let mut swing = [0.0; NUM_FEET];
        let mut touchdown_hz = [0.0; NUM_FEET];
        let secs = self.episode_seconds.max(1e-9);
        for f in 0..NUM_FEET {
            swing[f] = (self.swing_steps[f] as f64 / n) as f32;
            touchdown_hz[f] = (self.touchdowns[f] as f64 / secs) as f32;
        }
        let episodes = self.heading_changes.len().max(1) as f32;
        let drift = self.heading_changes.iter().map(|d| d.abs()).sum::<f32>() / episodes;
        let signed = self.heading_changes.iter().sum::<f32>() / episodes;
        let start = self
            .start_heading_changes
            .iter()
            .map(|d| d.abs())
            .sum::<f32>()
            / episodes;
        let settled = self
            .heading_changes
            .iter()
            .zip(&self.start_heading_changes)
            .map(|(total, start)| (total - start).abs())
            .sum::<f32>()
            / episodes;
        GaitReport {
            steps: self.steps,
            base_height_mean: mean_h,
            base_height_min: if self.steps > 0 { self.height_min } else { 0.0 },
            base_height_pct: 100.0 * mean_h / standing_height.max(1e-6),
            standing_height,
            swing_share: swing,
            touchdown_hz,
            non_foot_contact_share: (self.non_foot_contact_steps as f64 / n) as f32,
            base_contact_share: (self.base_contact_steps as f64 / n) as f32,
            endings: self.endings,
            target_change_rms: (self.target_change_sq_sum / self.target_change_steps.max(1) as f64)
                .sqrt() as f32,
            target_second_diff_rms: (self.target_second_diff_sq_sum
                / self.target_second_diff_steps.max(1) as f64)
                .sqrt() as f32,
            joint_second_diff_rms: std::array::from_fn(|j| {
                (self.joint_second_diff_sq_sum[j] / self.target_second_diff_steps.max(1) as f64)
                    .sqrt() as f32
            }),
            mean_abs_torque: (self.abs_torque_sum / n) as f32,
            mean_power: (self.power_sum / n) as f32,
            heading_drift_rad: drift,
            heading_change_mean_rad: signed,
            heading_start_change_rad: start,
            heading_settled_drift_rad: settled,
            mean_heading_velocity: self.heading_vel_sum.map(|v| (v / n) as f32),
        }
    }
}

/// Gait diagnostics of an evaluation (see the module doc for each measure).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaitReport {
    pub steps: u64,
    /// Mean base height above the ground (m).
    pub base_height_mean: f32,
    /// Lowest base height seen (m).
    pub base_height_min: f32,
    /// Mean base height as % of the standing height.
    pub base_height_pct: f32,
    /// The robot's nominal standing height (m).
    pub standing_height: f32,
    /// Share of steps each foot (FL, FR, RL, RR) is off the ground.
    pub swing_share: [f32; NUM_FEET],
    /// Touchdowns per second per foot.
    pub touchdown_hz: [f32; NUM_FEET],
    /// Share of steps with any non-foot body on the ground.
    pub non_foot_contact_share: f32,
    /// Share of steps with the base (the termination links) on the ground. Absent (0) in reports
    /// written before it existed.
    #[serde(default)]
    pub base_contact_share: f32,
    /// How the episodes ended. Absent (all 0) in reports written before it existed.
    #[serde(default)]
    pub endings: EpisodeEndings,
    /// RMS joint-target change per control step (rad).
    pub target_change_rms: f32,
    /// RMS second difference of the joint targets (rad): ≈ 4× the amplitude for a sign flip every
    /// step (25 Hz chatter at 50 Hz), ≈ (2π f dt)² × amplitude for a smooth gait at f Hz — tells
    /// chatter from fast but smooth stepping, which `target_change_rms` alone cannot.
    pub target_second_diff_rms: f32,
    /// The second difference per joint (canonical order: per leg abduction, hip, knee), to find
    /// which joints chatter.
    pub joint_second_diff_rms: [f32; NUM_JOINTS],
    /// Mean |τ| over joints (N·m).
    pub mean_abs_torque: f32,
    /// Mean Σ|τ·q̇| (W).
    pub mean_power: f32,
    /// Mean |heading change| over an episode (rad).
    pub heading_drift_rad: f32,
    /// Mean signed heading change over an episode (rad, + = left): equal in size to
    /// `heading_drift_rad` when the robot turns one way in every episode (a bias), near 0 when its
    /// heading wanders both ways. Absent in reports written before it existed.
    #[serde(default)]
    pub heading_change_mean_rad: f32,
    /// Mean |heading change| over the first [`HEADING_START_SECONDS`] of an episode (rad): the
    /// turn a standing start gives (the first stride's diagonal), which no later step undoes
    /// without a heading signal. Absent in reports written before it existed.
    #[serde(default)]
    pub heading_start_change_rad: f32,
    /// Mean |heading change| over the rest of an episode (rad): the drift of walking itself.
    /// Absent in reports written before it existed.
    #[serde(default)]
    pub heading_settled_drift_rad: f32,
    /// Mean base velocity in the heading frame, [forward, left] (m/s). Absent in reports written
    /// before it existed.
    #[serde(default)]
    pub mean_heading_velocity: [f32; 2],
}

/// How many episodes ended, by [`DoneReason`]: the terminations say why a policy falls.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EpisodeEndings {
    pub time_out: u64,
    pub base_contact: u64,
    pub tilt: u64,
    pub too_low: u64,
    pub non_finite: u64,
}

impl EpisodeEndings {
    /// Counts one ending (`DoneReason::None` is not an ending and is ignored).
    pub fn count(&mut self, reason: DoneReason) {
        match reason {
            DoneReason::None => {}
            DoneReason::TimeOut => self.time_out += 1,
            DoneReason::BaseContact => self.base_contact += 1,
            DoneReason::Tilt => self.tilt += 1,
            DoneReason::TooLow => self.too_low += 1,
            DoneReason::NonFinite => self.non_finite += 1,
        }
    }

    /// Adds another tally.
    pub fn add(&mut self, other: &EpisodeEndings) {
        self.time_out += other.time_out;
        self.base_contact += other.base_contact;
        self.tilt += other.tilt;
        self.too_low += other.too_low;
        self.non_finite += other.non_finite;
    }

    /// Episodes that ended by a termination (not a time-out).
    pub fn terminations(&self) -> u64 {
        self.base_contact + self.tilt + self.too_low + self.non_finite
    }

    /// `"base contact 10, tilt 2"`: the non-zero terminations, or `"none"`.
    pub fn describe_terminations(&self) -> String {
        let parts: Vec<String> = [
            ("base contact", self.base_contact),
            ("tilt", self.tilt),
            ("too low", self.too_low),
            ("non-finite", self.non_finite),
        ]
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(name, n)| format!("{name} {n}"))
        .collect();
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }
}

/// The walk criterion (issue "A real trot"): every bound must hold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WalkCriterion {
    pub max_lin_vel_error: f32,
    pub max_yaw_rate_error: f32,
    pub max_fall_fraction: f32,
    /// Base height, % of standing.
    pub min_base_height_pct: f32,
    pub swing_share: [f32; 2],
    pub max_non_foot_contact_share: f32,
    /// RMS joint-target change per step (rad).
    pub max_target_change_rms: f32,
    /// Mean |heading change| per episode (degrees) under a zero yaw command with heading hold off:
    /// a robot that tracks its speed in the base frame while it turns walks in circles.
    pub max_heading_change_deg: f32,
}

impl Default for WalkCriterion {
    fn default() -> Self {
        WalkCriterion {
            max_lin_vel_error: 0.2,
            max_yaw_rate_error: 0.3,
            max_fall_fraction: 0.05,
            min_base_height_pct: 80.0,
            swing_share: [0.2, 0.6],
            max_non_foot_contact_share: 0.02,
            max_target_change_rms: 0.08,
            max_heading_change_deg: 15.0,
        }
    }
}

/// The tracking half of an evaluation, next to its [`GaitReport`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackingSummary {
    pub lin_vel_error: f32,
    pub yaw_rate_error: f32,
    pub fall_fraction: f32,
}

impl WalkCriterion {
    /// The bounds that fail, as readable lines (empty: it walks).
    pub fn failures(&self, t: &TrackingSummary, g: &GaitReport) -> Vec<String> {
        let mut out = Vec::new();
        if !at_most(t.lin_vel_error, self.max_lin_vel_error) {
            out.push(format!(
                "xy tracking error {:.3} > {:.3} m/s",
                t.lin_vel_error, self.max_lin_vel_error
            ));
        }
        if !at_most(t.yaw_rate_error, self.max_yaw_rate_error) {
            out.push(format!(
                "yaw-rate error {:.3} > {:.3} rad/s",
                t.yaw_rate_error, self.max_yaw_rate_error
            ));
        }
        if !below(t.fall_fraction, self.max_fall_fraction) {
            out.push(format!(
                "falls {:.1}% >= {:.1}%",
                100.0 * t.fall_fraction,
                100.0 * self.max_fall_fraction
            ));
        }
        if !at_most(self.min_base_height_pct, g.base_height_pct) {
            out.push(format!(
                "base height {:.0}% < {:.0}% of standing",
                g.base_height_pct, self.min_base_height_pct
            ));
        }
        for (f, s) in g.swing_share.iter().enumerate() {
            if !(at_most(self.swing_share[0], *s) && at_most(*s, self.swing_share[1])) {
                out.push(format!(
                    "foot {} swings {:.0}% of steps (want {:.0}-{:.0}%)",
                    FOOT_NAMES[f],
                    100.0 * s,
                    100.0 * self.swing_share[0],
                    100.0 * self.swing_share[1]
                ));
            }
        }
        if !below(g.non_foot_contact_share, self.max_non_foot_contact_share) {
            out.push(format!(
                "non-foot ground contact in {:.1}% of steps (want < {:.1}%)",
                100.0 * g.non_foot_contact_share,
                100.0 * self.max_non_foot_contact_share
            ));
        }
        if !at_most(g.target_change_rms, self.max_target_change_rms) {
            out.push(format!(
                "joint-target change {:.3} rad RMS per step > {:.3}",
                g.target_change_rms, self.max_target_change_rms
            ));
        }
        let heading_deg = g.heading_drift_rad.to_degrees();
        if !at_most(heading_deg, self.max_heading_change_deg) {
            out.push(format!(
                "heading changes {heading_deg:.0}° per episode (want <= {:.0}°)",
                self.max_heading_change_deg
            ));
        }
        out
    }
}

/// `a <= b`, false for NaN (a NaN measurement fails its bound).
fn at_most(a: f32, b: f32) -> bool {
    a <= b
}

/// `a < b`, false for NaN.
fn below(a: f32, b: f32) -> bool {
    a < b
}

/// How long the start of an episode is, for [`GaitReport::heading_start_change_rad`].
pub const HEADING_START_SECONDS: f32 = 2.0;

/// Canonical foot order.
pub const FOOT_NAMES: [&str; NUM_FEET] = ["FL", "FR", "RL", "RR"];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::quat_from_yaw;

    fn sample<'a>(state: &'a SimState, targets: &'a [f32; NUM_JOINTS]) -> GaitSample<'a> {
        GaitSample {
            state,
            targets,
            ground_height: 0.0,
            num_penalised: 8,
            contact_threshold: 1.0,
            dt: 0.02,
        }
    }

    /// A trot: diagonal pairs (FL+RR, FR+RL) alternate every 10 steps; targets change smoothly.
    #[test]
    fn known_trot_pattern_gives_known_swing_share_and_touchdowns() {
        let mut meter = GaitMeter::new();
        let mut state = SimState::default();
        state.base_pos[2] = 0.27;
        for step in 0..200 {
            let phase_a = (step / 10) % 2 == 0;
            state.foot_force = if phase_a {
                [50.0, 0.0, 0.0, 50.0]
            } else {
                [0.0, 50.0, 50.0, 0.0]
            };
            let targets = [0.01 * step as f32; NUM_JOINTS];
            meter.record(&sample(&state, &targets));
        }
        meter.end_episode(DoneReason::TimeOut);
        let r = meter.report(0.30);
        assert_eq!(r.steps, 200);
        for s in r.swing_share {
            assert!((s - 0.5).abs() < 1e-6, "swing {s}");
        }
        // 10 touchdowns per foot over 4 s (the first step's contact is not a touchdown).
        for (f, hz) in r.touchdown_hz.iter().enumerate() {
            let expected = if f == 0 || f == 3 { 9.0 } else { 10.0 } / 4.0;
            assert!((hz - expected).abs() < 1e-4, "foot {f}: {hz} vs {expected}");
        }
        assert!((r.target_change_rms - 0.01).abs() < 1e-5);
        assert!(
            r.target_second_diff_rms < 1e-5,
            "a ramp has no second difference"
        );
        assert!((r.base_height_pct - 90.0).abs() < 1e-3);
        assert_eq!(r.non_foot_contact_share, 0.0);
    }

    /// Chatter: targets flip ±0.1 rad every step → RMS change 0.2 rad; knees down half the time.
    #[test]
    fn known_chatter_and_knee_contact() {
        let mut meter = GaitMeter::new();
        let mut state = SimState::default();
        state.base_pos[2] = 0.13;
        state.foot_force = [30.0; NUM_FEET];
        for step in 0..100 {
            let sign = if step % 2 == 0 { 1.0 } else { -1.0 };
            state.penalised_force[5] = if step % 2 == 0 { 5.0 } else { 0.0 };
            state.joint_torque = [2.0; NUM_JOINTS];
            state.joint_vel = [-1.5; NUM_JOINTS];
            meter.record(&sample(&state, &[0.1 * sign; NUM_JOINTS]));
        }
        let r = meter.report(0.30);
        assert!((r.target_change_rms - 0.2).abs() < 1e-5);
        assert!((r.target_second_diff_rms - 0.4).abs() < 1e-5);
        assert!(
            r.joint_second_diff_rms
                .iter()
                .all(|d| (d - 0.4).abs() < 1e-5)
        );
        assert!((r.non_foot_contact_share - 0.5).abs() < 1e-6);
        assert_eq!(r.base_contact_share, 0.0, "a knee is not the base");
        assert_eq!(r.swing_share, [0.0; NUM_FEET]);
        assert!((r.mean_abs_torque - 2.0).abs() < 1e-6);
        assert!((r.mean_power - 36.0).abs() < 1e-4);
        assert!((r.base_height_min - 0.13).abs() < 1e-6);
        let fails = WalkCriterion::default().failures(
            &TrackingSummary {
                lin_vel_error: 0.1,
                yaw_rate_error: 0.1,
                fall_fraction: 0.0,
            },
            &r,
        );
        assert_eq!(fails.len(), 1 + 4 + 1 + 1, "{fails:#?}");
    }

    #[test]
    fn heading_drift_unwraps_across_pi_and_is_per_episode() {
        let mut meter = GaitMeter::new();
        let mut state = SimState::default();
        // Turns 0.05 rad per step for 100 steps (5 rad: crosses ±π) in episode one…
        for k in 0..=100 {
            state.base_quat = quat_from_yaw(wrap_to_pi(0.05 * k as f32));
            meter.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        meter.end_episode(DoneReason::TimeOut);
        // …and −1 rad in episode two, merged from another env.
        let mut other = GaitMeter::new();
        for k in 0..=10 {
            state.base_quat = quat_from_yaw(-0.1 * k as f32);
            other.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        other.end_episode(DoneReason::Tilt);
        meter.merge(&other);
        let r = meter.report(0.3);
        assert_eq!(
            r.endings,
            EpisodeEndings {
                time_out: 1,
                tilt: 1,
                ..Default::default()
            }
        );
        assert!(
            (r.heading_drift_rad - 3.0).abs() < 1e-3,
            "{}",
            r.heading_drift_rad
        );
        // Signed: +5 and −1 rad average to +2 (a bias shows as |signed| = drift).
        assert!(
            (r.heading_change_mean_rad - 2.0).abs() < 1e-3,
            "{}",
            r.heading_change_mean_rad
        );
    }

    /// A start that turns left by 0.5 rad in its first second, then a straight stretch and a turn
    /// right by 1 rad from the third second: the start and the rest are told apart, the total is
    /// their sum.
    #[test]
    fn heading_change_splits_into_start_and_settled_parts() {
        let mut meter = GaitMeter::new();
        let mut state = SimState::default();
        let mut yaw = 0.0f32;
        for k in 0..=250 {
            if (1..=50).contains(&k) {
                yaw += 0.01;
            } else if k > 150 {
                yaw -= 0.01;
            }
            state.base_quat = quat_from_yaw(yaw);
            meter.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        meter.end_episode(DoneReason::TimeOut);
        let r = meter.report(0.3);
        assert!((r.heading_drift_rad - 0.5).abs() < 1e-3, "{r:?}");
        assert!((r.heading_start_change_rad - 0.5).abs() < 1e-3, "{r:?}");
        assert!((r.heading_settled_drift_rad - 1.0).abs() < 1e-3, "{r:?}");
    }

    /// The base on the ground in 1 step of 4, three episodes ending three ways (and a `None`
    /// that is not an ending): the shares and the tally say why the policy fell.
    #[test]
    fn base_contact_and_endings_are_tallied() {
        let mut meter = GaitMeter::new();
        let mut state = SimState::default();
        for step in 0..8 {
            state.base_force = if step % 4 == 0 { 20.0 } else { 0.0 };
            meter.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        for reason in [
            DoneReason::BaseContact,
            DoneReason::None,
            DoneReason::BaseContact,
            DoneReason::TooLow,
        ] {
            meter.end_episode(reason);
        }
        let r = meter.report(0.3);
        assert!((r.base_contact_share - 0.25).abs() < 1e-6);
        assert!((r.non_foot_contact_share - 0.25).abs() < 1e-6);
        assert_eq!(r.endings.terminations(), 3);
        assert_eq!(r.endings.time_out, 0);
        assert_eq!(
            r.endings.describe_terminations(),
            "base contact 2, too low 1"
        );
        assert_eq!(EpisodeEndings::default().describe_terminations(), "none");
    }

    #[test]
    fn mean_velocity_is_in_the_heading_frame() {
        // Facing +y (yaw 90°) and moving at 0.8 m/s along +y, then drifting 0.2 m/s along −x (to
        // the robot's left): forward 0.8, left 0.2 whatever the world axes.
        let mut state = SimState {
            base_quat: quat_from_yaw(std::f32::consts::FRAC_PI_2),
            base_lin_vel_w: [-0.2, 0.8, 0.1],
            ..Default::default()
        };
        let mut meter = GaitMeter::new();
        for _ in 0..4 {
            meter.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        // A second env facing +x, standing still: the mean is over both.
        state.base_quat = quat_from_yaw(0.0);
        state.base_lin_vel_w = [0.0; 3];
        let mut other = GaitMeter::new();
        for _ in 0..4 {
            other.record(&sample(&state, &[0.0; NUM_JOINTS]));
        }
        meter.merge(&other);
        let [f, l] = meter.report(0.3).mean_heading_velocity;
        assert!((f - 0.4).abs() < 1e-5 && (l - 0.1).abs() < 1e-5, "{f} {l}");
    }

    #[test]
    fn a_clean_walk_passes_the_criterion() {
        let g = GaitReport {
            steps: 1000,
            base_height_mean: 0.28,
            base_height_min: 0.25,
            base_height_pct: 93.0,
            standing_height: 0.30,
            swing_share: [0.4; NUM_FEET],
            touchdown_hz: [2.0; NUM_FEET],
            non_foot_contact_share: 0.0,
            base_contact_share: 0.0,
            endings: EpisodeEndings::default(),
            target_change_rms: 0.03,
            target_second_diff_rms: 0.01,
            joint_second_diff_rms: [0.01; NUM_JOINTS],
            mean_abs_torque: 3.0,
            mean_power: 40.0,
            heading_drift_rad: 0.1,
            heading_change_mean_rad: 0.1,
            heading_start_change_rad: 0.05,
            heading_settled_drift_rad: 0.05,
            mean_heading_velocity: [0.5, 0.0],
        };
        let t = TrackingSummary {
            lin_vel_error: 0.1,
            yaw_rate_error: 0.2,
            fall_fraction: 0.0,
        };
        assert!(WalkCriterion::default().failures(&t, &g).is_empty());
        let t_nan = TrackingSummary {
            lin_vel_error: f32::NAN,
            ..t
        };
        assert_eq!(WalkCriterion::default().failures(&t_nan, &g).len(), 1);
        // Tracking in the base frame while turning 30° per episode: walking in circles.
        let turning = GaitReport {
            heading_drift_rad: 30f32.to_radians(),
            ..g
        };
        let fails = WalkCriterion::default().failures(&t, &turning);
        assert_eq!(fails.len(), 1, "{fails:#?}");
        assert!(fails[0].contains("heading changes 30°"), "{}", fails[0]);
    }
}
