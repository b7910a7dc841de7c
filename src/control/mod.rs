//! # Optimal control: trajectory optimization and LQR tracking
//!
//! Everything here works on one discrete-time problem built from a continuous model
//! ẋ = f(x, u) that implements [`Linearize`](crate::physics::linearize::Linearize):
//!
//! - dynamics x_{k+1} = F(x_k, u_k), one classic RK4 step of `dt` with u_k held constant
//!   ([`Rk4Map`]);
//! - cost J = g(x_N) + Σ_{k<N} dt·(q(x_k) + ½ u_kᵀ R u_k) ([`QuadraticCost`]), with the
//!   terminal cost g(x) = (x − x̄)ᵀ Q_f (x − x̄) of linear Bellman combination (§5.1) and an
//!   optional running state cost q(x) = (x − r_k)ᵀ Q (x − r_k).
//!
//! The derivatives of F are exact for the RK4 map: with stage states y_s = x + c_s k_{s−1}
//! (c = 0, h/2, h/2, h) and stage Jacobians A_s, B_s of f at (y_s, u),
//!
//! ```text
//! ∂k_s/∂x = A_s (I + c_s ∂k_{s−1}/∂x),   ∂k_s/∂u = A_s c_s ∂k_{s−1}/∂u + B_s,
//! F_x = I + h/6 (∂k_1 + 2∂k_2 + 2∂k_3 + ∂k_4)/∂x,   F_u likewise without the I.
//! ```
//!
//! Second derivatives (full DDP only) are central differences of (F_x, F_u).
//!
//! - [`ddp`]: differential dynamic programming, iLQR and full second-order, with
//!   Levenberg–Marquardt regularization, line search and box control bounds.
//! - [`lqr`]: time-varying LQR tracking of a given trajectory and its quadratic value function
//!   (linear Bellman combination, eq. 12), for an RK4 map or any source of step Jacobians;
//!   [`step_tracker`]: the same tracker along a tape learned through an emulator, linearized by
//!   the emulator's exact Jacobians (value functions for linear Bellman combination of BPTT
//!   controllers). A tracker keeps its per-knot vectors and matrices in [`Knots`]: one
//!   contiguous buffer each, not one heap matrix per knot.
//!
//! - [`objective`]: NeuroAnimator control-learning objectives (§4.2) as composable terms with
//!   gradients; [`bptt`]: backpropagation through time through any
//!   [`crate::physics::DifferentiableStep`] (an emulator, or [`Rk4Map`] of a physical model:
//!   its vector–Jacobian product is
//!   s̄ = F_xᵀ s̄', ū = F_uᵀ s̄' with the exact Jacobians above), plain and momentum descent on
//!   piecewise-constant controls (§4.3);
//!   [`search`]: box-bounded searches with one trace and budget — simulated annealing,
//!   Nelder–Mead, parallel hill climbing and BPTT — on emulator or simulator rollouts (§6).
//!
//! Solvers return data; they never print or write files.

pub mod bptt;
pub mod conditioning;
pub mod ddp;
pub mod gait_value;
pub mod knots;
pub mod lqr;
pub mod objective;
pub mod search;
pub mod simbicon;
pub mod step_tracker;
pub mod tracker;

mod cost;
mod rk4;
pub(crate) mod small;

pub use cost::{QuadraticCost, StageDerivatives, StateCost};
pub use knots::Knots;
pub use rk4::{Rk4Map, Rk4StepScratch, Rk4Workspace};

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// Errors of the control module; each carries the offending value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ControlError {
    /// The time step must be positive and finite.
    #[error("time step must be positive and finite, got {0}")]
    InvalidTimeStep(f64),
    /// The horizon must have at least one step.
    #[error("the horizon must have at least one step")]
    EmptyHorizon,
    /// A vector or matrix has the wrong size.
    #[error("{what}: expected size {expected}, got {found}")]
    DimensionMismatch {
        /// Which argument.
        what: &'static str,
        /// Size the problem needs.
        expected: usize,
        /// Size given.
        found: usize,
    },
    /// A control bound has lower > upper (or is NaN).
    #[error("control bound {index}: lower {lower} > upper {upper}")]
    InvalidBounds {
        /// Control index.
        index: usize,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// A rollout produced NaN or infinity.
    #[error("rollout became non-finite at step {step}")]
    NonFinite {
        /// Step index whose result was not finite.
        step: usize,
    },
    /// A search budget sets no limit (iterations, evaluations or seconds).
    #[error("the search budget sets no limit")]
    UnboundedBudget,
    /// A search setting is out of its range.
    #[error("{what} out of range: {value}")]
    InvalidSetting {
        /// Which setting.
        what: &'static str,
        /// The value given.
        value: f64,
    },
    /// The control Hessian Q_uu of the LQR recursion is not positive definite.
    #[error("Q_uu is not positive definite at step {step}")]
    NotPositiveDefinite {
        /// Step index.
        step: usize,
    },
}

/// `Ok` when a size is as expected, else [`ControlError::DimensionMismatch`] naming `what`.
pub(crate) fn check_dim(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), ControlError> {
    if expected == found {
        Ok(())
    } else {
        Err(ControlError::DimensionMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Replaces a square matrix by ½(A + Aᵀ) in place.
pub(crate) fn symmetrize<N: Dim, S: RawStorageMut<f64, N, N>>(a: &mut Matrix<f64, N, N, S>) {
    let n = a.nrows();
    for j in 0..n {
        for i in 0..j {
            let v = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// In-place Cholesky factorization of the leading `dim` × `dim` block of `a` (its lower
/// triangle becomes L with A = L Lᵀ). Returns false when the block is not positive definite.
pub(crate) fn cholesky_in_place<R: Dim, C: Dim, S: RawStorageMut<f64, R, C>>(
    a: &mut Matrix<f64, R, C, S>,
    dim: usize,
) -> bool {
    for j in 0..dim {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[(j, j)] = d;
        for i in j + 1..dim {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / d;
        }
    }
    true
}

/// Solves L Lᵀ y = b in place with the factor of [`cholesky_in_place`] (leading `dim` block).
pub(crate) fn cholesky_solve_in_place<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
    l: &Matrix<f64, R, C, S>,
    dim: usize,
    b: &mut [f64],
) {
    for i in 0..dim {
        let mut s = b[i];
        for k in 0..i {
            s -= l[(i, k)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
    for i in (0..dim).rev() {
        let mut s = b[i];
        for k in i + 1..dim {
            s -= l[(k, i)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
}

#[cfg(test)]
pub(crate) mod test_models {
    //! Models used only by the control tests.
    use crate::physics::linearize::Linearize;
    use crate::physics::{Model, Ode, Parameter};
    use nalgebra::{DMatrix, DVector};
    use rand::Rng;
    use rand_chacha::ChaCha8Rng;

    /// A vector of n uniform draws from (−s, s).
    pub fn random_vec(rng: &mut ChaCha8Rng, n: usize, s: f64) -> DVector<f64> {
        DVector::from_fn(n, |_, _| rng.random_range(-s..s))
    }

    /// ẋ = A x + B u.
    #[derive(Debug, Clone)]
    pub struct LinearOde {
        pub a: DMatrix<f64>,
        pub b: DMatrix<f64>,
    }

    impl Model for LinearOde {
        fn name(&self) -> &str {
            "linear"
        }
        fn state_names(&self) -> Vec<String> {
            (0..self.a.nrows()).map(|i| format!("x{i}")).collect()
        }
        fn control_names(&self) -> Vec<String> {
            (0..self.b.ncols()).map(|i| format!("u{i}")).collect()
        }
        fn parameters(&self) -> Vec<Parameter> {
            vec![]
        }
        fn default_dt(&self) -> f64 {
            0.1
        }
    }

    impl Ode for LinearOde {
        fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
            for (i, d) in dx.iter_mut().enumerate() {
                *d = (0..x.len()).map(|j| self.a[(i, j)] * x[j]).sum::<f64>()
                    + (0..u.len()).map(|j| self.b[(i, j)] * u[j]).sum::<f64>();
            }
        }
    }

    impl Linearize for LinearOde {
        fn jacobians(&self, _x: &[f64], _u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
            a.copy_from(&self.a);
            b.copy_from(&self.b);
        }
    }

    /// A damped pendulum, θ̈ = −(g/l) sin θ − c θ̇ + u: a nonlinear model with two states and
    /// one control (the 2 × 1 fixed-size arm of `super::small::on_dims`).
    #[derive(Debug, Clone)]
    pub struct DampedPendulum;

    const G_OVER_L: f64 = 9.81;
    const DAMPING: f64 = 0.3;

    impl Model for DampedPendulum {
        fn name(&self) -> &str {
            "damped pendulum"
        }
        fn state_names(&self) -> Vec<String> {
            vec!["theta".into(), "omega".into()]
        }
        fn control_names(&self) -> Vec<String> {
            vec!["torque".into()]
        }
        fn parameters(&self) -> Vec<Parameter> {
            vec![]
        }
        fn default_dt(&self) -> f64 {
            0.05
        }
    }

    impl Ode for DampedPendulum {
        fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -G_OVER_L * x[0].sin() - DAMPING * x[1] + u[0];
        }
    }

    impl Linearize for DampedPendulum {
        fn jacobians(&self, x: &[f64], _u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
            a.as_mut_slice()
                .copy_from_slice(&[0.0, -G_OVER_L * x[0].cos(), 1.0, -DAMPING]);
            b.as_mut_slice().copy_from_slice(&[0.0, 1.0]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::acrobot::Acrobot;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn cholesky_helpers_solve_spd_systems_and_reject_indefinite_ones() {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let mut l = a.clone();
        assert!(cholesky_in_place(&mut l, 3));
        let mut y = [1.0, -2.0, 0.5];
        cholesky_solve_in_place(&l, 3, &mut y);
        let r = &a * DVector::from_row_slice(&y) - DVector::from_row_slice(&[1.0, -2.0, 0.5]);
        assert!(r.amax() < 1e-12);
        let mut bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky_in_place(&mut bad, 2));
    }

    #[test]
    fn invalid_inputs_are_reported_with_their_values() {
        assert_eq!(
            Rk4Map::new(Acrobot::default(), -0.1).unwrap_err(),
            ControlError::InvalidTimeStep(-0.1)
        );
        let cost = QuadraticCost::effort(0.01, 2, DMatrix::identity(4, 4), DVector::zeros(4));
        assert_eq!(
            cost.validate(4, 1, 10).unwrap_err(),
            ControlError::DimensionMismatch {
                what: "R rows",
                expected: 1,
                found: 2
            }
        );
    }
}
