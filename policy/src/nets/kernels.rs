//! Fused `elu(z + b)` for the flex CPU backend, with its own backward pass.
//!
//! burn-flex runs elementwise kernels on one thread and allocates a tensor per op; the ELU of a
//! hidden layer (bias add + 5 elementwise ops forward, as many backward) cost more than the matrix
//! products on two threads. Here one burn backend-extension op does `y = elu(z + b)` in place
//! (rows split over the rayon pool, an `exp` polynomial that vectorises) and its backward computes
//! `dz = g · (y > 0 ? 1 : y + 1)` and `db = Σ_rows dz` in one pass.
//!
//! [`BiasEluBackend`] is implemented for `Flex` (the kernels) and for `Autodiff<B>` (registers the
//! backward step); [`crate::nets::bias_elu`] is the `Tensor` front end.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, DType, Flex, backend_extension};
use burn::tensor::{Bytes, Shape};
use macerator::{AutoArch, Simd, WithSimd};
use rayon::prelude::*;

/// Backends that run the fused bias + ELU.
#[backend_extension(Flex, Autodiff)]
pub trait BiasEluBackend: Backend {
    /// `elu(z + b)`, `z: [m, n]`, `b: [n]` broadcast over rows.
    fn bias_elu(z: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// The backward kernel of [`BiasEluBackend::bias_elu`] (concrete backends only).
pub trait BiasEluBackward: Backend {
    /// From the output `y = elu(z + b)` and its gradient `g` (both `[m, n]`): `(dz [m, n], db [n])`.
    fn bias_elu_backward(
        out: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>);
}

/// Fewer elements than this per task are not worth a rayon split.
const MIN_TASK_ELEMS: usize = 16 * 1024;

fn dims2(t: &FlexTensor) -> (usize, usize) {
    let dims = t.layout().shape().to_vec();
    assert!(
        dims.len() == 2,
        "bias_elu: expected a 2-D tensor, got {dims:?}"
    );
    (dims[0], dims[1])
}

/// An f32 tensor whose storage this call owns, contiguous from offset 0 (copied if shared).
fn owned_f32(t: FlexTensor) -> FlexTensor {
    assert_eq!(t.dtype(), DType::F32, "bias_elu: f32 tensors only");
    if t.is_unique() && t.layout().is_contiguous() && t.layout().start_offset() == 0 {
        return t;
    }
    let shape = t.layout().shape().clone();
    let data = contiguous_f32(&t).to_vec();
    FlexTensor::new(
        Bytes::from_elems(data),
        burn::backend::flex::Layout::contiguous(shape),
        DType::F32,
    )
}

fn contiguous_f32(t: &FlexTensor) -> std::borrow::Cow<'_, [f32]> {
    assert_eq!(t.dtype(), DType::F32, "bias_elu: f32 tensors only");
    match t.as_slice::<f32>() {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => {
            std::borrow::Cow::Owned(t.to_contiguous().as_slice::<f32>().unwrap_or(&[]).to_vec())
        }
    }
}

/// Rows per rayon task for an `[m, n]` pass (`m` when one task is enough).
fn rows_per_task(m: usize, n: usize) -> usize {
    let threads = rayon::current_num_threads().max(1);
    if threads == 1 || m * n < 2 * MIN_TASK_ELEMS {
        return m.max(1);
    }
    let min_rows = MIN_TASK_ELEMS.div_ceil(n.max(1));
    m.div_ceil(threads * 4).max(min_rows)
}

/// `e^x` for `x ∈ [-87, 0]` (Cephes `expf`: range reduction by ln 2, degree-6 polynomial; a few
/// ulp), branch-free so the row loops vectorise.
#[inline(always)]
fn exp_nonpos(x: f32) -> f32 {
    let x = x.max(-87.0);
    let n = (x * std::f32::consts::LOG2_E + 12_582_912.0) - 12_582_912.0; // round to nearest
    let r = x - n * 0.693_359_4 + n * 2.121_944_4e-4;
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e = p * r * r + r + 1.0;
    e * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

#[inline(always)]
fn bias_elu_rows(rows: &mut [f32], bias: &[f32]) {
    for row in rows.chunks_exact_mut(bias.len()) {
        for (v, b) in row.iter_mut().zip(bias) {
            let x = *v + *b;
            let e = exp_nonpos(x.min(0.0)) - 1.0;
            *v = if x > 0.0 { x } else { e };
        }
    }
}

#[inline(always)]
fn elu_backward_rows(grad: &mut [f32], out: &[f32], db: &mut [f32]) {
    let n = db.len();
    for (g_row, y_row) in grad.chunks_exact_mut(n).zip(out.chunks_exact(n)) {
        for ((g, y), acc) in g_row.iter_mut().zip(y_row).zip(db.iter_mut()) {
            let d = if *y > 0.0 { 1.0 } else { *y + 1.0 };
            *g *= d;
            *acc += *g;
        }
    }
}

/// `bias_elu_rows` compiled for the best instruction set of this CPU (macerator's safe dispatch).
struct BiasEluRows<'a> {
    rows: &'a mut [f32],
    bias: &'a [f32],
}

impl WithSimd for BiasEluRows<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self) {
        bias_elu_rows(self.rows, self.bias)
    }
}

/// `elu_backward_rows` compiled for the best instruction set of this CPU.
struct EluBackwardRows<'a> {
    grad: &'a mut [f32],
    out: &'a [f32],
    db: &'a mut [f32],
}

impl WithSimd for EluBackwardRows<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self) {
        elu_backward_rows(self.grad, self.out, self.db)
    }
}

fn bias_elu_task(rows: &mut [f32], bias: &[f32]) {
    AutoArch::new().dispatch(BiasEluRows { rows, bias })
}

fn elu_backward_task(grad: &mut [f32], out: &[f32], db: &mut [f32]) {
    AutoArch::new().dispatch(EluBackwardRows { grad, out, db })
}

/// In place: `data [m, n] ← elu(data + bias)`.
pub fn bias_elu_slice(data: &mut [f32], bias: &[f32]) {
    let n = bias.len();
    assert!(
        n > 0 && data.len().is_multiple_of(n),
        "bias_elu: shape mismatch"
    );
    let rows = rows_per_task(data.len() / n, n);
    if rows * n >= data.len() {
        bias_elu_task(data, bias);
    } else {
        data.par_chunks_mut(rows * n)
            .for_each(|c| bias_elu_task(c, bias));
    }
}

/// In place: `grad [m, n] ← grad · elu'(z)` (from the output `out = elu(z)`); returns `Σ_rows`.
pub fn elu_backward_slice(grad: &mut [f32], out: &[f32], n: usize) -> Vec<f32> {
    assert!(
        n > 0 && grad.len().is_multiple_of(n) && grad.len() == out.len(),
        "bias_elu backward: shape mismatch"
    );
    let rows = rows_per_task(grad.len() / n, n);
    if rows * n >= grad.len() {
        let mut db = vec![0f32; n];
        elu_backward_task(grad, out, &mut db);
        return db;
    }
    grad.par_chunks_mut(rows * n)
        .zip(out.par_chunks(rows * n))
        .map(|(g, y)| {
            let mut db = vec![0f32; n];
            elu_backward_task(g, y, &mut db);
            db
        })
        .reduce(
            || vec![0f32; n],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

impl BiasEluBackend for Flex {
    fn bias_elu(z: FlexTensor, bias: FlexTensor) -> FlexTensor {
        let (_, n) = dims2(&z);
        let bias = contiguous_f32(&bias);
        assert_eq!(
            bias.len(),
            n,
            "bias_elu: bias has {} entries for {n} columns",
            bias.len()
        );
        let mut z = owned_f32(z);
        bias_elu_slice(z.storage_mut::<f32>(), &bias);
        z
    }
}

impl BiasEluBackward for Flex {
    fn bias_elu_backward(out: FlexTensor, grad: FlexTensor) -> (FlexTensor, FlexTensor) {
        let (_, n) = dims2(&out);
        let y = contiguous_f32(&out);
        let mut grad = owned_f32(grad);
        let db = elu_backward_slice(grad.storage_mut::<f32>(), &y, n);
        let db = FlexTensor::new(
            Bytes::from_elems(db),
            burn::backend::flex::Layout::contiguous(Shape::new([n])),
            DType::F32,
        );
        (grad, db)
    }
}

#[derive(Debug)]
struct BiasElu;

impl<B: Backend + BiasEluBackward> Backward<B, 2> for BiasElu {
    /// The output `elu(z + b)`.
    type State = FloatTensor<B>;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let grad = grads.consume::<B>(&ops.node);
        let [node_z, node_b] = ops.parents;
        let (dz, db) = B::bias_elu_backward(ops.state, grad);
        if let Some(node) = node_z {
            grads.register::<B>(node.id, dz);
        }
        if let Some(node) = node_b {
            grads.register::<B>(node.id, db);
        }
    }
}

impl<B, C> BiasEluBackend for Autodiff<B, C>
where
    B: Backend + BiasEluBackend + BiasEluBackward,
    C: CheckpointStrategy,
{
    fn bias_elu(z: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self> {
        let (z, z_node) = z.into_parts();
        let (bias, b_node) = bias.into_parts();
        match BiasElu
            .prepare::<C>([z_node, b_node])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let out = B::bias_elu(z, bias);
                prep.finish(out.clone(), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::bias_elu(z, bias)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_polynomial_matches_std() {
        let mut worst = 0f32;
        // Below -87 the input is clamped (e^-87 ≈ 1.6e-38, next to f32's smallest normal).
        for i in 0..=86_900 {
            let x = -(i as f32) * 1e-3;
            let (a, b) = (exp_nonpos(x) as f64, (x as f64).exp());
            worst = worst.max(((a - b).abs() / b) as f32);
        }
        assert!(worst < 4e-7, "relative error {worst}");
        assert_eq!(exp_nonpos(0.0), 1.0);
        assert!(exp_nonpos(-1e4) >= 0.0 && exp_nonpos(-1e4) < 1e-37);
    }

    #[test]
    fn slices_match_definition() {
        let (m, n) = (301, 7);
        let bias: Vec<f32> = (0..n).map(|j| j as f32 * 0.3 - 1.0).collect();
        let z: Vec<f32> = (0..m * n)
            .map(|i| ((i * 37) % 101) as f32 * 0.1 - 5.0)
            .collect();
        let mut y = z.clone();
        bias_elu_slice(&mut y, &bias);
        let mut g: Vec<f32> = (0..m * n).map(|i| ((i * 13) % 17) as f32 - 8.0).collect();
        let g0 = g.clone();
        let db = elu_backward_slice(&mut g, &y, n);
        let mut db_ref = vec![0f64; n];
        for i in 0..m * n {
            let x = z[i] + bias[i % n];
            let want = if x > 0.0 { x } else { x.exp_m1() };
            assert!(
                (y[i] - want).abs() <= 1e-6 * (1.0 + want.abs()),
                "{x}: {} vs {want}",
                y[i]
            );
            let d = if x > 0.0 { 1.0 } else { x.exp() };
            assert!((g[i] - g0[i] * d).abs() <= 1e-6 * (1.0 + g0[i].abs()));
            db_ref[i % n] += (g0[i] * d) as f64;
        }
        for (a, b) in db.iter().zip(&db_ref) {
            assert!((*a as f64 - b).abs() < 1e-3, "{a} vs {b}");
        }
    }
}

#[cfg(test)]
mod autodiff_tests {
    use burn::tensor::{Distribution, Tensor};

    use crate::nets::{bias_elu, elu};

    fn host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    /// Values and gradients of the fused op equal those of `elu(z + b)` built from burn ops, on a
    /// batch large enough to be split over the rayon pool.
    #[test]
    fn fused_matches_composed_ops() {
        let device = crate::train_device();
        let (m, n) = (300, 200);
        let z0 = Tensor::<2>::random([m, n], Distribution::Uniform(-3.0, 3.0), &device);
        let b0 = Tensor::<1>::random([n], Distribution::Uniform(-1.0, 1.0), &device);
        let w = Tensor::<2>::random([m, n], Distribution::Uniform(-1.0, 1.0), &device);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let run = |fused: bool| {
            let z = z0.clone().require_grad();
            let b = b0.clone().require_grad();
            let y = if fused {
                bias_elu(z.clone(), b.clone())
            } else {
                elu(z.clone().add(b.clone().unsqueeze_dim::<2>(0)))
            };
            let grads = y.clone().mul(w.clone()).sum().backward();
            let gz = z.grad(&grads).unwrap();
            let gb = b.grad(&grads).unwrap();
            (host(y.inner()), host(gz), host(gb))
        };
        let (y1, gz1, gb1) = pool.install(|| run(true));
        let (y2, gz2, gb2) = run(false);
        let close = |a: &[f32], b: &[f32], tol: f32| {
            assert_eq!(a.len(), b.len());
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= tol * (1.0 + y.abs()), "{x} vs {y}");
            }
        };
        close(&y1, &y2, 1e-6);
        close(&gz1, &gz2, 1e-6);
        // The bias gradient sums 300 rows in another order: f32 reassociation error grows with
        // the row count (≈ m · 2⁻²⁴ · Σ|terms|), so 1e-5 failed on unlucky draws.
        close(&gb1, &gb2, m as f32 * 1e-6);
        // Inference path (no autodiff).
        let y3 = bias_elu(z0.clone().inner(), b0.clone().inner());
        close(&host(y3), &y2, 1e-6);
    }
}
