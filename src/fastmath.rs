//! # Sine and cosine for the hot physics loops
//!
//! The acrobot's derivative and linearization need sin and cos of both joint angles at every
//! RK4 stage; glibc's `sincos` costs about 20 ns a call and was a quarter of a DDP iteration
//! in a profile. [`sin_cos`] and [`sin_cos2`] compute the pair with
//!
//! 1. a Cody–Waite reduction x = k π/2 + r, |r| ≤ π/4 (k rounded to nearest, π/2 split into
//!    three doubles, each term subtracted by a fused multiply–add);
//! 2. Taylor polynomials on r: sin through r¹⁷, cos through r¹⁶ (truncation below 10⁻¹⁸
//!    relative on |r| ≤ π/4), evaluated in r² by Estrin's scheme with fused multiply–adds;
//! 3. the quadrant k mod 4 choosing and signing the pair.
//!
//! Within 1 ulp of libm's value over |x| < [`REDUCED_LIMIT`] (a test measures it on 220,000
//! arguments, quadrant boundaries included; where the value is within 10⁻⁶ of zero, within
//! one machine epsilon absolute); beyond that, and for non-finite x, it returns libm's
//! `sin_cos`.
//!
//! **Same bits on every machine.** Every multiply–add is `f64::mul_add` (one rounding). On a
//! CPU with FMA the functions run inside a `#[target_feature(enable = "fma")]` copy, where
//! it is one instruction; elsewhere `mul_add` is libm's exact `fma`, slower but the same
//! bits (a test checks the two copies agree).

use crate::lanes::{Real, X4};

/// |x| from which [`sin_cos`] hands over to libm (the three-part reduction stays exact
/// enough well beyond this).
pub const REDUCED_LIMIT: f64 = 1.0e5;

/// π/2 as an unevaluated sum of three doubles (hi + mid + lo; 159 bits).
const PIO2_HI: f64 = std::f64::consts::FRAC_PI_2;
const PIO2_MID: f64 = 6.123_233_995_736_766e-17;
const PIO2_LO: f64 = -1.497_384_904_859_169_8e-33;

/// 1.5 · 2⁵²: adding and subtracting it rounds a double below 2⁵¹ to the nearest integer
/// (ties to even) in plain arithmetic.
const ROUNDER: f64 = 6_755_399_441_055_744.0;

/// (−1)ⁿ / (2n+1)! for n = 1 … 8: sin r = r + r³ Σ c_n r^{2(n−1)}.
const SIN: [f64; 8] = [
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
    1.0 / 355_687_428_096_000.0,
];

/// (−1)ⁿ / (2n)! for n = 1 … 8: cos r = 1 + r² Σ c_n r^{2(n−1)}.
const COS: [f64; 8] = [
    -1.0 / 2.0,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
];

/// Σ c_n zⁿ by Estrin's scheme (pairs, then pairs of pairs: a dependency chain of 3
/// multiply–adds after z² and z⁴ instead of Horner's 7).
#[inline(always)]
fn estrin<T: Real>(c: &[f64; 8], z: T, z2: T, z4: T) -> T {
    let c = c.map(T::splat);
    let p01 = c[1].mul_add(z, c[0]);
    let p23 = c[3].mul_add(z, c[2]);
    let p45 = c[5].mul_add(z, c[4]);
    let p67 = c[7].mul_add(z, c[6]);
    let lo = p23.mul_add(z2, p01);
    let hi = p67.mul_add(z2, p45);
    hi.mul_add(z4, lo)
}

/// Whether [`sin_cos_reduced`] computes x itself (else libm does).
#[inline(always)]
fn in_reduced_range(x: f64) -> bool {
    !x.is_nan() && x.abs() < REDUCED_LIMIT
}

/// Steps 1 and 2 of the module docs for x in the reduced range: the quadrant count k (an
/// integer, as a double) and the polynomials' sin r, cos r.
#[inline(always)]
fn reduced_polynomials<T: Real>(x: T) -> (T, T, T) {
    let c = T::splat;
    let k = (x * c(std::f64::consts::FRAC_2_PI) + c(ROUNDER)) - c(ROUNDER);
    let r = (-k).mul_add(c(PIO2_HI), x);
    let r = (-k).mul_add(c(PIO2_MID), r);
    let r = (-k).mul_add(c(PIO2_LO), r);
    let z = r * r;
    let (z2, rz) = (z * z, r * z);
    let z4 = z2 * z2;
    let s = rz.mul_add(estrin(&SIN, z, z2, z4), r);
    let cos = z.mul_add(estrin(&COS, z, z2, z4), c(1.0));
    (k, s, cos)
}

/// Step 3: the quadrant q = k mod 4 picks and signs the pair without branches (the quadrant
/// is data, and a mispredicted branch costs more than the selection): (s, c), (c, −s),
/// (−s, −c), (−c, s) for q = 0 … 3, a sign flip being the sign bit's XOR (exactly `-x`).
#[inline(always)]
fn quadrant(k: f64, s: f64, c: f64) -> (f64, f64) {
    let q = (k as i64) & 3;
    let odd = q & 1 != 0;
    let (a, b) = if odd { (c, s) } else { (s, c) };
    let sign = |flip: bool| (flip as u64) << 63;
    let sin = f64::from_bits(a.to_bits() ^ sign(q & 2 != 0));
    let cos = f64::from_bits(b.to_bits() ^ sign((q + 1) & 2 != 0));
    (sin, cos)
}

#[inline(always)]
// Beyond the reduced range (NaN, or |x| at or above `REDUCED_LIMIT`, which no model reaches)
// the platform's function is the fallback.
#[allow(clippy::disallowed_methods)]
fn sin_cos_reduced(x: f64) -> (f64, f64) {
    if !in_reduced_range(x) {
        return x.sin_cos();
    }
    let (k, s, c) = reduced_polynomials(x);
    quadrant(k, s, c)
}

/// [`sin_cos`] of four angles in the lanes of an [`X4`], lane i bit for bit `sin_cos` of
/// lane i: the reduction and polynomials run on the lanes (the same operations), the
/// quadrant's selection lane by lane; if any lane is outside the reduced range every lane goes
/// through the scalar function. Inline: compiled with FMA it takes the caller's features
/// (`f64::mul_add` is one rounding either way).
#[inline(always)]
pub fn sin_cos_x4(x: X4) -> (X4, X4) {
    let (mut sin, mut cos) = (X4::splat(0.0), X4::splat(0.0));
    if x.0.iter().all(|&v| in_reduced_range(v)) {
        let (k, s, c) = reduced_polynomials(x);
        for i in 0..4 {
            (sin.0[i], cos.0[i]) = quadrant(k.0[i], s.0[i], c.0[i]);
        }
    } else {
        for i in 0..4 {
            (sin.0[i], cos.0[i]) = sin_cos(x.0[i]);
        }
    }
    (sin, cos)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "fma")]
unsafe fn sin_cos2_fma(a: f64, b: f64) -> ((f64, f64), (f64, f64)) {
    (sin_cos_reduced(a), sin_cos_reduced(b))
}

#[cfg(target_arch = "x86_64")]
fn has_fma() -> bool {
    crate::simd::fma()
}

/// (sin x, cos x), within 1 ulp of libm's (module docs).
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    sin_cos2(x, 0.0).0
}

/// The pairs of two angles at once (their polynomials overlap in the pipeline).
#[inline]
pub fn sin_cos2(a: f64, b: f64) -> ((f64, f64), (f64, f64)) {
    #[cfg(target_arch = "x86_64")]
    if has_fma() {
        // SAFETY: the CPU supports FMA, the only feature the copy is compiled for.
        return unsafe { sin_cos2_fma(a, b) };
    }
    portable(a, b)
}

/// The copy without the FMA instruction (libm's `fma` for every multiply–add).
fn portable(a: f64, b: f64) -> ((f64, f64), (f64, f64)) {
    (sin_cos_reduced(a), sin_cos_reduced(b))
}

/// Whether the processor has AVX2 and FMA: code written over [`crate::lanes::X4`] is compiled
/// a second time for them, where each lane operation is one 4-lane instruction. Same bits
/// either way: Rust never fuses `a * b + c` into one multiply–add and the compiler never
/// reassociates floating-point sums, so each operation is the same IEEE operation on either
/// path (`f64::mul_add` is one rounding on both).
#[cfg(target_arch = "x86_64")]
pub fn has_avx2_fma() -> bool {
    crate::simd::avx2_fma()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn rng(seed: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(seed)
    }

    /// Distance in units in the last place of the exact value's neighbourhood, measured
    /// against libm (itself within 1 ulp) — so up to 1 of the reported ulp is libm's.
    fn ulps(got: f64, want: f64) -> f64 {
        if got == want {
            return 0.0;
        }
        let ulp = f64::from_bits(want.abs().to_bits() + 1) - want.abs();
        // Near a zero of the function compare on the argument's scale (absolute error).
        (got - want).abs() / ulp.max(f64::EPSILON * 1e-3)
    }

    #[test]
    fn within_one_ulp_of_libm_over_the_reduced_range() {
        let mut r = rng(7);
        let mut worst = 0.0_f64;
        let mut args: Vec<f64> = (0..200_000)
            .map(|i| {
                let scale = [1e-8, 1.0, 10.0, 1e3, 9e4][i % 5];
                r.random_range(-scale..scale)
            })
            .collect();
        // Around the quadrant boundaries, where the reduction cancels.
        for k in -2000..2000 {
            let c = k as f64 * std::f64::consts::FRAC_PI_4;
            args.extend([c, c.next_up(), c.next_down(), c + 1e-9, c - 1e-9]);
        }
        args.extend([0.0, -0.0, 1e-300, -1e-300, f64::MIN_POSITIVE]);
        for &x in &args {
            let (s, c) = sin_cos(x);
            let (ws, wc) = x.sin_cos();
            // Absolute error where the value is tiny (next to a zero of sin or cos): the
            // reduction's error is relative to π/2, not to the result.
            let es = if ws.abs() < 1e-6 {
                (s - ws).abs() / f64::EPSILON
            } else {
                ulps(s, ws)
            };
            let ec = if wc.abs() < 1e-6 {
                (c - wc).abs() / f64::EPSILON
            } else {
                ulps(c, wc)
            };
            worst = worst.max(es).max(ec);
            assert!(
                es <= 1.0 && ec <= 1.0,
                "x = {x:e}: ({s:e}, {c:e}) vs ({ws:e}, {wc:e})"
            );
        }
        assert!(worst > 0.0, "compared against libm itself?");
    }

    #[test]
    fn four_lanes_are_the_scalar_function_bit_for_bit() {
        let mut r = rng(8);
        for round in 0..20_000 {
            let scale = [1e-8, 1.0, 10.0, 1e3, 9e4][round % 5];
            let mut x = X4([0.0; 4].map(|_| r.random_range(-scale..scale)));
            if round % 97 == 0 {
                // One lane outside the reduced range: every lane goes the scalar way.
                x.0[round % 4] = [3e7, f64::NAN, f64::INFINITY][round % 3];
            }
            let (s, c) = sin_cos_x4(x);
            for i in 0..4 {
                let (ws, wc) = sin_cos(x.0[i]);
                assert!(
                    s.0[i].to_bits() == ws.to_bits() || (ws.is_nan() && s.0[i].is_nan()),
                    "sin {:e}",
                    x.0[i]
                );
                assert!(
                    c.0[i].to_bits() == wc.to_bits() || (wc.is_nan() && c.0[i].is_nan()),
                    "cos {:e}",
                    x.0[i]
                );
            }
        }
    }

    #[test]
    fn hands_large_and_non_finite_arguments_to_libm() {
        for x in [REDUCED_LIMIT, -3e7, 1e300] {
            assert_eq!(sin_cos(x), x.sin_cos());
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let (s, c) = sin_cos(x);
            assert!(s.is_nan() && c.is_nan());
        }
    }

    #[test]
    fn the_fma_and_portable_copies_give_the_same_bits() {
        let mut r = rng(8);
        for _ in 0..20_000 {
            let (a, b) = (r.random_range(-100.0..100.0), r.random_range(-1e4..1e4));
            let p = portable(a, b);
            let f = sin_cos2(a, b);
            assert_eq!(
                [p.0 .0, p.0 .1, p.1 .0, p.1 .1].map(f64::to_bits),
                [f.0 .0, f.0 .1, f.1 .0, f.1 .1].map(f64::to_bits)
            );
        }
    }

    #[test]
    fn odd_and_even() {
        let mut r = rng(9);
        for _ in 0..10_000 {
            let x: f64 = r.random_range(-50.0..50.0);
            let ((s, c), (sn, cn)) = sin_cos2(x, -x);
            assert_eq!(sn, -s);
            assert_eq!(cn, c);
        }
    }
}
