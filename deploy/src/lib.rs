//! Running a trained policy as a safe 50 Hz controller over Zenoh (DESIGN §8).
//!
//! Main types: [`artifact::LoadedPolicy`] (a deploy artifact checked against its robot:
//! [`artifact::fetch_policy`], [`artifact::read_policy_file`]), [`controller::Controller`] (the
//! safety state machine: zero-torque → ramp → policy, watchdog → latched damping),
//! [`runtime::run_deploy`] (the deadline loop with Zenoh I/O), [`latest::LatestSlot`] (latest-value
//! subscriber for robot state and commands), [`simrobot::run_sim_robot`] (the
//! simulator as a stand-in robot on the same keys), [`io::robot_io`] and
//! [`io::ObservationBuilder`] (the policy's robot I/O contract and observations built exactly as in
//! training).

pub mod artifact;
pub mod controller;
pub mod io;
pub mod latest;
pub mod pacer;
pub mod runtime;
pub mod simrobot;
pub mod stats;

pub use artifact::{LoadedPolicy, fetch_policy, load_policy, read_policy_file};
pub use controller::{Controller, Fault, SafetyConfig};
pub use io::{ObservationBuilder, robot_io};
pub use runtime::{DeployOptions, run_deploy};
pub use simrobot::{SimRobotOptions, SimRobotSummary, run_sim_robot};

/// Why a policy cannot be deployed or the controller stopped.
#[derive(Debug, thiserror::Error)]
pub enum DeployError {
    #[error(
        "refusing {reference}: it is a policy for {policy_robot}, this robot is {robot}\nhint: deploy the {robot} artifact (learners publish <run>-{robot})"
    )]
    WrongRobot {
        reference: String,
        policy_robot: String,
        robot: String,
    },
    #[error("refusing {reference}: sha256 {actual} does not match the registry's {expected}")]
    Integrity {
        reference: String,
        expected: String,
        actual: String,
    },
    #[error("policy not deployable: {0}")]
    Policy(String),
    #[error("robot model: {0}")]
    Robot(String),
    #[error("invalid deploy setting: {0}")]
    Config(String),
    #[error("registry: {0}")]
    Registry(String),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}
