//! # One small matrix per knot, stored contiguously
//!
//! A trajectory's controllers keep a matrix of one shape at each knot: the gains K_k (m × n),
//! the value Hessians P_k (n × n), the reference states x̄_k (n × 1). [`Knots`] holds all of
//! them in one buffer (each knot's matrix column-major, knot after knot) instead of one heap
//! matrix per knot, so building a tracker allocates a handful of buffers rather than thousands,
//! and reading it walks memory in order. Each knot is lent out as an nalgebra view.

use nalgebra::{DMatrixView, DMatrixViewMut, DVector, DVectorView};

/// `len` matrices of `rows` × `cols`, contiguous (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Knots {
    len: usize,
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

impl Knots {
    /// `len` zero matrices of `rows` × `cols`.
    pub fn zeros(len: usize, rows: usize, cols: usize) -> Self {
        Self {
            len,
            rows,
            cols,
            data: vec![0.0; len * rows * cols],
        }
    }

    /// The vectors as one column each; panics unless all have the same length.
    pub fn from_vectors(vectors: &[DVector<f64>]) -> Self {
        let rows = vectors.first().map_or(0, |v| v.len());
        let mut data = Vec::with_capacity(vectors.len() * rows);
        for (k, v) in vectors.iter().enumerate() {
            assert_eq!(
                v.len(),
                rows,
                "vector {k} has length {}, not {rows}",
                v.len()
            );
            data.extend_from_slice(v.as_slice());
        }
        Self {
            len: vectors.len(),
            rows,
            cols: 1,
            data,
        }
    }

    /// Number of knots.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no knots.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// (rows, columns) of every knot's matrix.
    pub fn shape(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    /// Knot `k`'s entries, column-major.
    #[inline]
    pub fn slice(&self, k: usize) -> &[f64] {
        assert!(k < self.len, "knot {k} of {}", self.len);
        let size = self.rows * self.cols;
        &self.data[k * size..(k + 1) * size]
    }

    /// Knot `k`'s matrix.
    #[inline]
    pub fn matrix(&self, k: usize) -> DMatrixView<'_, f64> {
        DMatrixView::from_slice(self.slice(k), self.rows, self.cols)
    }

    /// Knot `k`'s matrix, mutable.
    #[inline]
    pub fn matrix_mut(&mut self, k: usize) -> DMatrixViewMut<'_, f64> {
        assert!(k < self.len, "knot {k} of {}", self.len);
        let size = self.rows * self.cols;
        let slice = &mut self.data[k * size..(k + 1) * size];
        DMatrixViewMut::from_slice(slice, self.rows, self.cols)
    }

    /// Knot `k`'s vector; panics unless the matrices have one column.
    #[inline]
    pub fn vector(&self, k: usize) -> DVectorView<'_, f64> {
        assert_eq!(
            self.cols, 1,
            "knots of {} columns are not vectors",
            self.cols
        );
        DVectorView::from_slice(self.slice(k), self.rows)
    }

    /// The knots' matrices in order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = DMatrixView<'_, f64>> + '_ {
        (0..self.len()).map(|k| self.matrix(k))
    }

    /// Every entry, knot after knot (each knot column-major).
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn knots_are_contiguous_column_major_matrices() {
        let mut knots = Knots::zeros(3, 2, 3);
        assert_eq!((knots.len(), knots.shape()), (3, (2, 3)));
        knots.matrix_mut(1)[(1, 2)] = 5.0;
        knots.matrix_mut(2)[(0, 1)] = -1.0;
        assert_eq!(knots.matrix(1)[(1, 2)], 5.0);
        assert_eq!(knots.slice(1)[1 + 2 * 2], 5.0);
        assert_eq!(knots.as_slice()[2 * 6 + 2], -1.0);
        let expected = DMatrix::from_row_slice(2, 3, &[0.0, -1.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(knots.matrix(2), expected);
        assert_eq!(knots.iter().filter(|m| m.amax() > 0.0).count(), 2);
        let vs = [
            DVector::from_vec(vec![1.0, 2.0]),
            DVector::from_vec(vec![3.0, 4.0]),
        ];
        let v = Knots::from_vectors(&vs);
        assert_eq!((v.len(), v.shape()), (2, (2, 1)));
        assert_eq!(v.vector(1), vs[1]);
        assert_eq!(Knots::from_vectors(&[]).len(), 0);
        assert!(Knots::zeros(0, 4, 4).is_empty());
    }

    #[test]
    #[should_panic(expected = "vector 1 has length 3")]
    fn vectors_of_different_lengths_are_rejected() {
        Knots::from_vectors(&[DVector::zeros(2), DVector::zeros(3)]);
    }
}
