//! Domain randomisation and the reset distribution: [`RandomizationConfig`] with IsaacLab's
//! per-robot events and l3p's actuator ranges, and its TOML side [`RandomizationOverrides`].

use serde::{Deserialize, Serialize};

use super::RobotFamily;

/// Domain randomisation and reset distribution (IsaacLab `EventCfg`). Ranges are `[lo, hi]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomizationConfig {
    /// Static friction coefficient of the robot's bodies, drawn per episode (IsaacLab: 0.8 fixed).
    pub static_friction: [f32; 2],
    /// Dynamic friction coefficient (IsaacLab: 0.6 fixed).
    pub dynamic_friction: [f32; 2],
    /// Mass added to the base (kg).
    pub added_base_mass: [f32; 2],
    /// Half-ranges of a uniform base centre-of-mass shift (m); zeros = off.
    pub base_com_offset: [f32; 3],
    /// Whether pushes happen (IsaacLab `push_robot`; off for A1/Go1/Go2).
    pub pushes: bool,
    /// Push interval range (s), drawn per push per env.
    pub push_interval_s: [f32; 2],
    /// Pushes set the base x and y velocity to `U(−v, v)` (m/s).
    pub push_velocity_xy: f32,
    /// Reset: base xy offset from the tile origin `U(−d, d)` (m).
    pub reset_base_xy: f32,
    /// Reset: base yaw `U(−y, y)` (rad).
    pub reset_yaw: f32,
    /// Reset: each of the 6 base velocity components `U(−v, v)` (m/s, rad/s).
    pub reset_base_velocity: f32,
    /// Reset: joint positions = default × `U(lo, hi)` (IsaacLab `reset_joints_by_scale`).
    pub reset_joint_pos_scale: [f32; 2],
    /// Passive viscous joint damping (N·m·s/rad), added to the PD's kd; real gearmotors have it.
    pub joint_damping: [f32; 2],
    /// Coulomb joint friction (N·m).
    pub joint_friction: [f32; 2],
    /// Scale of the motor torque (motor strength).
    pub motor_strength: [f32; 2],
    /// Scales of the PD gains kp and kd.
    pub kp_scale: [f32; 2],
    pub kd_scale: [f32; 2],
    /// Delay (s) before new joint targets act, rounded to physics steps.
    pub latency_s: [f32; 2],
}

impl Default for RandomizationConfig {
    /// IsaacLab 2.1 base (ANYmal) `EventCfg`.
    fn default() -> Self {
        RandomizationConfig {
            static_friction: [0.8, 0.8],
            dynamic_friction: [0.6, 0.6],
            added_base_mass: [-5.0, 5.0],
            base_com_offset: [0.05, 0.05, 0.01],
            pushes: true,
            push_interval_s: [10.0, 15.0],
            push_velocity_xy: 0.5,
            reset_base_xy: 0.5,
            reset_yaw: std::f32::consts::PI,
            reset_base_velocity: 0.5,
            reset_joint_pos_scale: [0.5, 1.5],
            joint_damping: [0.0, 0.0],
            joint_friction: [0.0, 0.0],
            motor_strength: [1.0, 1.0],
            kp_scale: [1.0, 1.0],
            kd_scale: [1.0, 1.0],
            latency_s: [0.0, 0.0],
        }
    }
}

impl RandomizationConfig {
    /// IsaacLab 2.1 per-robot events (reference §1.7): A1/Go1/Go2 use added mass (−1, 3), no CoM
    /// shift, no pushes, joints reset at the default pose, zero reset velocities; Spot's flat cfg
    /// uses friction (0.3–1.0 / 0.3–0.8), mass ±2.5 and pushes.
    pub fn for_robot(robot: &str) -> RandomizationConfig {
        let mut r = RandomizationConfig::default();
        match RobotFamily::from_name(robot) {
            RobotFamily::Unitree => {
                r.added_base_mass = [-1.0, 3.0];
                r.base_com_offset = [0.0; 3];
                r.pushes = false;
                r.reset_joint_pos_scale = [1.0, 1.0];
                r.reset_base_velocity = 0.0;
            }
            RobotFamily::Spot => {
                r.static_friction = [0.3, 1.0];
                r.dynamic_friction = [0.3, 0.8];
                r.added_base_mass = [-2.5, 2.5];
                r.base_com_offset = [0.0; 3];
            }
            RobotFamily::Anymal | RobotFamily::Other => {}
        }
        r
    }

    /// l3p's robustness ranges on top of IsaacLab's events: what a second simulator and a real
    /// motor have and IsaacLab's flat tasks leave out (a policy trained without joint damping
    /// collapsed in MuJoCo with the vendor's 1–2 N·m·s/rad). Damping and friction scale with the
    /// motor size of the family; ground friction 0.4–1.25; pushes on.
    pub fn add_actuator_randomization(&mut self, family: RobotFamily) {
        let (damping, friction) = match family {
            RobotFamily::Unitree => (2.0, 0.3),
            RobotFamily::Anymal => (5.0, 0.8),
            RobotFamily::Spot | RobotFamily::Other => (3.0, 0.5),
        };
        self.joint_damping = [0.0, damping];
        self.joint_friction = [0.0, friction];
        self.motor_strength = [0.85, 1.15];
        self.kp_scale = [0.85, 1.15];
        self.kd_scale = [0.85, 1.15];
        self.latency_s = [0.0, 0.02];
        self.static_friction = [0.4, 1.25];
        self.dynamic_friction = [0.4, 1.0];
        self.pushes = true;
        self.push_interval_s = [10.0, 15.0];
        self.push_velocity_xy = 0.5;
    }
}

overrides! {
    /// `[env.randomization]`: per-field overrides on top of [`RandomizationConfig::for_robot`].
    RandomizationOverrides for RandomizationConfig {
        static_friction: [f32; 2],
        dynamic_friction: [f32; 2],
        added_base_mass: [f32; 2],
        base_com_offset: [f32; 3],
        pushes: bool,
        push_interval_s: [f32; 2],
        push_velocity_xy: f32,
        reset_base_xy: f32,
        reset_yaw: f32,
        reset_base_velocity: f32,
        reset_joint_pos_scale: [f32; 2],
        joint_damping: [f32; 2],
        joint_friction: [f32; 2],
        motor_strength: [f32; 2],
        kp_scale: [f32; 2],
        kd_scale: [f32; 2],
        latency_s: [f32; 2],
    }
}
