//! Library half of the `l3p` binary: the top-level [`config::Config`] that assembles each crate's config
//! section, and one module per command group holding its argument struct and `run` function. The
//! modules only parse and glue; the work lives in the library crates.

pub mod config;
pub mod bench_cmd;
pub mod config_cmd;
pub mod robots_cmd;
