//! [`HeadMap`]: linear maps on a robot's observations and actions, folded into a copy of another
//! robot's heads so that the copy acts on the new robot as the original acted on its own (the
//! `mapped` transfer warm start; the maps come from `l3p_task::morphology`).
//!
//! Folding is exact for every layer that touches the robot's own spaces: the first layer of the
//! encoder (the whole actor under `mlp`), of the critic and of `R_act` take mapped inputs
//! (`W' = Mᵀ W`), the actor's last layer gives mapped outputs (`V' = V M_aᵀ`, `c' = M_a c`), and the
//! std becomes the mapped distribution's (`σ'ᵢ = √Σⱼ (M_a)ᵢⱼ² σⱼ²`). `R_obs` (a denoiser in
//! observation space, not linear in it) stays the copy it was.

use burn::module::Param;
use burn::nn::Linear;
use burn::tensor::{Tensor, TensorData};

use crate::PolicyError;
use crate::model::RobotHeads;
use crate::nets::Mlp;

/// Maps between a source robot's task spaces and a target robot's.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadMap {
    /// Observation size `n`.
    pub obs_dim: usize,
    /// Row-major `n × n`: `x_source = M x_target`.
    pub observation: Vec<f32>,
    /// Action size `m`.
    pub action_dim: usize,
    /// Row-major `m × m`: `a_target = M a_source`.
    pub action: Vec<f32>,
    /// Row-major `m × m`: `a_source = M a_target` (the inverse of `action`).
    pub action_inverse: Vec<f32>,
}

/// `Mᵀ W` for row-major `m [n × n]` and `w [n × k]`.
fn transpose_times(m: &[f32], w: &[f32], n: usize, k: usize) -> Vec<f32> {
    let mut out = vec![0.0; n * k];
    for r in 0..n {
        for i in 0..n {
            let a = m[i * n + r];
            if a != 0.0 {
                for c in 0..k {
                    out[r * k + c] += a * w[i * k + c];
                }
            }
        }
    }
    out
}

fn host(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_into_vec::<f32>().unwrap_or_default()
}

fn host1(t: Tensor<1>) -> Vec<f32> {
    t.into_data().try_into_vec::<f32>().unwrap_or_default()
}

fn set_weight(layer: &mut Linear, w: Vec<f32>, dims: [usize; 2]) {
    let device = layer.weight.val().device();
    layer.weight = Param::from_tensor(Tensor::from_data(TensorData::new(w, dims), &device));
}

/// The first layer of `mlp` takes inputs mapped by `m` (`x_source = M x_new`).
fn map_input(mlp: &mut Mlp, m: &[f32], n: usize, what: &str) -> Result<(), PolicyError> {
    let layer = mlp
        .layers
        .first_mut()
        .ok_or_else(|| PolicyError::Shape(format!("{what}: no layers")))?;
    let [i, k] = layer.weight.shape().dims::<2>();
    if i != n || m.len() != n * n {
        return Err(PolicyError::Shape(format!(
            "{what}: input {i}, map {n} × {n} ({} values)",
            m.len()
        )));
    }
    let w = transpose_times(m, &host(layer.weight.val()), n, k);
    set_weight(layer, w, [n, k]);
    Ok(())
}

/// The last layer of `mlp` gives outputs mapped by `m` (`y_new = M y_source`).
fn map_output(mlp: &mut Mlp, m: &[f32], n: usize, what: &str) -> Result<(), PolicyError> {
    let layer = mlp
        .layers
        .last_mut()
        .ok_or_else(|| PolicyError::Shape(format!("{what}: no layers")))?;
    let [k, o] = layer.weight.shape().dims::<2>();
    if o != n || m.len() != n * n {
        return Err(PolicyError::Shape(format!(
            "{what}: output {o}, map {n} × {n} ({} values)",
            m.len()
        )));
    }
    let w = host(layer.weight.val());
    // V' = V Mᵀ: row h of V' is M (row h of V).
    let mut mapped = vec![0.0; k * n];
    for h in 0..k {
        for r in 0..n {
            mapped[h * n + r] = (0..n).map(|c| m[r * n + c] * w[h * n + c]).sum();
        }
    }
    set_weight(layer, mapped, [k, n]);
    if let Some(bias) = &mut layer.bias {
        let b = host1(bias.val());
        let device = bias.val().device();
        let mb: Vec<f32> = (0..n)
            .map(|r| (0..n).map(|c| m[r * n + c] * b[c]).sum())
            .collect();
        *bias = Param::from_tensor(Tensor::from_data(TensorData::new(mb, [n]), &device));
    }
    Ok(())
}

impl RobotHeads {
    /// Folds `map` into these heads (copied from the source robot); see the module docs.
    pub fn map_spaces(mut self, map: &HeadMap) -> Result<Self, PolicyError> {
        let (n, m) = (map.obs_dim, map.action_dim);
        map_input(&mut self.encoder, &map.observation, n, "encoder")?;
        map_input(&mut self.critic, &map.observation, n, "critic")?;
        match &mut self.decoder {
            Some(decoder) => map_output(decoder, &map.action, m, "decoder")?,
            None => map_output(&mut self.encoder, &map.action, m, "actor")?,
        }
        if let Some(r_act) = &mut self.r_act {
            map_input(r_act, &map.action_inverse, m, "r_act")?;
        }
        let sigma = host1(self.std.val());
        if sigma.len() != m {
            return Err(PolicyError::Shape(format!(
                "std: {} values, action map {m}",
                sigma.len()
            )));
        }
        let mapped: Vec<f32> = (0..m)
            .map(|r| {
                (0..m)
                    .map(|c| (map.action[r * m + c] * sigma[c]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
            .collect();
        let device = self.std.val().device();
        self.std = Param::from_tensor(Tensor::from_data(TensorData::new(mapped, [m]), &device));
        Ok(self)
    }
}
