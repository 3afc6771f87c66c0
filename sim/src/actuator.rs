//! Joint actuators: [`Actuator`] holds per-joint PD gains and DC-motor limits and computes the
//! clipped torque `τ = clip(kp (q* − q) − kd q̇)` with IsaacLab's DC-motor torque–speed curve
//! ([`dc_motor_clip`]).

use l3p_robot::catalog::{Gains, NUM_JOINTS, RobotSpec};

/// Clips `tau` with the DC-motor model (IsaacLab `DCMotor`): the available torque falls linearly
/// from `saturation` at rest to 0 at `velocity_limit`, and never exceeds `effort_limit`.
pub fn dc_motor_clip(
    tau: f32,
    qd: f32,
    effort_limit: f32,
    saturation: f32,
    velocity_limit: f32,
) -> f32 {
    let vl = velocity_limit.max(1e-6);
    let max = (saturation * (1.0 - qd / vl)).min(effort_limit);
    let min = (saturation * (-1.0 - qd / vl)).max(-effort_limit);
    if max < min {
        return 0.0;
    }
    tau.clamp(min, max)
}

/// Per-joint PD gains and motor limits, canonical joint order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Actuator {
    /// Stiffness per joint.
    pub kp: [f32; NUM_JOINTS],
    /// Damping per joint.
    pub kd: [f32; NUM_JOINTS],
    /// Effort limit per joint (N·m).
    pub effort_limit: [f32; NUM_JOINTS],
    /// DC-motor stall torque per joint (N·m).
    pub saturation: [f32; NUM_JOINTS],
    /// No-load speed per joint (rad/s).
    pub velocity_limit: [f32; NUM_JOINTS],
}

impl Actuator {
    /// Actuator of a built-in robot with the given gains.
    pub fn from_spec(spec: &RobotSpec, gains: Gains) -> Self {
        Self {
            kp: [gains.kp; NUM_JOINTS],
            kd: [gains.kd; NUM_JOINTS],
            effort_limit: spec.effort_limit,
            saturation: spec.saturation_effort,
            velocity_limit: spec.velocity_limit,
        }
    }

    /// Clipped PD torque of joint `k`.
    pub fn torque(&self, k: usize, target: f32, q: f32, qd: f32) -> f32 {
        let tau = self.kp[k] * (target - q) - self.kd[k] * qd;
        dc_motor_clip(
            tau,
            qd,
            self.effort_limit[k],
            self.saturation[k],
            self.velocity_limit[k],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dc_motor_curve_matches_isaaclab() {
        // At rest the effort limit binds; at half the speed limit the curve gives sat * 0.5.
        assert_eq!(dc_motor_clip(100.0, 0.0, 80.0, 120.0, 7.5), 80.0);
        assert!((dc_motor_clip(100.0, 3.75, 80.0, 120.0, 7.5) - 60.0).abs() < 1e-4);
        // Braking against the motion is allowed up to the effort limit.
        assert_eq!(dc_motor_clip(-100.0, 3.75, 80.0, 120.0, 7.5), -80.0);
        // Beyond the speed limit no torque in the direction of motion.
        assert!(dc_motor_clip(10.0, 8.0, 80.0, 120.0, 7.5) <= 0.0);
        assert_eq!(dc_motor_clip(5.0, 0.0, 80.0, 120.0, 7.5), 5.0);
    }
}
