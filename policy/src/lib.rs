//! Burn modules of the L3P policy, its action distribution, checkpoint/export I/O and a pure-Rust
//! inference path.
//!
//! # Public API
//! - Config: [`PolicyConfig`] (TOML section; [`Arch`] `mlp` | `l3p`, `d_h`, `d_z`, hidden sizes,
//!   [`RecoveryConfig`] with diffusion steps and λ), [`PolicyRobot`] (name, dims, action scale).
//! - Model: [`PolicyModel::new`]`(config, robots, &device)` → [`PolicyModel`] holding a burn
//!   [`PolicyNet`] (one shared core, a [`RobotHeads`] per robot: encoder `E_r`, decoder `D_r`, std,
//!   critic, `R_obs` [`ObsDiffusion`], `R_act`). [`PolicyNet::actors`] runs several robots through the
//!   shared core in one batch; [`PolicyModel::freeze_core`], [`PolicyModel::add_robot`],
//!   [`PolicyModel::param_report`], [`PolicyModel::act_mean_host`]; [`HeadMap`] folds linear maps
//!   of a robot's observations and actions into a copy of another robot's heads
//!   ([`RobotHeads::map_spaces`], the `mapped` transfer warm start).
//! - Distribution: [`gaussian_log_prob`], [`gaussian_entropy`].
//! - I/O ([`checkpoint`], the only module that reads or writes model files):
//!   [`checkpoint_to_bytes`] / [`checkpoint_from_bytes`] / [`save_checkpoint`] / [`load_checkpoint`]
//!   (model + optimiser + iteration), [`export_bytes`] / [`export_to_dir`] (one robot's deployable
//!   policy, safetensors + JSON, format documented in [`export`]).
//! - Inference without burn: [`DeployPolicy`] (`load`, `from_bytes`, `act`, `act_into`, `sample`).
//! - Devices: [`cpu_device`] (`flex`, the measured choice), [`train_device`] (its autodiff form).
//!
//! Architecture invariant: no zenoh, no rapier; this crate knows robots only as [`PolicyRobot`]s.

pub mod checkpoint;
pub mod diffusion;
pub mod headmap;
pub mod model;
pub mod nets;

// The burn-free half (description, export format, pure-Rust inference, errors) lives in
// `l3p-infer`, so that the deploy controller does not link burn; re-exported whole.
pub use l3p_infer::{PolicyError, config, export};

pub use checkpoint::{
    Checkpoint, CheckpointHeader, checkpoint_from_bytes, checkpoint_to_bytes, core_sha256,
    export_bytes, export_to_dir, is_checkpoint, load_checkpoint, save_checkpoint, write_atomic,
};
pub use diffusion::{DdpmSchedule, ObsDiffusion, ObsDiffusionConfig};
pub use headmap::HeadMap;
pub use l3p_infer::{
    Arch, IO_VERSION, ObsSegment, PolicyConfig, PolicyRobot, RecoveryConfig, RobotIo, mlp_params,
};
pub use l3p_infer::{
    DeployPolicy, EXPORT_FORMAT, ExportConfig, ExportLayer, InferScratch, replace_export_config,
};
pub use model::{ActorOut, PolicyModel, PolicyNet, RobotHeads, tensor_to_vec};
pub use nets::{Mlp, MlpConfig, elu};

pub use burn;

use burn::tensor::{Device, Tensor};

/// The CPU inference device (`flex`, pure-Rust; chosen by measurement, see `learner/NOTES.md`).
pub fn cpu_device() -> Device {
    Device::flex()
}

/// The training device: `flex` (CPU) with autodiff. Built with a GPU feature the learner trains on
/// the GPU unless `L3P_DEVICE=cpu`: `wgpu` (Vulkan/Metal/DX12 adapter picked by wgpu, builds
/// offline) or `cuda` (CUDA device 0; its build script downloads an LLVM bundle). Actors and deploy
/// always infer on the CPU ([`cpu_device`], exports).
pub fn train_device() -> Device {
    #[cfg(any(feature = "cuda", feature = "wgpu"))]
    if std::env::var("L3P_DEVICE").map_or(true, |v| v != "cpu") {
        #[cfg(feature = "cuda")]
        return Device::cuda(0).autodiff();
        #[cfg(all(feature = "wgpu", not(feature = "cuda")))]
        return Device::wgpu(burn::tensor::DeviceKind::DefaultDevice).autodiff();
    }
    Device::flex().autodiff()
}

const LN_2PI: f32 = 1.837_877_1;

/// Log-density of `actions` under `N(mean, std)`, summed over action dimensions.
///
/// # Shapes
/// `actions [B, A]`, `mean [B, A]`, `std [A]` → `[B]`
pub fn gaussian_log_prob(actions: Tensor<2>, mean: Tensor<2>, std: Tensor<1>) -> Tensor<1> {
    let [_, a] = mean.dims();
    let std2 = std.clone().unsqueeze_dim::<2>(0);
    let z = actions.sub(mean).div(std2);
    let quad = z.square().mul_scalar(-0.5).sum_dim(1).squeeze_dim::<1>(1);
    let log_det = std.log().sum().add_scalar(0.5 * a as f32 * LN_2PI);
    quad.sub(log_det)
}

/// Entropy of `N(·, std)` summed over action dimensions (independent of the mean).
///
/// # Shapes
/// `std [A]` → `[1]`
pub fn gaussian_entropy(std: Tensor<1>) -> Tensor<1> {
    let a = std.dims()[0];
    std.log().sum().add_scalar(a as f32 * 0.5 * (1.0 + LN_2PI))
}
