//! # Single-example passes of many examples at once
//!
//! The k-step rollout loss runs the net on every window of a chunk at the same step, each
//! window an example of its own. One [`super::forward`] per example reads all the weights for
//! every example (the 84-50-78 net's 67 KB do not stay in a 32 KB L1 cache), and its
//! multiply–adds ran at about 40% of the core's peak on AMD Zen 4. Here a register tile of
//! several examples × several lane groups of outputs takes each loaded row of weights once for
//! all its examples, as a matrix product does.
//!
//! The sums are the single-example kernels' own, lane by lane: each output of each example
//! starts from its bias (or zero) and adds one fused multiply–add per input in ascending order,
//! in two chains (even and odd inputs, added at the end) exactly where [`super::columns`] uses
//! two (the same blocks of 32 lanes decide it). So every value is the same bits as one pass
//! per example, whatever the tile; tests check that on every net shape the rollout loss
//! fine-tunes, and others.

use super::{dual_chains, pad4, sigmoid_lanes, Lanes, Packed, Portable};
#[cfg(target_arch = "x86_64")]
use super::{Avx2, Avx512};

/// Examples and lane groups of one register tile, by lane width and whether its outputs are
/// summed in two chains: (MR, NR). AVX-512 has 32 registers: 24 accumulators. AVX2 has 16:
/// 9 or 8 accumulators, as the weights' row and two broadcasts need registers too (with 12
/// accumulators one was kept on the stack, and the loop waited on it).
const fn tile_shape(width: usize, dual: bool) -> (usize, usize) {
    match (width, dual) {
        (8, false) => (6, 4),
        (8, true) => (3, 4),
        (_, false) => (3, 3),
        (_, true) => (2, 2),
    }
}

/// For every example e < `examples` (inputs `xs[e·xstride ..]`, `k` of them) and output
/// l < `n`: s = init[l] + Σ_k a[k, l] x_e[k] (σ(s) when `SIGMOID`), summed as [`super::columns`]
/// sums it, handed to `out` a lane group at a time (outputs j .. j + WIDTH, those at `n` and
/// beyond padding).
#[inline(always)]
fn columns_many<L: Lanes, const SIGMOID: bool>(
    a: &[f64],
    stride: usize,
    (xs, xstride, k): (&[f64], usize, usize),
    examples: usize,
    (init, n): (&[f64], usize),
    out: &mut Out<'_>,
) {
    let w = L::WIDTH;
    assert!(stride.is_multiple_of(w) && n <= stride);
    assert!(a.len() >= k * stride, "packed matrix too short");
    assert!(init.len() >= stride, "initial values too short");
    if examples == 0 {
        return;
    }
    assert!((examples - 1) * xstride + k <= xs.len(), "inputs too short");
    let mut j0 = 0;
    while j0 < n {
        // The blocks of `columns`: up to 32 lanes, two chains where the block (its outputs
        // padded to 4) has at most 5 groups of 4.
        let width = (stride - j0).min(32);
        let dual = dual_chains((pad4(n) - j0).min(32) / 4);
        let groups = width / w;
        let mut g0 = 0;
        while g0 < groups {
            let nr = tile_shape(w, dual).1.min(groups - g0);
            let args = (a, stride, j0 + g0 * w, (xs, xstride, k), init);
            match (dual, nr) {
                (false, 4) => rows::<L, SIGMOID, 4, false>(args, examples, out),
                (false, 3) => rows::<L, SIGMOID, 3, false>(args, examples, out),
                (false, 2) => rows::<L, SIGMOID, 2, false>(args, examples, out),
                (false, _) => rows::<L, SIGMOID, 1, false>(args, examples, out),
                (true, 4) => rows::<L, SIGMOID, 4, true>(args, examples, out),
                (true, 3) => rows::<L, SIGMOID, 3, true>(args, examples, out),
                (true, 2) => rows::<L, SIGMOID, 2, true>(args, examples, out),
                (true, _) => rows::<L, SIGMOID, 1, true>(args, examples, out),
            }
            g0 += nr;
        }
        j0 += width;
    }
}

/// A strip's arguments: the matrix, its stride, the strip's first output, the inputs (values,
/// stride, count) and the initial values.
type Strip<'a> = (
    &'a [f64],
    usize,
    usize,
    (&'a [f64], usize, usize),
    &'a [f64],
);

/// The NR lane groups from output `jg` of every example, in tiles of examples.
#[inline(always)]
fn rows<L: Lanes, const SIGMOID: bool, const NR: usize, const DUAL: bool>(
    args: Strip<'_>,
    examples: usize,
    out: &mut Out<'_>,
) {
    let mr = tile_shape(L::WIDTH, DUAL).0;
    let mut e0 = 0;
    while e0 < examples {
        // Tiles of MR examples, then of 4, 3, 2 or 1 (at most MR).
        e0 += match mr.min(examples - e0) {
            6 => tile::<L, SIGMOID, 6, NR, DUAL>(args, e0, out),
            5 | 4 => tile::<L, SIGMOID, 4, NR, DUAL>(args, e0, out),
            3 => tile::<L, SIGMOID, 3, NR, DUAL>(args, e0, out),
            2 => tile::<L, SIGMOID, 2, NR, DUAL>(args, e0, out),
            _ => tile::<L, SIGMOID, 1, NR, DUAL>(args, e0, out),
        };
    }
}

/// One tile: MR examples from `e0` × NR lane groups from output `jg`, the accumulators in
/// registers over the whole sum; returns MR.
#[inline(always)]
fn tile<L: Lanes, const SIGMOID: bool, const MR: usize, const NR: usize, const DUAL: bool>(
    (a, stride, jg, (xs, xstride, k), init): Strip<'_>,
    e0: usize,
    out: &mut Out<'_>,
) -> usize {
    let w = L::WIDTH;
    // What `step` reads without checks (`columns_many` checked the rest).
    assert!(jg + NR * w <= stride && (e0 + MR - 1) * xstride + k <= xs.len());
    let mut acc = [[L::splat(0.0); NR]; MR];
    for row in acc.iter_mut() {
        for (g, v) in row.iter_mut().enumerate() {
            *v = L::load(&init[jg + g * w..]);
        }
    }
    let x = &xs[e0 * xstride..];
    if DUAL {
        let mut odd = [[L::splat(0.0); NR]; MR];
        let mut kk = 0;
        while kk + 1 < k {
            step::<L, MR, NR>(&mut acc, a, stride, jg, (x, xstride), kk);
            step::<L, MR, NR>(&mut odd, a, stride, jg, (x, xstride), kk + 1);
            kk += 2;
        }
        if kk < k {
            step::<L, MR, NR>(&mut acc, a, stride, jg, (x, xstride), kk);
        }
        for (row, odd) in acc.iter_mut().zip(odd) {
            for (v, o) in row.iter_mut().zip(odd) {
                *v = L::add(*v, o);
            }
        }
    } else {
        for kk in 0..k {
            step::<L, MR, NR>(&mut acc, a, stride, jg, (x, xstride), kk);
        }
    }
    for (e, row) in acc.iter().enumerate() {
        for (g, &v) in row.iter().enumerate() {
            let v = if SIGMOID { sigmoid_lanes::<L>(v) } else { v };
            out.put::<L>(e0 + e, jg + g * w, v);
        }
    }
    MR
}

/// Input `kk` of a tile: acc[e][g] ← fma(a[kk, jg + g·WIDTH ..], x_e[kk], acc[e][g]).
#[inline(always)]
fn step<L: Lanes, const MR: usize, const NR: usize>(
    acc: &mut [[L::V; NR]; MR],
    a: &[f64],
    stride: usize,
    jg: usize,
    (x, xstride): (&[f64], usize),
    kk: usize,
) {
    let w = L::WIDTH;
    let start = kk * stride + jg;
    debug_assert!(start + NR * w <= a.len() && (MR - 1) * xstride + kk < x.len());
    // SAFETY: kk < k and jg + NR·WIDTH ≤ stride with a.len() ≥ k·stride (checked by
    // `columns_many` and `tile`), and x holds MR rows of `xstride` with k inputs each.
    let row = unsafe { a.get_unchecked(start..start + NR * w) };
    let mut b = [L::splat(0.0); NR];
    for (g, b) in b.iter_mut().enumerate() {
        *b = L::load(&row[g * w..]);
    }
    for (e, acc) in acc.iter_mut().enumerate() {
        let xv = L::splat(unsafe { *x.get_unchecked(e * xstride + kk) });
        for (acc, &b) in acc.iter_mut().zip(&b) {
            *acc = L::fma(b, xv, *acc);
        }
    }
}

/// Where a product's sums go: rows of `n` values of `out`, each value as it is, or, for h̄, times
/// h ⊙ (1 − h) with h the same place's value in `hidden`.
struct Out<'a> {
    out: &'a mut [f64],
    n: usize,
    hidden: Option<&'a [f64]>,
}

impl Out<'_> {
    /// Lane group `v`: outputs j .. j + WIDTH of example `e`, those before `n` written.
    #[inline(always)]
    fn put<L: Lanes>(&mut self, e: usize, j: usize, v: L::V) {
        let (w, n) = (L::WIDTH, self.n);
        if j >= n {
            // Padding only (4 lanes on a layout padded for 8).
            return;
        }
        let v = match self.hidden {
            // s · h · (1 − h), multiplied in that order as `hidden_bar` does.
            Some(h) => {
                let hv = if j + w <= n {
                    L::load(&h[e * n + j..])
                } else {
                    let mut lanes = [0.0; 8];
                    lanes[..n - j].copy_from_slice(&h[e * n + j..(e + 1) * n]);
                    L::load(&lanes)
                };
                L::mul(L::mul(v, hv), L::sub(L::splat(1.0), hv))
            }
            None => v,
        };
        if j + w <= n {
            L::store(v, &mut self.out[e * n + j..]);
        } else {
            let mut lanes = [0.0; 8];
            L::store(v, &mut lanes);
            self.out[e * n + j..(e + 1) * n].copy_from_slice(&lanes[..n - j]);
        }
    }
}

/// [`super::forward`] of `examples` examples: rows of `x` (p values each), `h` (q) and `y` (r).
#[inline(always)]
fn forward_many_generic<L: Lanes>(
    pk: &Packed,
    examples: usize,
    x: &[f64],
    h: &mut [f64],
    y: &mut [f64],
) {
    let d = pk.d;
    assert!(x.len() >= examples * d.p && h.len() >= examples * d.q && y.len() >= examples * d.r);
    let mut out = Out {
        out: h,
        n: d.q,
        hidden: None,
    };
    columns_many::<L, true>(
        &pk.w1t,
        d.qs,
        (x, d.p, d.p),
        examples,
        (&pk.b1, d.q),
        &mut out,
    );
    let mut out = Out {
        out: y,
        n: d.r,
        hidden: None,
    };
    columns_many::<L, false>(
        &pk.w2t,
        d.rs,
        (h, d.q, d.q),
        examples,
        (&pk.b2, d.r),
        &mut out,
    );
}

/// [`super::hidden_bar`] and [`super::input_bar`] of `examples` examples: rows of `h` and `hb`
/// (q values each), `y_bar` (r) and `x_bar` (p).
#[inline(always)]
fn backward_many_generic<L: Lanes>(
    pk: &Packed,
    examples: usize,
    (h, y_bar): (&[f64], &[f64]),
    hb: &mut [f64],
    x_bar: &mut [f64],
) {
    let d = pk.d;
    assert!(h.len() >= examples * d.q && hb.len() >= examples * d.q);
    assert!(y_bar.len() >= examples * d.r && x_bar.len() >= examples * d.p);
    let (w2, w1, zeros) = (&pk.w2, &pk.w1, &pk.zeros);
    let mut out = Out {
        out: hb,
        n: d.q,
        hidden: Some(h),
    };
    columns_many::<L, false>(
        w2,
        d.qs,
        (y_bar, d.r, d.r),
        examples,
        (zeros, d.q),
        &mut out,
    );
    let mut out = Out {
        out: x_bar,
        n: d.p,
        hidden: None,
    };
    columns_many::<L, false>(w1, d.ps, (hb, d.q, d.q), examples, (zeros, d.p), &mut out);
}

/// [`super::forward`] of `examples` examples at once, the same bits: rows of `x` (p values
/// each), `h` (q) and `y` (r), one after the other.
pub(in crate::emulator::mlp) fn forward_many(
    pk: &Packed,
    examples: usize,
    x: &[f64],
    h: &mut [f64],
    y: &mut [f64],
) {
    forward_many_run(pk, examples, x, h, y);
}

/// [`super::hidden_bar`] then [`super::input_bar`] of `examples` examples at once, the same
/// bits: rows of `h` and `hb` (q values each), `y_bar` (r) and `x_bar` (p).
pub(in crate::emulator::mlp) fn backward_many(
    pk: &Packed,
    examples: usize,
    (h, y_bar): (&[f64], &[f64]),
    hb: &mut [f64],
    x_bar: &mut [f64],
) {
    backward_many_run(pk, examples, (h, y_bar), hb, x_bar);
}

dispatch_wide!(
    forward_many_run,
    forward_many_generic,
    (pk: &Packed, examples: usize, x: &[f64], h: &mut [f64], y: &mut [f64])
);
dispatch_wide!(
    backward_many_run,
    backward_many_generic,
    (
        pk: &Packed,
        examples: usize,
        hy: (&[f64], &[f64]),
        hb: &mut [f64],
        x_bar: &mut [f64]
    )
);

#[cfg(test)]
mod tests {
    use super::super::{forward_generic, hidden_bar_generic, input_bar_generic};
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// On portable lanes (what a processor without AVX2 runs), the many-example passes are
    /// the single-example passes bit for bit (the dispatched lanes are tested through
    /// [`crate::emulator::mlp::Mlp`]).
    #[test]
    fn portable_many_example_passes_are_the_single_example_passes() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        for (p, q, r) in [(17, 50, 13), (84, 50, 78), (15, 7, 13), (3, 5, 2)] {
            let mut draw =
                |n: usize| -> Vec<f64> { (0..n).map(|_| rng.random_range(-2.0..2.0)).collect() };
            let (w1, b1, w2, b2) = (draw(q * p), draw(q), draw(r * q), draw(r));
            let pk = Packed::new(p, q, r, &w1, &b1, &w2, &b2);
            let examples = 11;
            let (x, yb) = (draw(examples * p), draw(examples * r));
            let (mut h, mut y) = (vec![0.0; examples * q], vec![0.0; examples * r]);
            forward_many_generic::<Portable>(&pk, examples, &x, &mut h, &mut y);
            let (mut hb, mut xb) = (vec![0.0; examples * q], vec![0.0; examples * p]);
            backward_many_generic::<Portable>(&pk, examples, (&h, &yb), &mut hb, &mut xb);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            for e in 0..examples {
                let (mut h1, mut y1) = (vec![0.0; q], vec![0.0; r]);
                forward_generic::<Portable>(&pk, &x[e * p..(e + 1) * p], &mut h1, &mut y1);
                let (mut hb1, mut xb1) = (vec![0.0; q], vec![0.0; p]);
                hidden_bar_generic::<Portable>(&pk, &h1, &yb[e * r..(e + 1) * r], &mut hb1);
                input_bar_generic::<Portable>(&pk, &hb1, &mut xb1);
                let at = format!("{p}-{q}-{r}, example {e}");
                assert_eq!(bits(&h1), bits(&h[e * q..(e + 1) * q]), "{at}: hidden");
                assert_eq!(bits(&y1), bits(&y[e * r..(e + 1) * r]), "{at}: output");
                assert_eq!(bits(&hb1), bits(&hb[e * q..(e + 1) * q]), "{at}: h̄");
                assert_eq!(bits(&xb1), bits(&xb[e * p..(e + 1) * p]), "{at}: x̄");
            }
        }
    }
}
