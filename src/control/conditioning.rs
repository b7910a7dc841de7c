//! # Why first-order descent is slow on a control problem: the spectrum of its Gauss–Newton matrix
//!
//! A terminal objective ½ Σ_k w_k (s_Mk − s̄_k)² over knots v has the Gauss–Newton matrix
//! G = Jᵀ W J, J = ∂s_M/∂v ([`Bptt::gauss_newton`] with the state terms only). Its rank is at
//! most the number of independent final-state variables r, and descent with a fixed step
//! η/λ (λ: the step scale, the largest curvature measured at the start) shrinks the residual
//! along eigenvector i by the factor of the heavy-ball recursion
//!
//! ```text
//! e_{l+1} = (1 + α − h_i) e_l − α e_{l−1},      h_i = η μ_i / λ,
//! ```
//!
//! per iteration: the larger root magnitude ρ_i of z² − (1 + α − h_i) z + α
//! ([`heavy_ball_rate`]; α = 0 is plain descent, ρ = |1 − h|). The slowest weighted direction,
//! μ_r, sets the pace: ln 10 / −ln ρ_r iterations per tenfold reduction
//! ([`iterations_per_decade`]). A problem whose κ = μ_1/μ_r is in the thousands cannot be solved
//! in 15 iterations by any fixed-step first-order rule, whatever the gradient's source (an
//! emulator or the exact physics); Newton-type steps (Levenberg–Marquardt) are invariant to it.
//!
//! Exact for a linear step with a quadratic objective (a test checks the predicted pace
//! against momentum descent itself); elsewhere it describes the problem at the point where G
//! is taken.

use super::bptt::Bptt;
use super::objective::GaussNewton;
use crate::physics::differentiable::DifferentiableStep;

/// The spectrum of a problem's terminal Gauss–Newton matrix at some knots.
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    /// Eigenvalues of G = Jᵀ W J over the normalized knots, largest first.
    pub eigenvalues: Vec<f64>,
    /// Independent final-state variables r (the rank G can have).
    pub dof: usize,
}

impl Spectrum {
    /// μ_1.
    pub fn largest(&self) -> f64 {
        self.eigenvalues.first().copied().unwrap_or(f64::NAN)
    }

    /// μ_r, the smallest eigenvalue in the weighted range (NaN if there are fewer knots).
    pub fn slowest(&self) -> f64 {
        match self.dof {
            0 => f64::NAN,
            r => self.eigenvalues.get(r - 1).copied().unwrap_or(f64::NAN),
        }
    }

    /// κ = μ_1 / μ_r.
    pub fn condition(&self) -> f64 {
        self.largest() / self.slowest()
    }
}

/// The spectrum of G at normalized knots `v` from the state terms of `curvature` (control
/// effort terms left out: their Hessian only adds the small effort floor), with `dof`
/// independent final-state variables.
pub fn terminal_spectrum<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v: &[f64],
    curvature: &[GaussNewton],
    dof: usize,
) -> Spectrum {
    let d = bptt.dim();
    let states: Vec<GaussNewton> = curvature
        .iter()
        .filter(|c| matches!(c, GaussNewton::States { .. }))
        .cloned()
        .collect();
    let (mut g, mut h) = (vec![0.0; d], vec![0.0; d * d]);
    bptt.gauss_newton(v, &states, &mut g, &mut h);
    let m = nalgebra::DMatrix::from_row_slice(d, d, &h);
    let mut eigenvalues: Vec<f64> = m.symmetric_eigenvalues().iter().copied().collect();
    eigenvalues.sort_by(|a, b| b.total_cmp(a));
    Spectrum { eigenvalues, dof }
}

/// How far any choice of final-state weights could improve the conditioning: for the rows
/// J_k = ∂s_Mk/∂v of r independent final-state variables, every positive diagonal weighting
/// W gives G = Jᵀ W J the nonzero spectrum of W^½ K W^½, K = J Jᵀ (r × r). Equilibrating
/// (w_k = 1/K_kk, unit diagonal) is within a factor r of the best weighting (van der Sluis,
/// 1969: κ(D_J K D_J) ≤ r min_D κ(D K D) for symmetric positive definite K), so
/// κ_eq / r bounds from below the condition of every weighting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightingBound {
    /// r, the variables weighed.
    pub vars: usize,
    /// κ of the equilibrated K (infinite when K is singular: some variable combination does
    /// not respond to the knots under any weights).
    pub condition_equilibrated: f64,
    /// max(1, κ_eq / r): no diagonal weighting of these variables does better.
    pub condition_any_weighting: f64,
}

/// [`WeightingBound`] of the Jacobian rows `rows` (one per independent variable, each over
/// the knots). K's smallest eigenvalue below 1e-13 of its largest counts as singular.
pub fn weighting_bound(rows: &[Vec<f64>]) -> WeightingBound {
    let r = rows.len();
    let g = gram(rows);
    let k = nalgebra::DMatrix::from_fn(r, r, |i, j| {
        let (di, dj) = (g[(i, i)], g[(j, j)]);
        if di > 0.0 && dj > 0.0 {
            g[(i, j)] / (di * dj).sqrt()
        } else {
            0.0
        }
    });
    let e = k.symmetric_eigenvalues();
    let (lo, hi) = (e.min(), e.max());
    let condition_equilibrated = if r == 0 || lo.is_nan() || lo <= 1e-13 * hi {
        f64::INFINITY
    } else {
        hi / lo
    };
    WeightingBound {
        vars: r,
        condition_equilibrated,
        condition_any_weighting: (condition_equilibrated / r.max(1) as f64).max(1.0),
    }
}

/// The largest eigenvalue of W^½ K W^½, K the Gram matrix of the Jacobian rows `rows` and
/// `w` one weight per row: the largest terminal Gauss-Newton eigenvalue under those weights.
pub fn largest_weighted_eigenvalue(rows: &[Vec<f64>], w: &[f64]) -> f64 {
    let k = gram(rows);
    let r = k.nrows();
    nalgebra::DMatrix::from_fn(r, r, |i, j| k[(i, j)] * (w[i] * w[j]).sqrt())
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The Gram matrix K_ij = J_i · J_j of Jacobian rows.
fn gram(rows: &[Vec<f64>]) -> nalgebra::DMatrix<f64> {
    let r = rows.len();
    nalgebra::DMatrix::from_fn(r, r, |i, j| {
        rows[i]
            .iter()
            .zip(&rows[j])
            .map(|(x, y)| x * y)
            .sum::<f64>()
    })
}

/// κ of W^½ K W^½ for diagonal weights `w` (∞ when not positive definite).
fn weighted_condition(k: &nalgebra::DMatrix<f64>, w: &[f64]) -> f64 {
    let r = k.nrows();
    let m = nalgebra::DMatrix::from_fn(r, r, |i, j| k[(i, j)] * (w[i] * w[j]).sqrt());
    let e = m.symmetric_eigenvalues();
    let (lo, hi) = (e.min(), e.max());
    if lo > 1e-13 * hi {
        hi / lo
    } else {
        f64::INFINITY
    }
}

/// The diagonal weighting of the rows' variables with the smallest condition that a
/// Nelder–Mead search finds ([`crate::control::search::nelder_mead`], over log₁₀ factors within
/// ±3 decades of the equilibrating weights 1/K_kk, which are within a factor r of the best):
/// the weights (scaled so their largest eigenvalue of W^½ K W^½ is 1) and that condition.
/// `None` when K is singular (no weighting conditions it).
pub fn best_weighting(rows: &[Vec<f64>]) -> Option<(Vec<f64>, f64)> {
    use crate::control::search::{nelder_mead, Budget, SearchBox, SearchProblem, SimplexConfig};
    let k = gram(rows);
    let r = rows.len();
    let base: Vec<f64> = (0..r).map(|i| 1.0 / k[(i, i)]).collect();
    if r == 0 || !weighted_condition(&k, &base).is_finite() {
        return None;
    }
    struct LogCondition {
        k: nalgebra::DMatrix<f64>,
        base: Vec<f64>,
        bx: SearchBox,
    }
    impl LogCondition {
        fn weights(&self, x: &[f64]) -> Vec<f64> {
            self.base
                .iter()
                .zip(x)
                .map(|(b, x)| b * crate::portable::powf(10.0, *x))
                .collect()
        }
    }
    impl SearchProblem for LogCondition {
        fn search_box(&self) -> &SearchBox {
            &self.bx
        }
        fn evaluate(&self, x: &[f64]) -> f64 {
            crate::portable::ln(weighted_condition(&self.k, &self.weights(x)))
        }
    }
    let problem = LogCondition {
        k,
        base,
        bx: SearchBox::cube(r, -3.0, 3.0).expect("a valid box"),
    };
    let cfg = SimplexConfig {
        step: 0.1,
        ..SimplexConfig::default()
    };
    let found = nelder_mead(&problem, &vec![0.0; r], &cfg, &Budget::iterations(4000)).ok()?;
    let w = problem.weights(&found.best);
    let k = &problem.k;
    let m = nalgebra::DMatrix::from_fn(r, r, |i, j| k[(i, j)] * (w[i] * w[j]).sqrt());
    let top = m.symmetric_eigenvalues().max();
    Some((
        w.iter().map(|w| w / top).collect(),
        crate::portable::exp(found.best_value),
    ))
}

/// Per-iteration contraction ρ of heavy-ball descent (momentum `alpha`, 0 for plain) along a
/// direction whose scaled curvature is h = η μ / λ: the larger root magnitude of
/// z² − (1 + α − h) z + α (1 or more: no progress, or divergence).
pub fn heavy_ball_rate(h: f64, alpha: f64) -> f64 {
    let b = 1.0 + alpha - h;
    let disc = b * b - 4.0 * alpha;
    if disc >= 0.0 {
        let s = disc.sqrt();
        ((b + s) / 2.0).abs().max(((b - s) / 2.0).abs())
    } else {
        // Complex pair: |z|² = α.
        alpha.sqrt()
    }
}

/// Iterations per tenfold reduction of the residual along a direction with scaled curvature
/// h (infinite when ρ ≥ 1).
pub fn iterations_per_decade(h: f64, alpha: f64) -> f64 {
    let rho = heavy_ball_rate(h, alpha);
    if rho >= 1.0 {
        f64::INFINITY
    } else {
        std::f64::consts::LN_10 / -crate::portable::ln(rho)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_descent_rate_is_one_minus_the_step() {
        for h in [0.01_f64, 0.3, 1.0, 1.7] {
            assert!((heavy_ball_rate(h, 0.0) - (1.0_f64 - h).abs()).abs() < 1e-15);
        }
        assert!(heavy_ball_rate(2.5, 0.0) > 1.0);
        assert_eq!(iterations_per_decade(0.0, 0.5), f64::INFINITY);
    }

    /// The monomials (10 s)^p, p = 0 … 3, on a 400-point grid of [0, 1]: rows whose Gram
    /// matrix is a scaled Hilbert matrix H₄.
    fn hilbert_rows() -> Vec<Vec<f64>> {
        let grid = 400;
        (0..4)
            .map(|p| {
                (0..grid)
                    .map(|t| ((t as f64 + 0.5) / grid as f64).powi(p) * 10f64.powi(p))
                    .collect()
            })
            .collect()
    }

    /// Rows whose Gram matrix is the Hilbert-like K_ij = 1/(i + j + 1) (monomials 1 … s³ on
    /// a fine grid): the bound holds against random weightings and the equilibrated one, and
    /// orthogonal rows of any lengths are perfectly conditionable.
    #[test]
    fn no_weighting_beats_the_van_der_sluis_bound() {
        use rand::{Rng, SeedableRng};
        let rows = hilbert_rows();
        let b = weighting_bound(&rows);
        assert_eq!(b.vars, 4);
        // The Hilbert matrix H₄ equilibrated has κ in the thousands.
        assert!(b.condition_equilibrated > 1e3, "{b:?}");
        let kappa = |w: &[f64]| {
            let k = nalgebra::DMatrix::from_fn(4, 4, |i, j| {
                let d: f64 = rows[i].iter().zip(&rows[j]).map(|(x, y)| x * y).sum();
                d * (w[i] * w[j]).sqrt()
            });
            let e = k.symmetric_eigenvalues();
            e.max() / e.min()
        };
        // Weights within 10^±3 of the equilibrating ones (further out the weighted matrix's
        // smallest eigenvalue falls below what its eigen-solver resolves).
        let norm2: Vec<f64> = rows.iter().map(|r| r.iter().map(|x| x * x).sum()).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..2000 {
            let w: Vec<f64> = (0..4)
                .map(|i| 10f64.powf(rng.random_range(-3.0..3.0)) / norm2[i])
                .collect();
            assert!(kappa(&w) >= b.condition_any_weighting, "{w:?}");
        }
        let ortho = vec![
            vec![3.0, 0.0, 0.0],
            vec![0.0, 1e-4, 0.0],
            vec![0.0, 0.0, 7e5],
        ];
        let o = weighting_bound(&ortho);
        assert!((o.condition_equilibrated - 1.0).abs() < 1e-12);
        assert_eq!(o.condition_any_weighting, 1.0);
        // A variable that does not respond: singular under every weighting.
        let dead = vec![vec![1.0, 2.0], vec![0.0, 0.0]];
        assert_eq!(weighting_bound(&dead).condition_equilibrated, f64::INFINITY);
        let collinear = vec![vec![1.0, 2.0], vec![-2.0, -4.0]];
        assert_eq!(
            weighting_bound(&collinear).condition_any_weighting,
            f64::INFINITY
        );
    }

    /// The search's weighting beats the equilibrated one on the Hilbert-like rows, never the
    /// van der Sluis bound, and its scale puts W^½ K W^½'s largest eigenvalue at 1.
    #[test]
    fn the_best_weighting_lies_between_the_bound_and_equilibration() {
        let rows = hilbert_rows();
        let b = weighting_bound(&rows);
        let (w, kappa) = best_weighting(&rows).unwrap();
        assert!(kappa >= b.condition_any_weighting, "{kappa} {b:?}");
        assert!(kappa < 0.9 * b.condition_equilibrated, "{kappa} {b:?}");
        let k = gram(&rows);
        assert!((weighted_condition(&k, &w) - kappa).abs() <= 1e-6 * kappa);
        let m = nalgebra::DMatrix::from_fn(4, 4, |i, j| k[(i, j)] * (w[i] * w[j]).sqrt());
        assert!((m.symmetric_eigenvalues().max() - 1.0).abs() < 1e-12);
        assert!(best_weighting(&[vec![1.0, 2.0], vec![2.0, 4.0]]).is_none());
    }

    /// On a quadratic ½ Σ μ_i x_i², momentum descent with step η/λ needs, along its slowest
    /// direction, the predicted iterations per decade: run it and count.
    #[test]
    fn the_predicted_pace_matches_momentum_descent_on_a_quadratic() {
        let mu = [400.0, 30.0, 8.0, 2.5];
        let lambda = mu[0];
        // Settings whose slowest mode has real roots (a complex pair oscillates with a period
        // longer than a decade, which a settling count cannot resolve).
        for (eta, alpha) in [(1.5, 0.5), (1.0, 0.0), (0.5, 0.3)] {
            let mut x = [1.0_f64; 4];
            let mut delta = [0.0; 4];
            let mut slow = Vec::new();
            for _ in 0..20000 {
                for i in 0..4 {
                    delta[i] = -eta / lambda * mu[i] * x[i] + alpha * delta[i];
                    x[i] += delta[i];
                }
                slow.push(x[3].abs());
            }
            // Measured: iterations between |x_4| staying below 1e-3 and staying below 1e-4
            // (the last time above each: an oscillating mode crosses zero on the way).
            let settled = |t: f64| slow.iter().rposition(|v| *v >= t).unwrap() as f64;
            let measured = settled(1e-4) - settled(1e-3);
            let predicted = iterations_per_decade(eta * mu[3] / lambda, alpha);
            assert!(
                (measured - predicted).abs() <= 0.1 * predicted + 2.0,
                "eta {eta}, alpha {alpha}: measured {measured}, predicted {predicted}"
            );
        }
    }
}
