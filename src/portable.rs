//! # Elementary functions with the same bits on every machine
//!
//! glibc picks an implementation of `sin`, `cos`, `exp`, `log`, `pow`, `atan` … per processor
//! when the program starts (an FMA copy where the CPU has FMA, a plain one elsewhere), and the
//! copies differ in the last bit now and then; other C libraries differ again. A simulation
//! that calls them through `f64::sin_cos`, `f64::exp` … therefore gives different digits on
//! different machines, and a DDP optimization amplifies a last-bit difference into the 7th
//! significant digit (the diver's tables). Everything that simulates, optimizes or
//! combines on the way to a verdict calls these functions instead. Each is plain IEEE
//! arithmetic (`+ − × ÷ √` and `f64::mul_add`, all correctly rounded, so the same bits on
//! every x86-64 and every other IEEE machine):
//!
//! - [`sin_cos`], [`sin`], [`cos`]: [`crate::fastmath::sin_cos`] (within 1 ulp; libm's beyond
//!   |x| ≥ [`crate::fastmath::REDUCED_LIMIT`] rad, which no model reaches);
//! - [`exp`], [`ln`], [`atan`], [`atan2`]: the classic fdlibm algorithms (argument reduction,
//!   then a minimax polynomial or rational function; under 1 ulp);
//! - [`exp_m1`] (a Taylor polynomial near 0, [`exp`] elsewhere; under 2 ulp) and [`tanh`]
//!   (from it; under 3 ulp);
//! - [`hypot`]: √(x² + y²), rescaled by a power of two out of overflow and underflow;
//! - [`powf`]: exp(y ln x) (about 2 + 2 |y ln x| ulp; used only for step-size rules and
//!   search scales);
//! - [`standard_normal`]: `rand_distr`'s ziggurat with [`exp`] and [`ln`] (its draws bit
//!   for bit, tested).
//!
//! Tests compare every function with the platform's over wide ranges of arguments.
//!
//! ## References
//!
//! The constants and the methods of [`exp`], [`ln`] and [`atan`] are fdlibm's (e_exp.c,
//! e_log.c, s_atan.c, e_atan2.c), under this notice:
//!
//! > Copyright (C) 1993, 2004 by Sun Microsystems, Inc. All rights reserved. Permission to
//! > use, copy, modify, and distribute this software is freely granted, provided that this
//! > notice is preserved.

// fdlibm's coefficients are written as fdlibm writes them (more digits than an f64 holds, and
// split constants near π/4, π/2, 1/√2, √2 that are not the std constants): they are the
// reference's bits.
#![allow(clippy::excessive_precision, clippy::approx_constant)]

pub use crate::fastmath::sin_cos;

mod normal;
pub use normal::standard_normal;

/// sin x ([`sin_cos`]'s first half).
#[inline]
pub fn sin(x: f64) -> f64 {
    sin_cos(x).0
}

/// cos x ([`sin_cos`]'s second half).
#[inline]
pub fn cos(x: f64) -> f64 {
    sin_cos(x).1
}

/// ln 2 split so that k · `LN2_HI` is exact for |k| < 2²⁰ (its low 32 bits are zero).
const LN2_HI: f64 = 6.931_471_803_691_238_164_90e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;
const INV_LN2: f64 = 1.442_695_040_888_963_387_00;

/// Remez coefficients of r (eʳ + 1)/(eʳ − 1) ≈ 2 + P₁ r² + … + P₅ r¹⁰ on |r| ≤ ln 2 / 2.
const EXP_P: [f64; 5] = [
    1.666_666_666_666_660_190_37e-1,
    -2.777_777_777_701_559_338_42e-3,
    6.613_756_321_437_934_361_17e-5,
    -1.653_390_220_546_525_153_90e-6,
    4.138_136_797_057_238_460_39e-8,
];

/// y · 2ᵏ for y near 1 and k in [−1100, 1100], rounding once even where the result is
/// subnormal (the scale is applied in at most two exact steps before the last one).
fn scale2(mut y: f64, mut k: i32) -> f64 {
    let pow2 = |e: i32| f64::from_bits(((0x3ff + e) as u64) << 52);
    if k > 1023 {
        y *= pow2(1023);
        k -= 1023;
        if k > 1023 {
            y *= pow2(1023);
            k = (k - 1023).min(1023);
        }
    } else if k < -1022 {
        // 2⁻¹⁰²² · 2⁵³: stays normal, so the final multiply rounds only once.
        y *= pow2(-1022) * pow2(53);
        k += 1022 - 53;
        if k < -1022 {
            y *= pow2(-1022) * pow2(53);
            k = (k + 1022 - 53).max(-1022);
        }
    }
    y * pow2(k)
}

/// eˣ, under 1 ulp (fdlibm's method: x = k ln 2 + r with |r| ≤ ln 2 / 2 as hi − lo, a
/// rational approximation of eʳ, then 2ᵏ).
pub fn exp(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x > 7.097_827_128_933_839_730_96e2 {
        return f64::INFINITY;
    }
    if x < -7.451_332_191_019_411_084_2e2 {
        return 0.0;
    }
    let ax = x.abs();
    if ax < 3.725_290_298_461_914e-9 {
        // |x| < 2⁻²⁸: 1 + x is the rounded value.
        return 1.0 + x;
    }
    let (k, hi, lo) = if ax > 0.5 * std::f64::consts::LN_2 {
        let k = if ax < 1.5 * std::f64::consts::LN_2 {
            if x > 0.0 {
                1
            } else {
                -1
            }
        } else {
            // Round half away from zero (truncation of x/ln 2 ± 1/2).
            (INV_LN2 * x + 0.5f64.copysign(x)) as i32
        };
        let kf = k as f64;
        (k, x - kf * LN2_HI, kf * LN2_LO)
    } else {
        (0, x, 0.0)
    };
    let r = hi - lo;
    let z = r * r;
    let p = &EXP_P;
    let c = r - z * (p[0] + z * (p[1] + z * (p[2] + z * (p[3] + z * p[4]))));
    let y = 1.0 + (r * c / (2.0 - c) - lo + hi);
    if k == 0 {
        y
    } else {
        scale2(y, k)
    }
}

/// Remez coefficients of (ln(1+f) − 2s)/s ≈ Lg₁ s² + … + Lg₇ s¹⁴, s = f / (2 + f).
const LG: [f64; 7] = [
    6.666_666_666_666_735_130e-1,
    3.999_999_999_940_941_908e-1,
    2.857_142_874_366_239_149e-1,
    2.222_219_843_214_978_396e-1,
    1.818_357_216_161_805_012e-1,
    1.531_383_769_920_937_332e-1,
    1.479_819_860_511_658_591e-1,
];

/// ln x, under 1 ulp (fdlibm's method: x = 2ᵏ (1 + f) with 1 + f in [√2/2, √2), then
/// ln(1 + f) = 2s + s R(s²) with s = f / (2 + f)). −∞ at ±0, NaN below 0.
pub fn ln(x: f64) -> f64 {
    if x.is_nan() || x == f64::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f64::NEG_INFINITY;
    }
    if x < 0.0 {
        return f64::NAN;
    }
    if x == 1.0 {
        return 0.0;
    }
    let mut bits = x.to_bits();
    let mut k: i32 = 0;
    if bits < 0x0010_0000_0000_0000 {
        // Subnormal: scale up by 2⁵⁴.
        k -= 54;
        bits = (x * 18_014_398_509_481_984.0).to_bits();
    }
    // Reduce into [√2/2, √2): shift the high word so that the mantissa's top lands there.
    let hx = ((bits >> 32) as u32).wrapping_add(0x3ff0_0000 - 0x3fe6_a09e);
    k += (hx >> 20) as i32 - 0x3ff;
    let hx = (hx & 0x000f_ffff) + 0x3fe6_a09e;
    let m = f64::from_bits((u64::from(hx) << 32) | (bits & 0xffff_ffff));
    let f = m - 1.0;
    let hfsq = 0.5 * f * f;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (LG[1] + w * (LG[3] + w * LG[5]));
    let t2 = z * (LG[0] + w * (LG[2] + w * (LG[4] + w * LG[6])));
    let r = t2 + t1;
    let dk = k as f64;
    s * (hfsq + r) + dk * LN2_LO - hfsq + f + dk * LN2_HI
}

/// eˣ − 1 without cancellation near 0: a Taylor polynomial (through x¹⁸) for |x| < 1/2,
/// [`exp`] − 1 elsewhere; under 2 ulp.
pub fn exp_m1(x: f64) -> f64 {
    if x.abs() >= 0.5 || x.is_nan() {
        return exp(x) - 1.0;
    }
    if x == 0.0 {
        return x;
    }
    // x + x² (1/2! + x/3! + … + x¹⁶/18!), Horner from the top.
    let mut p = 0.0;
    for &c in EXPM1_TAYLOR.iter().rev() {
        p = p * x + c;
    }
    (x * x).mul_add(p, x)
}

/// 1/n! for n = 2 … 18.
const EXPM1_TAYLOR: [f64; 17] = {
    let mut c = [0.0; 17];
    let mut f = 2.0;
    let mut i = 0;
    while i < 17 {
        c[i] = 1.0 / f;
        f *= (i + 3) as f64;
        i += 1;
    }
    c
};

/// tanh x = t / (t + 2) with t = e^(2|x|) − 1 ([`exp_m1`]), signed; ±1 beyond |x| > 22.
/// Under 3 ulp (the quotient adds to [`exp_m1`]'s error).
pub fn tanh(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    let a = x.abs();
    let t = if a > 22.0 {
        1.0
    } else {
        let e = exp_m1(2.0 * a);
        e / (e + 2.0)
    };
    t.copysign(x)
}

/// atan(0.5), atan(1), atan(1.5), atan(∞) as hi + lo.
const ATAN_HI: [f64; 4] = [
    4.636_476_090_008_060_935_15e-1,
    7.853_981_633_974_482_789_99e-1,
    9.827_937_232_473_290_540_82e-1,
    1.570_796_326_794_896_558_00,
];
const ATAN_LO: [f64; 4] = [
    2.269_877_745_296_168_709_24e-17,
    3.061_616_997_868_383_017_93e-17,
    1.390_331_103_123_099_845_16e-17,
    6.123_233_995_736_766_035_87e-17,
];
/// Remez coefficients of (atan t − t)/t³ in t² on |t| ≤ 7/16.
const AT: [f64; 11] = [
    3.333_333_333_333_293_180_27e-1,
    -1.999_999_999_987_648_324_76e-1,
    1.428_571_427_250_346_637_11e-1,
    -1.111_111_040_546_235_578_80e-1,
    9.090_887_133_436_506_561_96e-2,
    -7.691_876_205_044_829_994_95e-2,
    6.661_073_137_387_531_206_69e-2,
    -5.833_570_133_790_573_486_45e-2,
    4.976_877_994_615_932_360_17e-2,
    -3.653_157_274_421_691_552_70e-2,
    1.628_582_011_536_578_236_23e-2,
];

/// atan x in [−π/2, π/2], under 1 ulp (fdlibm's method: |x| reduced to |t| ≤ 7/16 by
/// atan x = atan c + atan((x − c)/(1 + c x)) for c = 0, 1/2, 1, 3/2, ∞, then a polynomial).
pub fn atan(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    let a = x.abs();
    if a >= 7.378_697_629_483_820_6e19 {
        // |x| ≥ 2⁶⁶: π/2 rounded.
        return (ATAN_HI[3] + ATAN_LO[3]).copysign(x);
    }
    let (id, t) = if a < 0.4375 {
        if a < 7.450_580_596_923_828e-9 {
            // |x| < 2⁻²⁷: atan x rounds to x.
            return x;
        }
        (None, x)
    } else if a < 1.1875 {
        if a < 0.6875 {
            (Some(0), (2.0 * a - 1.0) / (2.0 + a))
        } else {
            (Some(1), (a - 1.0) / (a + 1.0))
        }
    } else if a < 2.4375 {
        (Some(2), (a - 1.5) / (1.0 + 1.5 * a))
    } else {
        (Some(3), -1.0 / a)
    };
    let z = t * t;
    let w = z * z;
    let s1 = z * (AT[0] + w * (AT[2] + w * (AT[4] + w * (AT[6] + w * (AT[8] + w * AT[10])))));
    let s2 = w * (AT[1] + w * (AT[3] + w * (AT[5] + w * (AT[7] + w * AT[9]))));
    match id {
        None => t - t * (s1 + s2),
        Some(i) => (ATAN_HI[i] - ((t * (s1 + s2) - ATAN_LO[i]) - t)).copysign(x),
    }
}

/// π as hi + lo.
const PI_LO: f64 = 1.224_646_799_147_353_177_2e-16;

/// The angle of (x, y) from the positive x axis, in [−π, π], under 1 ulp (fdlibm's
/// e_atan2.c: [`atan`] of |y/x|, then the quadrant; the same special values as C's `atan2`).
pub fn atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    if x.is_nan() || y.is_nan() {
        return x + y;
    }
    if x == 1.0 {
        return atan(y);
    }
    // Bit 0: y negative; bit 1: x negative.
    let m = (y.is_sign_negative() as u8) | ((x.is_sign_negative() as u8) << 1);
    if y == 0.0 {
        return match m {
            0 | 1 => y,
            2 => PI,
            _ => -PI,
        };
    }
    if x == 0.0 {
        return if m & 1 == 1 { -FRAC_PI_2 } else { FRAC_PI_2 };
    }
    if x.is_infinite() {
        return if y.is_infinite() {
            match m {
                0 => FRAC_PI_4,
                1 => -FRAC_PI_4,
                2 => 3.0 * FRAC_PI_4,
                _ => -3.0 * FRAC_PI_4,
            }
        } else {
            match m {
                0 => 0.0,
                1 => -0.0,
                2 => PI,
                _ => -PI,
            }
        };
    }
    let exponent = |v: f64| ((v.to_bits() >> 52) & 0x7ff) as i32;
    let (ex, ey) = (exponent(x), exponent(y));
    // |y/x| > 2⁶⁴ (or y infinite): ±π/2.
    if ey - ex > 64 || y.is_infinite() {
        return if m & 1 == 1 { -FRAC_PI_2 } else { FRAC_PI_2 };
    }
    let z = if m & 2 != 0 && ex - ey > 64 {
        // |y/x| < 2⁻⁶⁴ with x < 0: the angle is ±π to the last bit.
        0.0
    } else {
        atan((y / x).abs())
    };
    match m {
        0 => z,
        1 => -z,
        2 => PI - (z - PI_LO),
        _ => (z - PI_LO) - PI,
    }
}

/// √(x² + y²) without overflow or underflow in the squares: both scaled by the same power
/// of two when the larger is above 2⁵⁰⁰ or below 2⁻⁵⁰⁰. ∞ if either is infinite (even
/// with the other NaN), as C's `hypot`.
pub fn hypot(x: f64, y: f64) -> f64 {
    let (a, b) = (x.abs(), y.abs());
    if a.is_infinite() || b.is_infinite() {
        return f64::INFINITY;
    }
    if a.is_nan() || b.is_nan() {
        return f64::NAN;
    }
    let (big, small) = if a >= b { (a, b) } else { (b, a) };
    if small == 0.0 {
        return big;
    }
    const UP: f64 = 3.273_390_607_896_141_9e150; // 2⁵⁰⁰
    const DOWN: f64 = 3.054_936_363_499_604_7e-151; // 2⁻⁵⁰⁰
    let scale = if big > UP {
        DOWN
    } else if big < DOWN {
        UP
    } else {
        1.0
    };
    let (p, q) = (big * scale, small * scale);
    p.mul_add(p, q * q).sqrt() / scale
}

/// xʸ as exp(y ln x) (by squaring for integer |y| ≤ 8) with C's special cases (x < 0 only for integer y; 0 and ∞ by the sign
/// of y). Its error grows with |y ln x| (about 2 + 2 |y ln x| ulp): for step-size rules and
/// search scales, not for simulation.
pub fn powf(x: f64, y: f64) -> f64 {
    if y == 0.0 || x == 1.0 {
        return 1.0;
    }
    if x.is_nan() || y.is_nan() {
        return f64::NAN;
    }
    if y.is_infinite() {
        return match (x.abs() == 1.0, x.abs() > 1.0, y > 0.0) {
            (true, _, _) => 1.0,
            (_, true, true) | (_, false, false) => f64::INFINITY,
            _ => 0.0,
        };
    }
    let y_integer = y.fract() == 0.0;
    let y_odd = y_integer && y.abs() < 9.007_199_254_740_992e15 && (y % 2.0).abs() == 1.0;
    if x < 0.0 || (x == 0.0 && x.is_sign_negative()) {
        if !y_integer && x != 0.0 && !x.is_infinite() {
            return f64::NAN;
        }
        let r = powf(-x, y);
        return if y_odd { -r } else { r };
    }
    if x == 0.0 {
        return if y > 0.0 { 0.0 } else { f64::INFINITY };
    }
    if x.is_infinite() {
        return if y > 0.0 { f64::INFINITY } else { 0.0 };
    }
    if y_integer && y.abs() <= 8.0 {
        // Small integer powers by squaring: exact where the result is representable (2³ = 8).
        let (mut base, mut n, mut r) = (x, y.abs() as u32, 1.0);
        while n > 0 {
            if n & 1 == 1 {
                r *= base;
            }
            base *= base;
            n >>= 1;
        }
        return if y < 0.0 { 1.0 / r } else { r };
    }
    exp(y * ln(x))
}

/// √(x² + y²) by Borges's corrected algorithm ("An Improved Algorithm for hypot(a,b)", 2019):
/// the naive square root, then one Newton-like correction whose residual is formed exactly
/// enough in plain arithmetic (no fused multiply-add) that the result is within about 0.8 ulp.
/// It exists beside [`hypot`] for the local frame's heading norm
/// (`emulator::transform::spatial`): glibc ≥ 2.35 computes the platform's `hypot` on x86-64
/// this way, so on such a machine the bits are those every cached lander and dolphin net was
/// trained through, and every other machine now gets the same bits. Arguments whose larger
/// magnitude is above 2⁵¹¹ or whose smaller is below 2⁻⁴⁵⁹ are scaled by 2⁶⁰⁰ first; a
/// smaller argument below 2⁻⁵⁴ of the larger leaves the larger (rounded sum).
pub fn hypot_corrected(x: f64, y: f64) -> f64 {
    if !x.is_finite() || !y.is_finite() {
        if x.is_infinite() || y.is_infinite() {
            return f64::INFINITY;
        }
        return f64::NAN;
    }
    let (a, b) = (x.abs(), y.abs());
    let (big, small) = if a < b { (b, a) } else { (a, b) };
    const SCALE: f64 = 2.409_919_865_102_884e-181; // 2⁻⁶⁰⁰
    const LARGE: f64 = 6.703_903_964_971_299e153; // 2⁵¹¹
    const TINY: f64 = 6.717_876_107_567_089e-139; // 2⁻⁴⁵⁹
    const EPS: f64 = 5.551_115_123_125_783e-17; // 2⁻⁵⁴
    if big > LARGE {
        if small <= big * EPS {
            return big + small;
        }
        return corrected_kernel(big * SCALE, small * SCALE) / SCALE;
    }
    if small < TINY {
        if big >= small / EPS {
            return big + small;
        }
        return corrected_kernel(big / SCALE, small / SCALE) * SCALE;
    }
    if small <= big * EPS {
        return big + small;
    }
    corrected_kernel(big, small)
}

/// Borges's correction for `big` ≥ `small` > 0 in the unscaled range: h = √(big² + small²)
/// rounded, then h − (h² − big² − small²)/(2h) with the residual split so that each part is
/// nearly exact (which split depends on whether h is within twice `small`).
#[inline]
fn corrected_kernel(big: f64, small: f64) -> f64 {
    let h = (big * big + small * small).sqrt();
    let (t1, t2) = if h <= 2.0 * small {
        let d = h - small;
        (big * (2.0 * d - big), (d - 2.0 * (big - small)) * d)
    } else {
        let d = h - big;
        (
            2.0 * d * (big - 2.0 * small),
            (4.0 * d - small) * small + d * d,
        )
    };
    h - (t1 + t2) / (2.0 * h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// |got − want| in units in the last place of `want` (libm's, itself within 1 ulp, so up
    /// to 1 of the reported ulp may be libm's).
    fn ulps(got: f64, want: f64) -> f64 {
        if got == want || (got.is_nan() && want.is_nan()) {
            return 0.0;
        }
        if !want.is_finite() || !got.is_finite() {
            return f64::INFINITY;
        }
        let w = want.abs().max(f64::MIN_POSITIVE);
        let ulp = f64::from_bits(w.to_bits() + 1) - w;
        (got - want).abs() / ulp
    }

    /// Random arguments spread over the decades of [lo, hi] (log-uniform magnitudes), both
    /// signs where lo < 0.
    fn spread(seed: u64, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        let mut r = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                if i % 2 == 0 {
                    r.random_range(lo..hi)
                } else {
                    let big = lo.abs().max(hi.abs());
                    let m = 10f64.powf(r.random_range(-12.0..big.log10()));
                    let m = if lo < 0.0 && r.random::<bool>() {
                        -m
                    } else {
                        m
                    };
                    m.clamp(lo, hi)
                }
            })
            .collect()
    }

    fn worst(args: &[f64], f: impl Fn(f64) -> f64, g: impl Fn(f64) -> f64) -> (f64, f64) {
        let mut w = (0.0, 0.0);
        for &x in args {
            let e = ulps(f(x), g(x));
            if e > w.0 {
                w = (e, x);
            }
        }
        w
    }

    #[test]
    fn exp_within_one_ulp_of_libm() {
        let mut args = spread(1, 200_000, -745.0, 709.7);
        args.extend([
            0.0, -0.0, 1e-300, -1e-20, 709.78, -708.4, -744.0, 0.3465, 0.3466,
        ]);
        let (e, x) = worst(&args, exp, f64::exp);
        assert!(e <= 1.0, "exp: {e} ulp at {x:e}");
        assert_eq!(exp(710.0), f64::INFINITY);
        assert_eq!(exp(-746.0), 0.0);
        assert_eq!(exp(f64::NEG_INFINITY), 0.0);
        assert_eq!(exp(f64::INFINITY), f64::INFINITY);
        assert!(exp(f64::NAN).is_nan());
    }

    #[test]
    fn ln_within_one_ulp_of_libm() {
        let mut args = spread(2, 200_000, 0.0, 1e300);
        args.extend([
            1.0,
            1.0 + 1e-15,
            1.0 - 1e-16,
            0.7071,
            1.4142,
            5e-324,
            1e-310,
            2.0,
        ]);
        let args: Vec<f64> = args.into_iter().filter(|&x| x > 0.0).collect();
        let (e, x) = worst(&args, ln, f64::ln);
        assert!(e <= 1.0, "ln: {e} ulp at {x:e}");
        assert_eq!(ln(0.0), f64::NEG_INFINITY);
        assert!(ln(-1.0).is_nan() && ln(f64::NAN).is_nan());
        assert_eq!(ln(f64::INFINITY), f64::INFINITY);
        assert_eq!(ln(1.0), 0.0);
    }

    #[test]
    fn atan_and_atan2_within_one_ulp_of_libm() {
        let args = spread(3, 200_000, -1e25, 1e25);
        let (e, x) = worst(&args, atan, f64::atan);
        assert!(e <= 1.0, "atan: {e} ulp at {x:e}");
        let ys = spread(4, 100_000, -1e3, 1e3);
        let xs = spread(5, 100_000, -1e3, 1e3);
        for (&y, &x) in ys.iter().zip(&xs) {
            let e = ulps(atan2(y, x), y.atan2(x));
            assert!(e <= 1.0, "atan2({y:e}, {x:e}): {e} ulp");
        }
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e-300,
            1e300,
        ];
        for &y in &special {
            for &x in &special {
                assert_eq!(
                    atan2(y, x).to_bits(),
                    y.atan2(x).to_bits(),
                    "atan2({y}, {x})"
                );
            }
        }
        assert!(atan2(f64::NAN, 1.0).is_nan() && atan2(1.0, f64::NAN).is_nan());
    }

    #[test]
    fn exp_m1_within_two_and_tanh_within_three_ulp_of_libm() {
        let args = spread(6, 200_000, -30.0, 30.0);
        let (e, x) = worst(&args, exp_m1, f64::exp_m1);
        assert!(e <= 2.0, "exp_m1: {e} ulp at {x:e}");
        let (e, x) = worst(&args, tanh, f64::tanh);
        assert!(e <= 3.0, "tanh: {e} ulp at {x:e}");
        assert_eq!(tanh(0.0).to_bits(), 0.0f64.to_bits());
        assert_eq!(tanh(-0.0).to_bits(), (-0.0f64).to_bits());
        assert_eq!((tanh(40.0), tanh(-40.0)), (1.0, -1.0));
    }

    #[test]
    fn hypot_within_one_ulp_of_libm() {
        let xs = spread(7, 100_000, -1e300, 1e300);
        let ys = spread(8, 100_000, -1e-300, 1e200);
        for (&x, &y) in xs.iter().zip(&ys) {
            let e = ulps(hypot(x, y), x.hypot(y));
            assert!(e <= 1.0, "hypot({x:e}, {y:e}): {e} ulp");
        }
        assert_eq!(hypot(3.0, 4.0), 5.0);
        assert_eq!(hypot(f64::NAN, f64::INFINITY), f64::INFINITY);
        assert!(hypot(f64::NAN, 1.0).is_nan());
    }

    #[test]
    fn powf_within_its_stated_error_of_libm() {
        let mut r = ChaCha8Rng::seed_from_u64(9);
        for _ in 0..100_000 {
            let x: f64 = 10f64.powf(r.random_range(-5.0..5.0));
            let y: f64 = r.random_range(-6.0..6.0);
            let bound = 2.0 + 2.0 * (y * x.ln()).abs();
            let e = ulps(powf(x, y), x.powf(y));
            assert!(e <= bound, "powf({x:e}, {y}): {e} ulp > {bound}");
        }
        for (x, y) in [
            (0.0, 2.0),
            (0.0, -1.0),
            (-0.0, 3.0),
            (-0.0, -3.0),
            (-2.0, 3.0),
            (-2.0, 0.5),
            (2.0, f64::INFINITY),
            (0.5, f64::INFINITY),
            (f64::INFINITY, -1.0),
            (1.0, f64::NAN),
            (f64::NAN, 0.0),
            (10.0, 2.0),
        ] {
            let (got, want) = (powf(x, y), x.powf(y));
            assert!(
                got == want || (got.is_nan() && want.is_nan()),
                "powf({x}, {y})"
            );
        }
    }

    #[test]
    fn sin_and_cos_are_fastmaths() {
        for x in [0.3, -2.0, 40.0] {
            assert_eq!((sin(x), cos(x)), crate::fastmath::sin_cos(x));
        }
    }

    /// The corrected hypot: exact on Pythagorean triples at every scale, symmetric in its
    /// arguments and their signs, the C special values, and within one ulp of the exact value
    /// (checked by the residual h² − x² − y², formed exactly with fused multiply-adds, against
    /// half the spacing of h's neighbours) over wide random pairs, while the naive
    /// `sqrt(x*x + y*y)` is not correctly rounded on many of them.
    #[test]
    fn hypot_corrected_is_exact_on_triples_and_within_an_ulp() {
        for (a, b, c) in [
            (3.0, 4.0, 5.0),
            (5.0, 12.0, 13.0),
            (20.0, 21.0, 29.0),
            (1.0, 0.0, 1.0),
        ] {
            for e in [-1070, -700, -300, -20, 0, 20, 300, 700, 1000] {
                let k = 2f64.powi(e);
                if !(c * k).is_finite() || a * k == 0.0 {
                    continue;
                }
                assert_eq!(hypot_corrected(a * k, b * k), c * k, "{a} {b} at 2^{e}");
                assert_eq!(hypot_corrected(-b * k, a * k), c * k);
            }
        }
        assert_eq!(hypot_corrected(f64::INFINITY, f64::NAN), f64::INFINITY);
        assert_eq!(hypot_corrected(f64::NAN, f64::NEG_INFINITY), f64::INFINITY);
        assert!(hypot_corrected(f64::NAN, 1.0).is_nan());
        assert_eq!(hypot_corrected(0.0, -0.0), 0.0);
        assert_eq!(hypot_corrected(f64::MAX, 1.0), f64::MAX);
        // h is within one ulp of √(x² + y²) when h² − x² − y² (formed exactly enough with
        // fused multiply-adds) is negative one ulp below h and positive one ulp above.
        let residual = |h: f64, x: f64, y: f64| {
            let (hh, hl) = (h * h, h.mul_add(h, -(h * h)));
            let (xx, xl) = (x * x, x.mul_add(x, -(x * x)));
            let (yy, yl) = (y * y, y.mul_add(y, -(y * y)));
            (hh - xx - yy) + (hl - xl - yl)
        };
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut naive_off, n) = (0, 20_000);
        for _ in 0..n {
            let (x, y): (f64, f64) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let h = hypot_corrected(x, y);
            let (below, above) = (
                f64::from_bits(h.to_bits() - 1),
                f64::from_bits(h.to_bits() + 1),
            );
            assert!(
                residual(below, x, y) < 0.0 && residual(above, x, y) > 0.0,
                "{x} {y}"
            );
            if (x * x + y * y).sqrt() != h {
                naive_off += 1;
            }
            let (sx, sy) = (x * 2f64.powi(600), y * 2f64.powi(600));
            assert_eq!(
                hypot_corrected(sx, sy),
                h * 2f64.powi(600),
                "{x} {y} scaled"
            );
        }
        assert!(
            naive_off > n / 100,
            "the correction changed only {naive_off} of {n}"
        );
    }

    /// The rule these functions exist for, enforced: no code that simulates, optimizes,
    /// trains or measures on the way to a table calls the platform's elementary functions
    /// (`f64::sin`, `exp`, `atan2`, `hypot`, …; `powi` is repeated multiplication and
    /// allowed). Test modules are skipped; the files below draw figures, validate settings or
    /// time benchmarks, where a last-bit difference reaches no table, or are named with why
    /// they are not yet converted.
    #[test]
    fn no_data_path_calls_the_platforms_elementary_functions() {
        const ALLOWED: &[(&str, &str)] = &[
            (
                "src/bench/",
                "benchmark inputs, never written to a results table",
            ),
            ("src/experiment/plot/", "figure axes"),
            ("src/experiment/report.rs", "number formatting"),
            ("src/families/ms/lattice_draw.rs", "drawing"),
            ("src/families/ms/motion.rs", "the heading and pitch figure"),
            ("src/families/ms/search.rs", "a settings check (> 0)"),
            ("src/families/na/fig13_control/anim.rs", "animation frames"),
            (
                "src/families/na/fig13_control/frames.rs",
                "animation frames",
            ),
            ("src/physics/lattice/contact.rs", "a settings check (> 0)"),
        ];
        let names = [
            "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp",
            "exp2", "exp_m1", "ln", "ln_1p", "log", "log2", "log10", "powf", "hypot", "cbrt",
            "sin_cos",
        ];
        fn files(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
            for e in std::fs::read_dir(dir).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    files(&p, out);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    out.push(p);
                }
            }
        }
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut all = Vec::new();
        files(&root.join("src"), &mut all);
        let mut offending = Vec::new();
        for path in all {
            let rel = path
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            if rel == "src/portable.rs"
                || rel.starts_with("src/portable/")
                || rel == "src/fastmath.rs"
                || ALLOWED.iter().any(|(a, _)| rel.starts_with(a))
            {
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            let code = text.split("#[cfg(test)]").next().unwrap_or("");
            for (n, line) in code.lines().enumerate() {
                let line = line.split("//").next().unwrap_or("");
                for name in names {
                    let call = format!(".{name}(");
                    if line.contains(&call) {
                        offending.push(format!("{rel}:{}: {}", n + 1, line.trim()));
                    }
                }
            }
        }
        assert!(
            offending.is_empty(),
            "platform math on a data path (use crate::portable):\n{}",
            offending.join("\n")
        );
    }
}
