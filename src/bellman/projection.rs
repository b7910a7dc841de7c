//! # Projection of a desired terminal reward onto component rewards (LBC §4.1)
//!
//! Each component controller i has a quadratic terminal cost g_i(x) = (x − x̄_i)ᵀ Q_i (x − x̄_i),
//! i.e. a Gaussian terminal reward h_i = exp(−g_i). The fixed blend weights w of linear Bellman
//! combination make Σ w_i h_i the least-squares approximation (in L²) of a desired reward
//! h̄ = exp(−ḡ): solve the normal equations A w = b with A_ij = ⟨h_i, h_j⟩, b_i = ⟨h_i, h̄⟩.
//!
//! Inner products of Gaussians are analytic in any dimension d:
//!
//! ⟨h_a, h_b⟩ = π^{d/2} det(Q_a + Q_b)^{−1/2} exp(−(a − b)ᵀ Q_a (Q_a + Q_b)^{−1} Q_b (a − b)).
//!
//! The reconstructed terminal cost is g(x) = −log Σ w_i h_i(x); where the components lie far
//! apart relative to their width it has several minima (the paper's Fig. 4).
//!
//! ## References
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, §4.1 and Fig. 3–4.

use nalgebra::{DMatrix, DVector};

/// Errors of the projection.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum ProjectionError {
    /// Components of different dimensions.
    #[error("component {index} has dimension {got}, expected {expected}")]
    DimensionMismatch {
        /// Offending component (the desired reward is index `usize::MAX`).
        index: usize,
        /// Its dimension.
        got: usize,
        /// The first component's dimension.
        expected: usize,
    },
    /// A cost matrix that is not symmetric positive definite.
    #[error("cost matrix of component {index} is not symmetric positive definite")]
    NotPositiveDefinite {
        /// Offending component (the desired reward is index `usize::MAX`).
        index: usize,
    },
    /// The Gram matrix is singular (duplicate components).
    #[error("the Gram matrix of the component rewards is singular (duplicate components?)")]
    Singular,
    /// No components.
    #[error("no components to project onto")]
    Empty,
}

/// A Gaussian reward h(x) = exp(−(x − center)ᵀ Q (x − center)).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianReward {
    /// Minimum of the quadratic cost.
    pub center: DVector<f64>,
    /// Symmetric positive definite cost matrix Q.
    pub q: DMatrix<f64>,
}

impl GaussianReward {
    /// Reward with isotropic cost `scale · |x − center|²`.
    pub fn isotropic(center: &[f64], scale: f64) -> Self {
        let d = center.len();
        Self {
            center: DVector::from_column_slice(center),
            q: DMatrix::identity(d, d) * scale,
        }
    }

    /// The quadratic cost g(x).
    pub fn cost(&self, x: &DVector<f64>) -> f64 {
        let dx = x - &self.center;
        (dx.transpose() * &self.q * &dx)[0]
    }

    /// The reward h(x) = exp(−g(x)).
    pub fn reward(&self, x: &DVector<f64>) -> f64 {
        crate::portable::exp(-self.cost(x))
    }

    fn dim(&self) -> usize {
        self.center.len()
    }
}

/// ⟨h_a, h_b⟩ = ∫ h_a(x) h_b(x) dx over ℝ^d, analytically.
pub fn inner_product(a: &GaussianReward, b: &GaussianReward) -> Option<f64> {
    let d = a.dim();
    let sum = &a.q + &b.q;
    let chol = sum.clone().cholesky()?;
    let det = chol.determinant();
    let diff = &a.center - &b.center;
    // Qa (Qa+Qb)^{-1} Qb (a-b)
    let y = chol.solve(&(&b.q * &diff));
    let expo = (diff.transpose() * &a.q * y)[0];
    Some(
        crate::portable::powf(std::f64::consts::PI, d as f64 / 2.0) / det.sqrt()
            * crate::portable::exp(-expo),
    )
}

/// Result of projecting a desired reward onto component rewards.
#[derive(Debug, Clone, PartialEq)]
pub struct Projection {
    /// Blend weights w (solution of A w = b).
    pub weights: Vec<f64>,
    /// Gram matrix A_ij = ⟨h_i, h_j⟩.
    pub gram: DMatrix<f64>,
    /// b_i = ⟨h_i, h̄⟩.
    pub rhs: Vec<f64>,
    /// Relative L² residual ‖Σ w_i h_i − h̄‖ / ‖h̄‖.
    pub relative_residual: f64,
}

fn check(index: usize, g: &GaussianReward, d: usize) -> Result<(), ProjectionError> {
    if g.dim() != d || g.q.nrows() != d || g.q.ncols() != d {
        return Err(ProjectionError::DimensionMismatch {
            index,
            got: g.dim(),
            expected: d,
        });
    }
    let sym = (&g.q - g.q.transpose()).abs().max() <= 1e-12 * g.q.abs().max().max(1.0);
    if !sym || g.q.clone().cholesky().is_none() {
        return Err(ProjectionError::NotPositiveDefinite { index });
    }
    Ok(())
}

/// Projects `desired` onto `components`: the weights w minimizing ‖Σ w_i h_i − h̄‖_L².
pub fn project(
    components: &[GaussianReward],
    desired: &GaussianReward,
) -> Result<Projection, ProjectionError> {
    let first = components.first().ok_or(ProjectionError::Empty)?;
    let d = first.dim();
    for (i, c) in components.iter().enumerate() {
        check(i, c, d)?;
    }
    check(usize::MAX, desired, d)?;
    let n = components.len();
    let ip = |a: &GaussianReward, b: &GaussianReward| inner_product(a, b).expect("checked SPD");
    let gram = DMatrix::from_fn(n, n, |i, j| ip(&components[i], &components[j]));
    let rhs = DVector::from_fn(n, |i, _| ip(&components[i], desired));
    // Near-duplicate components make the normal equations meaningless.
    let eig = gram.clone().symmetric_eigenvalues();
    let (lo, hi) = eig.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &e| {
        (a.min(e), b.max(e.abs()))
    });
    if !(lo > 1e-12 * hi) {
        return Err(ProjectionError::Singular);
    }
    let w = gram
        .clone()
        .cholesky()
        .map(|c| c.solve(&rhs))
        .or_else(|| gram.clone().lu().solve(&rhs))
        .ok_or(ProjectionError::Singular)?;
    if w.iter().any(|v| !v.is_finite()) {
        return Err(ProjectionError::Singular);
    }
    // ‖Σ w h − h̄‖² = wᵀAw − 2wᵀb + ⟨h̄,h̄⟩
    let hh = ip(desired, desired);
    let r2 = ((w.transpose() * &gram * &w)[0] - 2.0 * w.dot(&rhs) + hh).max(0.0);
    Ok(Projection {
        weights: w.iter().copied().collect(),
        gram,
        rhs: rhs.iter().copied().collect(),
        relative_residual: (r2 / hh).sqrt(),
    })
}

/// The combined reward Σ w_i h_i(x).
pub fn combined_reward(components: &[GaussianReward], weights: &[f64], x: &DVector<f64>) -> f64 {
    components
        .iter()
        .zip(weights)
        .map(|(c, w)| w * c.reward(x))
        .sum()
}

/// The reconstructed terminal cost −log Σ w_i h_i(x); `+∞` where the combined reward is ≤ 0.
pub fn reconstructed_cost(components: &[GaussianReward], weights: &[f64], x: &DVector<f64>) -> f64 {
    let r = combined_reward(components, weights, x);
    if r > 0.0 {
        -crate::portable::ln(r)
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inner_product_matches_quadrature_in_2d() {
        let a = GaussianReward {
            center: DVector::from_vec(vec![0.2, -0.1]),
            q: DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]),
        };
        let b = GaussianReward::isotropic(&[-0.3, 0.4], 1.5);
        let exact = inner_product(&a, &b).unwrap();
        let (n, lim) = (600, 5.0);
        let h = 2.0 * lim / n as f64;
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                let x = DVector::from_vec(vec![
                    -lim + (i as f64 + 0.5) * h,
                    -lim + (j as f64 + 0.5) * h,
                ]);
                sum += a.reward(&x) * b.reward(&x);
            }
        }
        let quad = sum * h * h;
        assert!((exact - quad).abs() < 1e-8 * exact, "{exact} vs {quad}");
    }

    #[test]
    fn projecting_a_component_returns_a_unit_vector() {
        let comps = vec![
            GaussianReward::isotropic(&[0.0, 0.0, 0.0], 2.0),
            GaussianReward::isotropic(&[1.0, 0.0, 0.0], 2.0),
            GaussianReward::isotropic(&[0.0, 1.0, 0.5], 2.0),
        ];
        let p = project(&comps, &comps[1]).unwrap();
        for (i, w) in p.weights.iter().enumerate() {
            let expect = if i == 1 { 1.0 } else { 0.0 };
            assert!((w - expect).abs() < 1e-9, "{:?}", p.weights);
        }
        assert!(p.relative_residual < 1e-6);
    }

    #[test]
    fn rejects_bad_input() {
        let a = GaussianReward::isotropic(&[0.0], 1.0);
        let b = GaussianReward::isotropic(&[0.0, 1.0], 1.0);
        assert!(matches!(
            project(&[a.clone(), b], &a),
            Err(ProjectionError::DimensionMismatch { index: 1, .. })
        ));
        let neg = GaussianReward::isotropic(&[0.0], -1.0);
        assert!(matches!(
            project(&[neg], &a),
            Err(ProjectionError::NotPositiveDefinite { index: 0 })
        ));
        assert_eq!(project(&[], &a), Err(ProjectionError::Empty));
        assert_eq!(
            project(&[a.clone(), a.clone()], &a),
            Err(ProjectionError::Singular)
        );
    }

    #[test]
    fn far_components_give_two_minima() {
        let cost_at = |spacing: f64, x: f64| {
            let comps = vec![
                GaussianReward::isotropic(&[0.0], 1.0),
                GaussianReward::isotropic(&[spacing], 1.0),
            ];
            let des = GaussianReward::isotropic(&[spacing / 2.0], 1.0);
            let p = project(&comps, &des).unwrap();
            reconstructed_cost(&comps, &p.weights, &DVector::from_vec(vec![x]))
        };
        // Far: the midpoint is a local maximum of the reconstructed cost.
        let s = 6.0;
        assert!(cost_at(s, s / 2.0) > cost_at(s, 0.0));
        // Near: the midpoint is the minimum.
        let s = 0.8;
        assert!(cost_at(s, s / 2.0) < cost_at(s, 0.0));
        assert!(cost_at(s, s / 2.0) < cost_at(s, s / 2.0 + 0.1));
    }
}
