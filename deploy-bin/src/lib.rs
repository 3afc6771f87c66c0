//! The `l3p deploy` command as a library, and `l3p-deploy`, the lean binary a robot computer runs.
//!
//! - [`command`]: the command's arguments ([`DeployArgs`]), the network flags and config file of the
//!   lean binary ([`NetFlags`], [`DeployFile`]) and [`run`], which both `l3p deploy` and
//!   `l3p-deploy` call: one implementation of the links check, the policy loading and the
//!   controller's run.
//! - [`process`]: what every l3p binary does around a command (logging, the tokio runtime,
//!   Ctrl-C/SIGTERM as cancellation, the error report and exit status). It lives here, not in
//!   `l3p-cli`, so that the lean binary has it without linking `l3p-cli`; `l3p-cli` re-exports it.
//!
//! Architecture invariant: what this crate links is what the robot computer runs — no rapier, burn,
//! SQLite, Rerun, `l3p-policy`, `l3p-learner`, `l3p-actor` or `l3p-registry` (checked by
//! `tests/tests/tidy.rs`). A policy runs through `l3p-infer` (inside `l3p-deploy`), the robot is
//! known through `l3p-robot` (no simulator), the registry through its Zenoh client.

pub mod command;
pub mod process;

pub use command::{Cli, DeployArgs, DeployFile, NetFlags, check_deploy_links, run, seconds_arg};
