//! # Four independent problems in lockstep
//!
//! [`X4`] holds one `f64` from each of four independent evaluations of the same arithmetic
//! (four knots of a trajectory, say), and its operators apply the scalar operation to each
//! lane: lane i of `a + b` is `a.0[i] + b.0[i]`, one IEEE operation with one rounding. Code
//! written once over [`Real`] therefore computes, in lane i of an `X4` evaluation, exactly the
//! bits that the `f64` evaluation computes on problem i — the compiler neither fuses nor
//! reassociates floating-point operations. Compiled for AVX2 (as
//! [`crate::control::Rk4Map::jacobians_each`] is, where the processor has it) each operation
//! is one 4-lane instruction.
//!
//! [`Aligned`] stores `f64` values that lane groups load (the packed weights of the neural
//! kernels) from the start of a cache line.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A hint to bring the cache line at `p` into the L2 cache (nothing where there is no such
/// instruction).
#[inline(always)]
pub(crate) fn prefetch_l2(p: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing into the program and does not fault, whatever the
    // address.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T1};
        _mm_prefetch::<_MM_HINT_T1>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Four lanes of `f64`, each from its own problem (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(32))]
pub struct X4(pub [f64; 4]);

impl X4 {
    /// The same value in every lane.
    #[inline(always)]
    pub fn splat(v: f64) -> Self {
        X4([v; 4])
    }

    /// Lane `i`'s value.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f64 {
        self.0[i]
    }
}

macro_rules! lanewise {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for X4 {
            type Output = X4;
            #[inline(always)]
            fn $f(self, o: X4) -> X4 {
                let (a, b) = (self.0, o.0);
                X4([a[0] $op b[0], a[1] $op b[1], a[2] $op b[2], a[3] $op b[3]])
            }
        }
    };
}
lanewise!(Add, add, +);
lanewise!(Sub, sub, -);
lanewise!(Mul, mul, *);
lanewise!(Div, div, /);

impl Neg for X4 {
    type Output = X4;
    #[inline(always)]
    fn neg(self) -> X4 {
        let a = self.0;
        X4([-a[0], -a[1], -a[2], -a[3]])
    }
}

/// The scalar arithmetic both `f64` and [`X4`] provide, for code written once over either.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// `v` (in every lane).
    fn splat(v: f64) -> Self;

    /// self · a + b with one rounding ([`f64::mul_add`], in every lane).
    fn mul_add(self, a: Self, b: Self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }

    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        f64::mul_add(self, a, b)
    }
}

impl Real for X4 {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        X4::splat(v)
    }

    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        let (x, a, b) = (self.0, a.0, b.0);
        X4([
            x[0].mul_add(a[0], b[0]),
            x[1].mul_add(a[1], b[1]),
            x[2].mul_add(a[2], b[2]),
            x[3].mul_add(a[3], b[3]),
        ])
    }
}

/// One cache line of `f64` values: the unit of [`Aligned`]'s storage.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(64))]
struct Line([f64; 8]);

/// `f64` values stored from the start of a 64-byte cache line, read and written as a slice.
/// A lane group of 4 (or 8) values that starts at a multiple of 4 (or 8) then lies within one
/// cache line: a load of it never splits across two lines, which a `Vec<f64>` (aligned to 16
/// bytes by the allocator) does not promise.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Aligned {
    lines: Vec<Line>,
    len: usize,
}

impl Aligned {
    /// `len` zeros.
    pub fn zeros(len: usize) -> Self {
        Self {
            lines: vec![Line::default(); len.div_ceil(8)],
            len,
        }
    }
}

impl std::ops::Deref for Aligned {
    type Target = [f64];
    #[inline(always)]
    fn deref(&self) -> &[f64] {
        // SAFETY: `lines` holds len.div_ceil(8) lines of 8 contiguous f64 each (`repr(C)`), so
        // its first `len` values are initialized f64s in one allocation, borrowed with `self`.
        unsafe { std::slice::from_raw_parts(self.lines.as_ptr().cast::<f64>(), self.len) }
    }
}

impl std::ops::DerefMut for Aligned {
    #[inline(always)]
    fn deref_mut(&mut self) -> &mut [f64] {
        // SAFETY: as in `deref`, with the unique borrow of `self`.
        unsafe { std::slice::from_raw_parts_mut(self.lines.as_mut_ptr().cast::<f64>(), self.len) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligned_values_start_on_a_cache_line_and_keep_their_length_when_cloned() {
        for len in [0, 1, 7, 8, 9, 52, 850] {
            let mut a = Aligned::zeros(len);
            assert_eq!(a.len(), len);
            assert!(a.iter().all(|&v| v == 0.0));
            for (i, v) in a.iter_mut().enumerate() {
                *v = i as f64 + 0.5;
            }
            let b = a.clone();
            for v in [&a, &b] {
                assert_eq!(v.as_ptr() as usize % 64, 0, "length {len}");
                assert_eq!(v.len(), len);
                assert!(v.iter().enumerate().all(|(i, &x)| x == i as f64 + 0.5));
            }
        }
    }

    #[test]
    fn each_lane_is_the_scalar_operation() {
        let a = X4([1.5, -0.0, f64::INFINITY, 3.0e-310]);
        let b = X4([0.1, 3.0, 2.0, 7.0]);
        type Scalar = fn(f64, f64) -> f64;
        let ops: [(X4, Scalar); 4] = [
            (a + b, |x, y| x + y),
            (a - b, |x, y| x - y),
            (a * b, |x, y| x * y),
            (a / b, |x, y| x / y),
        ];
        for (got, f) in ops {
            for i in 0..4 {
                assert_eq!(got.lane(i).to_bits(), f(a.lane(i), b.lane(i)).to_bits());
            }
        }
        for i in 0..4 {
            assert_eq!((-a).lane(i).to_bits(), (-a.lane(i)).to_bits());
        }
    }
}
