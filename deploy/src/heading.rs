//! [`HeadingHold`]: the task's heading mode as a deploy controller's command input. An operator's
//! zero yaw-rate command means "keep this heading", closed on the base's measured yaw, instead of
//! "zero yaw rate, whatever drift the policy has".

use l3p_task::task::{heading_yaw_rate, yaw_of};

/// The task's heading-controller gain (`[env.commands] heading_stiffness`, IsaacLab's 0.5): yaw
/// rate = gain · heading error.
pub const HEADING_STIFFNESS: f32 = 0.5;
/// The largest yaw rate the hold commands (rad/s): the training command range's bound.
pub const MAX_HOLD_YAW_RATE: f32 = 1.0;
/// Yaw-rate commands below this (rad/s) count as zero: a joystick's rest position is rarely 0.0.
pub const YAW_DEADBAND: f32 = 0.02;

/// Holds the heading the robot had when the yaw-rate command became zero.
#[derive(Debug, Clone, Default)]
pub struct HeadingHold {
    target: Option<f32>,
}

impl HeadingHold {
    /// The command the policy sees for an operator's `(vx, vy, yaw rate)` and the base attitude
    /// `base_quat` (w, x, y, z): a yaw-rate command passes through (and releases the held
    /// heading); a zero one becomes the heading controller's output.
    pub fn command(&mut self, command: [f32; 3], base_quat: [f32; 4]) -> [f32; 3] {
        if command[2].abs() > YAW_DEADBAND || !command[2].is_finite() {
            self.target = None;
            return command;
        }
        let yaw = yaw_of(base_quat);
        let target = *self.target.get_or_insert(yaw);
        let range = [-MAX_HOLD_YAW_RATE, MAX_HOLD_YAW_RATE];
        [
            command[0],
            command[1],
            heading_yaw_rate(target, yaw, HEADING_STIFFNESS, range),
        ]
    }

    /// Forgets the held heading (the policy starts again).
    pub fn reset(&mut self) {
        self.target = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use l3p_task::task::quat_from_yaw;

    #[test]
    fn holds_the_heading_of_the_first_zero_command_and_releases_on_a_turn() {
        let mut hold = HeadingHold::default();
        let c = hold.command([0.5, 0.0, 0.0], quat_from_yaw(0.3));
        assert_eq!(c[..2], [0.5, 0.0]);
        assert!(c[2].abs() < 1e-6, "{c:?}");
        // drifted 0.2 rad left: turn right at 0.1 rad/s
        let c = hold.command([0.5, 0.0, 0.01], quat_from_yaw(0.5));
        assert!((c[2] + 0.1).abs() < 1e-5, "{c:?}");
        // far off: clipped
        let c = hold.command([0.5, 0.0, 0.0], quat_from_yaw(-3.0));
        // target 0.3, yaw -3.0: the short way round is 2.98 rad clockwise, clipped
        assert_eq!(c[2], -MAX_HOLD_YAW_RATE, "{c:?}");
        // an operator's turn passes through, and the hold restarts from the new heading
        assert_eq!(
            hold.command([0.5, 0.0, 0.4], quat_from_yaw(1.0)),
            [0.5, 0.0, 0.4]
        );
        let c = hold.command([0.5, 0.0, 0.0], quat_from_yaw(1.2));
        assert!(c[2].abs() < 1e-6, "{c:?}");
        hold.reset();
        let c = hold.command([0.0, 0.0, 0.0], quat_from_yaw(-1.0));
        assert!(c[2].abs() < 1e-6, "{c:?}");
    }
}
