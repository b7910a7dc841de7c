//! The one conversion point between ndarray (batches, tables) and nalgebra (small dense linear
//! algebra: Cholesky, LU, eigen).

use nalgebra::{DMatrix, DVector};
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

#[cfg(test)]
mod tests {
    use super::*;

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
