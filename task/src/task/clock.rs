//! Gait-clock and trot-contact helpers: the phase a policy and the deploy controller share, the
//! stance pattern and swing height it asks for, and how well contacts match it.

use super::NUM_FEET;

/// 1 when the feet move in diagonal pairs — FL with RR, FR with RL, the two pairs in opposite
/// phases (one pair on the ground, the other in the air) — else 0. A trot without a clock: the
/// policy needs no phase input, so the observation layout stays the deployable 48.
pub fn trot_contact(foot_force: &[f32; NUM_FEET], threshold: f32) -> f32 {
    let c = foot_force.map(|f| f > threshold);
    let diagonal_a = c[0] == c[3];
    let diagonal_b = c[1] == c[2];
    if diagonal_a && diagonal_b && c[0] != c[1] {
        1.0
    } else {
        0.0
    }
}

/// Phase φ ∈ [0, 1) of a `hz` gait clock after `steps` control steps of `dt` seconds since the
/// episode (or the deploy controller's policy mode) began. Counting steps, not accumulating time,
/// keeps training and deployment on the same phase however long either runs.
pub fn gait_clock_phase(steps: u64, hz: f32, dt: f32) -> f32 {
    let cycles = steps as f64 * hz as f64 * dt as f64;
    (cycles - cycles.floor()) as f32
}

/// The clock's observation: `[sin 2πφ, cos 2πφ]` (continuous across the period's wrap).
pub fn gait_clock_observation(phase: f32) -> [f32; 2] {
    let a = std::f32::consts::TAU * phase;
    [a.sin(), a.cos()]
}

/// The trot the clock asks for, per foot (FL, FR, RL, RR): `true` = stance. The diagonal pair
/// FL + RR stands in the first half of the period while FR + RL swing, then they swap.
pub fn gait_clock_stance(phase: f32) -> [bool; NUM_FEET] {
    let first_half = phase < 0.5;
    [first_half, !first_half, !first_half, first_half]
}

/// Target sole height of each foot at clock `phase`: `peak · sin(π · s)` for a foot the clock
/// swings, with s ∈ [0, 1) its progress through the swing half-cycle, and 0 for a stance foot.
pub fn gait_clock_swing_height(phase: f32, peak: f32) -> [f32; NUM_FEET] {
    let stance = gait_clock_stance(phase);
    let progress = 2.0 * phase.rem_euclid(0.5);
    let h = peak * (std::f32::consts::PI * progress).sin();
    stance.map(|s| if s { 0.0 } else { h })
}

/// Share of feet whose contact (force above `threshold`) matches [`gait_clock_stance`].
pub fn gait_clock_match(foot_force: &[f32; NUM_FEET], threshold: f32, phase: f32) -> f32 {
    let stance = gait_clock_stance(phase);
    let matching = foot_force
        .iter()
        .zip(stance)
        .filter(|(f, s)| (**f > threshold) == *s)
        .count();
    matching as f32 / NUM_FEET as f32
}
