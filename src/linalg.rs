//! The one conversion point between ndarray (batches, tables) and nalgebra (small dense linear
//! algebra: Cholesky, LU, eigen), and the matrix product every control recursion uses.
//!
//! **One product, the same bits everywhere.** nalgebra multiplies dynamic matrices whose four
//! dimensions all exceed 5 through `matrixmultiply`, which picks its kernel by processor at
//! run time (AVX-512, AVX2 + FMA, AVX, plain), and the kernels round differently (a fused
//! multiply–add rounds once). [`gemm`] and [`mul_to`] are nalgebra's own small-matrix path
//! (column by column, C₍:,j₎ = Σ_k (α A₍:,k₎) B₍k,j₎ accumulated in k order) for every
//! size: bit for bit nalgebra's product wherever nalgebra does not hand it over (every
//! fixed-size and every small matrix), and the same on every processor for large ones.

use nalgebra::{DMatrix, DVector, Dim, Matrix, Storage, StorageMut};
use ndarray::{Array1, Array2, ArrayView1, ArrayView2};

/// ndarray matrix → nalgebra matrix.
pub fn to_dmatrix(a: ArrayView2<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]])
}

/// ndarray vector → nalgebra vector.
pub fn to_dvector(a: ArrayView1<'_, f64>) -> DVector<f64> {
    DVector::from_iterator(a.len(), a.iter().copied())
}

/// nalgebra matrix → ndarray matrix.
pub fn to_array2(m: &DMatrix<f64>) -> Array2<f64> {
    Array2::from_shape_fn((m.nrows(), m.ncols()), |(i, j)| m[(i, j)])
}

/// nalgebra vector → ndarray vector.
pub fn to_array1(v: &DVector<f64>) -> Array1<f64> {
    Array1::from_iter(v.iter().copied())
}

/// C ← α A B + β C (β = 0: C is not read), as nalgebra's `gemm` computes it for small
/// matrices, for any size (module docs). Panics if the shapes do not match.
pub fn gemm<R1, C1, R2, C2, R3, C3, SC, SA, SB>(
    c: &mut Matrix<f64, R1, C1, SC>,
    alpha: f64,
    a: &Matrix<f64, R2, C2, SA>,
    b: &Matrix<f64, R3, C3, SB>,
    beta: f64,
) where
    R1: Dim,
    C1: Dim,
    R2: Dim,
    C2: Dim,
    R3: Dim,
    C3: Dim,
    SC: StorageMut<f64, R1, C1>,
    SA: Storage<f64, R2, C2>,
    SB: Storage<f64, R3, C3>,
{
    assert!(
        a.ncols() == b.nrows() && c.nrows() == a.nrows() && c.ncols() == b.ncols(),
        "gemm: dimensions mismatch"
    );
    for j in 0..c.ncols() {
        let mut cj = c.column_mut(j);
        if a.ncols() == 0 {
            cj.iter_mut()
                .for_each(|v| *v = if beta == 0.0 { 0.0 } else { *v * beta });
            continue;
        }
        for k in 0..a.ncols() {
            let bkj = b[(k, j)];
            // nalgebra's axcpy: y = α a_ik b_kj + β y, β = 0 not reading y, β = 1 after k = 0.
            let scale = if k == 0 { beta } else { 1.0 };
            for (y, &aik) in cj.iter_mut().zip(a.column(k).iter()) {
                let p = alpha * aik * bkj;
                *y = if scale == 0.0 { p } else { p + scale * *y };
            }
        }
    }
}

/// C ← A B ([`gemm`] with α = 1, β = 0), as nalgebra's `mul_to` for small matrices.
pub fn mul_to<R1, C1, R2, C2, R3, C3, SC, SA, SB>(
    a: &Matrix<f64, R2, C2, SA>,
    b: &Matrix<f64, R3, C3, SB>,
    c: &mut Matrix<f64, R1, C1, SC>,
) where
    R1: Dim,
    C1: Dim,
    R2: Dim,
    C2: Dim,
    R3: Dim,
    C3: Dim,
    SC: StorageMut<f64, R1, C1>,
    SA: Storage<f64, R2, C2>,
    SB: Storage<f64, R3, C3>,
{
    gemm(c, 1.0, a, b, 0.0);
}

/// Solves the leading `n` × `n` block of the symmetric positive-definite system `a x = b` in
/// place by Cholesky (`a` becomes its factor L, `b` becomes x), in fixed arrays so a model's
/// `derivative` never allocates; pivots are floored at 1e-300 before their square root.
pub fn cholesky_solve_fixed<const N: usize>(a: &mut [[f64; N]; N], b: &mut [f64; N], n: usize) {
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        let d = d.max(1e-300).sqrt();
        a[j][j] = d;
        for i in j + 1..n {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i][k] * b[k];
        }
        b[i] = s / a[i][i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k][i] * b[k];
        }
        b[i] = s / a[i][i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random(r: &mut rand_chacha::ChaCha8Rng, n: usize, m: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, m, |_, _| r.random_range(-1.0..1.0))
    }

    #[test]
    fn gemm_is_nalgebras_small_matrix_product_bit_for_bit() {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (n, k, m) in [(1, 1, 1), (4, 4, 1), (5, 5, 5), (2, 5, 3), (5, 0, 2)] {
            for (alpha, beta) in [(1.0, 0.0), (0.37, 1.0), (-1.3, 0.6)] {
                let (a, b) = (random(&mut r, n, k), random(&mut r, k, m));
                let c0 = random(&mut r, n, m);
                let (mut ours, mut theirs) = (c0.clone(), c0.clone());
                gemm(&mut ours, alpha, &a, &b, beta);
                theirs.gemm(alpha, &a, &b, beta);
                assert_eq!(
                    ours.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    theirs.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    "{n}x{k}x{m}"
                );
            }
        }
    }

    #[test]
    fn large_products_are_the_product() {
        let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let (a, b) = (random(&mut r, 18, 18), random(&mut r, 18, 6));
        let mut c = DMatrix::zeros(18, 6);
        mul_to(&a, &b, &mut c);
        assert!((c - &a * &b).abs().max() < 1e-13);
        // A fixed-size product through the same function.
        let f = nalgebra::Matrix2::new(1.0, 2.0, 3.0, 4.0);
        let mut g = nalgebra::Matrix2::zeros();
        mul_to(&f, &f, &mut g);
        assert_eq!(g, f * f);
    }

    #[test]
    fn round_trips() {
        let a = ndarray::array![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        let m = to_dmatrix(a.view());
        assert_eq!(m[(1, 2)], 6.0);
        assert_eq!(to_array2(&m), a);
        let v = ndarray::array![1.0, -2.0];
        assert_eq!(to_array1(&to_dvector(v.view())), v);
    }
}
