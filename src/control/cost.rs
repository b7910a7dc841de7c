//! # The quadratic cost of trajectory optimization (linear Bellman combination §5.1)
//!
//! J = g(x_N) + Σ_{k<N} l_k(x_k, u_k) with running cost l_k = dt·(q(x_k) + ½ u_kᵀ R u_k),
//! optional state cost q(x) = (x − r_k)ᵀ Q (x − r_k) around a reference, and terminal cost
//! g(x) = (x − x̄)ᵀ Q_f (x − x̄). Their derivatives are closed-form,
//!
//! ```text
//! l_x = dt (Q + Qᵀ)(x − r_k),  l_xx = dt (Q + Qᵀ),  l_u = dt ½(R + Rᵀ) u,  l_uu = dt ½(R + Rᵀ),
//! g_x = (Q_f + Q_fᵀ)(x − x̄),   g_xx = Q_f + Q_fᵀ,
//! ```
//!
//! which DDP and LQR consume ([`StageDerivatives`]).
//!
//! ## References
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, §5.1.

use super::{check_dim, ControlError};
use nalgebra::{DMatrix, DVector};

/// Running state cost q(x) = (x − r_k)ᵀ Q (x − r_k) around a reference.
#[derive(Debug, Clone, PartialEq)]
pub struct StateCost {
    /// Weight Q (n × n, symmetric positive semidefinite).
    pub weight: DMatrix<f64>,
    /// Reference states: one (constant reference) or one per step k = 0..N−1.
    pub reference: Vec<DVector<f64>>,
}

impl StateCost {
    fn reference(&self, k: usize) -> &DVector<f64> {
        if self.reference.len() == 1 {
            &self.reference[0]
        } else {
            &self.reference[k]
        }
    }
}

/// First and second derivatives of one step's running cost l(x, u).
#[derive(Debug, Clone, PartialEq)]
pub struct StageDerivatives {
    /// ∂l/∂x (n).
    pub lx: DVector<f64>,
    /// ∂l/∂u (m).
    pub lu: DVector<f64>,
    /// ∂²l/∂x² (n × n).
    pub lxx: DMatrix<f64>,
    /// ∂²l/∂u² (m × m).
    pub luu: DMatrix<f64>,
}

impl StageDerivatives {
    /// Zeroed buffers for n states and m controls.
    pub fn new(n: usize, m: usize) -> Self {
        Self {
            lx: DVector::zeros(n),
            lu: DVector::zeros(m),
            lxx: DMatrix::zeros(n, n),
            luu: DMatrix::zeros(m, m),
        }
    }
}

/// The cost J = g(x_N) + Σ_k dt·(q(x_k) + ½ u_kᵀ R u_k) with g(x) = (x − x̄)ᵀ Q_f (x − x̄).
#[derive(Debug, Clone, PartialEq)]
pub struct QuadraticCost {
    /// Time step weighting the running cost (s); use the map's `dt`.
    pub dt: f64,
    /// Control weight R (m × m, symmetric positive definite).
    pub r: DMatrix<f64>,
    /// Optional running state cost q.
    pub state: Option<StateCost>,
    /// Terminal weight Q_f (n × n, symmetric positive semidefinite).
    pub q_final: DMatrix<f64>,
    /// Terminal target x̄.
    pub x_final: DVector<f64>,
}

impl QuadraticCost {
    /// ½∫uᵀu dt plus the terminal cost (x − x̄)ᵀ Q_f (x − x̄): the swing-up objective of linear
    /// Bellman combination §6.2.
    pub fn effort(
        dt: f64,
        control_dim: usize,
        q_final: DMatrix<f64>,
        x_final: DVector<f64>,
    ) -> Self {
        Self {
            dt,
            r: DMatrix::identity(control_dim, control_dim),
            state: None,
            q_final,
            x_final,
        }
    }

    /// Checks sizes against a problem with n states, m controls and horizon N.
    pub fn validate(&self, n: usize, m: usize, horizon: usize) -> Result<(), ControlError> {
        let dim = check_dim;
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(ControlError::InvalidTimeStep(self.dt));
        }
        dim("R rows", m, self.r.nrows())?;
        dim("R columns", m, self.r.ncols())?;
        dim("Q_f rows", n, self.q_final.nrows())?;
        dim("Q_f columns", n, self.q_final.ncols())?;
        dim("terminal target", n, self.x_final.len())?;
        if let Some(s) = &self.state {
            dim("Q rows", n, s.weight.nrows())?;
            dim("Q columns", n, s.weight.ncols())?;
            if s.reference.len() != 1 {
                dim("state references", horizon, s.reference.len())?;
            }
            for r in &s.reference {
                dim("state reference", n, r.len())?;
            }
        }
        Ok(())
    }

    /// Running cost of step k: dt·(q(x) + ½ uᵀ R u).
    pub fn running(&self, k: usize, x: &DVector<f64>, u: &DVector<f64>) -> f64 {
        let mut c = 0.5 * quad_form(&self.r, u.as_slice(), None);
        if let Some(s) = &self.state {
            c += quad_form(&s.weight, x.as_slice(), Some(s.reference(k).as_slice()));
        }
        self.dt * c
    }

    /// Terminal cost g(x) = (x − x̄)ᵀ Q_f (x − x̄).
    pub fn terminal(&self, x: &DVector<f64>) -> f64 {
        quad_form(&self.q_final, x.as_slice(), Some(self.x_final.as_slice()))
    }

    /// Total cost of a trajectory of N + 1 states and N controls.
    pub fn total(&self, xs: &[DVector<f64>], us: &[DVector<f64>]) -> f64 {
        let run: f64 = us
            .iter()
            .enumerate()
            .map(|(k, u)| self.running(k, &xs[k], u))
            .sum();
        run + self.terminal(&xs[us.len()])
    }

    /// Derivatives of the running cost of step k into `out` (l_ux = 0). Does not allocate.
    pub fn running_derivatives(
        &self,
        k: usize,
        x: &DVector<f64>,
        u: &DVector<f64>,
        out: &mut StageDerivatives,
    ) {
        let dt = self.dt;
        // ½ uᵀRu: gradient ½(R + Rᵀ)u, Hessian ½(R + Rᵀ).
        sym_grad_hess(
            &self.r,
            u.as_slice(),
            None,
            0.5 * dt,
            &mut out.lu,
            &mut out.luu,
        );
        match &self.state {
            Some(s) => sym_grad_hess(
                &s.weight,
                x.as_slice(),
                Some(s.reference(k).as_slice()),
                dt,
                &mut out.lx,
                &mut out.lxx,
            ),
            None => {
                out.lx.fill(0.0);
                out.lxx.fill(0.0);
            }
        }
    }

    /// Derivatives of the terminal cost: g_x = (Q_f + Q_fᵀ)(x − x̄), g_xx = Q_f + Q_fᵀ.
    pub fn terminal_derivatives(
        &self,
        x: &DVector<f64>,
        gx: &mut DVector<f64>,
        gxx: &mut DMatrix<f64>,
    ) {
        sym_grad_hess(
            &self.q_final,
            x.as_slice(),
            Some(self.x_final.as_slice()),
            1.0,
            gx,
            gxx,
        );
    }
}

/// (x − c)ᵀ W (x − c), with c = 0 when absent.
fn quad_form(w: &DMatrix<f64>, x: &[f64], c: Option<&[f64]>) -> f64 {
    let d = |i: usize| x[i] - c.map_or(0.0, |c| c[i]);
    let mut s = 0.0;
    for j in 0..x.len() {
        let dj = d(j);
        for i in 0..x.len() {
            s += d(i) * w[(i, j)] * dj;
        }
    }
    s
}

/// Gradient and Hessian of scale·(x − c)ᵀ W (x − c): scale·(W + Wᵀ)(x − c), scale·(W + Wᵀ).
fn sym_grad_hess(
    w: &DMatrix<f64>,
    x: &[f64],
    c: Option<&[f64]>,
    scale: f64,
    grad: &mut DVector<f64>,
    hess: &mut DMatrix<f64>,
) {
    let n = x.len();
    for j in 0..n {
        for i in 0..n {
            hess[(i, j)] = scale * (w[(i, j)] + w[(j, i)]);
        }
    }
    for i in 0..n {
        let mut g = 0.0;
        for j in 0..n {
            g += hess[(i, j)] * (x[j] - c.map_or(0.0, |c| c[j]));
        }
        grad[i] = g;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::test_models::random_vec;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn cost_derivatives_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (n, m) = (3, 2);
        let sym = |rng: &mut ChaCha8Rng, d: usize| {
            let a = DMatrix::from_fn(d, d, |_, _| rng.random_range(-1.0..1.0));
            &a * a.transpose() + DMatrix::identity(d, d)
        };
        // A deliberately non-symmetric Q: the derivatives must use its symmetric part.
        let mut q = sym(&mut rng, n);
        q[(0, 1)] += 0.3;
        let cost = QuadraticCost {
            dt: 0.1,
            r: sym(&mut rng, m),
            state: Some(StateCost {
                weight: q,
                reference: vec![random_vec(&mut rng, n, 1.0), random_vec(&mut rng, n, 1.0)],
            }),
            q_final: sym(&mut rng, n),
            x_final: random_vec(&mut rng, n, 1.0),
        };
        cost.validate(n, m, 2).unwrap();
        let x = random_vec(&mut rng, n, 2.0);
        let u = random_vec(&mut rng, m, 2.0);
        let mut l = StageDerivatives::new(n, m);
        cost.running_derivatives(1, &x, &u, &mut l);
        let StageDerivatives { lx, lu, lxx, luu } = l;
        let (mut gx, mut gxx) = (DVector::zeros(n), DMatrix::zeros(n, n));
        cost.terminal_derivatives(&x, &mut gx, &mut gxx);
        let h = 1e-5;
        for i in 0..n {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += h;
            xm[i] -= h;
            let d = (cost.running(1, &xp, &u) - cost.running(1, &xm, &u)) / (2.0 * h);
            assert!((d - lx[i]).abs() < 1e-8, "l_x[{i}] {d} vs {}", lx[i]);
            let d = (cost.terminal(&xp) - cost.terminal(&xm)) / (2.0 * h);
            assert!((d - gx[i]).abs() < 1e-8, "g_x[{i}] {d} vs {}", gx[i]);
            // Hessian columns from differences of the analytic gradient.
            let (mut gp, mut gm) = (DVector::zeros(n), DVector::zeros(n));
            let mut scratch = DMatrix::zeros(n, n);
            cost.terminal_derivatives(&xp, &mut gp, &mut scratch);
            cost.terminal_derivatives(&xm, &mut gm, &mut scratch);
            let col = (gp - gm) / (2.0 * h);
            assert!((col - gxx.column(i)).amax() < 1e-7);
            let (mut lp, mut lm) = (StageDerivatives::new(n, m), StageDerivatives::new(n, m));
            cost.running_derivatives(1, &xp, &u, &mut lp);
            cost.running_derivatives(1, &xm, &u, &mut lm);
            assert!(((lp.lx - lm.lx) / (2.0 * h) - lxx.column(i)).amax() < 1e-7);
        }
        for i in 0..m {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[i] += h;
            um[i] -= h;
            let d = (cost.running(1, &x, &up) - cost.running(1, &x, &um)) / (2.0 * h);
            assert!((d - lu[i]).abs() < 1e-8, "l_u[{i}] {d} vs {}", lu[i]);
            let (mut lp, mut lm) = (StageDerivatives::new(n, m), StageDerivatives::new(n, m));
            cost.running_derivatives(1, &x, &up, &mut lp);
            cost.running_derivatives(1, &x, &um, &mut lm);
            assert!(((lp.lu - lm.lu) / (2.0 * h) - luu.column(i)).amax() < 1e-7);
        }
    }
}
