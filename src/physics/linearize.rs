//! # Linearization: the Jacobians of ẋ = f(x, u)
//!
//! A model that can be linearized gives, at any (x, u), the continuous-time Jacobians
//!
//! - A = ∂f/∂x (d × d) and
//! - B = ∂f/∂u (d × m),
//!
//! so that f(x + δx, u + δu) ≈ f(x, u) + A δx + B δu. Trajectory optimizers (DDP, iLQR) and
//! LQR trackers need them; gradient-free searches do not.
//!
//! [`finite_difference_jacobians`] computes them by central differences for any [`Ode`]
//! (2(d + m) evaluations of f, truncation error O(ε²)); [`FiniteDifference`] wraps any model so
//! that it implements [`Linearize`] that way. Models with analytic Jacobians (the
//! [`super::acrobot::Acrobot`]) implement the trait directly, and tests compare the two.

use super::{Model, Ode, Parameter};
use crate::lanes::X4;
use nalgebra::DMatrix;

/// A continuous-time system whose Jacobians A = ∂f/∂x and B = ∂f/∂u are available.
pub trait Linearize: Ode {
    /// Writes A = ∂f/∂x (d × d) into `a` and B = ∂f/∂u (d × m) into `b` at (x, u).
    ///
    /// `a` and `b` must already have those shapes.
    fn jacobians(&self, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>);

    /// Writes f(x, u) into `dx` and the Jacobians into `a` and `b` at the same point, exactly
    /// the values of [`Ode::derivative`] and [`Linearize::jacobians`] (the default calls
    /// both). A model overrides it to share the work of the two (the acrobot's trigonometry),
    /// as the RK4 map's Jacobians need both at every stage.
    fn derivative_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        dx: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        self.derivative(x, u, dx);
        self.jacobians(x, u, a, b);
    }

    /// [`Linearize::derivative_and_jacobians`] at four points at once, point i in lane i of
    /// every value ([`X4`]): `x` (d), `u` (m), `dx` (d), `a` (d × d) and `b` (d × m), the
    /// matrices column-major. Lane i must be bit for bit the scalar method's value at point i.
    /// Returns false, writing nothing, where the model has no lane form (the default); the
    /// RK4 map's [`crate::control::Rk4Map::jacobians_each`] then goes point by point.
    fn derivative_and_jacobians_x4(
        &self,
        _x: &[X4],
        _u: &[X4],
        _dx: &mut [X4],
        _a: &mut [X4],
        _b: &mut [X4],
    ) -> bool {
        false
    }
}

/// Default relative step of [`finite_difference_jacobians`]: about ε_mach^(1/3), the best
/// balance of truncation (O(h²)) and round-off (O(ε_mach/h)) error for central differences.
pub const DEFAULT_FD_STEP: f64 = 6e-6;

/// Central-difference Jacobians of any [`Ode`]: column j of A is
/// (f(x + h e_j, u) − f(x − h e_j, u)) / 2h with h = `step`·max(1, |x_j|), likewise for B.
///
/// Allocates three small scratch vectors per call; prefer analytic Jacobians in hot loops.
pub fn finite_difference_jacobians<M: Ode + ?Sized>(
    model: &M,
    x: &[f64],
    u: &[f64],
    step: f64,
    a: &mut DMatrix<f64>,
    b: &mut DMatrix<f64>,
) {
    let (d, m) = (x.len(), u.len());
    assert_eq!(a.shape(), (d, d), "A must be d × d");
    assert_eq!(b.shape(), (d, m), "B must be d × m");
    let mut xp = x.to_vec();
    let mut up = u.to_vec();
    let mut fp = vec![0.0; d];
    let mut fm = vec![0.0; d];
    for j in 0..d {
        let h = step * x[j].abs().max(1.0);
        xp[j] = x[j] + h;
        model.derivative(&xp, u, &mut fp);
        xp[j] = x[j] - h;
        model.derivative(&xp, u, &mut fm);
        xp[j] = x[j];
        for i in 0..d {
            a[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
    for j in 0..m {
        let h = step * u[j].abs().max(1.0);
        up[j] = u[j] + h;
        model.derivative(x, &up, &mut fp);
        up[j] = u[j] - h;
        model.derivative(x, &up, &mut fm);
        up[j] = u[j];
        for i in 0..d {
            b[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
}

/// Any [`Ode`], linearized by central finite differences ([`finite_difference_jacobians`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FiniteDifference<M> {
    /// The wrapped model.
    pub model: M,
    /// Relative difference step (see [`DEFAULT_FD_STEP`]).
    pub step: f64,
}

impl<M> FiniteDifference<M> {
    /// Wraps `model` with the default step.
    pub fn new(model: M) -> Self {
        Self {
            model,
            step: DEFAULT_FD_STEP,
        }
    }
}

impl<M: Model> Model for FiniteDifference<M> {
    fn name(&self) -> &str {
        self.model.name()
    }
    fn state_names(&self) -> Vec<String> {
        self.model.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.model.control_names()
    }
    fn parameters(&self) -> Vec<Parameter> {
        self.model.parameters()
    }
    fn default_dt(&self) -> f64 {
        self.model.default_dt()
    }
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.model.control_dim()
    }
}

impl<M: Ode> Ode for FiniteDifference<M> {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.model.derivative(x, u, dx)
    }
    fn position_dim(&self) -> Option<usize> {
        self.model.position_dim()
    }
    fn energy(&self, x: &[f64]) -> Option<f64> {
        self.model.energy(x)
    }
}

impl<M: Ode> Linearize for FiniteDifference<M> {
    fn jacobians(&self, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        finite_difference_jacobians(&self.model, x, u, self.step, a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::acrobot::Acrobot;
    use crate::physics::pendulum::{Pendulum3, PendulumVariant};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Max |X − Y| / max(1, max |Y|).
    fn rel_err(x: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
        (x - y).amax() / y.amax().max(1.0)
    }

    #[test]
    fn acrobot_analytic_jacobians_match_finite_differences() {
        let model = Acrobot::default();
        let fd = FiniteDifference::new(model.clone());
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut a, mut b) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        let (mut a_fd, mut b_fd) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        for _ in 0..20 {
            let x: Vec<f64> = (0..4).map(|_| rng.random_range(-3.0..3.0)).collect();
            let u = [rng.random_range(-5.0..5.0)];
            model.jacobians(&x, &u, &mut a, &mut b);
            fd.jacobians(&x, &u, &mut a_fd, &mut b_fd);
            assert!(rel_err(&a, &a_fd) < 1e-6, "A at {x:?}: {a} vs {a_fd}");
            assert!(rel_err(&b, &b_fd) < 1e-6, "B at {x:?}: {b} vs {b_fd}");
        }
    }

    #[test]
    fn finite_differences_are_exact_for_a_linear_ode() {
        // The pendulum's first two state rows are q̇ = ω: exact identity blocks.
        let p = FiniteDifference::new(Pendulum3::new(PendulumVariant::Active));
        let d = p.state_dim();
        let m = p.control_dim();
        let x = vec![0.1; d];
        let u = vec![0.0; m];
        let (mut a, mut b) = (DMatrix::zeros(d, d), DMatrix::zeros(d, m));
        p.jacobians(&x, &u, &mut a, &mut b);
        let nq = p.position_dim().unwrap();
        for i in 0..nq {
            for j in 0..d {
                let want = if j == nq + i { 1.0 } else { 0.0 };
                assert!(
                    (a[(i, j)] - want).abs() < 1e-9,
                    "A[{i},{j}] = {}",
                    a[(i, j)]
                );
            }
        }
    }
}
