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

use std::ops::{Add, Div, Mul, Neg, Sub};

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

#[cfg(test)]
mod tests {
    use super::*;

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
