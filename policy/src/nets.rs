//! Building blocks: [`Mlp`] (fully connected, ELU between layers, linear output) with its
//! [`MlpConfig`], and [`elu`], written without masks because burn's `activation::elu` (built on
//! `mask_where`) is several times slower on the `flex` CPU backend (`reference/burn-cpu-notes.md`).
//! Hidden layers of an [`Mlp`] use [`bias_elu`] (one fused, multi-threaded op, see [`kernels`]).

pub mod kernels;

use burn::backend::Dispatch;
use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use kernels::BiasEluBackend;

/// ELU with α = 1: `relu(x) + exp(-relu(-x)) - 1` — the same values and gradients as
/// `x > 0 ? x : exp(x) - 1`, with only elementwise ops.
///
/// # Shapes
/// any `[..]` → same shape
pub fn elu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    let pos = relu(x.clone());
    let neg = relu(x.neg()).neg().exp();
    pos.add(neg).sub_scalar(1.0)
}

/// `elu(z + b)` as one op (forward and backward fused, rows split over the rayon pool); the same
/// values and gradients as `elu(z + b.unsqueeze())`.
///
/// # Shapes
/// `z [m, n]`, `b [n]` → `[m, n]`
pub fn bias_elu(z: Tensor<2>, b: Tensor<1>) -> Tensor<2> {
    // The fused kernels exist for the CPU backend only; GPU devices (`cuda` feature) compose.
    if z.device().inner() != burn::tensor::Device::flex() {
        return elu(z.add(b.unsqueeze_dim(0)));
    }
    Tensor::from_dispatch(<Dispatch as BiasEluBackend>::bias_elu(
        z.into_dispatch(),
        b.into_dispatch(),
    ))
}

/// Sizes of an [`Mlp`]: `input → hidden… → output`.
#[derive(Debug, Clone, PartialEq)]
pub struct MlpConfig {
    pub input: usize,
    pub hidden: Vec<usize>,
    pub output: usize,
}

impl MlpConfig {
    pub fn new(input: usize, hidden: &[usize], output: usize) -> Self {
        Self {
            input,
            hidden: hidden.to_vec(),
            output,
        }
    }

    /// Layer widths including input and output.
    pub fn sizes(&self) -> Vec<usize> {
        let mut s = vec![self.input];
        s.extend_from_slice(&self.hidden);
        s.push(self.output);
        s
    }

    /// Initialise with PyTorch's default `nn.Linear` init (Kaiming uniform, gain 1/√3), as rsl_rl.
    pub fn init(&self, device: &Device) -> Mlp {
        let sizes = self.sizes();
        let layers = sizes
            .windows(2)
            .map(|w| LinearConfig::new(w[0], w[1]).init(device))
            .collect();
        Mlp { layers }
    }
}

/// Fully connected network, ELU after every layer but the last.
#[derive(Module, Debug)]
pub struct Mlp {
    pub layers: Vec<Linear>,
}

impl Mlp {
    /// # Shapes
    /// `[batch, input]` → `[batch, output]`
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len().saturating_sub(1);
        let mut x = x;
        for (i, layer) in self.layers.iter().enumerate() {
            x = match (&layer.bias, i < last) {
                (Some(b), true) => bias_elu(x.matmul(layer.weight.val()), b.val()),
                (None, true) => elu(layer.forward(x)),
                (_, false) => layer.forward(x),
            };
        }
        x
    }

    pub fn input_dim(&self) -> usize {
        self.layers
            .first()
            .map(|l| l.weight.shape().dims::<2>()[0])
            .unwrap_or(0)
    }

    pub fn output_dim(&self) -> usize {
        self.layers
            .last()
            .map(|l| l.weight.shape().dims::<2>()[1])
            .unwrap_or(0)
    }

    /// Weights `[in, out]` and biases `[out]` of every layer, copied to host memory.
    pub fn to_host(&self) -> Vec<(Vec<f32>, Vec<f32>, usize, usize)> {
        self.layers
            .iter()
            .map(|l| {
                let [i, o] = l.weight.shape().dims::<2>();
                let w = l
                    .weight
                    .val()
                    .into_data()
                    .try_into_vec::<f32>()
                    .unwrap_or_default();
                let b = match &l.bias {
                    Some(b) => b
                        .val()
                        .into_data()
                        .try_into_vec::<f32>()
                        .unwrap_or_default(),
                    None => vec![0.0; o],
                };
                (w, b, i, o)
            })
            .collect()
    }
}
