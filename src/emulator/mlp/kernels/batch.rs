//! # Batch passes: a chunk's five products, one multiply–add chain per entry
//!
//! The loss gradient of a chunk of n examples (rows of X, n × p, and of the targets T) is five
//! matrix products and three element-wise steps:
//!
//! ```text
//! H  = σ(X W₁ᵀ + b₁)        n × q
//! E  = H W₂ᵀ + b₂ − T       n × r     loss ½ Σ E²
//! H̄  = (E W₂) ⊙ H ⊙ (1 − H)  n × q
//! ∂W₁ = H̄ᵀ X,  ∂b₁ = Σ_τ H̄[τ]       ∂W₂ = Eᵀ H,  ∂b₂ = Σ_τ E[τ]
//! ```
//!
//! Every entry of a product is one sum Σ_k a[i, k] b[k, j] taken from zero in ascending k, one
//! fused multiply–add per term, the bias (where there is one) added after the sum. That is the
//! order in which `matrixmultiply`'s `dgemm` (which ndarray's products call) sums each entry
//! when k is at most its depth block [`MAX_DEPTH`], on every processor with fused multiply–add,
//! so these passes are the same bits as the ndarray products they replace (tested against
//! them). What is gone is its generality: it packs both operands into aligned panels on every
//! call and allocates, and for the small products of a mini-batch that was about as much time
//! as the arithmetic. Here the weights are packed once per gradient ([`BatchNet`]),
//! the activations are written by one product in the layout the next one reads, the σ, bias
//! and cotangent steps run on the lanes as each product's rows are finished, and the scratch
//! is one buffer per thread.
//!
//! A product C = A B vectorizes across the columns of C: B's rows hold lane groups of W
//! columns (W = 8 on AVX-512, 4 on AVX2), and a register tile of MR rows × NR groups of C
//! takes, for each k, NR loads of B's row k and MR broadcasts of A's column k. A is read
//! through strides, so H̄ᵀ and Eᵀ are never formed.

use super::{sigmoid_groups, sigmoid_lanes, wide_lanes, Dims, Lanes, Portable};
#[cfg(target_arch = "x86_64")]
use super::{Avx2, Avx512};
use crate::lanes::Aligned;
use ndarray::ArrayView2;
use std::cell::RefCell;

/// The longest sum (inputs, hidden units, outputs, rows of a chunk) the batch passes take:
/// `matrixmultiply` splits sums longer than its depth block (KC = 256 for f64) into partial
/// sums, an order these passes do not reproduce.
pub(in crate::emulator::mlp) const MAX_DEPTH: usize = 256;

/// Values per 64-byte cache line. The buffers start on a line and every padded row is a whole
/// number of lane groups, so no AVX-512 load or store of a lane group straddles two lines
/// (measured: 12% of the 84-50-78 full-batch gradient), nor an AVX2 one.
const LINE: usize = 8;

/// The index of the first value of `v` on a cache line.
fn line_offset(v: &[f64]) -> usize {
    v.as_ptr().align_offset(64).min(LINE)
}

/// The rows of the chunk this thread will most likely take next (the batch's next chunk), to
/// be fetched into the L2 cache a few lines at a time, before each register tile of this
/// chunk's products, so that reading them does not wait on memory.
///
/// The 84-50-78 full batch streams 85 MB of examples and targets through the cache; a chunk's
/// products run long enough to fetch the next chunk's rows many times over, but without a hint
/// the first reads of each chunk (copying its inputs, subtracting its targets) waited on them.
/// A prefetch only moves data into the cache: it changes no value, faults on no address, and
/// costs nothing but time when the guess is wrong (the next chunk went to another thread).
pub(in crate::emulator::mlp) struct Ahead {
    /// Each part's first cache line and its number of lines (the inputs, then the targets).
    parts: [(*const u8, usize); 2],
    /// The part being fetched, and the next line in it.
    part: usize,
    line: usize,
    /// Lines per tile, set by [`Ahead::pace`].
    per: usize,
}

impl Ahead {
    /// Nothing to fetch.
    pub(in crate::emulator::mlp) fn none() -> Self {
        Self {
            parts: [(std::ptr::null(), 0); 2],
            part: 2,
            line: 0,
            per: 0,
        }
    }

    /// The rows of `x` and `t` where each is contiguous (a part that is not is skipped).
    pub(in crate::emulator::mlp) fn rows(x: ArrayView2<'_, f64>, t: ArrayView2<'_, f64>) -> Self {
        let lines = |v: ArrayView2<'_, f64>| match v.to_slice() {
            Some(s) if !s.is_empty() => {
                let skew = s.as_ptr() as usize % 64;
                let first = s.as_ptr().cast::<u8>().wrapping_sub(skew);
                (first, (skew + std::mem::size_of_val(s)).div_ceil(64))
            }
            _ => (std::ptr::null(), 0),
        };
        Self {
            parts: [lines(x), lines(t)],
            part: 0,
            line: 0,
            per: 0,
        }
    }

    /// Spreads the lines over `tiles` calls of [`Ahead::fetch`].
    fn pace(&mut self, tiles: usize) {
        let lines = self.parts[0].1 + self.parts[1].1;
        self.per = lines.div_ceil(tiles.max(1));
    }

    /// Fetches the next [`Ahead::pace`] lines, if any are left.
    #[inline(always)]
    fn fetch(&mut self) {
        for _ in 0..self.per {
            match self.next_line() {
                Some(line) => crate::lanes::prefetch_l2(line),
                None => return,
            }
        }
    }

    /// The next cache line to fetch: every line of the inputs, then of the targets.
    #[inline(always)]
    fn next_line(&mut self) -> Option<*const u8> {
        while self.part < 2 {
            let (first, lines) = self.parts[self.part];
            if self.line < lines {
                self.line += 1;
                return Some(first.wrapping_add((self.line - 1) * 64));
            }
            (self.part, self.line) = (self.part + 1, 0);
        }
        None
    }
}

/// The register tiles [`product`] takes for `m` rows and `groups` lane groups of `w` lanes.
fn tile_count(m: usize, groups: usize, w: usize) -> usize {
    let mut tiles = 0;
    let mut g0 = 0;
    while g0 < groups {
        let nr = strip_width(groups, g0, w);
        tiles += m.div_ceil(tile_rows(nr, w));
        g0 += nr;
    }
    tiles
}

/// NR, the most lane groups of `w` lanes in one of [`product`]'s tiles: 16 accumulators on
/// AVX-512 (32 registers), at most 10 on AVX2 (16 registers; [`tile_rows`]).
const fn strip_groups(w: usize) -> usize {
    if w == 8 {
        4
    } else {
        3
    }
}

/// The lane groups of [`product`]'s strip from group `g0` of `groups` groups of `w` lanes: NR
/// ([`strip_groups`]) or what is left, except that on 4 lanes the last four groups of a
/// product wider than four go as two strips of two, so that it does not end in a strip of one
/// group (13 groups, the 50 hidden units of every Table 1 net, as 3, 3, 3, 2, 2 instead of
/// 3, 3, 3, 3, 1). The strips' widths do not change any entry's chain, only which tile
/// computes it.
const fn strip_width(groups: usize, g0: usize, w: usize) -> usize {
    let (nr, left) = (strip_groups(w), groups - g0);
    if w != 8 && left == nr + 1 && g0 > 0 {
        2
    } else if left < nr {
        left
    } else {
        nr
    }
}

/// MR, the rows of [`product`]'s tiles of `nr` lane groups of `w` lanes.
///
/// On 4 lanes (AVX2's 16 registers) a tile keeps at most 10 accumulators: with 12 (4 × 3 and
/// 6 × 2), LLVM kept one on the stack, stored and reloaded at every depth step, and that
/// accumulator's chain (a store-to-load forward and a multiply–add each step) held the whole
/// tile. On AMD Zen 3 (no AVX-512) these shapes alone took the 84-50-78 full batch from 138 to
/// 101 ms.
const fn tile_rows(nr: usize, w: usize) -> usize {
    match (nr, w) {
        (4, _) => 6,
        (3, 8) => 8,
        (3, _) => 3,
        (2, 8) => 6,
        (2, _) => 5,
        _ => 8,
    }
}

/// A p → q → r net's weights in the layouts the batch products read, each row padded with
/// zeros to whole lane groups (8 lanes where the processor has AVX-512, else 4):
///
/// ```text
/// w1t  p × q̃   W₁ᵀ   (B of H = X W₁ᵀ)
/// w2t  q × r̃   W₂ᵀ   (B of E = H W₂ᵀ)
/// w2   r × q̃   W₂    (B of H̄ = E W₂)
/// b1   q̃,  b2  r̃
/// ```
///
/// Packed once per gradient, in one buffer (the thread's last, [`BatchNet::reused`]); every
/// chunk reads it.
#[derive(Debug, Clone)]
pub(in crate::emulator::mlp) struct BatchNet {
    d: Dims,
    /// w1t, w2t, w2, b1, b2, one after the other, the first value on a cache line.
    data: Aligned,
}

impl BatchNet {
    /// Packs W₁ (q × p, row-major), b₁, W₂ (r × q, row-major) and b₂, padded for 8 lanes
    /// (`wide`, only where the processor has AVX-512) or 4.
    pub(in crate::emulator::mlp) fn with_lanes(
        (p, q, r): (usize, usize, usize),
        weights: (&[f64], &[f64], &[f64], &[f64]),
        wide: bool,
    ) -> Self {
        let d = Dims::padded(p, q, r, wide);
        let data = Aligned::zeros(p * d.qs + q * d.rs + r * d.qs + d.qs + d.rs);
        let mut net = Self { d, data };
        net.fill(weights);
        net
    }

    /// [`BatchNet::with_lanes`] for this processor's lanes, in the buffer of this thread's last
    /// packing given back by [`BatchNet::recycle`] when it was of the same shape (else a new
    /// one): every weight is written again, and the padding, never written, is still zero. A
    /// mini-batch step packs the net once, and the allocation and zeroing were about 3% of a
    /// 17-50-13 step.
    pub(in crate::emulator::mlp) fn reused(
        (p, q, r): (usize, usize, usize),
        (w1, b1, w2, b2): (&[f64], &[f64], &[f64], &[f64]),
    ) -> Self {
        let d = Dims::padded(p, q, r, wide_lanes());
        // Taken out of the thread's slot, not borrowed: a nested gradient on this thread
        // (rayon may run one while this one waits) finds the slot empty and allocates.
        match LAST_PACKED.take() {
            Some(mut net) if net.d == d => {
                net.fill((w1, b1, w2, b2));
                net
            }
            _ => Self::with_lanes((p, q, r), (w1, b1, w2, b2), d.wide),
        }
    }

    /// Gives the buffer back to this thread for its next [`BatchNet::reused`].
    pub(in crate::emulator::mlp) fn recycle(self) {
        LAST_PACKED.set(Some(self));
    }

    /// Writes W₁ (q × p, row-major), b₁, W₂ (r × q, row-major) and b₂ to their places in the
    /// layouts (the padding is not written).
    fn fill(&mut self, (w1, b1, w2, b2): (&[f64], &[f64], &[f64], &[f64])) {
        let Dims {
            p, q, r, qs, rs, ..
        } = self.d;
        let (w1t, rest) = self.data.split_at_mut(p * qs);
        let (w2t, rest) = rest.split_at_mut(q * rs);
        let (w2p, rest) = rest.split_at_mut(r * qs);
        let (b1p, b2p) = rest.split_at_mut(qs);
        transpose(w1, (q, p), w1t, qs);
        transpose(w2, (r, q), w2t, rs);
        for (row, s) in w2p.chunks_exact_mut(qs).zip(w2.chunks_exact(q)) {
            row[..q].copy_from_slice(s);
        }
        b1p[..q].copy_from_slice(b1);
        b2p[..r].copy_from_slice(b2);
    }

    /// (w1t, w2t, w2, b1, b2).
    #[allow(clippy::type_complexity)]
    fn parts(&self) -> (&[f64], &[f64], &[f64], &[f64], &[f64]) {
        let (w1t, rest) = self.data.split_at(self.d.p * self.d.qs);
        let (w2t, rest) = rest.split_at(self.d.q * self.d.rs);
        let (w2, rest) = rest.split_at(self.d.r * self.d.qs);
        let (b1, b2) = rest.split_at(self.d.qs);
        (w1t, w2t, w2, b1, b2)
    }
}

/// d[c·ds + r] = s[r·cols + c] for the `rows` × `cols` row-major matrix `s` (a copy: the same
/// bits). 4 × 4 blocks go through AVX registers where the processor has AVX2 (measured: 7–8%
/// of a mini-batch step faster than element by element; with the buffer reused
/// ([`BatchNet::reused`]), the two transposes are about 6% of a 17-50-13 step in `perf`).
fn transpose(s: &[f64], (rows, cols): (usize, usize), d: &mut [f64], ds: usize) {
    assert!(s.len() >= rows * cols && ds >= rows);
    assert!(cols == 0 || d.len() >= (cols - 1) * ds + rows);
    let (mut r4, mut c4) = (0, 0);
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2() {
        (r4, c4) = (rows / 4 * 4, cols / 4 * 4);
        // SAFETY: the processor has AVX2 (checked just above); the blocks read rows < r4 ≤
        // rows and columns < c4 ≤ cols of `s`, and write d[c·ds + r] for the same r and c,
        // in bounds by the assertions.
        unsafe { transpose_blocks(s, cols, d, ds, (r4, c4)) };
    }
    for r in 0..rows {
        let from = if r < r4 { c4 } else { 0 };
        for c in from..cols {
            d[c * ds + r] = s[r * cols + c];
        }
    }
}

/// The 4 × 4 blocks of [`transpose`] over rows < r4 and columns < c4 (multiples of 4).
///
/// # Safety
/// The processor must have AVX2, and `s` (row stride `cols`) and `d` (row stride `ds`) must
/// hold those rows and columns.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn transpose_blocks(
    s: &[f64],
    cols: usize,
    d: &mut [f64],
    ds: usize,
    (r4, c4): (usize, usize),
) {
    use std::arch::x86_64::*;
    let (sp, dp) = (s.as_ptr(), d.as_mut_ptr());
    for r in (0..r4).step_by(4) {
        for c in (0..c4).step_by(4) {
            // SAFETY: rows r .. r + 4 and columns c .. c + 4 are in bounds (the caller).
            unsafe {
                let a0 = _mm256_loadu_pd(sp.add(r * cols + c));
                let a1 = _mm256_loadu_pd(sp.add((r + 1) * cols + c));
                let a2 = _mm256_loadu_pd(sp.add((r + 2) * cols + c));
                let a3 = _mm256_loadu_pd(sp.add((r + 3) * cols + c));
                let t0 = _mm256_unpacklo_pd(a0, a1);
                let t1 = _mm256_unpackhi_pd(a0, a1);
                let t2 = _mm256_unpacklo_pd(a2, a3);
                let t3 = _mm256_unpackhi_pd(a2, a3);
                _mm256_storeu_pd(dp.add(c * ds + r), _mm256_permute2f128_pd::<0x20>(t0, t2));
                _mm256_storeu_pd(
                    dp.add((c + 1) * ds + r),
                    _mm256_permute2f128_pd::<0x20>(t1, t3),
                );
                _mm256_storeu_pd(
                    dp.add((c + 2) * ds + r),
                    _mm256_permute2f128_pd::<0x31>(t0, t2),
                );
                _mm256_storeu_pd(
                    dp.add((c + 3) * ds + r),
                    _mm256_permute2f128_pd::<0x31>(t1, t3),
                );
            }
        }
    }
}

/// c[i, ·] = Σ_k a[i·ars + k·acs] b[k·bs + ·] for i < m over the first `groups` lane groups of
/// each row of B and C (row strides `bs`, `cs`): each entry summed from zero, k ascending, one
/// fused multiply–add per term.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn product<L: Lanes>(
    m: usize,
    groups: usize,
    k: usize,
    a: (&[f64], usize, usize),
    b: (&[f64], usize),
    c: (&mut [f64], usize),
    ahead: &mut Ahead,
) {
    product_alongside::<L, ()>(m, groups, k, a, b, c, ahead, &mut ());
}

/// [`product`] with `side`'s work done a little at every depth step of every tile
/// ([`Alongside`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn product_alongside<L: Lanes, S: Alongside>(
    m: usize,
    groups: usize,
    k: usize,
    (a, ars, acs): (&[f64], usize, usize),
    (b, bs): (&[f64], usize),
    (c, cs): (&mut [f64], usize),
    ahead: &mut Ahead,
    side: &mut S,
) {
    let w = L::WIDTH;
    if m == 0 || groups == 0 {
        return;
    }
    assert!(groups * w <= bs.min(cs), "lane groups beyond a row");
    assert!((m - 1) * cs + groups * w <= c.len(), "C too short");
    if k == 0 {
        for i in 0..m {
            c[i * cs..i * cs + groups * w].fill(0.0);
        }
        return;
    }
    assert!((m - 1) * ars + (k - 1) * acs < a.len(), "A too short");
    assert!((k - 1) * bs + groups * w <= b.len(), "B too short");
    let mut g0 = 0;
    while g0 < groups {
        let nr = strip_width(groups, g0, w);
        let b = &b[g0 * w..];
        let (a, c) = ((a, ars, acs), (&mut c[g0 * w..], cs));
        // The rows of the tiles, MR, are `tile_rows(nr, w)` (which `tile_count` counts).
        match (nr, w) {
            (4, _) => rows::<L, S, 4, 6>(m, k, a, (b, bs), c, ahead, side),
            (3, 8) => rows::<L, S, 3, 8>(m, k, a, (b, bs), c, ahead, side),
            (3, _) => rows::<L, S, 3, 3>(m, k, a, (b, bs), c, ahead, side),
            (2, 8) => rows::<L, S, 2, 6>(m, k, a, (b, bs), c, ahead, side),
            (2, _) => rows::<L, S, 2, 5>(m, k, a, (b, bs), c, ahead, side),
            _ => rows::<L, S, 1, 8>(m, k, a, (b, bs), c, ahead, side),
        }
        g0 += nr;
    }
}

/// The rows of [`product`] for NR lane groups: tiles of MR rows, then one tile of the rows
/// left. The bounds were checked by [`product`].
#[inline(always)]
fn rows<L: Lanes, S: Alongside, const NR: usize, const MR: usize>(
    m: usize,
    k: usize,
    (a, ars, acs): (&[f64], usize, usize),
    (b, bs): (&[f64], usize),
    (c, cs): (&mut [f64], usize),
    ahead: &mut Ahead,
    side: &mut S,
) {
    let mut i0 = 0;
    while i0 < m {
        ahead.fetch();
        let mr = MR.min(m - i0);
        // SAFETY: `product` checked that rows i0 .. i0 + mr of A (k columns) and of C (NR
        // groups), and k rows of B (NR groups from this offset), are in bounds.
        unsafe {
            let (ap, cp) = (a.as_ptr().add(i0 * ars), c.as_mut_ptr().add(i0 * cs));
            let args = (k, ap, ars, acs, b.as_ptr(), bs, cp, cs);
            match mr {
                8 => tile::<L, S, 8, NR>(args, side),
                7 => tile::<L, S, 7, NR>(args, side),
                6 => tile::<L, S, 6, NR>(args, side),
                5 => tile::<L, S, 5, NR>(args, side),
                4 => tile::<L, S, 4, NR>(args, side),
                3 => tile::<L, S, 3, NR>(args, side),
                2 => tile::<L, S, 2, NR>(args, side),
                _ => tile::<L, S, 1, NR>(args, side),
            }
        }
        i0 += mr;
    }
}

/// Arguments of one [`tile`]: depth, A (pointer, row and column strides), B (pointer, row
/// stride), C (pointer, row stride).
type TileArgs = (
    usize,
    *const f64,
    usize,
    usize,
    *const f64,
    usize,
    *mut f64,
    usize,
);

/// One MR × NR-group tile of C, its accumulators in registers over the whole sum.
///
/// # Safety
/// A's entries (i·ars + k·acs) for i < MR, k < depth, B's (k·bs + l) and C's (i·cs + l) for
/// l < NR·WIDTH must be in bounds.
#[inline(always)]
unsafe fn tile<L: Lanes, S: Alongside, const MR: usize, const NR: usize>(
    (k, a, ars, acs, b, bs, c, cs): TileArgs,
    side: &mut S,
) {
    let w = L::WIDTH;
    let mut acc = [[L::splat(0.0); NR]; MR];
    let (mut a, mut b) = (a, b);
    for _ in 0..k {
        let mut bv = [L::splat(0.0); NR];
        for (g, v) in bv.iter_mut().enumerate() {
            *v = L::load(unsafe { std::slice::from_raw_parts(b.add(g * w), w) });
        }
        for (i, row) in acc.iter_mut().enumerate() {
            let s = L::splat(unsafe { *a.add(i * ars) });
            for (acc, &bv) in row.iter_mut().zip(&bv) {
                *acc = L::fma(s, bv, *acc);
            }
        }
        side.step();
        a = a.wrapping_add(acs);
        b = b.wrapping_add(bs);
    }
    for (i, row) in acc.iter().enumerate() {
        for (g, &v) in row.iter().enumerate() {
            L::store(v, unsafe {
                std::slice::from_raw_parts_mut(c.add(i * cs + g * w), w)
            });
        }
    }
}

/// Work done a little at each depth step of a [`product_alongside`]'s tiles: a chain of
/// dependent operations (each waiting on the last) that the tile's independent multiply–adds
/// hide, where alone it would wait on its own latency.
trait Alongside {
    /// One step's share of the work.
    fn step(&mut self);
}

/// Nothing alongside.
impl Alongside for () {
    #[inline(always)]
    fn step(&mut self) {}
}

/// The sum of squares of a chunk's errors, the first `r` values of each of the `n` rows of E
/// (row stride `rs`), taken in row-major order one after the other from −0, as
/// `Iterator::sum` takes them (so the same bits), `per` values at each step.
///
/// The rows are taken whole, their padding included, which must be zeros (±0, as the products
/// leave it): a square of zero is +0, and adding +0 to a sum changes nothing but a −0 start,
/// which the next value's square replaces just the same (a row starts with one of its own
/// values). One bound and one index a value, where skipping each row's padding took two more
/// tests and three more values held in registers: on AVX2's 16 registers those were
/// reloaded from the stack at every step of the product they ride along (seen in the
/// disassembly on AMD Zen 3).
///
/// Alone, the 84-50-78 full batch's sum (19,968 additions per chunk of 256, each waiting on the
/// last) was about a twentieth of the gradient's time; carried along the next product, the
/// tiles' multiply–adds hide it.
struct Squares<'a> {
    /// The n rows of E whole (padding included).
    e: &'a [f64],
    /// Index of the next value.
    at: usize,
    /// Values per step.
    per: usize,
    sum: f64,
}

impl<'a> Squares<'a> {
    /// The sum over `e` (n rows of stride `rs`, the first `r` of each, the rest zeros), `per`
    /// values a step.
    fn new(e: &'a [f64], n: usize, (r, rs): (usize, usize), per: usize) -> Self {
        assert!(r <= rs && n * rs <= e.len());
        let e = &e[..n * rs];
        debug_assert!(
            e.chunks_exact(rs.max(1))
                .all(|row| row[r..].iter().all(|v| *v == 0.0)),
            "padding that is not zero"
        );
        Self {
            e,
            at: 0,
            per,
            sum: -0.0,
        }
    }

    /// The sum, after the values no step took.
    fn finish(mut self) -> f64 {
        for v in &self.e[self.at.min(self.e.len())..] {
            self.sum += v * v;
        }
        self.sum
    }
}

impl Alongside for Squares<'_> {
    #[inline(always)]
    fn step(&mut self) {
        if self.per == 1 {
            // One value a step (AVX2's smaller tiles take more steps): no inner loop.
            if let Some(v) = self.e.get(self.at) {
                self.sum += v * v;
                self.at += 1;
            }
            return;
        }
        let (from, to) = (self.at, (self.at + self.per).min(self.e.len()));
        if from < to {
            for v in &self.e[from..to] {
                self.sum += v * v;
            }
            self.at = to;
        }
    }
}

thread_local! {
    /// Each thread's last [`BatchNet`], for [`BatchNet::reused`].
    static LAST_PACKED: std::cell::Cell<Option<BatchNet>> = const { std::cell::Cell::new(None) };
    /// Each thread's scratch for [`chunk_loss_grad`]: the chunk's padded inputs, activations,
    /// errors, cotangents and gradient products.
    static SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

/// The loss ½ Σ ‖N(x^τ) − t^τ‖² of a chunk (at most [`MAX_DEPTH`] rows of `x` and `t`, the
/// net's sizes at most [`MAX_DEPTH`], at least 2 hidden units and 2 outputs) and its gradient,
/// written into the four parts of the weight layout (every value overwritten), each value and
/// the loss as 0 + v ([`plus_zero`]): the same bits as the ndarray products (module docs) added
/// to zero, as [`super::super::Mlp::loss_grad`] adds its chunks.
pub(in crate::emulator::mlp) fn chunk_loss_grad(
    pk: &BatchNet,
    x: ArrayView2<'_, f64>,
    t: ArrayView2<'_, f64>,
    (g1, gb1, g2, gb2): Grads<'_>,
    mut ahead: Ahead,
) -> f64 {
    let n = x.nrows();
    assert!(n <= MAX_DEPTH && pk.d.p.max(pk.d.q).max(pk.d.r) <= MAX_DEPTH);
    assert!(
        pk.d.q >= 2 && pk.d.r >= 2,
        "bias sums of one unit are ordered differently"
    );
    assert_eq!((x.ncols(), t.ncols(), t.nrows()), (pk.d.p, pk.d.r, n));
    assert_eq!((g1.len(), gb1.len()), (pk.d.q * pk.d.p, pk.d.q));
    assert_eq!((g2.len(), gb2.len()), (pk.d.r * pk.d.q, pk.d.r));
    let (ps, qs, rs) = (pk.d.ps, pk.d.qs, pk.d.rs);
    let need = n * (ps + 2 * qs + rs) + pk.d.q * ps + pk.d.r * qs + qs + rs;
    with_scratch(need, |scratch| {
        let mut loss = 0.0;
        run(pk, x, t, (g1, gb1, g2, gb2), scratch, &mut loss, &mut ahead);
        loss
    })
}

/// The loss ½ Σ ‖N(x^τ) − t^τ‖² of a chunk ([`chunk_loss_grad`]'s conditions), the same bits
/// as ndarray's products.
pub(in crate::emulator::mlp) fn chunk_loss(
    pk: &BatchNet,
    x: ArrayView2<'_, f64>,
    t: ArrayView2<'_, f64>,
    mut ahead: Ahead,
) -> f64 {
    let n = x.nrows();
    assert!(n <= MAX_DEPTH && pk.d.p.max(pk.d.q).max(pk.d.r) <= MAX_DEPTH);
    assert_eq!((x.ncols(), t.ncols(), t.nrows()), (pk.d.p, pk.d.r, n));
    with_scratch(n * (pk.d.ps + pk.d.qs + pk.d.rs), |scratch| {
        let mut loss = 0.0;
        run_loss(pk, x, t, scratch, &mut loss, &mut ahead);
        loss
    })
}

/// `f` on this thread's scratch, `len` values from a cache line.
fn with_scratch<T>(len: usize, f: impl FnOnce(&mut [f64]) -> T) -> T {
    SCRATCH.with_borrow_mut(|scratch| {
        if scratch.len() < len + LINE {
            scratch.resize(len + LINE, 0.0);
        }
        let start = line_offset(scratch);
        f(&mut scratch[start..start + len])
    })
}

dispatch_wide!(
    run_loss,
    chunk_loss_generic,
    (
        pk: &BatchNet,
        x: ArrayView2<'_, f64>,
        t: ArrayView2<'_, f64>,
        scratch: &mut [f64],
        loss: &mut f64,
        ahead: &mut Ahead
    )
);

dispatch_wide!(
    run,
    chunk_loss_grad_generic,
    (
        pk: &BatchNet,
        x: ArrayView2<'_, f64>,
        t: ArrayView2<'_, f64>,
        grads: Grads<'_>,
        scratch: &mut [f64],
        loss: &mut f64,
        ahead: &mut Ahead
    )
);

/// C ← A B, or C ← C + A B when `add`, for matrices of any shapes and strides (m × k times
/// k × n), each entry summed as `matrixmultiply`'s FMA kernel sums it (what ndarray's
/// `general_mat_mul` gave on a processor with FMA, the path the cached nets were trained on):
/// from zero, k ascending, one fused multiply–add per term, in blocks of [`MAX_DEPTH`] terms,
/// each block's sum added to C (the first one written instead where not `add`). The order is
/// fixed by the shapes, so the same bits on every processor (unlike `matrixmultiply`'s, whose
/// kernel is picked at run time: plain multiplies and adds without FMA), at the cost of libm's
/// exact `fma` per term where the processor has no FMA (or [`crate::simd`] forbids it). The
/// products of [`product`] on 4 lanes, A and B copied first into contiguous rows.
pub(in crate::emulator::mlp) fn general_product(
    a: ArrayView2<'_, f64>,
    b: ArrayView2<'_, f64>,
    mut c: ndarray::ArrayViewMut2<'_, f64>,
    add: bool,
) {
    let (m, k) = a.dim();
    let n = b.ncols();
    assert_eq!(b.nrows(), k, "inner dimensions");
    assert_eq!(c.dim(), (m, n), "C's shape");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !add {
            c.fill(0.0);
        }
        return;
    }
    let ns = n.div_ceil(4) * 4;
    let mut ap = Vec::with_capacity(m * k);
    for row in a.rows() {
        ap.extend(row.iter());
    }
    let mut bp = vec![0.0; k * ns];
    for (d, row) in bp.chunks_exact_mut(ns).zip(b.rows()) {
        for (d, s) in d.iter_mut().zip(row) {
            *d = *s;
        }
    }
    let mut sums = vec![0.0; m * ns];
    for (block, k0) in (0..k).step_by(MAX_DEPTH).enumerate() {
        let depth = MAX_DEPTH.min(k - k0);
        let args = (m, ns / 4, depth);
        general_product_lanes(args, (&ap[k0..], k), (&bp[k0 * ns..], ns), &mut sums);
        for (row, s) in c.rows_mut().into_iter().zip(sums.chunks_exact(ns)) {
            for (v, s) in row.into_iter().zip(s) {
                *v = if block == 0 && !add { *s } else { *v + s };
            }
        }
    }
}

/// One depth block of [`general_product`]: `sums` (m rows of `bs` values) ← A B for A's
/// rows of stride `ars` and B's rows of stride `bs`, `groups` lane groups of 4.
#[inline(always)]
fn general_product_generic<L: Lanes>(
    (m, groups, k): (usize, usize, usize),
    (a, ars): (&[f64], usize),
    (b, bs): (&[f64], usize),
    sums: &mut [f64],
) {
    let mut ahead = Ahead::none();
    product::<L>(m, groups, k, (a, ars, 1), (b, bs), (sums, bs), &mut ahead);
}

dispatch!(
    general_product_lanes,
    general_product_generic,
    (
        shape: (usize, usize, usize),
        a: (&[f64], usize),
        b: (&[f64], usize),
        sums: &mut [f64]
    )
);

/// The four parts of a gradient in the weight layout: ∂W₁, ∂b₁, ∂W₂, ∂b₂.
type Grads<'a> = (&'a mut [f64], &'a mut [f64], &'a mut [f64], &'a mut [f64]);

/// The forward half of a chunk on lanes `L`: the padded inputs `xp` (n × p̃), activations
/// `h` (n × q̃) and errors `e` (n × r̃).
#[inline(always)]
fn forward_generic<L: Lanes>(
    pk: &BatchNet,
    x: ArrayView2<'_, f64>,
    t: ArrayView2<'_, f64>,
    (xp, h, e): (&mut [f64], &mut [f64], &mut [f64]),
    ahead: &mut Ahead,
) {
    let w = L::WIDTH;
    let (p, q) = (pk.d.p, pk.d.q);
    let (ps, qs, rs) = (pk.d.ps, pk.d.qs, pk.d.rs);
    let n = x.nrows();
    let (w1t, w2t, _, b1, b2) = pk.parts();
    // The inputs, zero-padded to whole lane groups (they are B of ∂W₁ = H̄ᵀ X).
    for (row, xr) in xp.chunks_exact_mut(ps).zip(x.rows()) {
        copy_row::<L>(&mut row[..p], xr.view());
        row[p..].fill(0.0);
    }
    // H = σ(X W₁ᵀ + b₁): the sum, then the bias, then σ, on whole lane groups.
    product::<L>(n, qs / w, p, (xp, ps, 1), (w1t, qs), (h, qs), ahead);
    bias_sigmoid::<L>(&mut h[..n * qs], &b1[..qs]);
    // E = (H W₂ᵀ + b₂) − T.
    product::<L>(n, rs / w, q, (h, qs, 1), (w2t, rs), (e, rs), ahead);
    /// A row of E: the sum, then the bias, then the target off.
    #[inline(always)]
    fn error_row<'a>(row: &mut [f64], b2: &[f64], t: impl Iterator<Item = &'a f64>) {
        for ((v, b), t) in row.iter_mut().zip(b2).zip(t) {
            *v = (*v + b) - t;
        }
    }
    for (row, tr) in e.chunks_exact_mut(rs).zip(t.rows()) {
        // A contiguous target row as a slice, which the compiler vectorizes.
        match tr.as_slice() {
            Some(tr) => error_row(row, b2, tr.iter()),
            None => error_row(row, b2, tr.iter()),
        }
    }
}

/// h ← σ(h + b) on rows of `b.len()` values (a multiple of the lane width), several lane
/// groups at a time ([`sigmoid_groups`]; the same bits as one at a time): four on AVX-512,
/// six on 4 lanes. σ's polynomial is a chain of 13 multiply–adds per group; AMD Zen 3 runs
/// two 4-lane multiply–adds a cycle, each ready 4 cycles later, so four chains kept its units
/// half idle (the loop, about 200 instructions, is too long for the next block's chains to
/// start early). Six measured faster on Zen 3 (mini-batch steps, 17-50-13).
#[inline(always)]
fn bias_sigmoid<L: Lanes>(h: &mut [f64], b: &[f64]) {
    if L::WIDTH == 8 {
        bias_sigmoid_groups::<L, 4>(h, b)
    } else {
        bias_sigmoid_groups::<L, 6>(h, b)
    }
}

/// [`bias_sigmoid`], G lane groups at a time.
#[inline(always)]
fn bias_sigmoid_groups<L: Lanes, const G: usize>(h: &mut [f64], b: &[f64]) {
    let w = L::WIDTH;
    let per_row = b.len() / w;
    debug_assert!(per_row > 0 && h.len().is_multiple_of(b.len()));
    // The bias group of each lane group, counted along the rows (a remainder of the group's
    // index took an integer division per group).
    let mut g = 0;
    let mut bias = || {
        let v = L::load(&b[g * w..]);
        g = if g + 1 == per_row { 0 } else { g + 1 };
        v
    };
    let mut blocks = h.chunks_exact_mut(G * w);
    for block in &mut blocks {
        let mut z = [L::splat(0.0); G];
        for (j, z) in z.iter_mut().enumerate() {
            *z = L::add(L::load(&block[j * w..]), bias());
        }
        sigmoid_groups::<L, G>(&mut z);
        for (j, z) in z.iter().enumerate() {
            L::store(*z, &mut block[j * w..]);
        }
    }
    for v in blocks.into_remainder().chunks_exact_mut(w) {
        L::store(sigmoid_lanes::<L>(L::add(L::load(v), bias())), v);
    }
}

/// The loss ½ Σ E² of a chunk's errors `e` (n rows of stride r̃, the first r of each), the
/// rows in order as `Iterator::sum` sums a row-major array.
#[inline(always)]
fn loss_of(e: &[f64], (r, rs): (usize, usize)) -> f64 {
    0.5 * e
        .chunks_exact(rs)
        .flat_map(|row| &row[..r])
        .map(|v| v * v)
        .sum::<f64>()
}

/// The loss of a chunk on lanes `L` (no gradient).
#[inline(always)]
fn chunk_loss_generic<L: Lanes>(
    pk: &BatchNet,
    x: ArrayView2<'_, f64>,
    t: ArrayView2<'_, f64>,
    scratch: &mut [f64],
    loss: &mut f64,
    ahead: &mut Ahead,
) {
    let (n, d, w) = (x.nrows(), pk.d, L::WIDTH);
    ahead.pace(tile_count(n, d.qs / w, w) + tile_count(n, d.rs / w, w));
    let (xp, rest) = scratch.split_at_mut(n * d.ps);
    let (h, e) = rest.split_at_mut(n * d.qs);
    let e = &mut e[..n * d.rs];
    forward_generic::<L>(pk, x, t, (xp, h, e), ahead);
    *loss = loss_of(e, (d.r, d.rs));
}

/// The body of [`chunk_loss_grad`] on lanes `L` (the packing's width).
#[inline(always)]
fn chunk_loss_grad_generic<L: Lanes>(
    pk: &BatchNet,
    x: ArrayView2<'_, f64>,
    t: ArrayView2<'_, f64>,
    (g1, gb1, g2, gb2): Grads<'_>,
    scratch: &mut [f64],
    loss: &mut f64,
    ahead: &mut Ahead,
) {
    let w = L::WIDTH;
    let (p, q, r) = (pk.d.p, pk.d.q, pk.d.r);
    let (ps, qs, rs) = (pk.d.ps, pk.d.qs, pk.d.rs);
    let n = x.nrows();
    ahead.pace(
        2 * tile_count(n, qs / w, w)
            + tile_count(n, rs / w, w)
            + tile_count(q, ps / w, w)
            + tile_count(r, qs / w, w),
    );
    let (_, _, w2, _, _) = pk.parts();
    let (xp, rest) = scratch.split_at_mut(n * ps);
    let (h, rest) = rest.split_at_mut(n * qs);
    let (e, rest) = rest.split_at_mut(n * rs);
    let (hb, rest) = rest.split_at_mut(n * qs);
    let (g1s, rest) = rest.split_at_mut(q * ps);
    let (g2s, rest) = rest.split_at_mut(r * qs);
    let (sb1, sb2) = rest.split_at_mut(qs);
    forward_generic::<L>(pk, x, t, (xp, h, e), ahead);
    // H̄ = (E W₂) ⊙ (H ⊙ (1 − H)), the loss's sum of squares carried along E W₂'s tiles: a few
    // values at each of their r depth steps, enough to take all n·r.
    let steps = tile_count(n, qs / w, w) * r;
    let mut squares = Squares::new(e, n, (r, rs), (n * r).div_ceil(steps.max(1)));
    product_alongside::<L, _>(
        n,
        qs / w,
        r,
        (e, rs, 1),
        (w2, qs),
        (hb, qs),
        ahead,
        &mut squares,
    );
    *loss = 0.0 + 0.5 * squares.finish();
    let one = L::splat(1.0);
    for (row, hrow) in hb.chunks_exact_mut(qs).zip(h.chunks_exact(qs)) {
        for (v, hv) in row.chunks_exact_mut(w).zip(hrow.chunks_exact(w)) {
            let hv = L::load(hv);
            L::store(L::mul(L::load(v), L::mul(hv, L::sub(one, hv))), v);
        }
    }
    // ∂b₁ and ∂b₂: the rows added in order from zero.
    sb1.fill(0.0);
    sb2.fill(0.0);
    for (hrow, erow) in hb.chunks_exact(qs).zip(e.chunks_exact(rs)) {
        for (s, v) in sb1.chunks_exact_mut(w).zip(hrow.chunks_exact(w)) {
            L::store(L::add(L::load(s), L::load(v)), s);
        }
        for (s, v) in sb2.chunks_exact_mut(w).zip(erow.chunks_exact(w)) {
            L::store(L::add(L::load(s), L::load(v)), s);
        }
    }
    plus_zero(gb1, &sb1[..q]);
    plus_zero(gb2, &sb2[..r]);
    // ∂W₁ = H̄ᵀ X and ∂W₂ = Eᵀ H: A read down the columns of H̄ and E.
    product::<L>(q, ps / w, n, (hb, 1, qs), (xp, ps), (g1s, ps), ahead);
    product::<L>(r, qs / w, n, (e, 1, rs), (h, qs), (g2s, qs), ahead);
    for (g, s) in g1.chunks_exact_mut(p).zip(g1s.chunks_exact(ps)) {
        plus_zero(g, &s[..p]);
    }
    for (g, s) in g2.chunks_exact_mut(q).zip(g2s.chunks_exact(qs)) {
        plus_zero(g, &s[..q]);
    }
}

/// `d` ← 0 + `s`, as the sums over chunks start from zero: the same values, but a sum that
/// underflowed to −0 becomes +0, so that a gradient of one chunk is the same bits as a sum of
/// chunk gradients.
#[inline(always)]
fn plus_zero(d: &mut [f64], s: &[f64]) {
    for (d, s) in d.iter_mut().zip(s) {
        *d = 0.0 + s;
    }
}

/// `d` ← the values of `s` (a row of a matrix view, contiguous or not); a contiguous row by
/// whole lane groups and the rest one by one, in registers (a short row through `memcpy` was a
/// thirtieth of a 17-50-13 mini-batch step, in the calls).
#[inline(always)]
fn copy_row<L: Lanes>(d: &mut [f64], s: ndarray::ArrayView1<'_, f64>) {
    match s.as_slice() {
        Some(s) => {
            let w = L::WIDTH;
            let whole = s.len() / w * w;
            for (d, s) in d[..whole].chunks_exact_mut(w).zip(s.chunks_exact(w)) {
                L::store(L::load(s), d);
            }
            // Fewer than 8 values left: copies of fixed sizes (moves, not a call).
            let (d, s) = (&mut d[whole..s.len()], &s[whole..]);
            let mut k = 0;
            if s.len() - k >= 4 {
                d[k..k + 4].copy_from_slice(&s[k..k + 4]);
                k += 4;
            }
            if s.len() - k >= 2 {
                d[k..k + 2].copy_from_slice(&s[k..k + 2]);
                k += 2;
            }
            if s.len() > k {
                d[k] = s[k];
            }
        }
        None => {
            for (d, s) in d.iter_mut().zip(s) {
                *d = *s;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Every tile shape and remainder of [`product`], on the dispatched and the portable
    /// lanes, against the plain scalar recurrence (from zero, k ascending, one fma per term).
    #[test]
    fn products_are_the_scalar_chains_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for &(m, cols, k) in &[
            (1, 4, 1),
            (13, 16, 50),
            (30, 56, 17),
            (50, 24, 30),
            (9, 40, 3),
            (7, 52, 5),
        ] {
            let (ars, acs) = if rng.random::<bool>() { (k, 1) } else { (1, m) };
            let a: Vec<f64> = (0..m * k).map(|_| rng.random_range(-2.0..2.0)).collect();
            let b: Vec<f64> = (0..k * cols).map(|_| rng.random_range(-2.0..2.0)).collect();
            let mut want = vec![0.0; m * cols];
            for i in 0..m {
                for j in 0..cols {
                    let mut s = 0.0_f64;
                    for kk in 0..k {
                        s = a[i * ars + kk * acs].mul_add(b[kk * cols + j], s);
                    }
                    want[i * cols + j] = s;
                }
            }
            let c = run::<Portable>(m, cols, k, &a, (ars, acs), &b);
            assert_eq!(bits(&c), bits(&want), "portable {m} × {cols} × {k}");
            #[cfg(target_arch = "x86_64")]
            {
                type Args<'a> = (usize, usize, usize, &'a [f64], (usize, usize), &'a [f64]);
                type Run = fn(Args<'_>) -> Vec<f64>;
                #[target_feature(enable = "avx2,fma")]
                fn avx2((m, n, k, a, s, b): Args<'_>) -> Vec<f64> {
                    run::<Avx2>(m, n, k, a, s, b)
                }
                #[target_feature(enable = "avx512f")]
                fn avx512((m, n, k, a, s, b): Args<'_>) -> Vec<f64> {
                    run::<Avx512>(m, n, k, a, s, b)
                }
                let fma = std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma");
                let wide = cols % 8 == 0 && std::arch::is_x86_feature_detected!("avx512f");
                // SAFETY (both): called only where the processor has the features (`fma`,
                // `wide`).
                let paths: [(&str, bool, Run); 2] = [
                    ("AVX2", fma, |args| unsafe { avx2(args) }),
                    ("AVX-512", wide, |args| unsafe { avx512(args) }),
                ];
                for (name, has, f) in paths {
                    if has {
                        let c = f((m, cols, k, &a, (ars, acs), &b));
                        assert_eq!(bits(&c), bits(&want), "{name} {m} × {cols} × {k}");
                    }
                }
            }
        }
    }

    /// A product's strips cover its groups in order, each at most NR wide, and on 4 lanes one
    /// wider than four groups never ends in a strip of one (13 groups as 3, 3, 3, 2, 2).
    #[test]
    fn strips_cover_the_groups_without_a_last_strip_of_one_on_four_lanes() {
        let strips = |groups: usize, w: usize| {
            let (mut g0, mut out) = (0, vec![]);
            while g0 < groups {
                let nr = strip_width(groups, g0, w);
                assert!(
                    (1..=strip_groups(w)).contains(&nr),
                    "{groups} groups of {w}"
                );
                out.push(nr);
                g0 += nr;
            }
            assert_eq!(g0, groups);
            out
        };
        assert_eq!(strips(13, 4), [3, 3, 3, 2, 2]);
        assert_eq!(strips(4, 4), [3, 1]);
        assert_eq!(strips(7, 4), [3, 2, 2]);
        assert_eq!(strips(21, 4), [3; 7]);
        assert_eq!(strips(13, 8), [4, 4, 4, 1]);
        for groups in 5..40 {
            assert_ne!(
                strips(groups, 4).last(),
                Some(&1),
                "{groups} groups of 4 lanes"
            );
        }
    }

    /// [`Ahead`] goes through every cache line that holds a value of the rows, once, inputs
    /// first, and no other line, and the pace spreads them over the tiles. (That the gradient
    /// keeps its bits with the prefetch is `batch_kernels_are_ndarray_products_bit_for_bit`,
    /// whose 300-row batches take three chunks.)
    #[test]
    fn the_next_chunk_is_fetched_line_by_line() {
        let data: Vec<f64> = (0..4000).map(|i| i as f64 * 0.25 - 300.0).collect();
        for (skew, (rows, p, r)) in [(0, (5, 3, 2)), (3, (7, 17, 13)), (5, (1, 1, 1))] {
            let x = ndarray::ArrayView2::from_shape((rows, p), &data[skew..skew + rows * p]);
            let at = skew + rows * p + 1;
            let t = ndarray::ArrayView2::from_shape((rows, r), &data[at..at + rows * r]);
            let (x, t) = (x.unwrap(), t.unwrap());
            let lines_of = |v: &[f64]| {
                let line = |p: *const f64| p as usize / 64 * 64;
                (line(v.as_ptr())..=line(v.as_ptr().wrapping_add(v.len() - 1)))
                    .step_by(64)
                    .collect::<Vec<_>>()
            };
            let mut want = lines_of(x.to_slice().unwrap());
            want.extend(lines_of(t.to_slice().unwrap()));
            let mut ahead = Ahead::rows(x, t);
            let got: Vec<usize> = std::iter::from_fn(|| ahead.next_line())
                .map(|p| p as usize)
                .collect();
            assert_eq!(got, want, "skew {skew}, {rows} rows");
            let mut ahead = Ahead::rows(x, t);
            ahead.pace(3);
            assert_eq!(ahead.per, want.len().div_ceil(3));
            (0..3).for_each(|_| ahead.fetch());
            assert!(ahead.next_line().is_none(), "three tiles fetch every line");
        }
        // Rows that are not contiguous are not fetched.
        let x = ndarray::ArrayView2::from_shape((4, 6), &data[..24]).unwrap();
        let mut ahead = Ahead::rows(x.slice(ndarray::s![.., ..3]), x.slice(ndarray::s![.., 3..]));
        assert!(ahead.next_line().is_none());
        assert!(Ahead::none().next_line().is_none());
    }

    /// `tile_count` counts the tiles [`product`] takes (one [`Ahead::fetch`] each), for every
    /// strip width and remainder, on 4 and (where the processor has them) 8 lanes.
    #[test]
    fn tile_count_counts_the_tiles_of_a_product() {
        let lines = vec![0.0; 8 * 4096];
        /// The fetches of one product of `m` rows and `groups` lane groups.
        #[inline(always)]
        fn fetches<L: Lanes>(m: usize, groups: usize, lines: &[f64]) -> usize {
            let (k, cols) = (3, groups * L::WIDTH);
            let a = vec![1.0; m * k];
            let b = vec![1.0; k * cols];
            let mut c = vec![0.0; m * cols];
            let all = ndarray::ArrayView2::from_shape((1, lines.len()), lines).unwrap();
            let mut ahead = Ahead::rows(all, all.slice(ndarray::s![.., ..0]));
            ahead.per = 1;
            product::<L>(
                m,
                groups,
                k,
                (&a, k, 1),
                (&b, cols),
                (&mut c, cols),
                &mut ahead,
            );
            std::iter::from_fn(|| ahead.next_line()).count()
        }
        let total = fetches::<Portable>(0, 0, &lines);
        for (m, groups) in [
            (1, 1),
            (7, 2),
            (13, 3),
            (50, 11),
            (128, 10),
            (128, 7),
            (30, 4),
        ] {
            let used = total - fetches::<Portable>(m, groups, &lines);
            assert_eq!(
                used,
                tile_count(m, groups, 4),
                "{m} rows, {groups} groups of 4"
            );
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx512f") {
                #[target_feature(enable = "avx512f")]
                fn wide(m: usize, groups: usize, lines: &[f64]) -> usize {
                    fetches::<Avx512>(m, groups, lines)
                }
                // SAFETY: the processor has AVX-512F (checked just above).
                let used = total - unsafe { wide(m, groups, &lines) };
                assert_eq!(
                    used,
                    tile_count(m, groups, 8),
                    "{m} rows, {groups} groups of 8"
                );
            }
        }
    }

    /// The sum of squares carried along a product is `Iterator::sum`'s over the rows' first r
    /// values, bit for bit, whatever the values taken per step and however many steps there
    /// are: none, too few (the rest taken by `finish`) or more than enough; rows with padding
    /// (zeros, +0 and −0) and without.
    #[test]
    fn squares_carried_along_are_the_iterator_sum_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for (n, r, rs) in [
            (1, 2, 8),
            (3, 13, 16),
            (30, 78, 80),
            (7, 8, 8),
            (256, 78, 80),
        ] {
            // The padding zeros, as the products leave it, some of them −0; in the 1 × 2 case
            // the first value is −0 too, so the sum's −0 start meets a square of zero first.
            let mut e: Vec<f64> = (0..n * rs)
                .map(|i| {
                    if i % rs < r {
                        rng.random_range(-3.0..3.0)
                    } else if i % 3 == 0 {
                        -0.0
                    } else {
                        0.0
                    }
                })
                .collect();
            if r == 2 {
                e[0] = -0.0;
            }
            let want: f64 = e
                .chunks_exact(rs)
                .flat_map(|row| &row[..r])
                .map(|v| v * v)
                .sum();
            for per in [1, 2, 3, 4, 7, 100] {
                for steps in [0, 1, n * r / per / 2, n * r] {
                    let mut sq = Squares::new(&e, n, (r, rs), per);
                    (0..steps).for_each(|_| sq.step());
                    let got = sq.finish();
                    assert_eq!(
                        got.to_bits(),
                        want.to_bits(),
                        "{n}×{r}/{rs}, {per} per step"
                    );
                }
            }
        }
    }

    #[test]
    fn transpose_copies_every_value_to_its_place() {
        for &(rows, cols) in &[(1, 1), (4, 4), (50, 17), (13, 50), (78, 50), (3, 9)] {
            let s: Vec<f64> = (0..rows * cols).map(|i| i as f64 + 0.5).collect();
            let ds = rows + 3;
            let mut d = vec![-1.0; cols * ds];
            transpose(&s, (rows, cols), &mut d, ds);
            for c in 0..cols {
                for r in 0..ds {
                    let want = if r < rows { s[r * cols + c] } else { -1.0 };
                    assert_eq!(d[c * ds + r], want, "{rows} × {cols}: ({r}, {c})");
                }
            }
        }
    }

    /// C = A B by [`product`] on lanes `L` (C with `cols` columns, NaN before).
    #[inline(always)]
    fn run<L: Lanes>(
        m: usize,
        cols: usize,
        k: usize,
        a: &[f64],
        s: (usize, usize),
        b: &[f64],
    ) -> Vec<f64> {
        let mut c = vec![f64::NAN; m * cols];
        product::<L>(
            m,
            cols / L::WIDTH,
            k,
            (a, s.0, s.1),
            (b, cols),
            (&mut c, cols),
            &mut Ahead::none(),
        );
        c
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }
}
