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
//! acc[l] ← acc[l] + a[k, j₀ + l] · x[k]     for l < W, k = 0, 1, …   (W ≤ 32, a multiple of 4)
//! ```
//!
//! which is exactly the scalar recurrence of each output, evaluated lane by lane (a separate
//! multiply and add: no fused multiply–add, as before).
//!
//! [`Packed`] holds the four layouts the passes read, each with its row stride padded with
//! zeros to a multiple of 4 so that every lane group is full (padded lanes are computed and
//! dropped):
//!
//! ```text
//! w1t  p × q̃   W₁ᵀ: row k holds the weights of input k to every hidden unit  (forward, hidden)
//! w2t  q × r̃   W₂ᵀ: row j holds the weights of hidden unit j to every output (forward, output)
//! w2   r × q̃   W₂ as stored: row i holds output i's weights                  (backward, h̄)
//! w1   q × p̃   W₁ as stored: row j holds hidden unit j's weights              (backward, x̄)
//! ```
//!
//! The lanes are groups of 4 ([`Lanes`]): 256-bit AVX2 registers on x86-64 processors that
//! have them (runtime detection), else plain `[f64; 4]` arrays. Both are the same IEEE
//! multiplies and adds lane by lane, so results do not depend on the path taken.

use super::sigmoid;

/// A multiple of 4 (one lane group) at least `n`.
fn pad4(n: usize) -> usize {
    n.div_ceil(4) * 4
}

/// Four f64 lanes and the three operations the kernels need. Implementations must evaluate
/// each lane exactly as the scalar `acc + w * x` (a rounded multiply, then a rounded add).
trait Lanes {
    /// A group of four lanes.
    type V: Copy;
    /// All four lanes set to `x`.
    fn splat(x: f64) -> Self::V;
    /// The first four values of `p`.
    fn load(p: &[f64]) -> Self::V;
    /// `acc + w * x` lane by lane.
    fn mul_add(acc: Self::V, w: Self::V, x: Self::V) -> Self::V;
    /// Writes the lanes to the first four values of `out`.
    fn store(v: Self::V, out: &mut [f64]);
}

/// Lanes as plain arrays (any target; the compiler vectorizes what it can).
struct Portable;

impl Lanes for Portable {
    type V = [f64; 4];
    #[inline(always)]
    fn splat(x: f64) -> [f64; 4] {
        [x; 4]
    }
    #[inline(always)]
    fn load(p: &[f64]) -> [f64; 4] {
        p[..4].try_into().expect("4 values")
    }
    #[inline(always)]
    fn mul_add(acc: [f64; 4], w: [f64; 4], x: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| acc[l] + w[l] * x[l])
    }
    #[inline(always)]
    fn store(v: [f64; 4], out: &mut [f64]) {
        out[..4].copy_from_slice(&v);
    }
}

/// Lanes in AVX2 registers; only used from functions compiled with AVX2 enabled, on
/// processors that have it.
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    type V = std::arch::x86_64::__m256d;
    #[inline(always)]
    fn splat(x: f64) -> Self::V {
        // SAFETY: only reached from `#[target_feature(enable = "avx2")]` code (see `dispatch`).
        unsafe { std::arch::x86_64::_mm256_set1_pd(x) }
    }
    #[inline(always)]
    fn load(p: &[f64]) -> Self::V {
        assert!(p.len() >= 4);
        // SAFETY: four values are in bounds (checked); AVX2 as for `splat`.
        unsafe { std::arch::x86_64::_mm256_loadu_pd(p.as_ptr()) }
    }
    #[inline(always)]
    fn mul_add(acc: Self::V, w: Self::V, x: Self::V) -> Self::V {
        use std::arch::x86_64::{_mm256_add_pd, _mm256_mul_pd};
        // SAFETY: AVX2 as for `splat`. A separate multiply and add, as the scalar code.
        unsafe { _mm256_add_pd(acc, _mm256_mul_pd(w, x)) }
    }
    #[inline(always)]
    fn store(v: Self::V, out: &mut [f64]) {
        assert!(out.len() >= 4);
        // SAFETY: four values are in bounds (checked); AVX2 as for `splat`.
        unsafe { std::arch::x86_64::_mm256_storeu_pd(out.as_mut_ptr(), v) }
    }
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
        let (ps, qs, rs) = (pad4(p), pad4(q), pad4(r));
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
/// columns of `a` (rows of `stride` values, stride a multiple of 4 and at least n) against `x`.
#[inline(always)]
fn columns<L: Lanes>(
    a: &[f64],
    stride: usize,
    x: &[f64],
    init: f64,
    n: usize,
    mut emit: impl FnMut(usize, f64),
) {
    debug_assert!(stride.is_multiple_of(4) && n <= stride);
    assert!(a.len() >= x.len() * stride, "packed matrix too short");
    let mut j0 = 0;
    while j0 < n {
        // Blocks of up to 32 lanes (8 groups), each lane a separate sum.
        let w = (stride - j0).min(32);
        match w / 4 {
            8 => block::<L, 8>(a, stride, j0, x, init, n, &mut emit),
            7 => block::<L, 7>(a, stride, j0, x, init, n, &mut emit),
            6 => block::<L, 6>(a, stride, j0, x, init, n, &mut emit),
            5 => block::<L, 5>(a, stride, j0, x, init, n, &mut emit),
            4 => block::<L, 4>(a, stride, j0, x, init, n, &mut emit),
            3 => block::<L, 3>(a, stride, j0, x, init, n, &mut emit),
            2 => block::<L, 2>(a, stride, j0, x, init, n, &mut emit),
            _ => block::<L, 1>(a, stride, j0, x, init, n, &mut emit),
        }
        j0 += w;
    }
}

/// Columns `j0 .. j0 + 4G` of [`columns`], accumulated in G groups of 4 independent lanes.
#[inline(always)]
fn block<L: Lanes, const G: usize>(
    a: &[f64],
    stride: usize,
    j0: usize,
    x: &[f64],
    init: f64,
    n: usize,
    emit: &mut impl FnMut(usize, f64),
) {
    let mut acc = [L::splat(init); G];
    for (k, &xk) in x.iter().enumerate() {
        let start = k * stride + j0;
        let row = &a[start..start + 4 * G];
        let xv = L::splat(xk);
        for (g, acc) in acc.iter_mut().enumerate() {
            *acc = L::mul_add(*acc, L::load(&row[4 * g..]), xv);
        }
    }
    let mut sums = [0.0; 32];
    for (g, acc) in acc.iter().enumerate() {
        L::store(*acc, &mut sums[4 * g..]);
    }
    for (l, &v) in sums.iter().enumerate().take((4 * G).min(n - j0)) {
        emit(j0 + l, v);
    }
}

/// `$name` runs `$generic` on AVX2 lanes, compiled with AVX2 enabled, when the processor has
/// it, else on portable lanes.
macro_rules! dispatch {
    ($name:ident, $generic:ident, ($($arg:ident : $ty:ty),*)) => {
        #[allow(clippy::too_many_arguments)]
        pub(super) fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                /// The generic body on AVX2 lanes, compiled with AVX2 enabled.
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                fn avx2($($arg: $ty),*) {
                    $generic::<Avx2>($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the processor supports AVX2 (checked just above).
                    unsafe { avx2($($arg),*) };
                    return;
                }
            }
            $generic::<Portable>($($arg),*)
        }
    };
}

/// Hidden activations h = σ(W₁ x + b₁).
#[inline(always)]
fn hidden_generic<L: Lanes>(pk: &Packed, b1: &[f64], x: &[f64], h: &mut [f64]) {
    debug_assert_eq!(x.len(), pk.p);
    columns::<L>(&pk.w1t, pk.qs, x, -0.0, pk.q, |j, s| {
        h[j] = sigmoid(b1[j] + s)
    });
}

/// Forward pass: h = σ(W₁ x + b₁), y = W₂ h + b₂.
#[inline(always)]
fn forward_generic<L: Lanes>(
    pk: &Packed,
    b1: &[f64],
    b2: &[f64],
    x: &[f64],
    h: &mut [f64],
    y: &mut [f64],
) {
    hidden_generic::<L>(pk, b1, x, h);
    columns::<L>(&pk.w2t, pk.rs, h, -0.0, pk.r, |i, s| y[i] = b2[i] + s);
}

/// Hidden cotangent h̄ = (W₂ᵀ ȳ) ⊙ h ⊙ (1 − h).
#[inline(always)]
fn hidden_bar_generic<L: Lanes>(pk: &Packed, h: &[f64], y_bar: &[f64], hb: &mut [f64]) {
    debug_assert_eq!(y_bar.len(), pk.r);
    columns::<L>(&pk.w2, pk.qs, y_bar, 0.0, pk.q, |j, s| {
        let hj = h[j];
        hb[j] = s * hj * (1.0 - hj);
    });
}

/// Input cotangent x̄ = W₁ᵀ h̄.
#[inline(always)]
fn input_bar_generic<L: Lanes>(pk: &Packed, hb: &[f64], xb: &mut [f64]) {
    columns::<L>(&pk.w1, pk.ps, hb, 0.0, pk.p, |k, s| xb[k] = s);
}

/// Weight-gradient accumulation: ∂E/∂W₂ += ȳ hᵀ, ∂E/∂b₂ += ȳ, ∂E/∂W₁ += h̄ xᵀ, ∂E/∂b₁ += h̄.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn weight_grad_generic<L: Lanes>(
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// The portable lanes give bit for bit what the dispatched entry points (AVX2 where the
    /// processor has it) give.
    #[test]
    fn portable_lanes_match_the_dispatched_kernels() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for (p, q, r) in [(17, 50, 13), (84, 50, 78), (3, 5, 2), (70, 40, 24)] {
            let mut draw =
                |n: usize| -> Vec<f64> { (0..n).map(|_| rng.random_range(-2.0..2.0)).collect() };
            let (w1, w2, b1, b2) = (draw(q * p), draw(r * q), draw(q), draw(r));
            let (x, yb) = (draw(p), draw(r));
            let pk = Packed::new(p, q, r, &w1, &w2);
            let (mut h0, mut y0, mut h1, mut y1) =
                (vec![0.0; q], vec![0.0; r], vec![0.0; q], vec![0.0; r]);
            forward(&pk, &b1, &b2, &x, &mut h0, &mut y0);
            forward_generic::<Portable>(&pk, &b1, &b2, &x, &mut h1, &mut y1);
            assert_eq!(
                (bits(&h0), bits(&y0)),
                (bits(&h1), bits(&y1)),
                "{p}-{q}-{r}"
            );
            let (mut hb0, mut hb1) = (vec![0.0; q], vec![0.0; q]);
            hidden_bar(&pk, &h0, &yb, &mut hb0);
            hidden_bar_generic::<Portable>(&pk, &h0, &yb, &mut hb1);
            assert_eq!(bits(&hb0), bits(&hb1), "{p}-{q}-{r}");
            let (mut xb0, mut xb1) = (vec![0.0; p], vec![0.0; p]);
            input_bar(&pk, &hb0, &mut xb0);
            input_bar_generic::<Portable>(&pk, &hb0, &mut xb1);
            assert_eq!(bits(&xb0), bits(&xb1), "{p}-{q}-{r}");
        }
    }
}
