//! # Normalization (NeuroAnimator Appendix A)
//!
//! Inputs and outputs of the network are shifted and scaled per group of variables,
//!
//! ```text
//! Tₓ^σ : a ↦ (a − μ) / σ     (eq. 16)         T_y^σ : ŷ ↦ μ + σ ŷ     (eq. 19)
//! ```
//!
//! with one mean μ and one deviation σ shared by all variables of a group (state, force and
//! control variables form separate groups). Eq. 18 as printed divides by (N − 1)(K − 1), which
//! is undefined for a one-variable group; we use the unbiased pooled variance
//! Σ(x − μ)² / (NK − 1) over the N examples and K variables of the group and divide by its
//! square root. A group with zero spread gets σ = 1. Both maps are diagonal, so their
//! Jacobian–vector and vector–Jacobian products are the same scaling
//! ([`Normalizer::normalize_tangent`], [`Normalizer::denormalize_tangent`]).
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, Appendix A.

use crate::emulator::EmulatorError;
use ndarray::ArrayView2;

/// Normalization to zero mean, unit variance per group of variables (Appendix A).
#[derive(Debug, Clone, PartialEq)]
pub struct Normalizer {
    /// Mean per variable (shared within a group).
    pub mean: Vec<f64>,
    /// Standard deviation per variable (shared within a group; never zero).
    pub std: Vec<f64>,
}

impl Normalizer {
    /// The identity map on `n` variables (mean 0, std 1).
    pub fn identity(n: usize) -> Self {
        Self {
            mean: vec![0.0; n],
            std: vec![1.0; n],
        }
    }

    /// Fits statistics to the rows of `data` (N × K). `groups[k]` is the group id of column `k`;
    /// columns with the same id share a mean and a standard deviation (eqs. 17–18).
    pub fn fit(data: ArrayView2<'_, f64>, groups: &[usize]) -> Result<Self, EmulatorError> {
        let k = data.ncols();
        if groups.len() != k {
            return Err(EmulatorError::Dimension {
                what: "normalization groups",
                expected: k,
                got: groups.len(),
            });
        }
        if data.nrows() < 2 {
            return Err(EmulatorError::TooFewExamples(data.nrows()));
        }
        let n_groups = groups.iter().copied().max().map_or(0, |g| g + 1);
        let mut sum = vec![0.0; n_groups];
        let mut count = vec![0usize; n_groups];
        for row in data.rows() {
            for (c, v) in row.iter().enumerate() {
                sum[groups[c]] += v;
                count[groups[c]] += 1;
            }
        }
        let mu: Vec<f64> = sum
            .iter()
            .zip(&count)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
            .collect();
        let mut ss = vec![0.0; n_groups];
        for row in data.rows() {
            for (c, v) in row.iter().enumerate() {
                let g = groups[c];
                ss[g] += (v - mu[g]) * (v - mu[g]);
            }
        }
        let sd: Vec<f64> = (0..n_groups)
            .map(|g| {
                let var = if count[g] > 1 {
                    ss[g] / (count[g] - 1) as f64
                } else {
                    0.0
                };
                let s = var.sqrt();
                if s > 1e-12 * (1.0 + mu[g].abs()) {
                    s
                } else {
                    1.0
                }
            })
            .collect();
        Ok(Self {
            mean: groups.iter().map(|&g| mu[g]).collect(),
            std: groups.iter().map(|&g| sd[g]).collect(),
        })
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.mean.len()
    }

    /// Whether there are no variables.
    pub fn is_empty(&self) -> bool {
        self.mean.is_empty()
    }

    /// Forward: z = (x − μ) / σ.
    #[inline(always)]
    pub fn normalize(&self, x: &[f64], z: &mut [f64]) {
        for (((z, x), m), s) in z.iter_mut().zip(x).zip(&self.mean).zip(&self.std) {
            *z = (x - m) / s;
        }
    }

    /// Inverse: x = μ + σ z.
    #[inline(always)]
    pub fn denormalize(&self, z: &[f64], x: &mut [f64]) {
        for (((x, z), m), s) in x.iter_mut().zip(z).zip(&self.mean).zip(&self.std) {
            *x = m + s * z;
        }
    }

    /// JVP and VJP of [`Normalizer::normalize`] (a diagonal map): `out = v / σ`.
    #[inline(always)]
    pub fn normalize_tangent(&self, v: &[f64], out: &mut [f64]) {
        for ((o, v), s) in out.iter_mut().zip(v).zip(&self.std) {
            *o = v / s;
        }
    }

    /// JVP and VJP of [`Normalizer::denormalize`] (a diagonal map): `out = σ v`.
    #[inline(always)]
    pub fn denormalize_tangent(&self, v: &[f64], out: &mut [f64]) {
        for ((o, v), s) in out.iter_mut().zip(v).zip(&self.std) {
            *o = v * s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn normalizer_fits_groups_and_inverts() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let data = Array2::from_shape_fn((500, 4), |(_, c)| {
            [10.0, 20.0, -3.0, 0.0][c] + [1.0, 3.0, 0.5, 0.0][c] * rng.random_range(-1.0..1.0)
        });
        // Columns 0 and 1 share a group; 2 alone; 3 is constant.
        let n = Normalizer::fit(data.view(), &[0, 0, 1, 2]).unwrap();
        assert_eq!(n.mean[0], n.mean[1]);
        assert_eq!(n.std[0], n.std[1]);
        assert!((n.mean[0] - 15.0).abs() < 0.5);
        assert!((n.mean[2] + 3.0).abs() < 0.1);
        assert_eq!(n.std[3], 1.0);
        // Per-variable groups give zero mean, unit variance columns.
        let n = Normalizer::fit(data.view(), &[0, 1, 2, 3]).unwrap();
        let mut z = Array2::zeros((500, 4));
        for (r, mut zr) in data.rows().into_iter().zip(z.rows_mut()) {
            n.normalize(r.as_slice().unwrap(), zr.as_slice_mut().unwrap());
        }
        for c in 0..3 {
            let col = z.column(c);
            assert!(col.mean().unwrap().abs() < 1e-12);
            assert!((col.var(1.0) - 1.0).abs() < 1e-12);
        }
        let x = [1.0, -2.0, 3.5, 0.25];
        let mut zz = [0.0; 4];
        let mut back = [0.0; 4];
        n.normalize(&x, &mut zz);
        n.denormalize(&zz, &mut back);
        for k in 0..4 {
            assert!((back[k] - x[k]).abs() < 1e-12);
        }
        // Tangent maps: (f(x + h v) − f(x − h v)) / 2h.
        let v = [0.3, -0.1, 2.0, 1.0];
        let mut t = [0.0; 4];
        n.normalize_tangent(&v, &mut t);
        let h = 1e-5;
        let xp: Vec<f64> = x.iter().zip(&v).map(|(a, b)| a + h * b).collect();
        let xm: Vec<f64> = x.iter().zip(&v).map(|(a, b)| a - h * b).collect();
        let (mut zp, mut zm) = ([0.0; 4], [0.0; 4]);
        n.normalize(&xp, &mut zp);
        n.normalize(&xm, &mut zm);
        for k in 0..4 {
            assert!(((zp[k] - zm[k]) / (2.0 * h) - t[k]).abs() < 1e-8);
        }
        n.denormalize_tangent(&t, &mut back);
        for k in 0..4 {
            assert!((back[k] - v[k]).abs() < 1e-12);
        }
    }
}
