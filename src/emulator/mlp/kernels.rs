//! # Single-example kernels of the perceptron, vectorized across outputs
//!
//! Every single-example pass of [`super::Mlp`] is a handful of matrix–vector products. Each
//! output of such a product is one dot product summed *sequentially* over its inputs, and that
//! order is part of the result (floating-point addition does not associate), so the kernels
//! here never split or reorder a sum. They vectorize *across* outputs instead: with the matrix
//! stored so that the weights of all outputs for one input are contiguous, one pass over the
//! inputs k updates W accumulators at once,
//!
//! ```text
//! acc[l] ← acc[l] + a[k, j₀ + l] · x[k]     for l < W, k = 0, 1, …   (W = 32, 16 or 8)
//! ```
//!
//! which is exactly the scalar recurrence of each output, evaluated lane by lane (a separate
//! multiply and add: no fused multiply–add, as before).
//!
//! [`Packed`] holds the four layouts the passes read, each with its row stride padded with
//! zeros to a multiple of 8 so that every block is full width (padded lanes are computed and
//! dropped):
//!
//! ```text
//! w1t  p × q̃   W₁ᵀ: row k holds the weights of input k to every hidden unit  (forward, hidden)
//! w2t  q × r̃   W₂ᵀ: row j holds the weights of hidden unit j to every output (forward, output)
//! w2   r × q̃   W₂ as stored: row i holds output i's weights                  (backward, h̄)
//! w1   q × p̃   W₁ as stored: row j holds hidden unit j's weights              (backward, x̄)
//! ```
//!
//! On x86-64 the entry points run the same generic body compiled for AVX2 when the processor
//! has it (runtime detection; AVX2 only widens the vectors, the operations are the same IEEE
//! multiplies and adds, so results do not depend on the path taken).

use super::sigmoid;

/// A multiple of 8 at least `n`.
fn pad8(n: usize) -> usize {
    n.div_ceil(8) * 8
}

/// The weights of a p → q → r net in the layouts of the single-example kernels (module docs).
#[derive(Debug, Clone)]
pub(super) struct Packed {
    p: usize,
    q: usize,
    r: usize,
    /// Padded strides p̃, q̃, r̃.
    ps: usize,
    qs: usize,
    rs: usize,
    w1t: Vec<f64>,
    w2t: Vec<f64>,
    w2: Vec<f64>,
    w1: Vec<f64>,
}

impl Packed {
    /// Packs W₁ (q × p, row-major) and W₂ (r × q, row-major).
    pub(super) fn new(p: usize, q: usize, r: usize, w1: &[f64], w2: &[f64]) -> Self {
        let (ps, qs, rs) = (pad8(p), pad8(q), pad8(r));
        let mut w1t = vec![0.0; p * qs];
        let mut w1p = vec![0.0; q * ps];
        for j in 0..q {
            for k in 0..p {
                w1t[k * qs + j] = w1[j * p + k];
                w1p[j * ps + k] = w1[j * p + k];
            }
        }
        let mut w2t = vec![0.0; q * rs];
        let mut w2p = vec![0.0; r * qs];
        for i in 0..r {
            for j in 0..q {
                w2t[j * rs + i] = w2[i * q + j];
                w2p[i * qs + j] = w2[i * q + j];
            }
        }
        Self {
            p,
            q,
            r,
            ps,
            qs,
            rs,
            w1t,
            w2t,
            w2: w2p,
            w1: w1p,
        }
    }
}

/// `emit(l, init + Σ_k a[k, l] x[k])` for l < n, each sum taken in order k = 0, 1, …: the
/// columns of `a` (rows of `stride` values, stride a multiple of 8 and at least n) against `x`.
#[inline(always)]
fn columns(
    a: &[f64],
    stride: usize,
    x: &[f64],
    init: f64,
    n: usize,
    mut emit: impl FnMut(usize, f64),
) {
    debug_assert!(stride % 8 == 0 && n <= stride);
    assert!(a.len() >= x.len() * stride, "packed matrix too short");
    let mut j0 = 0;
    while j0 < n {
        let left = stride - j0;
        if left >= 32 {
            block::<32>(a, stride, j0, x, init, n, &mut emit);
            j0 += 32;
        } else if left >= 16 {
            block::<16>(a, stride, j0, x, init, n, &mut emit);
            j0 += 16;
        } else {
            block::<8>(a, stride, j0, x, init, n, &mut emit);
            j0 += 8;
        }
    }
}

/// Columns `j0 .. j0 + W` of [`columns`], accumulated in W independent lanes.
#[inline(always)]
fn block<const W: usize>(
    a: &[f64],
    stride: usize,
    j0: usize,
    x: &[f64],
    init: f64,
    n: usize,
    emit: &mut impl FnMut(usize, f64),
) {
    let mut acc = [init; W];
    for (k, &xk) in x.iter().enumerate() {
        let start = k * stride + j0;
        let row: &[f64; W] = a[start..start + W].try_into().expect("W values");
        for l in 0..W {
            acc[l] += row[l] * xk;
        }
    }
    for (l, &v) in acc.iter().enumerate().take(n - j0) {
        emit(j0 + l, v);
    }
}

/// Runs `$body` compiled for AVX2 when the processor has it, else for the baseline target.
macro_rules! dispatch {
    ($name:ident, $generic:ident, ($($arg:ident : $ty:ty),*)) => {
        #[allow(clippy::too_many_arguments)]
        pub(super) fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                /// The generic body compiled with AVX2 enabled.
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn avx2($($arg: $ty),*) {
                    $generic($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the processor supports AVX2 (checked just above).
                    unsafe { avx2($($arg),*) };
                    return;
                }
            }
            $generic($($arg),*)
        }
    };
}

/// Hidden activations h = σ(W₁ x + b₁).
#[inline(always)]
fn hidden_generic(pk: &Packed, b1: &[f64], x: &[f64], h: &mut [f64]) {
    debug_assert_eq!(x.len(), pk.p);
    columns(&pk.w1t, pk.qs, x, -0.0, pk.q, |j, s| {
        h[j] = sigmoid(b1[j] + s)
    });
}

/// Forward pass: h = σ(W₁ x + b₁), y = W₂ h + b₂.
#[inline(always)]
fn forward_generic(pk: &Packed, b1: &[f64], b2: &[f64], x: &[f64], h: &mut [f64], y: &mut [f64]) {
    hidden_generic(pk, b1, x, h);
    columns(&pk.w2t, pk.rs, h, -0.0, pk.r, |i, s| y[i] = b2[i] + s);
}

/// Hidden cotangent h̄ = (W₂ᵀ ȳ) ⊙ h ⊙ (1 − h).
#[inline(always)]
fn hidden_bar_generic(pk: &Packed, h: &[f64], y_bar: &[f64], hb: &mut [f64]) {
    debug_assert_eq!(y_bar.len(), pk.r);
    columns(&pk.w2, pk.qs, y_bar, 0.0, pk.q, |j, s| {
        let hj = h[j];
        hb[j] = s * hj * (1.0 - hj);
    });
}

/// Input cotangent x̄ = W₁ᵀ h̄.
#[inline(always)]
fn input_bar_generic(pk: &Packed, hb: &[f64], xb: &mut [f64]) {
    columns(&pk.w1, pk.ps, hb, 0.0, pk.p, |k, s| xb[k] = s);
}

/// Weight-gradient accumulation: ∂E/∂W₂ += ȳ hᵀ, ∂E/∂b₂ += ȳ, ∂E/∂W₁ += h̄ xᵀ, ∂E/∂b₁ += h̄.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn weight_grad_generic(
    x: &[f64],
    h: &[f64],
    hb: &[f64],
    y_bar: &[f64],
    g1: &mut [f64],
    gb1: &mut [f64],
    g2: &mut [f64],
    gb2: &mut [f64],
) {
    let (p, q) = (x.len(), h.len());
    for (i, yb) in y_bar.iter().enumerate() {
        gb2[i] += yb;
        for (g, h) in g2[i * q..(i + 1) * q].iter_mut().zip(h) {
            *g += yb * h;
        }
    }
    for (j, &hbj) in hb.iter().enumerate() {
        gb1[j] += hbj;
        for (g, xi) in g1[j * p..(j + 1) * p].iter_mut().zip(x) {
            *g += hbj * xi;
        }
    }
}

dispatch!(hidden, hidden_generic, (pk: &Packed, b1: &[f64], x: &[f64], h: &mut [f64]));
dispatch!(
    forward,
    forward_generic,
    (pk: &Packed, b1: &[f64], b2: &[f64], x: &[f64], h: &mut [f64], y: &mut [f64])
);
dispatch!(
    hidden_bar,
    hidden_bar_generic,
    (pk: &Packed, h: &[f64], y_bar: &[f64], hb: &mut [f64])
);
dispatch!(input_bar, input_bar_generic, (pk: &Packed, hb: &[f64], xb: &mut [f64]));
dispatch!(
    weight_grad,
    weight_grad_generic,
    (
        x: &[f64],
        h: &[f64],
        hb: &[f64],
        y_bar: &[f64],
        g1: &mut [f64],
        gb1: &mut [f64],
        g2: &mut [f64],
        gb2: &mut [f64]
    )
);
