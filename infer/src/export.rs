//! Pure-Rust inference of an exported policy (no burn): [`DeployPolicy`] loads the
//! safetensors + JSON export written by `l3p_policy::checkpoint` and computes action means (and samples
//! Gaussian actions with their log-probs) for a batch of observations. Used by the deploy controller
//! and, where it is faster than burn, by actors.
//!
//! # Export format (`l3p-export-v1`)
//! The export is one safetensors file whose header metadata holds the JSON config under the key
//! `l3p_export` (so one blob travels on the wire), written next to an identical `policy.json` when
//! exported to a directory. The JSON ([`ExportConfig`]):
//!
//! ```json
//! { "format": "l3p-export-v1", "robot": "go1", "arch": "l3p",
//!   "obs_dim": 48, "action_dim": 12, "action_scale": 0.25, "d_h": 64, "d_z": 16,
//!   "layers": [ { "name": "encoder.0", "in": 48, "out": 512, "activation": "elu" },
//!               { "name": "encoder.1", "in": 512, "out": 64, "activation": "none" },
//!               { "name": "core.0", ... }, ..., { "name": "decoder.1", ..., "activation": "none" } ],
//!   "std": "std", "core_sha256": "…",
//!   "io": { "control_dt": 0.02, "joint_names": [...], "default_joint_pos": [...], "kp": [...],
//!           "kd": [...], "soft_joint_limits": [[lo, hi], ...], "effort_limit": [...],
//!           "action_clip": 100.0, "action_filter_alpha": 1.0, "gait_clock_hz": 0.0, "obs_clip": 100.0, "version": 3,
//!           "obs_layout": [ { "name": "base_lin_vel", "len": 3, "scale": 1.0, "description": "…" }, ... ] } }
//! ```
//!
//! `layers` run in order: `y = act(x · Wᵀ + b)` with tensors `<name>.weight` (F32, `[out, in]`, the
//! PyTorch `nn.Linear` layout) and `<name>.bias` (`[out]`); `activation` is `elu` (α = 1) or `none`.
//! The result is the action mean `a`; tensor `std` (`[action_dim]`) is the Gaussian std; the robot
//! applies `q* = q_default + action_scale · a`. `core_sha256` (L3P) hashes the core's weights so
//! an adapter can be checked against the core it was trained with. `io` ([`RobotIo`]) is what a
//! controller needs to build observations and joint commands (`l3p deploy` refuses exports without it
//! unless it can rebuild it from its own robot catalog).

use std::collections::HashMap;
use std::path::Path;

use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use safetensors::SafeTensors;
use serde::{Deserialize, Serialize};

use crate::PolicyError;
use crate::config::RobotIo;

/// Format tag of the export.
pub const EXPORT_FORMAT: &str = "l3p-export-v1";
/// Metadata key of the JSON config inside the safetensors header.
pub const EXPORT_METADATA_KEY: &str = "l3p_export";

/// The JSON half of an export.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportConfig {
    pub format: String,
    pub robot: String,
    pub arch: String,
    pub obs_dim: usize,
    pub action_dim: usize,
    pub action_scale: f32,
    #[serde(default)]
    pub d_h: Option<usize>,
    #[serde(default)]
    pub d_z: Option<usize>,
    pub layers: Vec<ExportLayer>,
    pub std: String,
    #[serde(default)]
    pub core_sha256: Option<String>,
    /// Observation layout, joint order, default pose, gains and limits (see [`RobotIo`]); absent in
    /// exports written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub io: Option<RobotIo>,
}

/// One dense layer of the exported actor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportLayer {
    pub name: String,
    #[serde(rename = "in")]
    pub input: usize,
    #[serde(rename = "out")]
    pub output: usize,
    pub activation: String,
}

#[derive(Debug, Clone)]
struct Dense {
    /// `[in, out]` row-major (transposed from the file) for the axpy loop.
    w: Vec<f32>,
    b: Vec<f32>,
    input: usize,
    output: usize,
    elu: bool,
}

/// A loaded export, ready for inference.
#[derive(Debug, Clone)]
pub struct DeployPolicy {
    pub config: ExportConfig,
    layers: Vec<Dense>,
    std: Vec<f32>,
}

impl DeployPolicy {
    /// Load from a file (`*.safetensors`, config from its metadata or from a `policy.json` beside
    /// it) or a directory holding `policy.safetensors`.
    pub fn load(path: &Path) -> Result<Self, PolicyError> {
        let file = if path.is_dir() {
            path.join("policy.safetensors")
        } else {
            path.to_path_buf()
        };
        let bytes = std::fs::read(&file).map_err(|source| PolicyError::Io {
            path: file.display().to_string(),
            source,
        })?;
        Self::from_bytes(&bytes).map_err(|e| e.in_file(&file))
    }

    /// Parse an export blob (safetensors with the JSON config in its metadata).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyError> {
        let bad = |m: String| PolicyError::Export(m);
        let st = SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let (_, meta) = SafeTensors::read_metadata(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let json = meta
            .metadata()
            .as_ref()
            .and_then(|m| m.get(EXPORT_METADATA_KEY))
            .ok_or_else(|| bad(format!("no `{EXPORT_METADATA_KEY}` metadata (hint: write exports with l3p's export function)")))?;
        let config: ExportConfig =
            serde_json::from_str(json).map_err(|e| bad(format!("bad export config: {e}")))?;
        Self::from_parts(config, &st)
    }

    fn from_parts(config: ExportConfig, st: &SafeTensors<'_>) -> Result<Self, PolicyError> {
        let bad = |m: String| PolicyError::Export(m);
        if config.format != EXPORT_FORMAT {
            return Err(bad(format!(
                "format {} is not {EXPORT_FORMAT}",
                config.format
            )));
        }
        let read = |name: &str, shape: &[usize]| -> Result<Vec<f32>, PolicyError> {
            let t = st
                .tensor(name)
                .map_err(|e| bad(format!("tensor {name}: {e}")))?;
            if t.dtype() != safetensors::Dtype::F32 {
                return Err(bad(format!(
                    "tensor {name}: dtype {:?}, expected F32",
                    t.dtype()
                )));
            }
            if t.shape() != shape {
                return Err(bad(format!(
                    "tensor {name}: shape {:?}, expected {shape:?}",
                    t.shape()
                )));
            }
            let v: Vec<f32> = t
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("tensor {name}: non-finite values")));
            }
            Ok(v)
        };
        let mut layers = Vec::new();
        let mut width = config.obs_dim;
        for l in &config.layers {
            if l.input != width {
                return Err(bad(format!(
                    "layer {}: input {} does not follow width {width}",
                    l.name, l.input
                )));
            }
            let w_file = read(&format!("{}.weight", l.name), &[l.output, l.input])?;
            let b = read(&format!("{}.bias", l.name), &[l.output])?;
            let mut w = vec![0f32; l.input * l.output];
            for o in 0..l.output {
                for i in 0..l.input {
                    w[i * l.output + o] = w_file[o * l.input + i];
                }
            }
            let elu = match l.activation.as_str() {
                "elu" => true,
                "none" => false,
                other => return Err(bad(format!("layer {}: unknown activation {other}", l.name))),
            };
            layers.push(Dense {
                w,
                b,
                input: l.input,
                output: l.output,
                elu,
            });
            width = l.output;
        }
        if width != config.action_dim || layers.is_empty() {
            return Err(bad(format!(
                "network ends at width {width}, expected action_dim {}",
                config.action_dim
            )));
        }
        let std = read(&config.std, &[config.action_dim])?;
        Ok(Self {
            config,
            layers,
            std,
        })
    }

    pub fn obs_dim(&self) -> usize {
        self.config.obs_dim
    }

    pub fn action_dim(&self) -> usize {
        self.config.action_dim
    }

    /// Gaussian std per action dimension.
    pub fn std(&self) -> &[f32] {
        &self.std
    }

    /// Each layer's config with its weight in the file layout (`[out, in]` row-major, transposed
    /// back from the inference layout: exact) and its bias.
    pub(crate) fn layer_tensors(&self) -> impl Iterator<Item = (&ExportLayer, Vec<f32>, &[f32])> {
        self.config.layers.iter().zip(&self.layers).map(|(cfg, l)| {
            let mut w = vec![0f32; l.input * l.output];
            for i in 0..l.input {
                for o in 0..l.output {
                    w[o * l.input + i] = l.w[i * l.output + o];
                }
            }
            (cfg, w, l.b.as_slice())
        })
    }

    /// Action means for `n = obs.len() / obs_dim` observations (row-major), written into `out`
    /// (`[n, action_dim]`, resized). Batches of 128 rows or more are split over the rayon pool in
    /// blocks of 64 rows (each block allocates its buffers); smaller ones run on this thread,
    /// allocation-free after the first call with the same `n` when the same `scratch` is reused.
    pub fn act_into(
        &self,
        obs: &[f32],
        out: &mut Vec<f32>,
        scratch: &mut InferScratch,
    ) -> Result<(), PolicyError> {
        let d = self.config.obs_dim;
        if !obs.len().is_multiple_of(d) {
            return Err(PolicyError::Shape(format!(
                "observation buffer of {} floats is not a multiple of obs_dim {d}",
                obs.len()
            )));
        }
        let n = obs.len() / d;
        let a = self.config.action_dim;
        out.clear();
        out.resize(n * a, 0.0);
        if n < 2 * PARALLEL_ROWS || rayon::current_num_threads() < 2 {
            self.forward_rows(obs, n, out, scratch);
            return Ok(());
        }
        // Rows are independent: each block runs the whole network on its own thread (the actors'
        // batch of 512 observations took ~20% of collection time on one core).
        obs.par_chunks(PARALLEL_ROWS * d)
            .zip(out.par_chunks_mut(PARALLEL_ROWS * a))
            .for_each_init(InferScratch::default, |scratch, (x, y)| {
                self.forward_rows(x, x.len() / d, y, scratch);
            });
        Ok(())
    }

    /// The network on `n` rows of `obs`, into `out` (`[n, action_dim]`, already sized).
    fn forward_rows(&self, obs: &[f32], n: usize, out: &mut [f32], scratch: &mut InferScratch) {
        scratch.a.clear();
        scratch.a.extend_from_slice(obs);
        for layer in &self.layers {
            dense_forward(layer, &scratch.a, n, &mut scratch.b);
            std::mem::swap(&mut scratch.a, &mut scratch.b);
        }
        out.copy_from_slice(&scratch.a);
    }

    /// The policy seen through signed permutations of its inputs and outputs,
    /// `π'(o) = M_a π(M_o o)` with `(M o)[i] = sign[i] · o[index[i]]`, folded exactly into the
    /// first and last layers (the std follows the actions). With a task's left-right mirror maps
    /// this is the policy's mirror image: played in a symmetric simulator it turns the other way as
    /// much as the policy itself turns, so a drift that keeps its sign comes from the simulator
    /// (`l3p eval --mirrored`).
    pub fn permuted(
        &self,
        obs_index: &[usize],
        obs_sign: &[f32],
        action_index: &[usize],
        action_sign: &[f32],
    ) -> Result<Self, PolicyError> {
        let (d, a) = (self.config.obs_dim, self.config.action_dim);
        let is_perm = |index: &[usize], n: usize| {
            let mut seen = vec![false; n];
            index.len() == n
                && index
                    .iter()
                    .all(|&i| i < n && !std::mem::replace(&mut seen[i], true))
        };
        if !is_perm(obs_index, d) || obs_sign.len() != d {
            return Err(PolicyError::Shape(format!(
                "observation map of {} entries is not a permutation of {d}",
                obs_index.len()
            )));
        }
        if !is_perm(action_index, a) || action_sign.len() != a {
            return Err(PolicyError::Shape(format!(
                "action map of {} entries is not a permutation of {a}",
                action_index.len()
            )));
        }
        let mut out = self.clone();
        // First layer, w [in, out]: input idx[i] takes the row that input i had, signed.
        let first = &self.layers[0];
        let w = &mut out.layers[0].w;
        for (i, (&j, &s)) in obs_index.iter().zip(obs_sign).enumerate() {
            let (src, dst) = (i * first.output, j * first.output);
            for o in 0..first.output {
                w[dst + o] = s * first.w[src + o];
            }
        }
        // Last layer: output i is output idx[i], signed.
        let k = out.layers.len() - 1;
        let last = out.layers[k].clone();
        for (i, (&j, &s)) in action_index.iter().zip(action_sign).enumerate() {
            for r in 0..last.input {
                out.layers[k].w[r * last.output + i] = s * last.w[r * last.output + j];
            }
            out.layers[k].b[i] = s * last.b[j];
            out.std[i] = self.std[j];
        }
        Ok(out)
    }

    /// This policy averaged ([`averaged`](Self::averaged)) with its image under the maps of
    /// [`permuted`](Self::permuted): with a left-right mirror's maps, the exactly symmetric policy
    /// (`l3p export --symmetrized`, `[ppo] symmetrize_export`).
    pub fn symmetrized(
        &self,
        obs_index: &[usize],
        obs_sign: &[f32],
        action_index: &[usize],
        action_sign: &[f32],
    ) -> Result<Self, PolicyError> {
        self.averaged(&self.permuted(obs_index, obs_sign, action_index, action_sign)?)
    }

    /// The mean of two policies of the same shape, `½(π_a(o) + π_b(o))`, as one MLP of twice the
    /// width: the two hidden stacks side by side (block-diagonal weights; each block keeps its
    /// activation) and the last layer summing both halves. With `other` this policy's mirror image
    /// ([`permuted`](Self::permuted)) the result is exactly left-right symmetric at every state
    /// (`l3p eval --symmetrized`). Standard deviations are averaged too.
    pub fn averaged(&self, other: &Self) -> Result<Self, PolicyError> {
        let same = self.layers.len() == other.layers.len()
            && self
                .layers
                .iter()
                .zip(&other.layers)
                .all(|(a, b)| (a.input, a.output, a.elu) == (b.input, b.output, b.elu));
        if !same || self.std.len() != other.std.len() {
            return Err(PolicyError::Shape(
                "policies of different shapes cannot be averaged".into(),
            ));
        }
        let mut out = self.clone();
        let last = self.layers.len() - 1;
        for (k, (a, b)) in self.layers.iter().zip(&other.layers).enumerate() {
            // Inputs: the observation for the first layer, else both halves' hidden units.
            let (rows_a, rows_b) = if k == 0 {
                (a.input, 0)
            } else {
                (a.input, b.input)
            };
            let (cols_a, cols_b) = if k == last {
                (a.output, 0)
            } else {
                (a.output, b.output)
            };
            let (input, output) = (rows_a + rows_b, cols_a + cols_b);
            let mut w = vec![0.0f32; input * output];
            let mut bias = vec![0.0f32; output];
            let half = if k == last { 0.5 } else { 1.0 };
            for r in 0..a.input {
                for c in 0..a.output {
                    w[r * output + c] += half * a.w[r * a.output + c];
                }
            }
            for r in 0..b.input {
                let row = if k == 0 { r } else { rows_a + r };
                for c in 0..b.output {
                    let col = if k == last { c } else { cols_a + c };
                    w[row * output + col] += half * b.w[r * b.output + c];
                }
            }
            for c in 0..a.output {
                bias[c] += half * a.b[c];
            }
            for c in 0..b.output {
                let col = if k == last { c } else { cols_a + c };
                bias[col] += half * b.b[c];
            }
            out.layers[k] = Dense {
                w,
                b: bias,
                input,
                output,
                elu: a.elu,
            };
            if let Some(layer) = out.config.layers.get_mut(k) {
                (layer.input, layer.output) = (input, output);
            }
        }
        for (s, o) in out.std.iter_mut().zip(&other.std) {
            *s = 0.5 * (*s + o);
        }
        Ok(out)
    }

    /// Action means (allocating convenience form of [`act_into`](Self::act_into)).
    pub fn act(&self, obs: &[f32]) -> Result<Vec<f32>, PolicyError> {
        let mut out = Vec::new();
        self.act_into(obs, &mut out, &mut InferScratch::default())?;
        Ok(out)
    }

    /// Sample actions `a ~ N(mean, std)`; returns `(actions, log_probs)` with `log_probs` summed over
    /// action dimensions, given the means from [`act`](Self::act).
    pub fn sample<R: Rng>(&self, means: &[f32], rng: &mut R) -> (Vec<f32>, Vec<f32>) {
        let a = self.config.action_dim;
        let n = means.len() / a;
        let mut actions = vec![0f32; means.len()];
        let mut logp = vec![0f32; n];
        let log_norm: f32 = self.std.iter().map(|s| s.ln()).sum::<f32>()
            + 0.5 * a as f32 * (2.0 * std::f32::consts::PI).ln();
        for i in 0..n {
            let mut acc = 0f32;
            for j in 0..a {
                let e: f32 = rng.sample(StandardNormal);
                actions[i * a + j] = means[i * a + j] + self.std[j] * e;
                acc += 0.5 * e * e;
            }
            logp[i] = -acc - log_norm;
        }
        (actions, logp)
    }
}

/// Rows per parallel block of [`DeployPolicy::act_into`] (batches below twice this run serially).
const PARALLEL_ROWS: usize = 64;

/// Reusable buffers of [`DeployPolicy::act_into`].
#[derive(Debug, Default, Clone)]
pub struct InferScratch {
    a: Vec<f32>,
    b: Vec<f32>,
}

fn dense_forward(l: &Dense, x: &[f32], n: usize, y: &mut Vec<f32>) {
    let (din, dout) = (l.input, l.output);
    y.clear();
    y.resize(n * dout, 0.0);
    // Four rows at a time: every weight row loaded once feeds four accumulating rows.
    let mut r = 0;
    while r + 4 <= n {
        let (y0, rest) = y[r * dout..(r + 4) * dout].split_at_mut(dout);
        let (y1, rest) = rest.split_at_mut(dout);
        let (y2, y3) = rest.split_at_mut(dout);
        for yy in [&mut *y0, &mut *y1, &mut *y2, &mut *y3] {
            yy.copy_from_slice(&l.b);
        }
        for i in 0..din {
            let w = &l.w[i * dout..(i + 1) * dout];
            let (x0, x1, x2, x3) = (
                x[r * din + i],
                x[(r + 1) * din + i],
                x[(r + 2) * din + i],
                x[(r + 3) * din + i],
            );
            for j in 0..dout {
                let wj = w[j];
                y0[j] += x0 * wj;
                y1[j] += x1 * wj;
                y2[j] += x2 * wj;
                y3[j] += x3 * wj;
            }
        }
        r += 4;
    }
    while r < n {
        let yr = &mut y[r * dout..(r + 1) * dout];
        yr.copy_from_slice(&l.b);
        for i in 0..din {
            let xi = x[r * din + i];
            let w = &l.w[i * dout..(i + 1) * dout];
            for j in 0..dout {
                yr[j] += xi * w[j];
            }
        }
        r += 1;
    }
    if l.elu {
        for v in y.iter_mut() {
            if *v < 0.0 {
                *v = v.exp_m1();
            }
        }
    }
}

impl DeployPolicy {
    /// The export file of this policy (safetensors with its config in the metadata): what
    /// [`from_bytes`](Self::from_bytes) reads back exactly, e.g. for a policy made by
    /// [`averaged`](Self::averaged).
    pub fn to_bytes(&self) -> Result<Vec<u8>, PolicyError> {
        let bad = |m: String| PolicyError::Export(m);
        let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let mut buffers: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        for (cfg, w, b) in self.layer_tensors() {
            buffers.push((
                format!("{}.weight", cfg.name),
                vec![cfg.output, cfg.input],
                le(&w),
            ));
            buffers.push((format!("{}.bias", cfg.name), vec![cfg.output], le(b)));
        }
        buffers.push((self.config.std.clone(), vec![self.std.len()], le(&self.std)));
        let views = buffers
            .iter()
            .map(|(name, shape, data)| {
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), data)
                    .map(|v| (name.clone(), v))
                    .map_err(|e| bad(e.to_string()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        safetensors::serialize(views, Some(export_metadata(&self.config)?))
            .map_err(|e| bad(e.to_string()))
    }
}

/// Load the JSON config of a directory export (`policy.json`).
pub fn read_export_json(dir: &Path) -> Result<ExportConfig, PolicyError> {
    let path = dir.join("policy.json");
    let text = std::fs::read_to_string(&path).map_err(|source| PolicyError::Io {
        path: path.display().to_string(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| PolicyError::Export(format!("{}: {e}", path.display())))
}

/// Metadata map holding the config, for writing.
pub fn export_metadata(config: &ExportConfig) -> Result<HashMap<String, String>, PolicyError> {
    let json = serde_json::to_string(config).map_err(|e| PolicyError::Export(e.to_string()))?;
    Ok(HashMap::from([(EXPORT_METADATA_KEY.to_string(), json)]))
}

/// The same export with its JSON config replaced (tensors copied unchanged), e.g. to add the
/// robot I/O contract to an export written before it existed. The new config must describe the same
/// tensors: the result is parsed back before it is returned.
pub fn replace_export_config(bytes: &[u8], config: &ExportConfig) -> Result<Vec<u8>, PolicyError> {
    let bad = |m: String| PolicyError::Export(m);
    let st =
        SafeTensors::deserialize(bytes).map_err(|e| bad(format!("not a safetensors file: {e}")))?;
    let tensors: Vec<(String, safetensors::tensor::TensorView<'_>)> = st
        .tensors()
        .into_iter()
        .map(|(name, view)| (name.to_string(), view))
        .collect();
    let out = safetensors::serialize(tensors, Some(export_metadata(config)?))
        .map_err(|e| bad(e.to_string()))?;
    DeployPolicy::from_bytes(&out)?;
    Ok(out)
}
