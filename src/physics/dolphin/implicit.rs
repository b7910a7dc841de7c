//! Backward Euler for the dolphin, linearized once per step (Baraff & Witkin 1998, *Large
//! steps in cloth simulation*, §4.1), the kind of implicit mass-spring integrator the
//! NeuroAnimator's Table 2 timed the dolphin with (its ref. [18], Tu & Terzopoulos 1994,
//! solved a linear system per step as well).
//!
//! With forces f(x, v), masses M and step h, backward Euler asks
//! M Δv = h f(x₀ + h (v₀ + Δv), v₀ + Δv); one Newton step from (x₀, v₀) gives the linear system
//!
//! (M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f₀ + h ∂f/∂x v₀),  v₁ = v₀ + Δv,  x₁ = x₀ + h v₁.
//!
//! ∂f/∂x is the springs' stiffness: for spring a–b with direction e, length L and (muscle-set)
//! rest length L₀, the 3×3 block k e eᵀ + k max(1 − L₀/L, 0) (I − e eᵀ) (the geometric term of
//! a compressed spring is dropped, as is usual, so the matrix stays positive definite).
//! ∂f/∂v holds the springs' damping D e eᵀ and the hydrodynamic drag's velocity Jacobian: a face
//! pushing its `c` corners with −ρ A |n·v̄| (n·v̄) n / c, v̄ the corners' mean velocity, has
//! ∂f_i/∂v_j = −2 ρ A |n·v̄| n nᵀ / c² for each pair of its corners. Drag's dependence on the
//! positions (area, normal) and gravity are explicit. The 69 × 69 matrix is symmetric positive
//! definite and is factored densely by Cholesky each step, the O(N³) per step the paper charges
//! an implicit integrator with (§1, §5.1). The step is unconditionally stable for the linear
//! spring part and damps (never amplifies) the body's fast modes, so it runs at the paper's
//! δt = 0.01 s, where the semi-implicit Euler of [`crate::physics::IntegratorKind`] needs
//! ω_max δt < 2 and blows up (ω_max ≈ 330 rad/s).
//!
//! Stepping allocates nothing: the matrix, right-hand side and force buffers live in the
//! integrator and the Cholesky factor is computed in place.

use super::{add, point, Dolphin, N_MASSES, N_POS, N_SEGMENTS};
use crate::physics::{Dynamics, Model, Ode};
use nalgebra::{Cholesky, DMatrix, DVector, Matrix3};

/// The dolphin with a linearized backward-Euler step ([`Dynamics`]).
#[derive(Debug, Clone)]
pub struct ImplicitDolphin {
    dolphin: Dolphin,
    /// System matrix M − h ∂f/∂v − h² ∂f/∂x (overwritten by its Cholesky factor).
    a: DMatrix<f64>,
    /// Right-hand side, then Δv.
    b: DVector<f64>,
    /// Derivative buffer (positions' then velocities' rates).
    dx: Vec<f64>,
}

impl ImplicitDolphin {
    /// The integrator for `dolphin`.
    pub fn new(dolphin: Dolphin) -> Self {
        Self {
            dolphin,
            a: DMatrix::zeros(N_POS, N_POS),
            b: DVector::zeros(N_POS),
            dx: vec![0.0; 2 * N_POS],
        }
    }

    /// The model it integrates.
    pub fn dolphin(&self) -> &Dolphin {
        &self.dolphin
    }

    /// Adds `block` to the 3×3 blocks (i, i) and (j, j) and subtracts it from (i, j), (j, i):
    /// the pattern of a pairwise interaction's Jacobian.
    fn add_pair(&mut self, i: usize, j: usize, block: &Matrix3<f64>) {
        for r in 0..3 {
            for c in 0..3 {
                let v = block[(r, c)];
                self.a[(3 * i + r, 3 * i + c)] += v;
                self.a[(3 * j + r, 3 * j + c)] += v;
                self.a[(3 * i + r, 3 * j + c)] -= v;
                self.a[(3 * j + r, 3 * i + c)] -= v;
            }
        }
    }
}

impl Dynamics for ImplicitDolphin {
    fn state_dim(&self) -> usize {
        2 * N_POS
    }
    fn control_dim(&self) -> usize {
        N_SEGMENTS
    }

    fn step(&mut self, x: &mut [f64], u: &[f64], h: f64) {
        // f₀ = M a₀ (gravity included) from the force law itself.
        let mut dx = std::mem::take(&mut self.dx);
        self.dolphin.derivative(x, u, &mut dx);
        let (q, v) = x.split_at(N_POS);
        let masses = *self.dolphin.masses();
        self.a.fill(0.0);
        for (i, m) in masses.iter().enumerate() {
            for k in 0..3 {
                self.a[(3 * i + k, 3 * i + k)] = *m;
                self.b[3 * i + k] = h * m * dx[N_POS + 3 * i + k];
            }
        }
        let mut act = [0.0; N_SEGMENTS];
        for (a, ui) in act.iter_mut().zip(u) {
            *a = ui.clamp(-1.0, 1.0);
        }
        let damping = self.dolphin.params().damping;
        for s in 0..self.dolphin.springs().len() {
            let spring = self.dolphin.springs()[s];
            let d = point(q, spring.b) - point(q, spring.a);
            let len = d.norm();
            if len == 0.0 {
                continue;
            }
            let e = d / len;
            let eet = e * e.transpose();
            let rest = self.dolphin.active_rest_length(&spring, &act);
            let geometric = (1.0 - rest / len).max(0.0);
            // ∂f_a/∂p_b (= −∂f_a/∂p_a): positive semi-definite.
            let k = spring.stiffness * (eet + geometric * (Matrix3::identity() - eet));
            self.add_pair(spring.a, spring.b, &(h * h * k + h * damping * eet));
            // h² ∂f/∂x v₀: on a, k (v_b − v_a); on b the opposite.
            let kv = h * h * (k * (point(v, spring.b) - point(v, spring.a)));
            add(self.b.as_mut_slice(), spring.a, &kv);
            add(self.b.as_mut_slice(), spring.b, &-kv);
        }
        let rho = self.dolphin.params().drag;
        if rho > 0.0 {
            for f in 0..self.dolphin.faces().len() {
                let face = self.dolphin.faces()[f];
                let area_vec = face.vector_area(q);
                let area = area_vec.norm();
                if area == 0.0 {
                    continue;
                }
                let n = area_vec / area;
                let vn = n.dot(&face.mean(v));
                let c = face.n as f64;
                // −h ∂f/∂v: + h 2ρA|vn|/c² n nᵀ on every corner pair (i, j), i = j included.
                let block = (h * 2.0 * rho * area * vn.abs() / (c * c)) * (n * n.transpose());
                for &i in &face.corners[..face.n] {
                    for &j in &face.corners[..face.n] {
                        for r in 0..3 {
                            for col in 0..3 {
                                self.a[(3 * i + r, 3 * j + col)] += block[(r, col)];
                            }
                        }
                    }
                }
            }
        }
        self.dx = dx;
        let a = std::mem::replace(&mut self.a, DMatrix::zeros(0, 0));
        match Cholesky::new(a) {
            Some(chol) => {
                chol.solve_mut(&mut self.b);
                self.a = chol.unpack_dirty();
            }
            None => {
                // Not positive definite (a degenerate state): report a blow-up.
                self.a = DMatrix::zeros(N_POS, N_POS);
                x.fill(f64::NAN);
                return;
            }
        }
        let (q, v) = x.split_at_mut(N_POS);
        for i in 0..N_POS {
            v[i] += self.b[i];
            q[i] += h * v[i];
        }
        debug_assert_eq!(q.len(), 3 * N_MASSES);
    }
}

impl Model for ImplicitDolphin {
    fn name(&self) -> &str {
        self.dolphin.name()
    }
    fn state_names(&self) -> Vec<String> {
        self.dolphin.state_names()
    }
    fn control_names(&self) -> Vec<String> {
        self.dolphin.control_names()
    }
    fn parameters(&self) -> Vec<crate::physics::Parameter> {
        self.dolphin.parameters()
    }
    /// The paper's physical step for the dolphin (§6: 20 s are 2,000 physical steps).
    fn default_dt(&self) -> f64 {
        0.01
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::perturbed;
    use super::super::DolphinParams;
    use super::*;
    use crate::physics::{IntegratorKind, Simulator};

    fn run(sim: &mut dyn Dynamics, x0: &[f64], u: &[f64], h: f64, secs: f64) -> Vec<f64> {
        let mut x = x0.to_vec();
        for _ in 0..(secs / h).round() as usize {
            sim.step(&mut x, u, h);
        }
        x
    }

    fn max_diff(a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()))
    }

    #[test]
    fn converges_to_the_explicit_integrator_at_first_order() {
        // Drag, damping and muscles all on: the full force law.
        let d = Dolphin::default();
        let x0 = perturbed(&d, 0.02);
        let u = [0.5, -0.3, 0.8, -1.0, 0.2, 0.6];
        // ω_max h ≪ 1 (ω_max ≈ 330 rad/s), the asymptotic regime.
        let secs = 0.05;
        let mut rk4 = Simulator::new(d.clone(), IntegratorKind::Rk4);
        let reference = run(&mut rk4, &x0, &u, 1e-5, secs);
        let err = |h: f64| {
            let mut imp = ImplicitDolphin::new(d.clone());
            max_diff(&run(&mut imp, &x0, &u, h, secs), &reference)
        };
        let errs = [err(2e-4), err(1e-4), err(5e-5)];
        eprintln!("backward Euler max state error vs RK4 at h = 2e-4, 1e-4, 5e-5: {errs:?}");
        for w in errs.windows(2) {
            let ratio = w[0] / w[1];
            assert!((1.6..2.5).contains(&ratio), "not first order: {errs:?}");
        }
        let scale = reference.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(errs[2] < 0.05 * scale, "{errs:?} of {scale}");
        // ... and so does the semi-implicit Euler at the same steps: the two agree as h → 0.
        let mut sie = Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler);
        let explicit = run(&mut sie, &x0, &u, 5e-5, secs);
        let mut imp = ImplicitDolphin::new(d.clone());
        let implicit = run(&mut imp, &x0, &u, 5e-5, secs);
        assert!(max_diff(&explicit, &implicit) < 2.0 * errs[2] + 1e-9);
    }

    #[test]
    fn stable_at_the_papers_step_where_semi_implicit_euler_blows_up() {
        let d = Dolphin::default();
        let h = 0.01;
        let x0 = perturbed(&d, 0.02);
        let u = [0.0; N_SEGMENTS];
        let mut sie = Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler);
        let explicit = run(&mut sie, &x0, &u, h, 2.0);
        assert!(
            explicit.iter().any(|v| !v.is_finite() || v.abs() > 1e6),
            "semi-implicit Euler survived h = {h}"
        );
        let mut imp = ImplicitDolphin::new(d.clone());
        let x = run(&mut imp, &x0, &u, h, 20.0);
        assert!(x.iter().all(|v| v.is_finite()));
        assert!(
            d.shape_error(&x) < 0.05,
            "shape error {}",
            d.shape_error(&x)
        );
        // Also while swimming: a travelling wave for 10 s keeps the shape.
        let mut x = d.rest_state();
        let mut w = [0.0; N_SEGMENTS];
        for k in 0..1000 {
            for (s, ws) in w.iter_mut().enumerate() {
                *ws = (std::f64::consts::TAU * k as f64 * h - 0.5 * s as f64).sin();
            }
            imp.step(&mut x, &w, h);
        }
        assert!(x.iter().all(|v| v.is_finite()));
        assert!(d.shape_error(&x) < 0.1, "shape error {}", d.shape_error(&x));
    }

    #[test]
    fn dissipates_energy_without_external_forces() {
        // No drag, no gravity, no muscles, no spring damping: all the loss is the integrator's.
        let d = Dolphin::new(DolphinParams {
            drag: 0.0,
            damping: 0.0,
            gravity: 0.0,
            ..DolphinParams::default()
        })
        .unwrap();
        let x0 = perturbed(&d, 0.02);
        let e0 = d.energy(&x0).unwrap();
        let mut imp = ImplicitDolphin::new(d.clone());
        let mut x = x0.clone();
        let mut peak = e0;
        for _ in 0..500 {
            imp.step(&mut x, &[0.0; N_SEGMENTS], 0.01);
            peak = peak.max(d.energy(&x).unwrap());
        }
        let e = d.energy(&x).unwrap();
        eprintln!("backward Euler, h = 0.01, 5 s: energy {e0:.3} J -> {e:.3} J, peak {peak:.3} J");
        assert!(peak <= e0 * (1.0 + 1e-9), "energy created: {peak} > {e0}");
        assert!(e < 0.9 * e0, "no dissipation: {e} vs {e0}");
        // Momentum is still exact: the linearized forces stay internal and central.
        let p0 = d.momentum(&x0);
        assert!((d.momentum(&x) - p0).norm() < 1e-9 * p0.norm().max(1.0));
    }
}
