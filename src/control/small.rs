//! # Fixed-size matrices for the small problems of optimal control
//!
//! The recursions of [`super::rk4`], [`super::lqr`] and [`super::ddp`] work on n × n, n × m and
//! m × m matrices with n and m known per model (the acrobot: 4 and 1). Written once, generic
//! over nalgebra dimensions `N`, `M` ([`Dim`]), each recursion runs on stack-allocated
//! fixed-size matrices (`Const<n>`, loops the compiler unrolls, no heap) for the sizes
//! [`on_dims!`] lists, and on heap matrices (`Dyn`) for any other size.
//!
//! The two are the same arithmetic: the recursions multiply through [`crate::linalg::gemm`],
//! nalgebra's column-by-column kernel for any dimension type and size (nalgebra itself would
//! hand a dynamic product whose four dimensions all exceed 5 to `matrixmultiply`, whose kernel
//! and rounding depend on the processor), so both give the same bits (tested per recursion).

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, Matrix, OMatrix, OVector, RawStorage, RawStorageMut, U1};

/// The allocations an n-state, m-control recursion needs: n × n, n × m, m × n, m × m and
/// vectors of n and m (a bound alias for `DefaultAllocator`).
pub(crate) trait SmallAlloc<N: Dim, M: Dim>:
    Allocator<N, N> + Allocator<N, M> + Allocator<M, N> + Allocator<M, M> + Allocator<N> + Allocator<M>
{
}

impl<N: Dim, M: Dim, A> SmallAlloc<N, M> for A where
    A: Allocator<N, N>
        + Allocator<N, M>
        + Allocator<M, N>
        + Allocator<M, M>
        + Allocator<N>
        + Allocator<M>
{
}

/// Evaluates `$body` with `$nd`, `$md` bound to the nalgebra dimensions of n and m: fixed
/// ones (`Const`) for the sizes listed here, dynamic ones (`Dyn`) otherwise (module docs). The
/// body is expanded once per arm, so it may call functions generic over the dimensions. Every
/// fixed size must be at most 5 so that both paths give the same bits.
macro_rules! on_dims {
    ($n:expr, $m:expr, |$nd:ident, $md:ident| $body:expr) => {
        on_dims!($n, $m, |$nd, $md| $body, |$nd, $md| $body)
    };
    // With a separate body for the dynamic sizes (e.g. to use buffers kept in a workspace).
    ($n:expr, $m:expr, |$nd:ident, $md:ident| $body:expr, |$dn:ident, $dm:ident| $dyn_body:expr) => {
        match ($n, $m) {
            (4, 1) => {
                let ($nd, $md) = (nalgebra::Const::<4>, nalgebra::Const::<1>);
                $body
            }
            (2, 1) => {
                let ($nd, $md) = (nalgebra::Const::<2>, nalgebra::Const::<1>);
                $body
            }
            (n, m) => {
                let ($dn, $dm) = (nalgebra::Dyn(n), nalgebra::Dyn(m));
                $dyn_body
            }
        }
    };
}
pub(crate) use on_dims;

/// Copies a matrix of the same shape into `dst` (any storages; exact).
#[inline]
pub(crate) fn copy_into<R: Dim, C: Dim, R2: Dim, C2: Dim, S, S2>(
    dst: &mut Matrix<f64, R, C, S>,
    src: &Matrix<f64, R2, C2, S2>,
) where
    S: RawStorageMut<f64, R, C>,
    S2: RawStorage<f64, R2, C2>,
{
    assert_eq!(dst.shape(), src.shape(), "copy between different shapes");
    let (rows, cols) = dst.shape();
    for j in 0..cols {
        for i in 0..rows {
            // SAFETY: (i, j) is within both shapes (asserted equal above).
            unsafe { *dst.get_unchecked_mut((i, j)) = *src.get_unchecked((i, j)) };
        }
    }
}

/// Zero matrices and vectors of the shapes an n-state, m-control recursion uses (on the stack
/// for fixed dimensions).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Zeros<N: Dim, M: Dim> {
    /// n.
    pub(crate) n: N,
    /// m.
    pub(crate) m: M,
}

impl<N: Dim, M: Dim> Zeros<N, M>
where
    DefaultAllocator: SmallAlloc<N, M>,
{
    /// n × n.
    pub(crate) fn nn(self) -> OMatrix<f64, N, N> {
        OMatrix::zeros_generic(self.n, self.n)
    }
    /// n × m.
    pub(crate) fn nm(self) -> OMatrix<f64, N, M> {
        OMatrix::zeros_generic(self.n, self.m)
    }
    /// m × n.
    pub(crate) fn mn(self) -> OMatrix<f64, M, N> {
        OMatrix::zeros_generic(self.m, self.n)
    }
    /// m × m.
    pub(crate) fn mm(self) -> OMatrix<f64, M, M> {
        OMatrix::zeros_generic(self.m, self.m)
    }
    /// n.
    pub(crate) fn vn(self) -> OVector<f64, N> {
        OVector::zeros_generic(self.n, U1)
    }
    /// m.
    pub(crate) fn vm(self) -> OVector<f64, M> {
        OVector::zeros_generic(self.m, U1)
    }
}
