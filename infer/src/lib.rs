//! What a trained policy is without burn: its description and its exported form, run in pure Rust.
//! The deploy controller links this crate, not the training stack (`l3p-policy`, which re-exports
//! all of it).
//!
//! # Public API
//! - Description ([`config`]): [`PolicyConfig`] (architecture, latent and hidden sizes, [`Arch`],
//!   [`RecoveryConfig`]), [`PolicyRobot`] (a robot as the policy sees it: name, dims, action scale,
//!   [`RobotIo`]), [`RobotIo`] (the robot I/O contract — observation layout as [`ObsSegment`]s,
//!   default pose, gains, limits, period — versioned by [`IO_VERSION`]).
//! - Exports ([`export`]): the `l3p-export-v1` format ([`ExportConfig`], [`ExportLayer`],
//!   [`EXPORT_FORMAT`], [`replace_export_config`]) and [`DeployPolicy`] (`load`, `from_bytes`,
//!   `act`, `act_into` with an [`InferScratch`], `sample`).
//! - ONNX ([`onnx`]): [`DeployPolicy::to_onnx`] writes an export as an ONNX model (`Gemm` + `Elu`,
//!   the JSON config in its metadata), protobuf written by hand.
//! - [`PolicyError`]: every error of this crate and of `l3p-policy`.
//!
//! Architecture invariant: no burn, no rapier, no zenoh; depends on no other project crate.

pub mod config;
pub mod export;
pub mod onnx;

pub use config::{
    Arch, IO_VERSION, ObsSegment, PolicyConfig, PolicyRobot, RecoveryConfig, RobotIo, mlp_params,
};
pub use export::{
    DeployPolicy, EXPORT_FORMAT, ExportConfig, ExportLayer, InferScratch, read_export_json,
    replace_export_config,
};
pub use onnx::{ONNX_BATCH_DIM, ONNX_INPUT, ONNX_IR_VERSION, ONNX_OPSET, ONNX_OUTPUT};

/// Errors of this crate and of `l3p-policy` (model, checkpoint and export I/O).
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    #[error("invalid policy config: {0}")]
    Config(String),
    #[error("unknown robot {robot} (model has: {known})")]
    UnknownRobot { robot: String, known: String },
    #[error("shape mismatch: {0}")]
    Shape(String),
    #[error("cannot read or write {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("bad checkpoint: {0}")]
    Checkpoint(String),
    #[error("bad policy export: {0}")]
    Export(String),
    #[error("{path}: {inner}")]
    InFile {
        path: String,
        inner: Box<PolicyError>,
    },
}

impl PolicyError {
    /// Attach the file this error came from.
    pub fn in_file(self, path: &std::path::Path) -> Self {
        PolicyError::InFile {
            path: path.display().to_string(),
            inner: Box::new(self),
        }
    }
}
