//! The tensor-level pieces of a PPO step: rsl_rl's KL estimate, the clipped surrogate and value
//! losses, and `clip_grad_norm_` over a whole module ([`clip_global_grad_norm`]).

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::Tensor;
use l3p_policy::tensor_to_vec;

use crate::LearnerError;

/// rsl_rl's KL estimate between the behaviour policy `N(old_mu, old_sigma)` and the current
/// `N(mu, sigma)`: `Σ_a [log(σ/σ_old + 1e-5) + (σ_old² + (μ_old − μ)²)/(2σ²) − 0.5]`, batch mean.
///
/// # Shapes
/// `mu [B, A]`, `sigma [A]`, `old_mu [B, A]`, `old_sigma [B, A]` → `[1]`
pub fn approx_kl(
    mu: Tensor<2>,
    sigma: Tensor<1>,
    old_mu: Tensor<2>,
    old_sigma: Tensor<2>,
) -> Tensor<1> {
    let sigma = sigma.unsqueeze_dim::<2>(0);
    sigma
        .clone()
        .div(old_sigma.clone())
        .add_scalar(1e-5)
        .log()
        .add(
            old_sigma
                .square()
                .add(old_mu.sub(mu).square())
                .div(sigma.square().mul_scalar(2.0)),
        )
        .sub_scalar(0.5)
        .sum_dim(1)
        .mean()
}

/// Clipped surrogate `mean(max(−A·ρ, −A·clip(ρ, 1 ± ε)))`.
///
/// # Shapes
/// `ratio [B]`, `adv [B]` → `[1]`
pub fn surrogate_loss(ratio: Tensor<1>, adv: Tensor<1>, clip: f32) -> Tensor<1> {
    let surr = adv.clone().neg().mul(ratio.clone());
    let surr_clipped = adv.neg().mul(ratio.clamp(1.0 - clip, 1.0 + clip));
    surr.max_pair(surr_clipped).mean()
}

/// Value loss: clipped `mean(max((V − R)², (V_old + clip(V − V_old, ±ε) − R)²))` or plain
/// `mean((V − R)²)`.
///
/// # Shapes
/// `value [B]`, `old_value [B]`, `returns [B]` → `[1]`
pub fn value_loss(
    value: Tensor<1>,
    old_value: Tensor<1>,
    returns: Tensor<1>,
    clip: f32,
    clipped: bool,
) -> Tensor<1> {
    if clipped {
        let v_clipped = old_value
            .clone()
            .add(value.clone().sub(old_value).clamp(-clip, clip));
        let a = value.sub(returns.clone()).square();
        let b = v_clipped.sub(returns).square();
        a.max_pair(b).mean()
    } else {
        value.sub(returns).square().mean()
    }
}

/// The first element of a one-element tensor, read back to the host (NaN when empty).
pub(super) fn scalar(t: Tensor<1>) -> Result<f32, LearnerError> {
    Ok(tensor_to_vec(t)?.first().copied().unwrap_or(f32::NAN))
}

/// Collects the ids of every float parameter.
struct ParamIds(Vec<(ParamId, usize)>);

impl ModuleVisitor for ParamIds {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.push((param.id, D));
    }
}

/// Scales gradients in place.
struct GradScaler<'a> {
    grads: &'a mut GradientsParams,
    scale: f32,
    sq_norm: Option<Tensor<1>>,
}

impl ModuleVisitor for GradScaler<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if self.scale >= 1.0 {
            // First pass: accumulate Σ g².
            if let Some(g) = self.grads.get::<D>(param.id) {
                let s = g.square().sum();
                self.sq_norm = Some(match self.sq_norm.take() {
                    None => s,
                    Some(acc) => acc.add(s),
                });
            }
        } else if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register::<D>(param.id, g.mul_scalar(self.scale));
        }
    }
}

/// `torch.nn.utils.clip_grad_norm_` over all parameters jointly: total norm `√Σ‖g‖²`; if it
/// exceeds `max_norm`, every gradient is multiplied by `max_norm / (norm + 1e-6)`. Returns the norm
/// before clipping.
pub fn clip_global_grad_norm<M: Module>(
    module: &M,
    grads: &mut GradientsParams,
    max_norm: f32,
) -> Result<f32, LearnerError> {
    let mut pass = GradScaler {
        grads,
        scale: 1.0,
        sq_norm: None,
    };
    module.visit(&mut pass);
    let Some(sq) = pass.sq_norm else {
        return Ok(0.0);
    };
    let norm = scalar(sq)?.sqrt();
    let coef = max_norm / (norm + 1e-6);
    if coef < 1.0 {
        let mut pass = GradScaler {
            grads,
            scale: coef,
            sq_norm: None,
        };
        module.visit(&mut pass);
    }
    Ok(norm)
}

/// Ids of all float parameters of a module (for tests and freezing checks).
pub fn param_ids<M: Module>(module: &M) -> Vec<ParamId> {
    let mut v = ParamIds(Vec::new());
    module.visit(&mut v);
    v.0.into_iter().map(|(id, _)| id).collect()
}
