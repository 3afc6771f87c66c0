//! All checkpoint and export I/O, in one place.
//!
//! - **Checkpoint** (resume training): [`Checkpoint`] = model ([`PolicyModel`]: burn record of the
//!   [`crate::PolicyNet`] + config + robot list) + optimiser state (burn's `ModuleOptimizer` bytes) +
//!   iteration + free-form learner state (JSON). One binary blob: magic `L3PCKPT1`, then three
//!   length-prefixed (u64 LE) sections: JSON header, model burnpack, optimiser burnpack (may be empty).
//!   [`checkpoint_to_bytes`] / [`checkpoint_from_bytes`], [`save_checkpoint`] / [`load_checkpoint`].
//! - **Export** (deploy one robot's policy): encoder + core + decoder (or the MLP actor), std and
//!   action scale as safetensors with a JSON config (format in [`crate::export`]). [`export_bytes`],
//!   [`export_to_dir`]; read back with [`crate::DeployPolicy`] (pure Rust, no burn).

use std::path::Path;

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device};
use safetensors::tensor::TensorView;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::PolicyError;
use crate::config::{PolicyConfig, PolicyRobot};
use crate::export::{EXPORT_FORMAT, ExportConfig, ExportLayer, export_metadata};
use crate::model::{PolicyModel, PolicyNet, RobotHeads, tensor_to_vec};
use crate::nets::Mlp;

const MAGIC: &[u8; 8] = b"L3PCKPT1";
/// Refuse headers beyond this size (a corrupt length must not allocate gigabytes).
const MAX_HEADER: u64 = 16 << 20;

/// JSON header of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointHeader {
    pub format: String,
    pub config: PolicyConfig,
    pub robots: Vec<PolicyRobot>,
    pub iteration: u64,
    /// Learner state that is not tensors (learning rate, mode, …).
    #[serde(default)]
    pub learner: serde_json::Value,
}

/// A loaded checkpoint.
#[derive(Debug)]
pub struct Checkpoint {
    pub model: PolicyModel,
    /// burnpack bytes of the optimiser (`ModuleOptimizer::from_bytes` applies them); empty if the
    /// checkpoint holds none.
    pub optimizer: Vec<u8>,
    pub iteration: u64,
    pub learner: serde_json::Value,
}

/// Serialise model, optimiser state (`optimizer`: the bytes of `ModuleOptimizer::into_bytes`, or
/// empty), iteration and learner state.
pub fn checkpoint_to_bytes(
    model: &PolicyModel,
    optimizer: &[u8],
    iteration: u64,
    learner: serde_json::Value,
) -> Result<Vec<u8>, PolicyError> {
    let header = CheckpointHeader {
        format: "l3p-checkpoint-v1".into(),
        config: model.config.clone(),
        robots: model.robots.clone(),
        iteration,
        learner,
    };
    let header = serde_json::to_vec(&header).map_err(|e| PolicyError::Checkpoint(e.to_string()))?;
    let record = model
        .net
        .clone()
        .into_record()
        .into_bytes()
        .map_err(|e| PolicyError::Checkpoint(format!("model record: {e}")))?;
    let mut out = Vec::with_capacity(8 + 24 + header.len() + record.len() + optimizer.len());
    out.extend_from_slice(MAGIC);
    for section in [&header[..], &record[..], optimizer] {
        out.extend_from_slice(&(section.len() as u64).to_le_bytes());
        out.extend_from_slice(section);
    }
    Ok(out)
}

/// Whether `bytes` start like a checkpoint (rather than an export), without parsing them.
pub fn is_checkpoint(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

/// Parse a checkpoint blob and rebuild the model on `device`.
pub fn checkpoint_from_bytes(bytes: &[u8], device: &Device) -> Result<Checkpoint, PolicyError> {
    let bad = |m: &str| PolicyError::Checkpoint(m.to_string());
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(bad("not an l3p checkpoint (bad magic)"));
    }
    let mut pos = 8usize;
    let mut sections: Vec<&[u8]> = Vec::with_capacity(3);
    for i in 0..3 {
        let len_bytes: [u8; 8] = bytes
            .get(pos..pos + 8)
            .and_then(|s| s.try_into().ok())
            .ok_or_else(|| bad("truncated checkpoint"))?;
        let len = u64::from_le_bytes(len_bytes);
        if i == 0 && len > MAX_HEADER {
            return Err(bad("checkpoint header too large"));
        }
        pos += 8;
        let end = pos
            .checked_add(len as usize)
            .ok_or_else(|| bad("truncated checkpoint"))?;
        sections.push(
            bytes
                .get(pos..end)
                .ok_or_else(|| bad("truncated checkpoint"))?,
        );
        pos = end;
    }
    let header: CheckpointHeader = serde_json::from_slice(sections[0])
        .map_err(|e| PolicyError::Checkpoint(format!("bad header: {e}")))?;
    let mut model = PolicyModel::new(header.config.clone(), header.robots.clone(), device)?;
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(sections[1].to_vec()))
        .map_err(|e| PolicyError::Checkpoint(format!("model record: {e}")))?;
    model.net = model.net.try_load_record(record).map_err(|e| {
        PolicyError::Checkpoint(format!("model record does not fit the config: {e}"))
    })?;
    Ok(Checkpoint {
        model,
        optimizer: sections[2].to_vec(),
        iteration: header.iteration,
        learner: header.learner,
    })
}

/// Write a checkpoint file (written to a temporary file and renamed, so a crash never leaves a
/// half-written checkpoint under the final name).
pub fn save_checkpoint(
    path: &Path,
    model: &PolicyModel,
    optimizer: &[u8],
    iteration: u64,
    learner: serde_json::Value,
) -> Result<(), PolicyError> {
    let bytes = checkpoint_to_bytes(model, optimizer, iteration, learner)?;
    write_file(path, &bytes)
}

/// Read a checkpoint file.
pub fn load_checkpoint(path: &Path, device: &Device) -> Result<Checkpoint, PolicyError> {
    let bytes = std::fs::read(path).map_err(|source| PolicyError::Io {
        path: path.display().to_string(),
        source,
    })?;
    checkpoint_from_bytes(&bytes, device).map_err(|e| e.in_file(path))
}

/// Writes `bytes` to `path` so that a crash leaves the old file or the new one, never a part: a
/// temporary file in the same directory (created with it if missing), fsync, rename. The one
/// atomic write of the workspace (checkpoints, exports, fetched registry blobs).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} is not a file path", path.display()),
        )
    })?;
    let tmp = dir.join(format!(".{}.part", name.to_string_lossy()));
    let mut file = std::fs::File::create(&tmp)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    std::fs::rename(&tmp, path)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), PolicyError> {
    write_atomic(path, bytes).map_err(|source| PolicyError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Host copy of one dense layer in export layout.
struct HostLayer {
    name: String,
    /// `[out, in]`.
    weight: Vec<f32>,
    bias: Vec<f32>,
    input: usize,
    output: usize,
    elu: bool,
}

fn host_layers(prefix: &str, mlp: &Mlp, out: &mut Vec<HostLayer>) {
    let layers = mlp.to_host();
    let last = layers.len().saturating_sub(1);
    for (k, (w, b, i, o)) in layers.into_iter().enumerate() {
        // burn stores `[in, out]`; the export uses PyTorch's `[out, in]`.
        let mut wt = vec![0f32; i * o];
        for a in 0..i {
            for c in 0..o {
                wt[c * i + a] = w[a * o + c];
            }
        }
        out.push(HostLayer {
            name: format!("{prefix}.{k}"),
            weight: wt,
            bias: b,
            input: i,
            output: o,
            elu: k < last,
        });
    }
}

/// sha256 of the core's weights in export layout (hex), `None` for the MLP architecture.
pub fn core_sha256(net: &PolicyNet) -> Option<String> {
    let core = net.core.as_ref()?;
    let mut layers = Vec::new();
    host_layers("core", core, &mut layers);
    let mut h = Sha256::new();
    for l in &layers {
        for v in l.weight.iter().chain(&l.bias) {
            h.update(v.to_le_bytes());
        }
    }
    Some(hex::encode(h.finalize()))
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Export the deployable policy of one robot as a safetensors blob with the JSON config in its
/// metadata. Returns `(bytes, config)`.
pub fn export_bytes(
    model: &PolicyModel,
    robot: &str,
) -> Result<(Vec<u8>, ExportConfig), PolicyError> {
    let idx = model.robot_index(robot)?;
    let spec = &model.robots[idx];
    let heads: &RobotHeads = &model.net.robots[idx];
    let mut layers = Vec::new();
    host_layers("encoder", &heads.encoder, &mut layers);
    if let (Some(core), Some(dec)) = (&model.net.core, &heads.decoder) {
        // The encoder output `h` and the core output `z` feed the next net without activation.
        host_layers("core", core, &mut layers);
        host_layers("decoder", dec, &mut layers);
    }
    let std = tensor_to_vec(heads.std())?;
    let config = ExportConfig {
        format: EXPORT_FORMAT.into(),
        robot: spec.name.clone(),
        arch: model.config.arch.to_string(),
        obs_dim: spec.obs_dim,
        action_dim: spec.action_dim,
        action_scale: spec.action_scale,
        d_h: model.net.core.as_ref().map(|_| model.config.d_h),
        d_z: model.net.core.as_ref().map(|_| model.config.d_z),
        layers: layers
            .iter()
            .map(|l| ExportLayer {
                name: l.name.clone(),
                input: l.input,
                output: l.output,
                activation: if l.elu { "elu".into() } else { "none".into() },
            })
            .collect(),
        std: "std".into(),
        core_sha256: core_sha256(&model.net),
        io: spec.io.clone(),
    };
    let mut data: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    for l in &layers {
        data.push((
            format!("{}.weight", l.name),
            f32_bytes(&l.weight),
            vec![l.output, l.input],
        ));
        data.push((
            format!("{}.bias", l.name),
            f32_bytes(&l.bias),
            vec![l.output],
        ));
    }
    data.push(("std".into(), f32_bytes(&std), vec![spec.action_dim]));
    let views = data
        .iter()
        .map(|(name, bytes, shape)| {
            TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes)
                .map(|v| (name.clone(), v))
                .map_err(|e| PolicyError::Export(format!("tensor {name}: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let bytes = safetensors::serialize(views, Some(export_metadata(&config)?))
        .map_err(|e| PolicyError::Export(e.to_string()))?;
    Ok((bytes, config))
}

/// Export one robot's policy into `dir` as `policy.safetensors` + `policy.json`.
pub fn export_to_dir(
    model: &PolicyModel,
    robot: &str,
    dir: &Path,
) -> Result<ExportConfig, PolicyError> {
    let (bytes, config) = export_bytes(model, robot)?;
    let json =
        serde_json::to_vec_pretty(&config).map_err(|e| PolicyError::Export(e.to_string()))?;
    write_file(&dir.join("policy.safetensors"), &bytes)?;
    write_file(&dir.join("policy.json"), &json)?;
    Ok(config)
}
