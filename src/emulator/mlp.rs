//! # Three-layer perceptron
//!
//! The network N(x, w) of NeuroAnimator §2.1–2.2: p linear inputs, q logistic-sigmoid hidden
//! units, r linear outputs, each layer with a bias (Fig. 1b, eq. 2):
//!
//! ```text
//! h = σ(W₁ x + b₁),   σ(z) = 1 / (1 + e^{−z})
//! y = W₂ h + b₂
//! ```
//!
//! Backpropagation (§2.3) of an output cotangent ȳ = ∂E/∂y:
//!
//! ```text
//! ∂E/∂W₂ = ȳ hᵀ,   ∂E/∂b₂ = ȳ
//! h̄ = (W₂ᵀ ȳ) ⊙ h ⊙ (1 − h)
//! ∂E/∂W₁ = h̄ xᵀ,   ∂E/∂b₁ = h̄
//! x̄ = W₁ᵀ h̄          (vector–Jacobian product to the inputs, used by BPTT, §4.3)
//! ∂y/∂x = W₂ diag(h ⊙ (1 − h)) W₁
//! ```
//!
//! All weights live in one flat vector so that optimizers see a single parameter vector. The
//! layout is `[W₁ (q×p, row-major), b₁ (q), W₂ (r×q, row-major), b₂ (r)]`; gradients use the same
//! layout. The single-example passes (Appendix C) write into caller-provided scratch and never
//! allocate; they run the kernels of `kernels` on a packed copy of the weights (transposed and
//! padded so that the products vectorize across outputs, each sum still taken in input order),
//! built on first use and dropped whenever the weights are handed out mutably. The batch pass
//! works on fixed chunks of [`BATCH_CHUNK`] rows with ordered reduction, so its result is
//! bit-identical for any number of rayon threads.

use ndarray::{s, Array2, ArrayView1, ArrayView2, ArrayViewMut2, Axis};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::OnceLock;

mod kernels;

/// Rows per chunk in the batch passes; fixed so results do not depend on the thread count.
pub const BATCH_CHUNK: usize = 128;

/// Chunks whose gradients [`Mlp::loss_grad`] computes (in parallel) before adding them, in
/// chunk order, to the total.
const GRAD_WINDOW: usize = 16;

fn chunk_count(n: usize) -> usize {
    n.div_ceil(BATCH_CHUNK)
}

fn chunk(
    c: usize,
    n: usize,
) -> ndarray::SliceInfo<[ndarray::SliceInfoElem; 2], ndarray::Ix2, ndarray::Ix2> {
    s![c * BATCH_CHUNK..n.min((c + 1) * BATCH_CHUNK), ..]
}

/// The rows of chunk c + 1 of a batch (inputs and targets), for chunk c's kernel to fetch into
/// the cache while it computes ([`kernels::Ahead`]); nothing after the last chunk.
fn next_chunk(c: usize, (x, t): (ArrayView2<'_, f64>, ArrayView2<'_, f64>)) -> kernels::Ahead {
    let n = x.nrows();
    if c + 1 < chunk_count(n) {
        kernels::Ahead::rows(x.slice(chunk(c + 1, n)), t.slice(chunk(c + 1, n)))
    } else {
        kernels::Ahead::none()
    }
}

/// The logistic sigmoid σ(z) = 1 / (1 + e^{−z}), evaluated as every pass of the net evaluates
/// it (a vectorizable exponential within a few units in the last place; `kernels`' docs).
#[inline]
pub fn sigmoid(z: f64) -> f64 {
    kernels::sigmoid_scalar(z)
}

/// How the weights are drawn at construction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WeightInit {
    /// Uniform in `[low, high]`, biases included. The paper (§3.5) uses `[0, 1]`.
    Uniform {
        /// Lower bound.
        low: f64,
        /// Upper bound.
        high: f64,
    },
    /// Uniform in `±1/√(fan_in + 1)` per layer, biases included (a common default that keeps the
    /// sigmoids in their linear region for unit-variance inputs).
    FanIn,
}

/// A fully connected p → q (sigmoid) → r (linear) network with flattened weights.
#[derive(Clone)]
pub struct Mlp {
    n_in: usize,
    n_hidden: usize,
    n_out: usize,
    weights: Vec<f64>,
    /// The weights in the single-example kernels' layouts, built on first use; reset by
    /// [`Mlp::weights_mut`].
    packed: OnceLock<kernels::Packed>,
}

impl std::fmt::Debug for Mlp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mlp")
            .field("n_in", &self.n_in)
            .field("n_hidden", &self.n_hidden)
            .field("n_out", &self.n_out)
            .field("weights", &self.weights)
            .finish()
    }
}

/// Networks are equal when their shapes and weights are (the packed copy is derived).
impl PartialEq for Mlp {
    fn eq(&self, other: &Self) -> bool {
        self.n_in == other.n_in
            && self.n_hidden == other.n_hidden
            && self.n_out == other.n_out
            && self.weights == other.weights
    }
}

/// Scratch for one example: hidden activations and the hidden cotangent.
#[derive(Debug, Clone)]
pub struct MlpScratch {
    /// Hidden activations h of the last forward pass.
    pub hidden: Vec<f64>,
    /// Hidden-layer cotangent h̄ of the last backward pass.
    pub hidden_bar: Vec<f64>,
}

impl Mlp {
    /// Number of weights of a p → q → r network: q(p + 1) + r(q + 1).
    pub fn weight_count(n_in: usize, n_hidden: usize, n_out: usize) -> usize {
        n_hidden * (n_in + 1) + n_out * (n_hidden + 1)
    }

    /// A network with weights drawn from `rng` according to `init` (deterministic per seed).
    pub fn new(
        n_in: usize,
        n_hidden: usize,
        n_out: usize,
        init: WeightInit,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let mut weights = vec![0.0; Self::weight_count(n_in, n_hidden, n_out)];
        let first = n_hidden * (n_in + 1);
        for (k, w) in weights.iter_mut().enumerate() {
            let (low, high) = match init {
                WeightInit::Uniform { low, high } => (low, high),
                WeightInit::FanIn => {
                    let fan = if k < first { n_in } else { n_hidden };
                    let a = 1.0 / ((fan + 1) as f64).sqrt();
                    (-a, a)
                }
            };
            *w = low + (high - low) * rng.random::<f64>();
        }
        Self {
            n_in,
            n_hidden,
            n_out,
            weights,
            packed: OnceLock::new(),
        }
    }

    /// A network with the given flattened weights. Panics when the length is wrong.
    pub fn from_weights(n_in: usize, n_hidden: usize, n_out: usize, weights: Vec<f64>) -> Self {
        assert_eq!(
            weights.len(),
            Self::weight_count(n_in, n_hidden, n_out),
            "weight vector length does not match a {n_in}-{n_hidden}-{n_out} network"
        );
        Self {
            n_in,
            n_hidden,
            n_out,
            weights,
            packed: OnceLock::new(),
        }
    }

    /// Number of inputs p.
    pub fn n_in(&self) -> usize {
        self.n_in
    }
    /// Number of hidden units q.
    pub fn n_hidden(&self) -> usize {
        self.n_hidden
    }
    /// Number of outputs r.
    pub fn n_out(&self) -> usize {
        self.n_out
    }
    /// The flattened weights, layout `[W₁ (q×p), b₁ (q), W₂ (r×q), b₂ (r)]`.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The flattened weights, mutably (the length is fixed by the network shape). Drops the
    /// packed copy of the single-example kernels (rebuilt on the next single-example pass).
    pub fn weights_mut(&mut self) -> &mut [f64] {
        self.packed = OnceLock::new();
        &mut self.weights
    }

    /// The packed weights of the single-example kernels (built on first use).
    fn packed(&self) -> &kernels::Packed {
        self.packed.get_or_init(|| {
            let (w1, b1, w2, b2) = self.split(&self.weights);
            kernels::Packed::new(self.n_in, self.n_hidden, self.n_out, w1, b1, w2, b2)
        })
    }

    /// Number of weights.
    pub fn n_weights(&self) -> usize {
        self.weights.len()
    }

    /// Scratch sized for this network.
    pub fn scratch(&self) -> MlpScratch {
        MlpScratch {
            hidden: vec![0.0; self.n_hidden],
            hidden_bar: vec![0.0; self.n_hidden],
        }
    }

    /// Splits a flat weight (or gradient) slice into `(W₁, b₁, W₂, b₂)`.
    fn split<'a>(&self, w: &'a [f64]) -> (&'a [f64], &'a [f64], &'a [f64], &'a [f64]) {
        let (p, q) = (self.n_in, self.n_hidden);
        let (w1, rest) = w.split_at(q * p);
        let (b1, rest) = rest.split_at(q);
        let (w2, b2) = rest.split_at(self.n_out * q);
        (w1, b1, w2, b2)
    }

    fn split_mut<'a>(
        &self,
        w: &'a mut [f64],
    ) -> (&'a mut [f64], &'a mut [f64], &'a mut [f64], &'a mut [f64]) {
        let (p, q) = (self.n_in, self.n_hidden);
        let (w1, rest) = w.split_at_mut(q * p);
        let (b1, rest) = rest.split_at_mut(q);
        let (w2, b2) = rest.split_at_mut(self.n_out * q);
        (w1, b1, w2, b2)
    }

    /// Forward pass for one example (Appendix C): `y = N(x, w)`. Hidden activations are left in
    /// `scratch.hidden` for a following backward pass. Does not allocate.
    pub fn forward(&self, x: &[f64], scratch: &mut MlpScratch, y: &mut [f64]) {
        self.forward_into(x, &mut scratch.hidden, y);
    }

    /// [`Mlp::forward`] writing the hidden activations to `hidden` (length q), e.g. a tape
    /// for a later [`Mlp::backward_from`]. Does not allocate.
    pub fn forward_into(&self, x: &[f64], hidden: &mut [f64], y: &mut [f64]) {
        debug_assert_eq!(x.len(), self.n_in);
        debug_assert_eq!(y.len(), self.n_out);
        kernels::forward(self.packed(), x, hidden, y);
    }

    /// Backward pass for one example after [`Mlp::forward`] on the same `x` and `scratch`: adds
    /// ∂E/∂w to `grad_w` (when given) and writes the input cotangent x̄ = (∂y/∂x)ᵀ ȳ into
    /// `x_bar` (when given). Does not allocate.
    pub fn backward(
        &self,
        x: &[f64],
        scratch: &mut MlpScratch,
        y_bar: &[f64],
        grad_w: Option<&mut [f64]>,
        x_bar: Option<&mut [f64]>,
    ) {
        let MlpScratch { hidden, hidden_bar } = scratch;
        self.backward_from(x, hidden, hidden_bar, y_bar, grad_w, x_bar);
    }

    /// [`Mlp::backward`] with the hidden activations `hidden` of the forward pass at `x` given
    /// directly (e.g. from a tape); `hidden_bar` (length q) receives h̄. Does not allocate.
    pub fn backward_from(
        &self,
        x: &[f64],
        hidden: &[f64],
        hidden_bar: &mut [f64],
        y_bar: &[f64],
        grad_w: Option<&mut [f64]>,
        x_bar: Option<&mut [f64]>,
    ) {
        debug_assert_eq!(x.len(), self.n_in);
        debug_assert_eq!(y_bar.len(), self.n_out);
        let pk = self.packed();
        kernels::hidden_bar(pk, hidden, y_bar, hidden_bar);
        if let Some(g) = grad_w {
            let (g1, gb1, g2, gb2) = self.split_mut(g);
            kernels::weight_grad(x, hidden, hidden_bar, y_bar, g1, gb1, g2, gb2);
        }
        if let Some(xb) = x_bar {
            kernels::input_bar(pk, hidden_bar, xb);
        }
    }

    /// [`Mlp::forward_into`] of `examples` examples at once, the same bits as one call per
    /// example: rows of `x` (inputs), `hidden` and `y` (outputs), each stored contiguously row
    /// after row. A tile of examples takes each loaded row of weights for all of them, as a
    /// matrix product does (the k-step rollout loss runs every window of a chunk at once). Does
    /// not allocate.
    pub fn forward_many(&self, examples: usize, x: &[f64], hidden: &mut [f64], y: &mut [f64]) {
        let (p, q, r) = (self.n_in, self.n_hidden, self.n_out);
        assert!(x.len() >= examples * p && hidden.len() >= examples * q);
        assert!(y.len() >= examples * r);
        kernels::forward_many(self.packed(), examples, x, hidden, y);
    }

    /// [`Mlp::backward_from`] without the weight gradient, of `examples` examples at once (the
    /// same bits as one call per example): from rows of `hidden` (the forward passes'
    /// activations) and `y_bar` (output cotangents), writes rows of `hidden_bar` (h̄) and
    /// `x_bar` (input cotangents). Does not allocate.
    pub fn backward_many(
        &self,
        examples: usize,
        (hidden, y_bar): (&[f64], &[f64]),
        hidden_bar: &mut [f64],
        x_bar: &mut [f64],
    ) {
        let (p, q, r) = (self.n_in, self.n_hidden, self.n_out);
        assert!(hidden.len() >= examples * q && hidden_bar.len() >= examples * q);
        assert!(y_bar.len() >= examples * r && x_bar.len() >= examples * p);
        kernels::backward_many(self.packed(), examples, (hidden, y_bar), hidden_bar, x_bar);
    }

    /// Adds the weight gradients of `examples` examples to `grad_w`, in order, as one
    /// [`Mlp::backward_from`] per example would (the same bits): rows of `x` (inputs), `hidden`
    /// (activations), `hidden_bar` (h̄) and `y_bar` (output cotangents), each stored
    /// contiguously row after row. Does not allocate.
    pub fn weight_grad_many(
        &self,
        examples: usize,
        (x, hidden, hidden_bar, y_bar): (&[f64], &[f64], &[f64], &[f64]),
        grad_w: &mut [f64],
    ) {
        let (p, q, r) = (self.n_in, self.n_hidden, self.n_out);
        assert!(x.len() >= examples * p && y_bar.len() >= examples * r);
        assert!(hidden.len() >= examples * q && hidden_bar.len() >= examples * q);
        assert_eq!(grad_w.len(), self.n_weights());
        let (g1, gb1, g2, gb2) = self.split_mut(grad_w);
        kernels::weight_grad_many(examples, x, hidden, hidden_bar, y_bar, g1, gb1, g2, gb2);
    }

    /// Vector–Jacobian product to the inputs, x̄ = (∂N/∂x)ᵀ ȳ at `x` (runs its own forward pass).
    pub fn vjp_input(&self, x: &[f64], y_bar: &[f64], scratch: &mut MlpScratch, x_bar: &mut [f64]) {
        self.hidden_only(x, scratch);
        self.backward(x, scratch, y_bar, None, Some(x_bar));
    }

    fn hidden_only(&self, x: &[f64], scratch: &mut MlpScratch) {
        kernels::hidden(self.packed(), x, &mut scratch.hidden);
    }

    /// Full input Jacobian ∂N/∂x at `x`, row-major r × p into `jac`.
    pub fn input_jacobian(&self, x: &[f64], scratch: &mut MlpScratch, jac: &mut [f64]) {
        let (p, q) = (self.n_in, self.n_hidden);
        let (w1, _, w2, _) = self.split(&self.weights);
        self.hidden_only(x, scratch);
        jac.fill(0.0);
        for j in 0..q {
            let h = scratch.hidden[j];
            let d = h * (1.0 - h);
            for i in 0..self.n_out {
                let c = w2[i * q + j] * d;
                for (o, w) in jac[i * p..(i + 1) * p]
                    .iter_mut()
                    .zip(&w1[j * p..(j + 1) * p])
                {
                    *o += c * w;
                }
            }
        }
    }

    /// Batch forward pass: row τ of `outputs` (N × r) is N(row τ of `inputs` (N × p)).
    pub fn forward_batch(&self, inputs: ArrayView2<'_, f64>, mut outputs: ArrayViewMut2<'_, f64>) {
        assert_eq!(inputs.ncols(), self.n_in);
        assert_eq!(outputs.ncols(), self.n_out);
        assert_eq!(inputs.nrows(), outputs.nrows());
        let parts: Vec<Array2<f64>> = (0..chunk_count(inputs.nrows()))
            .into_par_iter()
            .map(|c| {
                let x = inputs.slice(chunk(c, inputs.nrows()));
                let h = self.hidden_batch(x);
                let mut y = Array2::zeros((x.nrows(), self.n_out));
                self.output_batch(h.view(), y.view_mut());
                y
            })
            .collect();
        for (c, y) in parts.into_iter().enumerate() {
            let n = outputs.nrows();
            outputs.slice_mut(chunk(c, n)).assign(&y);
        }
    }

    fn views(
        &self,
    ) -> (
        ArrayView2<'_, f64>,
        ArrayView1<'_, f64>,
        ArrayView2<'_, f64>,
        ArrayView1<'_, f64>,
    ) {
        let (p, q, r) = (self.n_in, self.n_hidden, self.n_out);
        let (w1, b1, w2, b2) = self.split(&self.weights);
        (
            ArrayView2::from_shape((q, p), w1).expect("shape"),
            ArrayView1::from(b1),
            ArrayView2::from_shape((r, q), w2).expect("shape"),
            ArrayView1::from(b2),
        )
    }

    fn hidden_batch(&self, x: ArrayView2<'_, f64>) -> Array2<f64> {
        let (w1, b1, _, _) = self.views();
        let mut h = Array2::zeros((x.nrows(), self.n_hidden));
        h.rows_mut().into_iter().for_each(|mut row| row.assign(&b1));
        kernels::general_product(x, w1.t(), h.view_mut(), true);
        kernels::sigmoid_slice(h.as_slice_mut().expect("a new array is contiguous"));
        h
    }

    fn output_batch(&self, h: ArrayView2<'_, f64>, mut y: ArrayViewMut2<'_, f64>) {
        let (_, _, w2, b2) = self.views();
        y.rows_mut().into_iter().for_each(|mut row| row.assign(&b2));
        kernels::general_product(h, w2.t(), y, true);
    }

    /// Sum of squared errors ½ Σ_τ ‖N(x^τ) − y^τ‖² over a batch and its gradient with respect
    /// to the weights (written to `grad`, overwriting it). Rows are processed in chunks of
    /// [`BATCH_CHUNK`] in parallel and summed in chunk order, so the result is bit-identical for
    /// any rayon thread count.
    pub fn loss_grad(
        &self,
        inputs: ArrayView2<'_, f64>,
        targets: ArrayView2<'_, f64>,
        grad: &mut [f64],
    ) -> f64 {
        assert_eq!(inputs.ncols(), self.n_in);
        assert_eq!(targets.ncols(), self.n_out);
        assert_eq!(inputs.nrows(), targets.nrows());
        assert_eq!(grad.len(), self.n_weights());
        let n = inputs.nrows();
        let nw = self.n_weights();
        let chunks = chunk_count(n);
        let packed = self.batch_packed();
        if let (1, Some(pk)) = (chunks, &packed) {
            // One chunk (e.g. a mini-batch): its gradient is the total, written in place (the
            // kernel adds each value to zero, as the sum over chunks below does).
            let (grads, ahead) = (self.split_mut(grad), kernels::Ahead::none());
            let loss = kernels::chunk_loss_grad(pk, inputs, targets, grads, ahead);
            if let Some(pk) = packed {
                pk.recycle();
            }
            return loss;
        }
        // Chunk gradients of one window at a time, summed in chunk order: the same sums as
        // over all chunks at once, without holding a gradient per chunk of a large batch.
        let width = GRAD_WINDOW.min(chunks);
        let mut parts = vec![0.0; width * nw];
        let mut losses = vec![0.0; width];
        grad.fill(0.0);
        let mut loss = 0.0;
        for w0 in (0..chunks).step_by(GRAD_WINDOW) {
            let count = GRAD_WINDOW.min(chunks - w0);
            let run = |(i, (g, l)): (usize, (&mut [f64], &mut f64))| {
                let c = w0 + i;
                let (x, t) = (inputs.slice(chunk(c, n)), targets.slice(chunk(c, n)));
                *l = match &packed {
                    Some(pk) => {
                        let ahead = next_chunk(c, (inputs, targets));
                        kernels::chunk_loss_grad(pk, x, t, self.split_mut(g), ahead)
                    }
                    None => self.chunk_loss_grad_gemm(x, t, g),
                };
            };
            if count == 1 {
                // One chunk (e.g. a mini-batch): no hand-off to the thread pool.
                run((0, (&mut parts[..nw], &mut losses[0])));
            } else {
                parts[..count * nw]
                    .par_chunks_mut(nw)
                    .zip(losses[..count].par_iter_mut())
                    .enumerate()
                    .for_each(run);
            }
            for (l, g) in losses[..count].iter().zip(parts.chunks(nw)) {
                loss += l;
                for (a, b) in grad.iter_mut().zip(g) {
                    *a += b;
                }
            }
        }
        if let Some(pk) = packed {
            pk.recycle();
        }
        loss
    }

    /// Sum of squared errors ½ Σ_τ ‖N(x^τ) − y^τ‖² over a batch (no gradient); deterministic
    /// like [`Mlp::loss_grad`].
    pub fn loss(&self, inputs: ArrayView2<'_, f64>, targets: ArrayView2<'_, f64>) -> f64 {
        assert_eq!(inputs.nrows(), targets.nrows());
        let n = inputs.nrows();
        let packed = self.batch_packed();
        let parts: Vec<f64> = (0..chunk_count(n))
            .into_par_iter()
            .map(|c| {
                let (x, t) = (inputs.slice(chunk(c, n)), targets.slice(chunk(c, n)));
                if let Some(pk) = &packed {
                    return kernels::chunk_loss(pk, x, t, next_chunk(c, (inputs, targets)));
                }
                let h = self.hidden_batch(x);
                let mut y = Array2::zeros((x.nrows(), self.n_out));
                self.output_batch(h.view(), y.view_mut());
                y -= &t;
                0.5 * y.iter().map(|e| e * e).sum::<f64>()
            })
            .collect();
        if let Some(pk) = packed {
            pk.recycle();
        }
        parts.iter().sum()
    }

    /// The weights packed for the batch kernels ([`kernels::chunk_loss_grad`]), or `None` for
    /// the shapes they do not take (a layer of one unit, or more than
    /// [`kernels::MAX_DEPTH`] inputs, hidden units or outputs), which go through ndarray's
    /// products ([`Mlp::chunk_loss_grad_gemm`]), the same bits either way. Packed in this
    /// thread's last packing's buffer where it fits ([`kernels::BatchNet::reused`]); give it back
    /// with [`kernels::BatchNet::recycle`].
    fn batch_packed(&self) -> Option<kernels::BatchNet> {
        let (p, q, r) = (self.n_in, self.n_hidden, self.n_out);
        (q >= 2 && r >= 2 && p.max(q).max(r) <= kernels::MAX_DEPTH)
            .then(|| kernels::BatchNet::reused((p, q, r), self.split(&self.weights)))
    }

    /// Loss of one chunk by ndarray's products; its gradient overwrites `grad` (every value is
    /// written).
    fn chunk_loss_grad_gemm(
        &self,
        x: ArrayView2<'_, f64>,
        t: ArrayView2<'_, f64>,
        grad: &mut [f64],
    ) -> f64 {
        let (q, r) = (self.n_hidden, self.n_out);
        let (_, _, w2, _) = self.views();
        let h = self.hidden_batch(x);
        let mut e = Array2::zeros((x.nrows(), r));
        self.output_batch(h.view(), e.view_mut());
        e -= &t;
        let loss = 0.5 * e.iter().map(|v| v * v).sum::<f64>();
        // Hidden cotangent: (E W₂) ⊙ h ⊙ (1 − h).
        let mut hb = Array2::zeros((x.nrows(), q));
        kernels::general_product(e.view(), w2, hb.view_mut(), false);
        hb.zip_mut_with(&h, |a, &h| *a *= h * (1.0 - h));
        {
            // Not `add`: the products overwrite g1 and g2 without reading them.
            let (g1, gb1, g2, gb2) = self.split_mut(grad);
            let g1 = ArrayViewMut2::from_shape((q, self.n_in), g1).expect("shape");
            kernels::general_product(hb.t(), x, g1, false);
            let g2 = ArrayViewMut2::from_shape((r, q), g2).expect("shape");
            kernels::general_product(e.t(), h.view(), g2, false);
            for (g, s) in gb1.iter_mut().zip(hb.sum_axis(Axis(0))) {
                *g = s;
            }
            for (g, s) in gb2.iter_mut().zip(e.sum_axis(Axis(0))) {
                *g = s;
            }
        }
        loss
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn net() -> Mlp {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        Mlp::new(
            4,
            6,
            3,
            WeightInit::Uniform {
                low: -1.0,
                high: 1.0,
            },
            &mut rng,
        )
    }

    fn random_batch(n: usize, p: usize, r: usize, seed: u64) -> (Array2<f64>, Array2<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x = Array2::from_shape_fn((n, p), |_| rng.random_range(-2.0..2.0));
        let t = Array2::from_shape_fn((n, r), |_| rng.random_range(-1.0..1.0));
        (x, t)
    }

    /// The loss and gradient of a batch as the code before the batch kernels computed them:
    /// ndarray's products per chunk, chunk gradients added to zero in order.
    fn gemm_loss_grad(
        mlp: &Mlp,
        x: ArrayView2<'_, f64>,
        t: ArrayView2<'_, f64>,
    ) -> (f64, Vec<f64>) {
        let n = x.nrows();
        let mut grad = vec![0.0; mlp.n_weights()];
        let mut part = vec![0.0; mlp.n_weights()];
        let mut loss = 0.0;
        for c in 0..chunk_count(n) {
            loss += mlp.chunk_loss_grad_gemm(x.slice(chunk(c, n)), t.slice(chunk(c, n)), &mut part);
            for (a, b) in grad.iter_mut().zip(&part) {
                *a += b;
            }
        }
        (loss, grad)
    }

    /// `Mlp::loss` as ndarray's products computed it.
    fn gemm_loss(mlp: &Mlp, x: ArrayView2<'_, f64>, t: ArrayView2<'_, f64>) -> f64 {
        let n = x.nrows();
        (0..chunk_count(n))
            .map(|c| {
                let (x, t) = (x.slice(chunk(c, n)), t.slice(chunk(c, n)));
                let h = mlp.hidden_batch(x);
                let mut y = Array2::zeros((x.nrows(), mlp.n_out));
                mlp.output_batch(h.view(), y.view_mut());
                y -= &t;
                0.5 * y.iter().map(|e| e * e).sum::<f64>()
            })
            .sum()
    }

    /// The batch kernels against ndarray's products (whose `matrixmultiply` sums each entry in
    /// the same order), bit for bit: the nets of the experiments and small ones, no example
    /// (a chunk of none, on 4 lanes: the loss +0 and a zero gradient), one example,
    /// mini-batches, one chunk, several chunks and a partial last one, inputs that are not
    /// contiguous rows, on the dispatched lanes (AVX-512 here where the processor has it) and
    /// on 4 lanes.
    #[test]
    fn batch_kernels_are_ndarray_products_bit_for_bit() {
        // The reference's products are `kernels::general_product`, the same order on every
        // processor (`general_product_is_matrixmultiply_with_fma_bit_for_bit` ties it to
        // ndarray's where `matrixmultiply` takes its FMA kernel).
        let fused = true;
        let shapes = [
            (17, 50, 13),
            (84, 50, 78),
            (70, 40, 24),
            (6, 20, 6),
            (4, 6, 3),
            (3, 2, 2),
        ];
        for (s, &(p, q, r)) in shapes.iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(40 + s as u64);
            let mlp = Mlp::new(p, q, r, WeightInit::FanIn, &mut rng);
            for (b, &n) in [0, 1, 2, 30, 128, 300].iter().enumerate() {
                let (x, t) = random_batch(n, p, r, 100 * s as u64 + b as u64);
                // The same inputs as a transposed array's view: rows that are not contiguous.
                let xt = x.t().to_owned();
                for x in [x.view(), xt.t()] {
                    let (want_loss, want) = gemm_loss_grad(&mlp, x, t.view());
                    let mut got = vec![f64::NAN; mlp.n_weights()];
                    let got_loss = mlp.loss_grad(x, t.view(), &mut got);
                    let what = format!("{p}-{q}-{r}, {n} rows");
                    if fused {
                        assert_eq!(got_loss.to_bits(), want_loss.to_bits(), "loss, {what}");
                        let (g, w): (Vec<u64>, Vec<u64>) = got
                            .iter()
                            .zip(&want)
                            .map(|(g, w)| (g.to_bits(), w.to_bits()))
                            .unzip();
                        assert_eq!(g, w, "gradient, {what}");
                        let l = mlp.loss(x, t.view());
                        assert_eq!(
                            l.to_bits(),
                            gemm_loss(&mlp, x, t.view()).to_bits(),
                            "{what}"
                        );
                    } else {
                        assert!((got_loss - want_loss).abs() <= 1e-12 * want_loss.abs().max(1.0));
                    }
                }
                if fused && n <= BATCH_CHUNK {
                    // Four lanes (AVX2 or portable) where the dispatch took AVX-512's eight.
                    let (w1, b1, w2, b2) = mlp.split(&mlp.weights);
                    let pk = kernels::BatchNet::with_lanes((p, q, r), (w1, b1, w2, b2), false);
                    let mut got = vec![f64::NAN; mlp.n_weights()];
                    let l = kernels::chunk_loss_grad(
                        &pk,
                        x.view(),
                        t.view(),
                        mlp.split_mut(&mut got),
                        kernels::Ahead::none(),
                    );
                    let (want_loss, want) = gemm_loss_grad(&mlp, x.view(), t.view());
                    assert_eq!(l.to_bits(), want_loss.to_bits());
                    assert!(got
                        .iter()
                        .zip(&want)
                        .all(|(g, w)| g.to_bits() == w.to_bits()));
                }
            }
        }
    }

    /// A gradient (and a loss) packed in the buffer the thread's previous one gave back, of the
    /// same shape with other weights or after another shape, is the same bits as ndarray's
    /// products; the inputs' lengths leave 5 and 7 values after whole groups of 8 lanes (and 1
    /// and 3 after groups of 4), so every copy of a row's tail is taken.
    #[test]
    fn reused_packing_gives_the_same_bits() {
        let mut rng = ChaCha8Rng::seed_from_u64(77);
        let nets: Vec<Mlp> = [(13, 9, 5), (13, 9, 5), (15, 9, 5), (13, 9, 5)]
            .iter()
            .map(|&(p, q, r)| Mlp::new(p, q, r, WeightInit::FanIn, &mut rng))
            .collect();
        for round in 0..2u64 {
            for (i, mlp) in nets.iter().enumerate() {
                let (x, t) = random_batch(30, mlp.n_in, mlp.n_out, 10 * round + i as u64);
                let (want_loss, want) = gemm_loss_grad(mlp, x.view(), t.view());
                let mut got = vec![f64::NAN; mlp.n_weights()];
                let loss = mlp.loss_grad(x.view(), t.view(), &mut got);
                assert_eq!(loss.to_bits(), want_loss.to_bits(), "net {i}");
                assert!(same_bits(&got, &want), "net {i}");
                let l = mlp.loss(x.view(), t.view());
                assert_eq!(l.to_bits(), gemm_loss(mlp, x.view(), t.view()).to_bits());
            }
        }
    }

    #[test]
    fn init_is_deterministic_per_seed() {
        let a = net();
        let b = net();
        assert_eq!(a, b);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let c = Mlp::new(4, 6, 3, WeightInit::FanIn, &mut rng);
        assert_ne!(a.weights(), c.weights());
        assert_eq!(a.n_weights(), 6 * 5 + 3 * 7);
    }

    #[test]
    fn single_and_batch_forward_agree() {
        let m = net();
        let (x, _) = random_batch(300, 4, 3, 1);
        let mut out = Array2::zeros((300, 3));
        m.forward_batch(x.view(), out.view_mut());
        let mut s = m.scratch();
        let mut y = [0.0; 3];
        for (row, o) in x.rows().into_iter().zip(out.rows()) {
            m.forward(row.as_slice().unwrap(), &mut s, &mut y);
            for k in 0..3 {
                assert!((y[k] - o[k]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn weight_gradient_matches_finite_differences() {
        let m = net();
        let (x, t) = random_batch(200, 4, 3, 2);
        let mut g = vec![0.0; m.n_weights()];
        m.loss_grad(x.view(), t.view(), &mut g);
        // Per-example backward agrees with the batch gradient.
        let mut g_single = vec![0.0; m.n_weights()];
        let mut s = m.scratch();
        let mut y = [0.0; 3];
        for (xr, tr) in x.rows().into_iter().zip(t.rows()) {
            let xs = xr.as_slice().unwrap();
            m.forward(xs, &mut s, &mut y);
            let yb: Vec<f64> = y.iter().zip(tr).map(|(a, b)| a - b).collect();
            m.backward(xs, &mut s, &yb, Some(&mut g_single), None);
        }
        let h = 1e-6;
        for k in 0..m.n_weights() {
            let mut mp = m.clone();
            mp.weights_mut()[k] += h;
            let mut mm = m.clone();
            mm.weights_mut()[k] -= h;
            let fd = (mp.loss(x.view(), t.view()) - mm.loss(x.view(), t.view())) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "w{k}: {fd} vs {}",
                g[k]
            );
            assert!((g_single[k] - g[k]).abs() < 1e-9 * (1.0 + g[k].abs()));
        }
    }

    #[test]
    fn input_vjp_and_jacobian_match_finite_differences() {
        let m = net();
        let x = [0.3, -1.2, 0.7, 2.0];
        let yb = [0.5, -1.0, 2.0];
        let mut s = m.scratch();
        let mut xb = [0.0; 4];
        m.vjp_input(&x, &yb, &mut s, &mut xb);
        let mut jac = [0.0; 12];
        m.input_jacobian(&x, &mut s, &mut jac);
        let h = 1e-6;
        let mut yp = [0.0; 3];
        let mut ym = [0.0; 3];
        for k in 0..4 {
            let mut xp = x;
            xp[k] += h;
            let mut xm = x;
            xm[k] -= h;
            m.forward(&xp, &mut s, &mut yp);
            m.forward(&xm, &mut s, &mut ym);
            let mut vjp_fd = 0.0;
            for i in 0..3 {
                let d = (yp[i] - ym[i]) / (2.0 * h);
                assert!((d - jac[i * 4 + k]).abs() < 1e-8, "J[{i},{k}]");
                vjp_fd += yb[i] * d;
            }
            assert!((vjp_fd - xb[k]).abs() < 1e-8);
        }
    }

    /// The single-example passes written out one output at a time (row-major weights): each
    /// output one fused multiply–add per input from its bias (two chains, even and odd inputs,
    /// where the kernels use two), the oracle the packed kernels must match bit for bit.
    mod oracle {
        use super::super::kernels::output_has_dual_chains;
        use super::super::sigmoid;

        /// init + Σ_k w(k) x[k] as the kernels sum output `j` of a product with `outputs`
        /// outputs.
        fn sum(init: f64, x: &[f64], w: impl Fn(usize) -> f64, outputs: usize, j: usize) -> f64 {
            let stride = outputs.div_ceil(4) * 4;
            if output_has_dual_chains(stride, j) {
                let (mut even, mut odd) = (init, 0.0);
                for (k, xk) in x.iter().enumerate() {
                    if k % 2 == 0 {
                        even = w(k).mul_add(*xk, even);
                    } else {
                        odd = w(k).mul_add(*xk, odd);
                    }
                }
                even + odd
            } else {
                x.iter()
                    .enumerate()
                    .fold(init, |acc, (k, xk)| w(k).mul_add(*xk, acc))
            }
        }

        pub fn forward(m: &super::Mlp, x: &[f64], hidden: &mut [f64], y: &mut [f64]) {
            let (p, q, r) = (m.n_in(), m.n_hidden(), m.n_out());
            let (w1, b1, w2, b2) = m.split(m.weights());
            for (j, h) in hidden.iter_mut().enumerate() {
                *h = sigmoid(sum(b1[j], x, |k| w1[j * p + k], q, j));
            }
            for (i, yi) in y.iter_mut().enumerate() {
                *yi = sum(b2[i], hidden, |j| w2[i * q + j], r, i);
            }
        }

        pub fn backward(
            m: &super::Mlp,
            x: &[f64],
            hidden: &[f64],
            y_bar: &[f64],
            grad_w: &mut [f64],
            xb: &mut [f64],
        ) {
            let (p, q) = (m.n_in(), m.n_hidden());
            let (w1, _, w2, _) = m.split(m.weights());
            let mut hidden_bar = vec![0.0; q];
            for j in 0..q {
                let s = sum(0.0, y_bar, |i| w2[i * q + j], q, j);
                let h = hidden[j];
                hidden_bar[j] = s * h * (1.0 - h);
            }
            let (g1, gb1, g2, gb2) = m.split_mut(grad_w);
            for (i, yb) in y_bar.iter().enumerate() {
                gb2[i] += yb;
                for (g, h) in g2[i * q..(i + 1) * q].iter_mut().zip(hidden) {
                    *g = yb.mul_add(*h, *g);
                }
            }
            for j in 0..q {
                let hb = hidden_bar[j];
                gb1[j] += hb;
                for (g, xi) in g1[j * p..(j + 1) * p].iter_mut().zip(x) {
                    *g = hb.mul_add(*xi, *g);
                }
            }
            for (k, o) in xb.iter_mut().enumerate() {
                *o = sum(0.0, &hidden_bar, |j| w1[j * p + k], p, k);
            }
        }
    }

    /// The batch gradient as first written: every chunk's gradient in its own vector, all
    /// collected, then summed in chunk order.
    fn oracle_loss_grad(
        m: &Mlp,
        inputs: ArrayView2<'_, f64>,
        targets: ArrayView2<'_, f64>,
        grad: &mut [f64],
    ) -> f64 {
        let chunk_grad = |x: ArrayView2<'_, f64>, t: ArrayView2<'_, f64>| {
            let (q, r) = (m.n_hidden, m.n_out);
            let (_, _, w2, _) = m.views();
            let h = m.hidden_batch(x);
            let mut e = Array2::zeros((x.nrows(), r));
            m.output_batch(h.view(), e.view_mut());
            e -= &t;
            let loss = 0.5 * e.iter().map(|v| v * v).sum::<f64>();
            let mut hb = Array2::zeros((x.nrows(), q));
            kernels::general_product(e.view(), w2, hb.view_mut(), false);
            hb.zip_mut_with(&h, |a, &h| *a *= h * (1.0 - h));
            let mut grad = vec![0.0; m.n_weights()];
            {
                let (g1, gb1, g2, gb2) = m.split_mut(&mut grad);
                let g1 = ArrayViewMut2::from_shape((q, m.n_in), g1).expect("shape");
                kernels::general_product(hb.t(), x, g1, false);
                let g2 = ArrayViewMut2::from_shape((r, q), g2).expect("shape");
                kernels::general_product(e.t(), h.view(), g2, false);
                for (g, s) in gb1.iter_mut().zip(hb.sum_axis(Axis(0))) {
                    *g = s;
                }
                for (g, s) in gb2.iter_mut().zip(e.sum_axis(Axis(0))) {
                    *g = s;
                }
            }
            (loss, grad)
        };
        let n = inputs.nrows();
        let parts: Vec<(f64, Vec<f64>)> = (0..chunk_count(n))
            .map(|c| chunk_grad(inputs.slice(chunk(c, n)), targets.slice(chunk(c, n))))
            .collect();
        grad.fill(0.0);
        let mut loss = 0.0;
        for (l, g) in parts {
            loss += l;
            for (a, b) in grad.iter_mut().zip(&g) {
                *a += b;
            }
        }
        loss
    }

    #[test]
    fn windowed_batch_gradient_is_bit_identical_to_collecting_every_chunk() {
        for (s, &(p, q, r, rows)) in [(4, 6, 3, 5000), (17, 50, 13, 2100), (8, 7, 6, 30)]
            .iter()
            .enumerate()
        {
            let mut rng = ChaCha8Rng::seed_from_u64(200 + s as u64);
            let m = Mlp::new(p, q, r, WeightInit::FanIn, &mut rng);
            let (x, t) = random_batch(rows, p, r, 300 + s as u64);
            let mut g0 = vec![0.0; m.n_weights()];
            let mut g1 = vec![f64::NAN; m.n_weights()];
            let l0 = oracle_loss_grad(&m, x.view(), t.view(), &mut g0);
            let l1 = m.loss_grad(x.view(), t.view(), &mut g1);
            assert_eq!(l0.to_bits(), l1.to_bits(), "{p}-{q}-{r} loss");
            assert!(same_bits(&g0, &g1), "{p}-{q}-{r} gradient");
            // Again with the buffers of the first call's last chunks dirty.
            let l2 = m.loss_grad(x.view(), t.view(), &mut g1);
            assert_eq!(l0.to_bits(), l2.to_bits());
            assert!(same_bits(&g0, &g1));
        }
    }

    /// Every dispatched kernel of the perceptron, run under each level this processor has
    /// (`crate::simd::with_level`: portable lanes with libm's `fma`, AVX2 + FMA, AVX-512),
    /// gives the bits of the portable path: single-example passes and their batched forms,
    /// the weight gradients, σ, the batch loss and gradient of one chunk (register-tiled
    /// kernels, and the general products for a net with one hidden unit and one with more
    /// than 256 inputs), the general product itself and the momentum step. Each level packs
    /// its own copy of the weights (8-lane padding under AVX-512).
    #[test]
    fn every_dispatched_kernel_gives_the_portable_bits_at_every_level() {
        use crate::simd::{available, with_level, Level};
        let shapes = [
            (17, 50, 13),
            (84, 50, 78),
            (70, 40, 24),
            (6, 20, 6),
            (3, 5, 2),
            (5, 1, 3),
            (300, 6, 4),
        ];
        let run = |level: Level| -> Vec<u64> {
            with_level(level, || {
                let mut out = Vec::new();
                let mut put = |v: &[f64]| out.extend(v.iter().map(|x| x.to_bits()));
                for (s, &(p, q, r)) in shapes.iter().enumerate() {
                    let mut rng = ChaCha8Rng::seed_from_u64(600 + s as u64);
                    let weights = Mlp::new(p, q, r, WeightInit::FanIn, &mut rng).weights;
                    // A fresh net: its packing is made under this level.
                    let m = Mlp::from_weights(p, q, r, weights);
                    let (x, t) = random_batch(100, p, r, 700 + s as u64);
                    let xs = x.as_slice().unwrap();
                    let mut sc = m.scratch();
                    let (mut y, mut xb) = (vec![0.0; r], vec![0.0; p]);
                    let mut g = vec![0.0; m.n_weights()];
                    for e in 0..5 {
                        let xe = &xs[e * p..(e + 1) * p];
                        m.forward(xe, &mut sc, &mut y);
                        put(&y);
                        put(&sc.hidden);
                        m.backward(
                            xe,
                            &mut sc,
                            &t.as_slice().unwrap()[..r],
                            Some(&mut g),
                            Some(&mut xb),
                        );
                        put(&xb);
                        put(&g);
                    }
                    let n = 7;
                    let (mut h, mut ym) = (vec![0.0; n * q], vec![0.0; n * r]);
                    m.forward_many(n, &xs[..n * p], &mut h, &mut ym);
                    let (mut hb, mut xbm) = (vec![0.0; n * q], vec![0.0; n * p]);
                    m.backward_many(n, (&h, &ym), &mut hb, &mut xbm);
                    m.weight_grad_many(n, (&xs[..n * p], &h, &hb, &ym), &mut g);
                    put(&ym);
                    put(&xbm);
                    put(&g);
                    // One chunk: computed on this thread.
                    let loss = m.loss_grad(x.view(), t.view(), &mut g);
                    put(&[loss]);
                    put(&g);
                    let mut z: Vec<f64> = (0..37).map(|i| (i as f64 - 18.0) * 3.1).collect();
                    kernels::sigmoid_slice(&mut z);
                    put(&z);
                    let mut c = Array2::from_elem((100, r), 0.5);
                    kernels::general_product(
                        x.view(),
                        x.t().slice(s![.., ..r]),
                        c.view_mut(),
                        true,
                    );
                    put(c.as_slice().unwrap());
                    let mut w = m.weights.clone();
                    let mut mom = crate::emulator::train::MomentumState::new(w.len());
                    mom.step(&mut w, &g, 0.05, 0.9);
                    mom.step(&mut w, &g, 0.05, 0.9);
                    put(&w);
                }
                out
            })
        };
        let portable = run(Level::Scalar);
        for level in available() {
            assert!(
                run(level) == portable,
                "{level:?} against the portable path"
            );
        }
    }

    /// [`kernels::general_product`] is what ndarray's `general_mat_mul` computes where
    /// `matrixmultiply` takes its AVX2 + FMA kernel (this processor's path when the cached nets
    /// were trained), bit for bit: with and without adding to C, A and B transposed or not,
    /// inner dimensions up to and beyond its depth block of 256, widths that are not whole
    /// lane groups, a single row or column. Skipped where the processor lacks AVX2 or FMA
    /// (`matrixmultiply` then multiplies and adds separately).
    #[test]
    fn general_product_is_matrixmultiply_with_fma_bit_for_bit() {
        #[cfg(target_arch = "x86_64")]
        if !(std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("avx2"))
        {
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(61);
        for &(m, k, n) in &[
            (1, 1, 1),
            (5, 3, 1),
            (1, 7, 6),
            (30, 17, 50),
            (128, 50, 13),
            (13, 128, 50),
            (9, 256, 7),
            (11, 257, 6),
            (7, 600, 5),
            (300, 84, 78),
        ] {
            let mut draw =
                |r: usize, c: usize| Array2::from_shape_fn((r, c), |_| rng.random_range(-2.0..2.0));
            let (a, b, at, bt, c0) = (draw(m, k), draw(k, n), draw(k, m), draw(n, k), draw(m, n));
            for add in [false, true] {
                for (a, b) in [
                    (a.view(), b.view()),
                    (at.t(), b.view()),
                    (a.view(), bt.t()),
                    (at.t(), bt.t()),
                ] {
                    let (mut want, mut got) = (c0.clone(), c0.clone());
                    let beta = if add { 1.0 } else { 0.0 };
                    ndarray::linalg::general_mat_mul(1.0, &a, &b, beta, &mut want);
                    kernels::general_product(a, b, got.view_mut(), add);
                    assert!(
                        same_bits(want.as_slice().unwrap(), got.as_slice().unwrap()),
                        "{m} × {k} × {n}, add {add}"
                    );
                }
            }
        }
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    #[test]
    fn single_example_passes_are_bit_identical_to_the_row_major_oracle() {
        let shapes = [
            (1, 1, 1),
            (4, 6, 3),
            (17, 50, 13),
            (8, 7, 6),
            (15, 7, 13),
            (84, 50, 78),
            (70, 40, 24),
            (9, 33, 17),
            // The hidden layer just filling the forward pass's lane buffer (61 units padded to
            // 64), and just beyond it (65 units: the one-value-at-a-time path).
            (12, 61, 6),
            (3, 65, 2),
        ];
        for (s, &(p, q, r)) in shapes.iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(100 + s as u64);
            let init = WeightInit::Uniform {
                low: -2.0,
                high: 2.0,
            };
            let mut m = Mlp::new(p, q, r, init, &mut rng);
            for round in 0..3 {
                if round == 2 {
                    // New weights after the packed copy was built: it must be rebuilt.
                    m.weights_mut().iter_mut().for_each(|w| *w *= -0.7);
                }
                let mut sc = m.scratch();
                for _ in 0..20 {
                    let x: Vec<f64> = (0..p).map(|_| rng.random_range(-3.0..3.0)).collect();
                    let yb: Vec<f64> = (0..r).map(|_| rng.random_range(-2.0..2.0)).collect();
                    let (mut h0, mut y0, mut y1) = (vec![0.0; q], vec![0.0; r], vec![0.0; r]);
                    oracle::forward(&m, &x, &mut h0, &mut y0);
                    m.forward(&x, &mut sc, &mut y1);
                    assert!(same_bits(&y0, &y1), "{p}-{q}-{r} forward");
                    assert!(same_bits(&h0, &sc.hidden), "{p}-{q}-{r} hidden");
                    let g_start: Vec<f64> = (0..m.n_weights())
                        .map(|_| rng.random_range(-1.0..1.0))
                        .collect();
                    let (mut g0, mut g1) = (g_start.clone(), g_start);
                    let (mut xb0, mut xb1) = (vec![0.0; p], vec![7.0; p]);
                    oracle::backward(&m, &x, &h0, &yb, &mut g0, &mut xb0);
                    m.backward(&x, &mut sc, &yb, Some(&mut g1), Some(&mut xb1));
                    assert!(same_bits(&g0, &g1), "{p}-{q}-{r} weight gradient");
                    assert!(same_bits(&xb0, &xb1), "{p}-{q}-{r} input cotangent");
                    let mut xb2 = vec![0.0; p];
                    m.vjp_input(&x, &yb, &mut sc, &mut xb2);
                    assert!(same_bits(&xb0, &xb2), "{p}-{q}-{r} vjp_input");
                }
            }
        }
    }

    /// The many-example passes are one single-example pass per example, bit for bit, on every
    /// tile shape and remainder (1 to 17 examples), for nets on both lane widths (84-50-78 keeps
    /// 4 lanes), outputs summed in one chain and in two, and rows that end inside a lane group:
    /// every net shape the rollout loss fine-tunes (the pendulums, truck, lander and the
    /// dolphin's global net), the dolphin's local nets, and others.
    #[test]
    fn many_example_passes_are_the_single_example_passes_bit_for_bit() {
        let shapes = [
            (1, 1, 1),
            (4, 6, 3),
            (6, 20, 6),
            (9, 20, 6),
            (12, 20, 6),
            (8, 40, 6),
            (17, 50, 13),
            (84, 50, 78),
            (70, 40, 24),
            (52, 40, 30),
            (58, 40, 12),
            (9, 33, 17),
            (3, 65, 2),
        ];
        for (s, &(p, q, r)) in shapes.iter().enumerate() {
            let mut rng = ChaCha8Rng::seed_from_u64(300 + s as u64);
            let init = WeightInit::Uniform {
                low: -2.0,
                high: 2.0,
            };
            let m = Mlp::new(p, q, r, init, &mut rng);
            for examples in (1..=17).chain([40]) {
                let x: Vec<f64> = (0..examples * p)
                    .map(|_| rng.random_range(-3.0..3.0))
                    .collect();
                let yb: Vec<f64> = (0..examples * r)
                    .map(|_| rng.random_range(-2.0..2.0))
                    .collect();
                // One value past the rows, which no pass may write.
                let (mut h, mut y) = (
                    vec![f64::NAN; examples * q + 1],
                    vec![9.0; examples * r + 1],
                );
                m.forward_many(examples, &x, &mut h, &mut y);
                let (mut hb, mut xb) = (
                    vec![5.0; examples * q + 1],
                    vec![f64::NAN; examples * p + 1],
                );
                m.backward_many(examples, (&h, &yb), &mut hb, &mut xb);
                assert!(h[examples * q].is_nan() && y[examples * r] == 9.0);
                assert!(hb[examples * q] == 5.0 && xb[examples * p].is_nan());
                let mut sc = m.scratch();
                for e in 0..examples {
                    let (xe, ybe) = (&x[e * p..(e + 1) * p], &yb[e * r..(e + 1) * r]);
                    let mut y1 = vec![0.0; r];
                    m.forward(xe, &mut sc, &mut y1);
                    let at = format!("{p}-{q}-{r}, example {e} of {examples}");
                    assert!(same_bits(&y1, &y[e * r..(e + 1) * r]), "{at}: output");
                    assert!(
                        same_bits(&sc.hidden, &h[e * q..(e + 1) * q]),
                        "{at}: hidden"
                    );
                    let mut xb1 = vec![0.0; p];
                    m.backward(xe, &mut sc, ybe, None, Some(&mut xb1));
                    assert!(
                        same_bits(&sc.hidden_bar, &hb[e * q..(e + 1) * q]),
                        "{at}: h̄"
                    );
                    assert!(same_bits(&xb1, &xb[e * p..(e + 1) * p]), "{at}: x̄");
                }
            }
        }
    }

    #[test]
    fn batch_is_bit_identical_across_thread_counts() {
        let m = net();
        let (x, t) = random_batch(1000, 4, 3, 3);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut g = vec![0.0; m.n_weights()];
                let l = m.loss_grad(x.view(), t.view(), &mut g);
                let mut out = Array2::zeros((1000, 3));
                m.forward_batch(x.view(), out.view_mut());
                (l, g, out, m.loss(x.view(), t.view()))
            })
        };
        let a = run(1);
        let b = run(2);
        assert_eq!(a.0.to_bits(), b.0.to_bits());
        assert!(a
            .1
            .iter()
            .zip(&b.1)
            .all(|(p, q)| p.to_bits() == q.to_bits()));
        assert_eq!(a.2, b.2);
        assert_eq!(a.3.to_bits(), b.3.to_bits());
    }
}
