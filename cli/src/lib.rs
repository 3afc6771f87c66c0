//! Library half of the `l3p` binary: the top-level [`config::Config`] that assembles each crate's config
//! section, and one module per command group holding its argument struct and `run` function. The
//! modules only parse and glue; the work lives in the library crates.

pub mod actor_cmd;
pub mod bench_cmd;
pub mod config;
pub mod config_cmd;
pub mod deploy_cmd;
pub mod eval_cmd;
pub mod experiment;
pub mod experiment_cmd;
pub mod learner_cmd;
pub mod metrics_cmd;
pub mod play_cmd;
#[cfg(feature = "rerun")]
mod play_rerun;
pub mod registry_cmd;
pub mod report_cmd;
pub mod robots_cmd;
pub mod router_cmd;
pub mod runtime;
pub mod sim2sim_cmd;
pub mod train_cmd;
pub mod transfer_cmd;
