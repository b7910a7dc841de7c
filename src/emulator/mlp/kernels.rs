//! # Single-example kernels of the perceptron, vectorized across outputs
//!
//! Every single-example pass of [`super::Mlp`] is a handful of matrix–vector products. Each
//! output of such a product is one dot product summed *sequentially* over its inputs, with one
//! fused multiply–add per input, starting from the bias:
//!
//! ```text
//! acc[l] ← b[j₀ + l];   acc[l] ← fma(a[k, j₀ + l], x[k], acc[l])   for k = 0, 1, …
//! ```
//!
//! That order is part of the result (floating-point addition does not associate), and it is
//! fixed by the shapes alone. The kernels vectorize *across* outputs: with the matrix stored so
//! that the weights of all outputs for one input are contiguous, one pass over the inputs
//! updates W accumulators (W ≤ 32, a multiple of 4) at once, each lane evaluating exactly the
//! scalar recurrence of its output. The outputs go in blocks of 32, the last block of a product
//! taking what is left; where a block has 5 lane groups or fewer (20 outputs or fewer, e.g. all
//! 13 outputs of a 17-50-13 net, or the last 20 of its 52 padded hidden units), too few chains
//! are in flight to hide the multiply–add's latency, so each of its outputs is summed in two
//! chains, even k (from the bias) and odd k (from zero), added at the end
//! (`output_has_dual_chains` says which outputs).
//!
//! The hidden units' logistic sigmoid is computed on the lanes too ([`sigmoid_lanes`]): a
//! Cody–Waite reduction e^t = 2ⁿ e^r, |r| ≤ ln 2 / 2, a degree-13 Taylor polynomial in Horner
//! form (fused multiply–adds) and one division, within a few units in the last place of the
//! exact value. [`super::sigmoid`] and the batch passes use the same lanes, so every pass of a
//! net, single or batch, agrees bit for bit on σ.
//!
//! [`Packed`] holds the four layouts the passes read and the biases, each with its row stride
//! padded with zeros to a multiple of 4 so that every lane group is full (padded lanes are
//! computed and dropped), and each stored from the start of a cache line ([`Aligned`]), so
//! that no lane group's load splits across two lines (with the allocator's 16-byte alignment,
//! every 8-lane load of an allocation that did not happen to start on a line did, and the
//! 17-50-13 forward pass took about 1.6 times as long: 255 against 165 ns on AMD Zen 4):
//!
//! ```text
//! w1t  p × q̃   W₁ᵀ: row k holds the weights of input k to every hidden unit  (forward, hidden)
//! w2t  q × r̃   W₂ᵀ: row j holds the weights of hidden unit j to every output (forward, output)
//! w2   r × q̃   W₂ as stored: row i holds output i's weights                  (backward, h̄)
//! w1   q × p̃   W₁ as stored: row j holds hidden unit j's weights              (backward, x̄)
//! ```
//!
//! The lanes are groups of 4 ([`Lanes`]): 256-bit AVX2 registers with FMA on x86-64 processors
//! that have them (runtime detection), else plain `[f64; 4]` arrays with [`f64::mul_add`]. Both
//! are the same IEEE operations lane by lane (a fused multiply–add is exactly rounded either
//! way), so results do not depend on the path taken.

use crate::lanes::Aligned;

/// A multiple of 4 (one lane group) at least `n`.
fn pad4(n: usize) -> usize {
    n.div_ceil(4) * 4
}

/// Four f64 lanes and the operations the kernels need. Implementations must evaluate each lane
/// exactly as the scalar IEEE operation named (fused multiply–add rounded once).
trait Lanes {
    /// A group of `WIDTH` lanes.
    type V: Copy;
    /// Lanes per group: 4, or 8 for [`Avx512`].
    const WIDTH: usize = 4;
    /// All lanes set to `x`.
    fn splat(x: f64) -> Self::V;
    /// The first `WIDTH` values of `p`.
    fn load(p: &[f64]) -> Self::V;
    /// `w * x + acc` lane by lane, rounded once.
    fn fma(w: Self::V, x: Self::V, acc: Self::V) -> Self::V;
    /// `a + b`.
    fn add(a: Self::V, b: Self::V) -> Self::V;
    /// `a - b`.
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    /// `a * b`.
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    /// `a / b`.
    fn div(a: Self::V, b: Self::V) -> Self::V;
    /// `lo` where `x < lo`, `hi` where `x > hi`, else `x` (NaN stays NaN).
    fn clamp(x: Self::V, lo: Self::V, hi: Self::V) -> Self::V;
    /// 2ⁿ from `k = n + 1.5·2⁵²` (the shifter's sum; −1022 ≤ n ≤ 1023): the bit pattern of k
    /// plus 1023, shifted into the exponent field.
    fn exp2_from_shifted(k: Self::V) -> Self::V;
    /// Writes the lanes to the first `WIDTH` values of `out`.
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
    fn fma(w: [f64; 4], x: [f64; 4], acc: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| w[l].mul_add(x[l], acc[l]))
    }
    #[inline(always)]
    fn add(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| a[l] + b[l])
    }
    #[inline(always)]
    fn sub(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| a[l] - b[l])
    }
    #[inline(always)]
    fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| a[l] * b[l])
    }
    #[inline(always)]
    fn div(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        [0, 1, 2, 3].map(|l| a[l] / b[l])
    }
    #[inline(always)]
    fn clamp(x: [f64; 4], lo: [f64; 4], hi: [f64; 4]) -> [f64; 4] {
        // As AVX's max(lo, x) then min(hi, ·): the second operand when either is NaN.
        [0, 1, 2, 3].map(|l| {
            let v = if lo[l] > x[l] { lo[l] } else { x[l] };
            if hi[l] < v {
                hi[l]
            } else {
                v
            }
        })
    }
    #[inline(always)]
    fn exp2_from_shifted(k: [f64; 4]) -> [f64; 4] {
        k.map(|k| f64::from_bits(k.to_bits().wrapping_add(1023) << 52))
    }
    #[inline(always)]
    fn store(v: [f64; 4], out: &mut [f64]) {
        out[..4].copy_from_slice(&v);
    }
}

/// Lanes in AVX2 registers; only used from functions compiled with AVX2 and FMA enabled, on
/// processors that have them.
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx2 {
    type V = std::arch::x86_64::__m256d;
    // SAFETY (every method): only reached from `#[target_feature(enable = "avx2,fma")]` code
    // (see `dispatch`), on processors that have both.
    #[inline(always)]
    fn splat(x: f64) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_set1_pd(x) }
    }
    #[inline(always)]
    fn load(p: &[f64]) -> Self::V {
        assert!(p.len() >= 4);
        // SAFETY: four values are in bounds (checked).
        unsafe { std::arch::x86_64::_mm256_loadu_pd(p.as_ptr()) }
    }
    #[inline(always)]
    fn fma(w: Self::V, x: Self::V, acc: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_fmadd_pd(w, x, acc) }
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_add_pd(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_sub_pd(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_mul_pd(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm256_div_pd(a, b) }
    }
    #[inline(always)]
    fn clamp(x: Self::V, lo: Self::V, hi: Self::V) -> Self::V {
        use std::arch::x86_64::{_mm256_max_pd, _mm256_min_pd};
        unsafe { _mm256_min_pd(hi, _mm256_max_pd(lo, x)) }
    }
    #[inline(always)]
    fn exp2_from_shifted(k: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let bits = _mm256_add_epi64(_mm256_castpd_si256(k), _mm256_set1_epi64x(1023));
            _mm256_castsi256_pd(_mm256_slli_epi64::<52>(bits))
        }
    }
    #[inline(always)]
    fn store(v: Self::V, out: &mut [f64]) {
        assert!(out.len() >= 4);
        // SAFETY: four values are in bounds (checked).
        unsafe { std::arch::x86_64::_mm256_storeu_pd(out.as_mut_ptr(), v) }
    }
}

/// Lanes in AVX-512 registers, 8 to a group; only used from functions compiled with AVX-512F
/// enabled, on processors that have it, for the single-example products of a [`Packed`] padded
/// to 8 ([`Packed::new`]). The same IEEE operations lane by lane as [`Avx2`].
#[cfg(target_arch = "x86_64")]
struct Avx512;

#[cfg(target_arch = "x86_64")]
impl Lanes for Avx512 {
    type V = std::arch::x86_64::__m512d;
    const WIDTH: usize = 8;
    // SAFETY (every method): only reached from `#[target_feature(enable = "avx512f")]` code
    // (see `dispatch_wide`), on processors that have it.
    #[inline(always)]
    fn splat(x: f64) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_set1_pd(x) }
    }
    #[inline(always)]
    fn load(p: &[f64]) -> Self::V {
        assert!(p.len() >= 8);
        // SAFETY: eight values are in bounds (checked).
        unsafe { std::arch::x86_64::_mm512_loadu_pd(p.as_ptr()) }
    }
    #[inline(always)]
    fn fma(w: Self::V, x: Self::V, acc: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_fmadd_pd(w, x, acc) }
    }
    #[inline(always)]
    fn add(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_add_pd(a, b) }
    }
    #[inline(always)]
    fn sub(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_sub_pd(a, b) }
    }
    #[inline(always)]
    fn mul(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_mul_pd(a, b) }
    }
    #[inline(always)]
    fn div(a: Self::V, b: Self::V) -> Self::V {
        unsafe { std::arch::x86_64::_mm512_div_pd(a, b) }
    }
    #[inline(always)]
    fn clamp(x: Self::V, lo: Self::V, hi: Self::V) -> Self::V {
        // VMAXPD/VMINPD return the second operand when either is NaN, as AVX's do.
        use std::arch::x86_64::{_mm512_max_pd, _mm512_min_pd};
        unsafe { _mm512_min_pd(hi, _mm512_max_pd(lo, x)) }
    }
    #[inline(always)]
    fn exp2_from_shifted(k: Self::V) -> Self::V {
        use std::arch::x86_64::*;
        unsafe {
            let bits = _mm512_add_epi64(_mm512_castpd_si512(k), _mm512_set1_epi64(1023));
            _mm512_castsi512_pd(_mm512_slli_epi64::<52>(bits))
        }
    }
    #[inline(always)]
    fn store(v: Self::V, out: &mut [f64]) {
        assert!(out.len() >= 8);
        // SAFETY: eight values are in bounds (checked).
        unsafe { std::arch::x86_64::_mm512_storeu_pd(out.as_mut_ptr(), v) }
    }
}

/// σ(z) = 1 / (1 + e^{−z}) on each lane (module docs): e^t for t = −z clamped to ±708 (beyond
/// that σ is 0 or 1 to double precision), by t = n ln 2 + r with n = round(t / ln 2) (the
/// 1.5·2⁵² shifter) and ln 2 in two parts, e^r by its Taylor series to degree 13 (the
/// truncation is below 2⁻⁵⁵ of e^r for |r| ≤ ln 2 / 2), then 2ⁿ from the exponent bits.
#[inline(always)]
fn sigmoid_lanes<L: Lanes>(z: L::V) -> L::V {
    let mut z = [z];
    sigmoid_groups::<L, 1>(&mut z);
    z[0]
}

/// [`sigmoid_lanes`] on `G` lane groups at once, each step taken for every group before the
/// next: the same operations on every lane, so the same bits, with `G` independent chains in
/// flight. One group alone is a chain of about 25 dependent operations, and the processor's
/// scheduler holds too few of them to overlap many groups by itself (measured on AMD Zen 4:
/// the batch forward pass's σ loop waited on each group's division).
#[inline(always)]
fn sigmoid_groups<L: Lanes, const G: usize>(z: &mut [L::V; G]) {
    // The shifter 1.5 · 2⁵², and ln 2 = LN2_HI + LN2_LO with 32 significant bits in the first
    // (fdlibm's split).
    const SHIFT: f64 = 6755399441055744.0;
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    // 1/k! for k = 13, 12, …, 0.
    const C: [f64; 14] = [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    let mut k = [L::splat(0.0); G];
    let mut r = [L::splat(0.0); G];
    for g in 0..G {
        let t = L::clamp(
            L::sub(L::splat(0.0), z[g]),
            L::splat(-708.0),
            L::splat(708.0),
        );
        k[g] = L::fma(t, L::splat(std::f64::consts::LOG2_E), L::splat(SHIFT));
        let n = L::sub(k[g], L::splat(SHIFT));
        let rg = L::fma(n, L::splat(-LN2_HI), t);
        r[g] = L::fma(n, L::splat(-LN2_LO), rg);
    }
    let mut p = [L::splat(C[0]); G];
    for &c in &C[1..] {
        for g in 0..G {
            p[g] = L::fma(p[g], r[g], L::splat(c));
        }
    }
    for g in 0..G {
        let e = L::mul(p[g], L::exp2_from_shifted(k[g]));
        z[g] = L::div(L::splat(1.0), L::add(L::splat(1.0), e));
    }
}

/// σ on every value of `v`, four at a time (the tail through a zero-padded group).
#[inline(always)]
fn sigmoid_slice_generic<L: Lanes>(v: &mut [f64]) {
    let mut groups = v.chunks_exact_mut(4);
    for g in &mut groups {
        L::store(sigmoid_lanes::<L>(L::load(g)), g);
    }
    let tail = groups.into_remainder();
    if !tail.is_empty() {
        let mut buf = [0.0; 4];
        buf[..tail.len()].copy_from_slice(tail);
        L::store(sigmoid_lanes::<L>(L::load(&buf)), &mut buf);
        tail.copy_from_slice(&buf[..tail.len()]);
    }
}

/// The scalar σ: lane 0 of [`sigmoid_lanes`] (the same bits as every kernel).
pub(super) fn sigmoid_scalar(z: f64) -> f64 {
    sigmoid_lanes::<Portable>([z; 4])[0]
}

/// Whether the single-example products run on [`Avx512`] lanes: on x86-64 processors with
/// AVX-512F, unless [`crate::simd`]'s switch (`MOTIONLAB_SIMD=avx2` or `scalar`, or
/// `MOTIONLAB_NO_AVX512`) caps the level (to compare the paths; the same bits either way).
fn wide_lanes() -> bool {
    crate::simd::avx512f()
}

/// A p → q → r net's layer sizes, and each padded to whole lane groups.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Dims {
    p: usize,
    q: usize,
    r: usize,
    /// p̃, q̃, r̃: multiples of 8 (for [`Avx512`] lanes) or 4.
    ps: usize,
    qs: usize,
    rs: usize,
    /// Whether the sizes are padded to 8, for [`Avx512`] lanes (see `dispatch_wide`).
    wide: bool,
}

impl Dims {
    /// The sizes, padded to multiples of 8 when `wide`, else of 4.
    fn padded(p: usize, q: usize, r: usize, wide: bool) -> Self {
        let pad = |n: usize| if wide { n.div_ceil(8) * 8 } else { pad4(n) };
        Self {
            p,
            q,
            r,
            ps: pad(p),
            qs: pad(q),
            rs: pad(r),
            wide,
        }
    }
}

/// The weights of a p → q → r net in the layouts of the single-example kernels (module docs).
#[derive(Debug, Clone)]
pub(super) struct Packed {
    d: Dims,
    w1t: Aligned,
    w2t: Aligned,
    w2: Aligned,
    w1: Aligned,
    /// b₁ and b₂, zero-padded to q̃ and r̃.
    b1: Aligned,
    b2: Aligned,
    /// q̃ zeros: the start of the sums without a bias.
    zeros: Aligned,
}

impl Packed {
    /// Packs W₁ (q × p, row-major), b₁, W₂ (r × q, row-major) and b₂.
    pub(super) fn new(
        p: usize,
        q: usize,
        r: usize,
        w1: &[f64],
        b1: &[f64],
        w2: &[f64],
        b2: &[f64],
    ) -> Self {
        // AVX-512 halves the instructions of a pass but runs at a lower clock (this bench's
        // `cpu.fma_f64.*` peaks: 45.7 against 24.6 GMAC/s, 7% below twice), so it pays where
        // the passes are bound by instruction issue (short products, the sigmoid) more than by
        // the latency of long multiply–add chains. Measured (one core, interleaved):
        // 17-50-13 13% and 70-40-24 8% faster, 84-50-78 6% slower; hence nets with more than
        // 72 inputs or 64 outputs keep 4 lanes.
        let wide = wide_lanes() && p <= 72 && r <= 64;
        let d = Dims::padded(p, q, r, wide);
        let (ps, qs, rs) = (d.ps, d.qs, d.rs);
        let mut w1t = Aligned::zeros(p * qs);
        let mut w1p = Aligned::zeros(q * ps);
        for j in 0..q {
            for k in 0..p {
                w1t[k * qs + j] = w1[j * p + k];
                w1p[j * ps + k] = w1[j * p + k];
            }
        }
        let mut w2t = Aligned::zeros(q * rs);
        let mut w2p = Aligned::zeros(r * qs);
        for i in 0..r {
            for j in 0..q {
                w2t[j * rs + i] = w2[i * q + j];
                w2p[i * qs + j] = w2[i * q + j];
            }
        }
        let padded = |b: &[f64], n: usize| {
            let mut v = Aligned::zeros(n);
            v[..b.len()].copy_from_slice(b);
            v
        };
        Self {
            d,
            w1t,
            w2t,
            w2: w2p,
            w1: w1p,
            b1: padded(b1, qs),
            b2: padded(b2, rs),
            zeros: Aligned::zeros(qs.max(ps)),
        }
    }
}

/// Where [`columns`] puts a block's sums: `put(j0, v)` gets the block's G lane groups, for
/// outputs j0 .. j0 + G·WIDTH (those at n and beyond are padding).
trait Sink<L: Lanes> {
    fn put<const G: usize>(&mut self, j0: usize, v: &[L::V; G]);
}

/// A sink that calls `f(l, s)` for each output l < `n`, one value at a time.
struct Emit<F> {
    n: usize,
    f: F,
}

impl<L: Lanes, F: FnMut(usize, f64)> Sink<L> for Emit<F> {
    #[inline(always)]
    fn put<const G: usize>(&mut self, j0: usize, v: &[L::V; G]) {
        let mut sums = [0.0; 32];
        for (g, v) in v.iter().enumerate() {
            L::store(*v, &mut sums[L::WIDTH * g..]);
        }
        for (l, &s) in sums
            .iter()
            .enumerate()
            .take((L::WIDTH * G).min(self.n - j0))
        {
            (self.f)(j0 + l, s);
        }
    }
}

/// A sink that stores each lane group whole at its place in a buffer of at least `stride`
/// values (padding lanes included): no value goes through memory one at a time, so the next
/// product's broadcasts read what the lane stores wrote.
struct Lanewise<'a>(&'a mut [f64]);

impl<L: Lanes> Sink<L> for Lanewise<'_> {
    #[inline(always)]
    fn put<const G: usize>(&mut self, j0: usize, v: &[L::V; G]) {
        for (g, v) in v.iter().enumerate() {
            L::store(*v, &mut self.0[j0 + L::WIDTH * g..]);
        }
    }
}

/// Output l < n gets s = init[l] + Σ_k a[k, l] x[k], or σ(s) when `SIGMOID`, each sum one fused
/// multiply–add per k in order k = 0, 1, …: the columns of `a` (rows of `stride` values,
/// stride a multiple of 4 and at least n) against `x`, from `init` (at least `stride` values).
/// σ acts on whole lane groups ([`sigmoid_lanes`]). The sums go to `sink`, a block of lane
/// groups at a time.
#[inline(always)]
fn columns<L: Lanes, const SIGMOID: bool>(
    a: &[f64],
    stride: usize,
    x: &[f64],
    init: &[f64],
    n: usize,
    sink: &mut impl Sink<L>,
) {
    debug_assert!(stride.is_multiple_of(L::WIDTH) && n <= stride);
    assert!(a.len() >= x.len() * stride, "packed matrix too short");
    assert!(init.len() >= stride, "initial values too short");
    let mut j0 = 0;
    while j0 < n {
        // Blocks of up to 32 lanes, each lane a separate sum. Whether a block sums in two
        // chains depends on its width with the outputs padded to 4 (the order of the sums
        // does not depend on the lanes' width).
        let w = (stride - j0).min(32);
        let dual = dual_chains((pad4(n) - j0).min(32) / 4);
        let args = (a, stride, j0, x, init, dual);
        match w / L::WIDTH {
            8 => sink.put(j0, &block::<L, SIGMOID, 8>(args)),
            7 => sink.put(j0, &block::<L, SIGMOID, 7>(args)),
            6 => sink.put(j0, &block::<L, SIGMOID, 6>(args)),
            5 => sink.put(j0, &block::<L, SIGMOID, 5>(args)),
            4 => sink.put(j0, &block::<L, SIGMOID, 4>(args)),
            3 => sink.put(j0, &block::<L, SIGMOID, 3>(args)),
            2 => sink.put(j0, &block::<L, SIGMOID, 2>(args)),
            _ => sink.put(j0, &block::<L, SIGMOID, 1>(args)),
        }
        j0 += w;
    }
}

/// Columns `j0 .. j0 + G·WIDTH` of [`columns`] (`a`, `stride`, `j0`, `x`, `init`, `dual`),
/// accumulated in G groups of independent lanes, each summed in two chains when `dual`.
#[inline(always)]
fn block<L: Lanes, const SIGMOID: bool, const G: usize>(
    (a, stride, j0, x, init, dual): (&[f64], usize, usize, &[f64], &[f64], bool),
) -> [L::V; G] {
    // What `step` reads without checks: the block's lanes within a row, every input's row.
    assert!(j0 + L::WIDTH * G <= stride && a.len() >= x.len() * stride);
    let mut acc = [L::splat(0.0); G];
    for (g, acc) in acc.iter_mut().enumerate() {
        *acc = L::load(&init[j0 + L::WIDTH * g..]);
    }
    if dual {
        // Too few groups to hide the multiply–add latency: even k into `acc`, odd k into a
        // second set, added at the end.
        let mut odd = [L::splat(0.0); G];
        let mut k = 0;
        while k + 1 < x.len() {
            step::<L, G>(&mut acc, a, stride, j0, x, k);
            step::<L, G>(&mut odd, a, stride, j0, x, k + 1);
            k += 2;
        }
        if k < x.len() {
            step::<L, G>(&mut acc, a, stride, j0, x, k);
        }
        for (a, o) in acc.iter_mut().zip(odd) {
            *a = L::add(*a, o);
        }
    } else {
        for k in 0..x.len() {
            step::<L, G>(&mut acc, a, stride, j0, x, k);
        }
    }
    if SIGMOID {
        for acc in acc.iter_mut() {
            *acc = sigmoid_lanes::<L>(*acc);
        }
    }
    acc
}

/// One input k of a [`block`]: acc ← fma(a[k, j₀ ..], x[k], acc). The caller ([`block`])
/// checked that j₀ + G·WIDTH ≤ `stride` and that `a` holds `stride` values for every input, so
/// the row is read without checks (the checks were about a third of the instructions of the
/// loop over the inputs, whose multiply–add chains are short).
#[inline(always)]
fn step<L: Lanes, const G: usize>(
    acc: &mut [L::V; G],
    a: &[f64],
    stride: usize,
    j0: usize,
    x: &[f64],
    k: usize,
) {
    let start = k * stride + j0;
    debug_assert!(k < x.len() && j0 + L::WIDTH * G <= stride && a.len() >= x.len() * stride);
    // SAFETY: k < x.len() (the caller's loops), so start + G·WIDTH ≤ (k + 1)·stride ≤ a.len().
    let row = unsafe { a.get_unchecked(start..start + L::WIDTH * G) };
    let xv = L::splat(x[k]);
    for (g, acc) in acc.iter_mut().enumerate() {
        *acc = L::fma(L::load(&row[L::WIDTH * g..]), xv, *acc);
    }
}

/// Whether a block of `groups` lane groups sums each output in two chains (module docs).
#[inline(always)]
const fn dual_chains(groups: usize) -> bool {
    groups <= 5
}

/// Whether output `j` of a product with padded stride `stride` is summed in two chains: the
/// block [`columns`] puts it in has at most 5 lane groups.
#[cfg(test)]
pub(super) fn output_has_dual_chains(stride: usize, j: usize) -> bool {
    let j0 = j / 32 * 32;
    dual_chains((stride - j0).min(32) / 4)
}

/// `$name` runs `$generic` on AVX2 lanes, compiled with AVX2 and FMA enabled, when the
/// processor has both and [`crate::simd`] allows them, else on portable lanes (the same bits:
/// without the FMA instruction each [`f64::mul_add`] is libm's exact `fma`, slower).
macro_rules! dispatch {
    ($vis:vis $name:ident, $generic:ident, ($($arg:ident : $ty:ty),*)) => {
        #[allow(clippy::too_many_arguments)]
        $vis fn $name($($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                /// The generic body on AVX2 lanes, compiled with AVX2 and FMA enabled.
                #[target_feature(enable = "avx2,fma")]
                #[allow(clippy::too_many_arguments)]
                fn avx2($($arg: $ty),*) {
                    $generic::<Avx2>($($arg),*)
                }
                if crate::simd::avx2_fma() {
                    // SAFETY: the processor supports AVX2 and FMA (checked just above).
                    unsafe { avx2($($arg),*) };
                    return;
                }
            }
            $generic::<Portable>($($arg),*)
        }
    };
}

/// [`dispatch`] for the single-example products of a [`Packed`] (`$pk`): on [`Avx512`] lanes,
/// compiled with AVX-512F enabled, when the matrices are padded for them ([`wide_lanes`]), else
/// as [`dispatch`].
macro_rules! dispatch_wide {
    ($name:ident, $generic:ident, ($pk:ident : $pkty:ty, $($arg:ident : $ty:ty),*)) => {
        #[allow(clippy::too_many_arguments)]
        pub(super) fn $name($pk: $pkty, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            {
                /// The generic body on AVX-512 lanes, compiled with AVX-512F enabled.
                #[target_feature(enable = "avx512f")]
                #[allow(clippy::too_many_arguments)]
                fn avx512($pk: $pkty, $($arg: $ty),*) {
                    $generic::<Avx512>($pk, $($arg),*)
                }
                if $pk.d.wide && crate::simd::avx512f() {
                    // SAFETY: the processor supports AVX-512F (checked just above).
                    unsafe { avx512($pk, $($arg),*) };
                    return;
                }
            }
            dispatch!(narrow, $generic, ($pk: $pkty, $($arg: $ty),*));
            narrow($pk, $($arg),*)
        }
    };
}

mod batch;
pub(super) use batch::{chunk_loss, chunk_loss_grad, general_product, Ahead, BatchNet, MAX_DEPTH};
mod many;
pub(super) use many::{backward_many, forward_many};

/// Hidden activations h = σ(W₁ x + b₁).
#[inline(always)]
fn hidden_generic<L: Lanes>(pk: &Packed, x: &[f64], h: &mut [f64]) {
    debug_assert_eq!(x.len(), pk.d.p);
    let mut sink = Emit {
        n: pk.d.q,
        f: |j, s| h[j] = s,
    };
    columns::<L, true>(&pk.w1t, pk.d.qs, x, &pk.b1, pk.d.q, &mut sink);
}

/// The most hidden units (padded) whose values the forward pass hands from one product to the
/// next in a [`LaneBuf`] on the stack rather than one at a time ([`forward_generic`]); larger
/// nets take the other way (the same bits either way).
const LANE_BUF: usize = 64;

/// [`LANE_BUF`] values from the start of a cache line, so that no lane group's load or store
/// splits across two.
#[repr(C, align(64))]
struct LaneBuf([f64; LANE_BUF]);

impl LaneBuf {
    fn zeros() -> Self {
        Self([0.0; LANE_BUF])
    }
}

/// `d` ← `s` (of the same length), a lane group at a time and the rest one by one.
#[inline(always)]
fn copy_lanes<L: Lanes>(s: &[f64], d: &mut [f64]) {
    assert_eq!(s.len(), d.len());
    let mut dc = d.chunks_exact_mut(L::WIDTH);
    let mut sc = s.chunks_exact(L::WIDTH);
    for (d, s) in (&mut dc).zip(&mut sc) {
        L::store(L::load(s), d);
    }
    for (d, s) in dc.into_remainder().iter_mut().zip(sc.remainder()) {
        *d = *s;
    }
}

/// Forward pass: h = σ(W₁ x + b₁), y = W₂ h + b₂.
///
/// Where the hidden layer fits a [`LaneBuf`] and the outputs one block of [`columns`] (32
/// lanes), the hidden lane groups are stored whole there and the output product broadcasts
/// from it; `h` gets a copy. Emitted one value at a time instead (as [`hidden_generic`] does),
/// each value goes through a store and a load to a scalar buffer and another store before the
/// output product reads it. Measured on AMD Zen 4: the lander's emulator step took
/// 7–8% longer that way (232 against 216 ns, medians of 12 interleaved rounds), on 8 lanes or
/// on 4; the forward pass timed alone, passes independent of each other, took as long either
/// way, so what it saves is latency on the step's chain. With more outputs (84-50-78's 78, three
/// blocks) the buffer measured 2% slower, for a reason not established, so those nets do not
/// take it.
#[inline(always)]
fn forward_generic<L: Lanes>(pk: &Packed, x: &[f64], h: &mut [f64], y: &mut [f64]) {
    let d = pk.d;
    let mut out = Emit {
        n: d.r,
        f: |i, s| y[i] = s,
    };
    if d.qs <= LANE_BUF && d.rs <= 32 {
        let mut hl = LaneBuf::zeros();
        columns::<L, true>(&pk.w1t, d.qs, x, &pk.b1, d.q, &mut Lanewise(&mut hl.0));
        columns::<L, false>(&pk.w2t, d.rs, &hl.0[..d.q], &pk.b2, d.r, &mut out);
        copy_lanes::<L>(&hl.0[..d.q], h);
    } else {
        hidden_generic::<L>(pk, x, h);
        columns::<L, false>(&pk.w2t, d.rs, h, &pk.b2, d.r, &mut out);
    }
}

/// Hidden cotangent h̄ = (W₂ᵀ ȳ) ⊙ h ⊙ (1 − h).
#[inline(always)]
fn hidden_bar_generic<L: Lanes>(pk: &Packed, h: &[f64], y_bar: &[f64], hb: &mut [f64]) {
    debug_assert_eq!(y_bar.len(), pk.d.r);
    let mut sink = Emit {
        n: pk.d.q,
        f: |j, s| {
            let hj = h[j];
            hb[j] = s * hj * (1.0 - hj);
        },
    };
    columns::<L, false>(&pk.w2, pk.d.qs, y_bar, &pk.zeros, pk.d.q, &mut sink);
}

/// Input cotangent x̄ = W₁ᵀ h̄.
#[inline(always)]
fn input_bar_generic<L: Lanes>(pk: &Packed, hb: &[f64], xb: &mut [f64]) {
    let mut sink = Emit {
        n: pk.d.p,
        f: |k, s| xb[k] = s,
    };
    columns::<L, false>(&pk.w1, pk.d.ps, hb, &pk.zeros, pk.d.p, &mut sink);
}

/// Weight-gradient accumulation: ∂E/∂W₂ += ȳ hᵀ, ∂E/∂b₂ += ȳ, ∂E/∂W₁ += h̄ xᵀ, ∂E/∂b₁ += h̄
/// (each product added by one fused multiply–add).
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
    #[inline(always)]
    fn rank1<L: Lanes>(g: &mut [f64], s: f64, v: &[f64]) {
        let sv = L::splat(s);
        let mut gc = g.chunks_exact_mut(4);
        let mut vc = v.chunks_exact(4);
        for (g, v) in (&mut gc).zip(&mut vc) {
            L::store(L::fma(sv, L::load(v), L::load(g)), g);
        }
        for (g, v) in gc.into_remainder().iter_mut().zip(vc.remainder()) {
            *g = s.mul_add(*v, *g);
        }
    }
    let (p, q) = (x.len(), h.len());
    for (i, yb) in y_bar.iter().enumerate() {
        gb2[i] += yb;
        rank1::<L>(&mut g2[i * q..(i + 1) * q], *yb, h);
    }
    for (j, &hbj) in hb.iter().enumerate() {
        gb1[j] += hbj;
        rank1::<L>(&mut g1[j * p..(j + 1) * p], hbj, x);
    }
}

/// Rank-one updates of many examples, in order: for every example e (row e of `coef`, stride
/// `rows`, and of `vecs`, stride `cols`), g[i, ·] += coef[e, i] · vecs[e, ·] over the `rows` ×
/// `cols` matrix `g`, each entry by one fused multiply–add per example, examples in turn: the
/// same operations, in the same order per entry, as one `rank1` call per example (so the same
/// bits), with the entries of a tile (up to 3 rows × 3 lane groups) held in registers across
/// the examples instead of loaded and stored once per example.
///
/// The columns past the last whole lane group (fewer than 4) take lanes across 4 rows instead
/// (the coefficients of consecutive rows are consecutive), with the same chain per entry
/// (multiplication commutes, so fma(coef, vec, g) either way). Tiles are at most 9
/// accumulators: with AVX2's 16 registers, 12 (3 rows × 4 groups) left one on the stack, and
/// the loop waited on it; and one entry at a time, each chain waits on its own latency.
#[inline(always)]
fn rank1_many<L: Lanes>(
    g: &mut [f64],
    rows: usize,
    cols: usize,
    coef: &[f64],
    vecs: &[f64],
    examples: usize,
) {
    assert!(g.len() >= rows * cols);
    assert!(coef.len() >= examples * rows && vecs.len() >= examples * cols);
    let args = (rows, cols, coef, vecs, examples);
    let groups = cols / 4;
    let mut i0 = 0;
    while i0 < rows {
        let rb = 3.min(rows - i0);
        let mut c0 = 0;
        while c0 < groups {
            let cb = 3.min(groups - c0);
            match (rb, cb) {
                (3, 3) => rank1_tile::<L, 3, 3>(g, args, i0, c0),
                (3, 2) => rank1_tile::<L, 3, 2>(g, args, i0, c0),
                (3, _) => rank1_tile::<L, 3, 1>(g, args, i0, c0),
                (2, 3) => rank1_tile::<L, 2, 3>(g, args, i0, c0),
                (2, 2) => rank1_tile::<L, 2, 2>(g, args, i0, c0),
                (2, _) => rank1_tile::<L, 2, 1>(g, args, i0, c0),
                (_, 3) => rank1_tile::<L, 1, 3>(g, args, i0, c0),
                (_, 2) => rank1_tile::<L, 1, 2>(g, args, i0, c0),
                _ => rank1_tile::<L, 1, 1>(g, args, i0, c0),
            }
            c0 += cb;
        }
        i0 += rb;
    }
    let j0 = groups * 4;
    if j0 == cols {
        return;
    }
    // The last columns, 4 rows to a lane group.
    let rows4 = rows / 4 * 4;
    let mut i0 = 0;
    while i0 < rows4 {
        let rb = 3.min((rows4 - i0) / 4);
        match (cols - j0, rb) {
            (3, 3) => rank1_tail::<L, 3, 3>(g, args, i0, j0),
            (3, 2) => rank1_tail::<L, 3, 2>(g, args, i0, j0),
            (3, _) => rank1_tail::<L, 3, 1>(g, args, i0, j0),
            (2, 3) => rank1_tail::<L, 2, 3>(g, args, i0, j0),
            (2, 2) => rank1_tail::<L, 2, 2>(g, args, i0, j0),
            (2, _) => rank1_tail::<L, 2, 1>(g, args, i0, j0),
            (_, 3) => rank1_tail::<L, 1, 3>(g, args, i0, j0),
            (_, 2) => rank1_tail::<L, 1, 2>(g, args, i0, j0),
            _ => rank1_tail::<L, 1, 1>(g, args, i0, j0),
        }
        i0 += 4 * rb;
    }
    // Fewer than 4 rows left in those columns: one entry at a time.
    for i in rows4..rows {
        for j in j0..cols {
            let mut v = g[i * cols + j];
            for e in 0..examples {
                v = coef[e * rows + i].mul_add(vecs[e * cols + j], v);
            }
            g[i * cols + j] = v;
        }
    }
}

/// [`rank1_many`]'s arguments after g: rows, cols, coef, vecs, examples.
type Rank1<'a> = (usize, usize, &'a [f64], &'a [f64], usize);

/// The entries of rows i0 .. i0 + RB and lane groups c0 .. c0 + CB of [`rank1_many`], in
/// registers over every example.
#[inline(always)]
fn rank1_tile<L: Lanes, const RB: usize, const CB: usize>(
    g: &mut [f64],
    (rows, cols, coef, vecs, examples): Rank1<'_>,
    i0: usize,
    c0: usize,
) {
    let at = |a: usize, c: usize| (i0 + a) * cols + (c0 + c) * 4;
    let mut acc = [[L::splat(0.0); CB]; RB];
    for (a, row) in acc.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = L::load(&g[at(a, c)..]);
        }
    }
    for (x, k) in vecs
        .chunks_exact(cols)
        .zip(coef.chunks_exact(rows))
        .take(examples)
    {
        let mut xv = [L::splat(0.0); CB];
        for (c, v) in xv.iter_mut().enumerate() {
            *v = L::load(&x[(c0 + c) * 4..]);
        }
        for (a, row) in acc.iter_mut().enumerate() {
            let s = L::splat(k[i0 + a]);
            for (v, &x) in row.iter_mut().zip(&xv) {
                *v = L::fma(s, x, *v);
            }
        }
    }
    for (a, row) in acc.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            L::store(v, &mut g[at(a, c)..]);
        }
    }
}

/// The entries of columns j0 .. j0 + NC (past the last whole lane group) and rows i0 .. i0 +
/// 4·RB of [`rank1_many`], each lane group holding one column of 4 consecutive rows.
#[inline(always)]
fn rank1_tail<L: Lanes, const NC: usize, const RB: usize>(
    g: &mut [f64],
    (rows, cols, coef, vecs, examples): Rank1<'_>,
    i0: usize,
    j0: usize,
) {
    let mut acc = [[L::splat(0.0); RB]; NC];
    let mut lanes = [0.0; 4];
    for (c, row) in acc.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate() {
            for (l, x) in lanes.iter_mut().enumerate() {
                *x = g[(i0 + 4 * b + l) * cols + j0 + c];
            }
            *v = L::load(&lanes);
        }
    }
    for (x, k) in vecs
        .chunks_exact(cols)
        .zip(coef.chunks_exact(rows))
        .take(examples)
    {
        let mut kv = [L::splat(0.0); RB];
        for (b, v) in kv.iter_mut().enumerate() {
            *v = L::load(&k[i0 + 4 * b..]);
        }
        for (c, row) in acc.iter_mut().enumerate() {
            let s = L::splat(x[j0 + c]);
            for (v, &k) in row.iter_mut().zip(&kv) {
                *v = L::fma(k, s, *v);
            }
        }
    }
    for (c, row) in acc.iter().enumerate() {
        for (b, &v) in row.iter().enumerate() {
            L::store(v, &mut lanes);
            for (l, x) in lanes.iter().enumerate() {
                g[(i0 + 4 * b + l) * cols + j0 + c] = *x;
            }
        }
    }
}

/// [`weight_grad`] of `examples` examples in turn (rows of `x` (stride p), `h` and `hb`
/// (stride q) and `y_bar` (stride r)): the same bits as one [`weight_grad`] call per example,
/// in that order, with far fewer loads and stores of the gradient.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn weight_grad_many_generic<L: Lanes>(
    examples: usize,
    x: &[f64],
    h: &[f64],
    hb: &[f64],
    y_bar: &[f64],
    g1: &mut [f64],
    gb1: &mut [f64],
    g2: &mut [f64],
    gb2: &mut [f64],
) {
    let (q, r) = (gb1.len(), gb2.len());
    let p = g1.len().checked_div(q).unwrap_or(0);
    for e in 0..examples {
        for (g, v) in gb2.iter_mut().zip(&y_bar[e * r..(e + 1) * r]) {
            *g += v;
        }
        for (g, v) in gb1.iter_mut().zip(&hb[e * q..(e + 1) * q]) {
            *g += v;
        }
    }
    rank1_many::<L>(g2, r, q, y_bar, h, examples);
    rank1_many::<L>(g1, q, p, hb, x, examples);
}

dispatch_wide!(hidden, hidden_generic, (pk: &Packed, x: &[f64], h: &mut [f64]));
dispatch_wide!(
    forward,
    forward_generic,
    (pk: &Packed, x: &[f64], h: &mut [f64], y: &mut [f64])
);
dispatch_wide!(
    hidden_bar,
    hidden_bar_generic,
    (pk: &Packed, h: &[f64], y_bar: &[f64], hb: &mut [f64])
);
dispatch_wide!(input_bar, input_bar_generic, (pk: &Packed, hb: &[f64], xb: &mut [f64]));
dispatch!(
    pub(super) weight_grad,
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
dispatch!(pub(super) sigmoid_slice, sigmoid_slice_generic, (v: &mut [f64]));
dispatch!(
    pub(super) weight_grad_many,
    weight_grad_many_generic,
    (
        examples: usize,
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

    /// The portable lanes give bit for bit what the dispatched entry points (AVX2 and FMA where
    /// the processor has them) give.
    #[test]
    fn portable_lanes_match_the_dispatched_kernels() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for (p, q, r) in [(17, 50, 13), (84, 50, 78), (3, 5, 2), (70, 40, 24)] {
            let mut draw =
                |n: usize| -> Vec<f64> { (0..n).map(|_| rng.random_range(-2.0..2.0)).collect() };
            let (w1, w2, b1, b2) = (draw(q * p), draw(r * q), draw(q), draw(r));
            let (x, yb) = (draw(p), draw(r));
            let pk = Packed::new(p, q, r, &w1, &b1, &w2, &b2);
            let (mut h0, mut y0, mut h1, mut y1) =
                (vec![0.0; q], vec![0.0; r], vec![0.0; q], vec![0.0; r]);
            forward(&pk, &x, &mut h0, &mut y0);
            forward_generic::<Portable>(&pk, &x, &mut h1, &mut y1);
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
            let n = q * (p + 1) + r * (q + 1);
            let (mut ga, mut gb) = (draw(n), vec![0.0; n]);
            gb.copy_from_slice(&ga);
            let split = |g: &mut [f64]| -> [Vec<f64>; 4] {
                let (g1, rest) = g.split_at(q * p);
                let (gb1, rest) = rest.split_at(q);
                let (g2, gb2) = rest.split_at(r * q);
                [g1.to_vec(), gb1.to_vec(), g2.to_vec(), gb2.to_vec()]
            };
            let [mut a1, mut ab1, mut a2, mut ab2] = split(&mut ga);
            let [mut c1, mut cb1, mut c2, mut cb2] = split(&mut gb);
            weight_grad(&x, &h0, &hb0, &yb, &mut a1, &mut ab1, &mut a2, &mut ab2);
            weight_grad_generic::<Portable>(
                &x, &h0, &hb0, &yb, &mut c1, &mut cb1, &mut c2, &mut cb2,
            );
            assert_eq!(
                [bits(&a1), bits(&ab1), bits(&a2), bits(&ab2)],
                [bits(&c1), bits(&cb1), bits(&c2), bits(&cb2)],
                "{p}-{q}-{r}"
            );
        }
        let mut z: Vec<f64> = (0..1003).map(|_| rng.random_range(-60.0..60.0)).collect();
        let mut zp = z.clone();
        sigmoid_slice(&mut z);
        sigmoid_slice_generic::<Portable>(&mut zp);
        assert_eq!(bits(&z), bits(&zp));
    }

    /// Many examples' weight gradients added at once give the bits of one [`weight_grad`] call
    /// per example in turn, on both paths, for shapes with and without remainders (rows not a
    /// multiple of the 3-row tiles or of 4, columns not of 4 or 12) and any example count.
    #[test]
    fn batched_weight_gradients_match_one_example_at_a_time_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        for (p, q, r) in [
            (17, 50, 13),
            (84, 50, 78),
            (3, 5, 2),
            (70, 40, 24),
            (6, 20, 6),
            (9, 1, 1),
            // Columns past the last lane group (3 and 2 of them) over rows in groups of 4 and
            // rows left over.
            (15, 7, 13),
            (58, 42, 30),
        ] {
            for examples in [0, 1, 7, 128] {
                let mut draw = |n: usize| -> Vec<f64> {
                    (0..n).map(|_| rng.random_range(-2.0..2.0)).collect()
                };
                let (x, h, hb, yb) = (
                    draw(examples * p),
                    draw(examples * q),
                    draw(examples * q),
                    draw(examples * r),
                );
                let start = [draw(q * p), draw(q), draw(r * q), draw(r)];
                let [mut a1, mut ab1, mut a2, mut ab2] = start.clone();
                for e in 0..examples {
                    weight_grad(
                        &x[e * p..(e + 1) * p],
                        &h[e * q..(e + 1) * q],
                        &hb[e * q..(e + 1) * q],
                        &yb[e * r..(e + 1) * r],
                        &mut a1,
                        &mut ab1,
                        &mut a2,
                        &mut ab2,
                    );
                }
                let want = [bits(&a1), bits(&ab1), bits(&a2), bits(&ab2)];
                let [mut c1, mut cb1, mut c2, mut cb2] = start.clone();
                weight_grad_many(
                    examples, &x, &h, &hb, &yb, &mut c1, &mut cb1, &mut c2, &mut cb2,
                );
                assert_eq!(
                    [bits(&c1), bits(&cb1), bits(&c2), bits(&cb2)],
                    want,
                    "{p}-{q}-{r}, {examples}"
                );
                let [mut d1, mut db1, mut d2, mut db2] = start;
                weight_grad_many_generic::<Portable>(
                    examples, &x, &h, &hb, &yb, &mut d1, &mut db1, &mut d2, &mut db2,
                );
                assert_eq!(
                    [bits(&d1), bits(&db1), bits(&d2), bits(&db2)],
                    want,
                    "portable {p}-{q}-{r}, {examples}"
                );
            }
        }
    }

    /// σ taken on several lane groups in step gives each group's own σ (one group alone) bit
    /// for bit, NaN and the saturated ends included.
    #[test]
    fn grouped_sigmoid_is_the_lane_sigmoid_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let special = [
            0.0,
            -0.0,
            708.0,
            -709.5,
            1e300,
            f64::INFINITY,
            f64::NAN,
            -1e-7,
        ];
        for round in 0..2000 {
            let mut z = [[0.0; 4]; 4];
            for (i, v) in z.iter_mut().flatten().enumerate() {
                *v = match (round + i) % 5 {
                    0 => special[(round * 7 + i) % special.len()],
                    1 => rng.random_range(-750.0..750.0),
                    _ => rng.random_range(-8.0..8.0),
                };
            }
            let mut grouped = z;
            sigmoid_groups::<Portable, 4>(&mut grouped);
            for (g, lanes) in z.iter().enumerate() {
                let one = sigmoid_lanes::<Portable>(*lanes);
                assert_eq!(bits(&one), bits(&grouped[g]), "σ of {lanes:?}");
            }
        }
    }

    /// σ on the lanes is within 4 units in the last place of 1 / (1 + e^{−z}) evaluated with
    /// libm's exp (itself within one) over the whole range, exact at the saturated ends, odd
    /// about one half (σ(−z) = 1 − σ(z) to rounding), and NaN stays NaN.
    #[test]
    fn lane_sigmoid_is_accurate_to_a_few_ulps() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let reference = |z: f64| 1.0 / (1.0 + (-z).exp());
        let mut zs: Vec<f64> = (0..200_000)
            .map(|i| match i % 4 {
                0 => rng.random_range(-1.0..1.0),
                1 => rng.random_range(-40.0..40.0),
                2 => rng.random_range(-750.0..750.0),
                _ => rng.random_range(-1e-6..1e-6),
            })
            .collect();
        zs.extend([0.0, -0.0, 708.0, -708.0, 709.5, -709.5, 1e300, -1e300]);
        zs.extend([f64::INFINITY, f64::NEG_INFINITY, f64::MIN_POSITIVE]);
        let mut s = zs.clone();
        sigmoid_slice(&mut s);
        let mut worst = 0.0f64;
        for (&z, &v) in zs.iter().zip(&s) {
            let r = reference(z);
            assert!((0.0..=1.0).contains(&v), "σ({z}) = {v}");
            if r > 1e-300 {
                let ulps = (v - r).abs() / (r * f64::EPSILON);
                worst = worst.max(ulps);
                assert!(ulps <= 4.0, "σ({z}) = {v:e}, libm {r:e}: {ulps} ulp");
            } else {
                assert!(v < 1e-300, "σ({z}) = {v:e}");
            }
            assert_eq!(v.to_bits(), sigmoid_scalar(z).to_bits(), "scalar σ({z})");
            if z.abs() < 30.0 {
                assert!((sigmoid_scalar(-z) - (1.0 - v)).abs() <= 4.0 * f64::EPSILON);
            }
        }
        assert!(worst > 0.0, "compared against libm at all");
        assert_eq!(sigmoid_scalar(800.0), 1.0);
        assert!(sigmoid_scalar(f64::NAN).is_nan());
        let mut v = [0.3, f64::NAN, -2.0, f64::NAN, 1.0];
        sigmoid_slice(&mut v);
        assert!(v[1].is_nan() && v[3].is_nan() && v[0] > 0.5 && v[2] < 0.5);
    }
}
