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
        std::f64::consts::LN_10 / -rho.ln()
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
