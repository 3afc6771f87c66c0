//! Running a trained policy as a safe 50 Hz controller over Zenoh (DESIGN §8).
//!
//! Main types: [`artifact::LoadedPolicy`] (a deploy artifact checked against its robot:
//! [`artifact::fetch_policy`], [`artifact::read_policy_file`]), [`controller::Controller`] (the
//! safety state machine: zero-torque → ramp → policy, watchdog → latched damping),
//! [`heading::HeadingHold`] (a zero yaw-rate command as a held heading),
//! [`runtime::run_deploy`] (the deadline loop with Zenoh I/O), [`latest::LatestSlot`] (latest-value
//! subscriber for robot state and commands), [`operate::operate`] (an operator's request to a
//! running controller, resent until its status confirms it), [`observation::ObservationBuilder`] (the
//! observation of a wire robot state, built exactly as in training, for the I/O contract that
//! `l3p_task::contract::robot_io` makes).
//!
//! Architecture invariant: no burn, no rapier, no SQLite — a policy runs through `l3p-infer`, the
//! robot is known through `l3p-robot` and its task through `l3p-task` (neither simulates), the
//! registry through its Zenoh client. The simulated robot that stands in for hardware (`l3p sim-robot`) lives with the
//! simulator, in `l3p-actor`.

pub mod artifact;
pub mod controller;
pub mod heading;
pub mod latest;
pub mod observation;
pub mod operate;
pub mod pacer;
pub mod runtime;
pub mod stats;

pub use artifact::{LoadedPolicy, fetch_policy, load_policy, read_policy_file};
pub use controller::{Controller, Fault, SafetyConfig};
pub use observation::ObservationBuilder;
pub use operate::{OperateError, operate};
pub use runtime::{DeployOptions, run_deploy};

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
