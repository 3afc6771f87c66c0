//! The reward terms, written once ([`RewardTerm`], [`RewardScales`] with IsaacLab's per-robot
//! tables and l3p's gait recipe, [`RewardOverrides`]) and the kernels' constants ([`RewardParams`]).

use serde::{Deserialize, Serialize};

use super::RobotFamily;

/// The reward-term table, written once: each row `Variant => field = default weight` declares
/// the [`RewardTerm`] variant (the index of every per-term array), its name (the IsaacLab term
/// name, the `[env.rewards]` key and the `Episode_Reward/<name>` metric), the [`RewardScales`]
/// field with its default weight, and the [`RewardOverrides`] field.
macro_rules! reward_terms {
    ($($(#[$doc:meta])* $variant:ident => $field:ident = $default:expr),* $(,)?) => {
        /// Reward terms, in the order of every per-term array (`[f32; NUM_REWARD_TERMS]`).
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(usize)]
        pub enum RewardTerm {
            $($(#[$doc])* $variant,)*
        }

        // The IsaacLab term name is the `[env.rewards]` key (`as_str`, `from_name`, `ALL` in order).
        l3p_names::string_enum!(RewardTerm {
            $($variant => stringify!($field)),*
        });

        /// Number of reward terms.
        pub const NUM_REWARD_TERMS: usize = RewardTerm::ALL.len();

        /// Weights of the reward terms: each adds `weight · value · dt` with `dt` the policy
        /// step (0.02 s), like IsaacLab's `RewardManager`. Defaults: IsaacLab 2.1's base
        /// `RewardsCfg` (= ANYmal B/C/D rough).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct RewardScales {
            $($(#[$doc])* pub $field: f32,)*
        }

        impl Default for RewardScales {
            fn default() -> Self {
                RewardScales {
                    $($field: $default,)*
                }
            }
        }

        impl RewardScales {
            /// `(name, weight)` pairs in [`RewardTerm`] order.
            pub fn named(&self) -> [(&'static str, f32); NUM_REWARD_TERMS] {
                [$((stringify!($field), self.$field),)*]
            }
        }

        overrides! {
            /// `[env.rewards]`: per-term weight overrides on top of [`RewardScales::for_robot`].
            RewardOverrides for RewardScales {
                $($field: f32,)*
            }
        }
    };
}

/// `[env.reward_params]`: the kernels' constants (IsaacLab `RewardsCfg` params).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RewardParams {
    /// Standard deviation of the tracking kernels, `exp(−err²/std²)`. IsaacLab: sqrt(0.25) = 0.5.
    pub tracking_std: f32,
    /// Standard deviation of `track_ang_vel_z_exp`'s kernel (rad/s); `tracking_std` when unset.
    /// A narrower yaw kernel pays for holding a zero yaw rate: at std 0.35 a 0.09 rad/s bias
    /// (100° of heading in 20 s) costs 6% of the term, at 0.15 it costs 30%.
    pub yaw_tracking_std: Option<f32>,
    /// Standard deviation of the wide kernels of `track_lin_vel_xy_coarse_exp` (m/s) and
    /// `track_ang_vel_z_coarse_exp` (rad/s).
    pub coarse_tracking_std: f32,
    /// Standard deviation of `track_yaw_rate_mean_exp`'s kernel (rad/s): at 0.05 a drift of
    /// 0.087 rad/s (100° in 20 s) pays e⁻³, one of 0.013 rad/s (15° in 20 s) 0.93.
    pub yaw_mean_std: f32,
    /// Window of `track_yaw_rate_mean_exp`'s moving mean (s): one stride of the 2 Hz trot clock
    /// (at most 64 control steps).
    pub yaw_mean_window_s: f32,
    /// Feet air-time threshold (s). IsaacLab: 0.5.
    pub air_time_threshold: f32,
    /// Air-time reward is zero when `‖cmd_xy‖ ≤` this (m/s). IsaacLab: 0.1.
    pub air_time_min_command: f32,
    /// Contact force norm above which a foot or penalised body is in contact (N). IsaacLab: 1.0.
    pub contact_threshold: f32,
    /// Clip each step's total reward at zero from below (legged_gym's `only_positive_rewards`, on
    /// for its A1): with penalties dominating early, falling fast would otherwise pay. IsaacLab:
    /// false.
    pub only_positive_rewards: bool,
    /// Target of `base_height_l2` as a fraction of the robot's standing height.
    pub base_height_fraction: f32,
    /// Peak swing height of `feet_clearance` (the sole above the terrain under it) as a fraction
    /// of the robot's standing height: 0.25 is 7.5 cm for A1, above the lowest stair riser (5 cm).
    pub feet_clearance_fraction: f32,
    /// Horizontal radius (m) of the ground `feet_clearance` measures a swing sole against: the
    /// highest terrain within this distance of the sole (`Terrain::max_height_within`), so that a
    /// foot swinging towards a stair riser is asked to clear the step ahead before it reaches it.
    /// 0 (the default): the terrain straight under the sole.
    pub feet_clearance_radius: f32,
}

impl Default for RewardParams {
    fn default() -> Self {
        RewardParams {
            tracking_std: 0.5,
            yaw_tracking_std: None,
            coarse_tracking_std: 1.0,
            yaw_mean_std: 0.05,
            yaw_mean_window_s: 0.5,
            air_time_threshold: 0.5,
            air_time_min_command: 0.1,
            contact_threshold: 1.0,
            only_positive_rewards: false,
            base_height_fraction: 1.0,
            feet_clearance_fraction: 0.25,
            feet_clearance_radius: 0.0,
        }
    }
}

reward_terms! {
    TrackLinVelXyExp => track_lin_vel_xy_exp = 1.0,
    TrackAngVelZExp => track_ang_vel_z_exp = 0.5,
    LinVelZL2 => lin_vel_z_l2 = -2.0,
    AngVelXyL2 => ang_vel_xy_l2 = -0.05,
    DofTorquesL2 => dof_torques_l2 = -1.0e-5,
    DofAccL2 => dof_acc_l2 = -2.5e-7,
    ActionRateL2 => action_rate_l2 = -0.01,
    FeetAirTime => feet_air_time = 0.125,
    UndesiredContacts => undesired_contacts = -1.0,
    FlatOrientationL2 => flat_orientation_l2 = 0.0,
    DofPosLimits => dof_pos_limits = 0.0,
    /// `(h − fraction · standing)²`, h = base height above the terrain under it.
    BaseHeightL2 => base_height_l2 = 0.0,
    /// 1 while the feet move in diagonal pairs (see `task::trot_contact`), when commanded to move.
    TrotContact => trot_contact = 0.0,
    /// Σ |q − q_default| over the hip abduction joints.
    JointDeviationL1 => joint_deviation_l1 = 0.0,
    /// Σ (a_t − 2 a_{t−1} + a_{t−2})² of the policy's mean action: zero for smooth motion at any
    /// speed, 16 a² for a sign flip every step (the 25 Hz chatter).
    ActionSmoothnessL2 => action_smoothness_l2 = 0.0,
    /// Share of feet whose contact matches the trot clock's pattern (`task::gait_clock_stance`),
    /// when commanded to move and `gait_clock_hz` > 0.
    GaitClock => gait_clock = 0.0,
    /// `exp(−err²/coarse_tracking_std²)` of the xy tracking error: a wide kernel that still rises
    /// when the robot is far from its command (standing at a 1 m/s command the sharp kernel with
    /// std 0.35 pays e⁻⁸ and its gradient has vanished).
    TrackLinVelXyCoarseExp => track_lin_vel_xy_coarse_exp = 0.0,
    /// Σ over the feet the trot clock swings of `max(h* − h, 0)²`: h the sole's height above the
    /// terrain under it (the highest within `feet_clearance_radius`), h* = `feet_clearance_fraction` × standing height × sin(π · swing
    /// progress) (`task::gait_clock_swing_height`). Zero without a gait clock or a move command.
    FeetClearance => feet_clearance = 0.0,
    /// `exp(−err²/coarse_tracking_std²)` of the yaw-rate error: the yaw twin of
    /// `track_lin_vel_xy_coarse_exp`. On rough ground the yaw error sits at 0.6–0.8 rad/s, where
    /// the sharp kernel (std 0.35) pays e⁻⁴ or less and teaches nothing.
    TrackAngVelZCoarseExp => track_ang_vel_z_coarse_exp = 0.0,
    /// `exp(−ē²/yaw_mean_std²)` of the yaw-rate error ē averaged over the last
    /// `yaw_mean_window_s` (one stride): the trot's yaw swing within a stride averages out and what is left is the drift that turns a robot under a zero yaw command —
    /// which the per-step kernel hardly sees under the swing.
    TrackYawRateMeanExp => track_yaw_rate_mean_exp = 0.0,
}

impl RewardScales {
    /// IsaacLab 2.1 weights for `robot` on rough terrain (`rough = true`) or on the flat task.
    ///
    /// Sources (reference §1.5): `VEL/velocity_env_cfg.py` (base = ANYmal rough), `VEL/config/{a1,go1,go2}/
    /// {rough,flat}_env_cfg.py`, `VEL/config/anymal_{b,c,d}/flat_env_cfg.py`. Spot and unknown robots
    /// get the base table (IsaacLab's Spot reward set is a different family of terms; see TASK_NOTES).
    pub fn for_robot(robot: &str, rough: bool) -> RewardScales {
        let mut s = RewardScales::default();
        match (RobotFamily::from_name(robot), rough) {
            (RobotFamily::Unitree, rough) => {
                // IsaacLab's flat Unitree configs inherit the rough ones and change two weights.
                s.track_lin_vel_xy_exp = 1.5;
                s.track_ang_vel_z_exp = 0.75;
                s.dof_torques_l2 = -2.0e-4;
                s.undesired_contacts = 0.0;
                if rough {
                    s.feet_air_time = 0.01;
                } else {
                    s.feet_air_time = 0.25;
                    s.flat_orientation_l2 = -2.5;
                }
            }
            (_, false) => {
                s.flat_orientation_l2 = -5.0;
                s.dof_torques_l2 = -2.5e-5;
                s.feet_air_time = 0.5;
            }
            (_, true) => {}
        }
        s
    }

    /// l3p's gait recipe on top of IsaacLab's tables (measured in BENCHMARKS.md "A real trot"):
    /// IsaacLab's flat A1 learned a crouched, chattering shuffle with its knees on the floor, so
    /// the base is held near standing height, feet move in diagonal pairs, thighs and calves may
    /// not touch the ground, hips stay near their default abduction, and the policy's mean action
    /// changes smoothly (`action_rate_l2` −0.05 and `action_smoothness_l2` −0.1, both on the mean:
    /// on the sampled actions the exploration noise alone zeroed every early clipped reward).
    pub fn add_gait_terms(&mut self, family: RobotFamily) {
        self.base_height_l2 = -40.0;
        self.trot_contact = 0.5;
        self.joint_deviation_l1 = -0.1;
        self.action_rate_l2 = -0.05;
        self.action_smoothness_l2 = -0.1;
        if family == RobotFamily::Unitree {
            self.undesired_contacts = -1.0;
        }
    }
}
