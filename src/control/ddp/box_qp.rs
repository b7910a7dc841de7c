//! # Box-constrained QP by projected Newton (control-limited DDP)
//!
//! With bounds on the controls, the feedforward step of DDP solves
//!
//! ```text
//! min_x ½ xᵀ H x + gᵀ x   subject to   lower ≤ x ≤ upper,
//! ```
//!
//! H = Q_uu + μI. Projected Newton (Bertsekas 1982; Tassa, Mansard, Todorov 2014): at x, a
//! control is *clamped* when it sits at a bound and the gradient g + Hx pushes outwards; the
//! Newton step is taken on the free set f with the clamped set c fixed,
//! x_f* = −H_ff⁻¹ (g_f + H_fc x_c), followed by an Armijo backtracking search along the
//! projected path clamp(x + s (x* − x)). The Cholesky factor of H_ff is kept: its rows give
//! DDP's feedback gains for the free controls (the rows of clamped controls are zero).
//!
//! ## References
//! - D. P. Bertsekas, *Projected Newton methods for optimization problems with simple
//!   constraints*, SIAM J. Control Optim. 20(2), 1982.
//! - Y. Tassa, N. Mansard, E. Todorov, *Control-limited differential dynamic programming*,
//!   ICRA 2014.

use crate::control::{cholesky_in_place, cholesky_solve_in_place};
use nalgebra::{DMatrix, DVector};

/// Scratch of [`box_qp`], sized for m controls.
#[derive(Debug, Clone)]
pub struct BoxQpWorkspace {
    /// Solution δu after a successful call.
    pub x: DVector<f64>,
    /// `free[i]`: control i is not at an active bound.
    pub free: Vec<bool>,
    /// Indices of the free controls (its length is the factor's dimension).
    pub free_index: Vec<usize>,
    /// Cholesky factor (lower triangle of the leading block) of H restricted to the free set.
    pub factor: DMatrix<f64>,
    grad: DVector<f64>,
    trial: DVector<f64>,
    search: DVector<f64>,
    pub(super) rhs: Vec<f64>,
}

impl BoxQpWorkspace {
    /// Buffers for an m-dimensional box QP.
    pub fn new(m: usize) -> Self {
        Self {
            x: DVector::zeros(m),
            free: vec![true; m],
            free_index: Vec::with_capacity(m),
            factor: DMatrix::zeros(m, m),
            grad: DVector::zeros(m),
            trial: DVector::zeros(m),
            search: DVector::zeros(m),
            rhs: Vec::with_capacity(m),
        }
    }
}

fn qp_value(h: &DMatrix<f64>, g: &DVector<f64>, x: &DVector<f64>) -> f64 {
    let n = x.len();
    let mut v = 0.0;
    for j in 0..n {
        v += g[j] * x[j];
        for i in 0..n {
            v += 0.5 * x[i] * h[(i, j)] * x[j];
        }
    }
    v
}

/// Projected-Newton solution of min ½ xᵀHx + gᵀx subject to lower ≤ x ≤ upper (Tassa, Mansard,
/// Todorov 2014), warm-started at clamp(`x0`). On success the solution, the free set and the
/// Cholesky factor of H on the free set are in `ws`; returns false when H restricted to the
/// free set is not positive definite. Does not allocate.
pub fn box_qp(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    lower: &DVector<f64>,
    upper: &DVector<f64>,
    x0: &DVector<f64>,
    ws: &mut BoxQpWorkspace,
) -> bool {
    let m = g.len();
    for i in 0..m {
        ws.x[i] = x0[i].clamp(lower[i], upper[i]);
    }
    let mut value = qp_value(h, g, &ws.x);
    let mut factored_free: Option<usize> = None; // number of free controls of the current factor
    for iter in 0..100 {
        // gradient and active set
        ws.grad.copy_from(g);
        ws.grad.gemv(1.0, h, &ws.x, 1.0);
        let mut changed = false;
        for i in 0..m {
            let clamped = (ws.x[i] <= lower[i] && ws.grad[i] > 0.0)
                || (ws.x[i] >= upper[i] && ws.grad[i] < 0.0);
            if ws.free[i] == clamped || iter == 0 {
                changed = true;
            }
            ws.free[i] = !clamped;
        }
        ws.free_index.clear();
        ws.free_index.extend((0..m).filter(|&i| ws.free[i]));
        let nf = ws.free_index.len();
        if changed || factored_free.is_none() {
            for (a, &i) in ws.free_index.iter().enumerate() {
                for (b, &j) in ws.free_index.iter().enumerate() {
                    ws.factor[(a, b)] = h[(i, j)];
                }
            }
            if !cholesky_in_place(&mut ws.factor, nf) {
                return false;
            }
            factored_free = Some(nf);
        }
        if nf == 0 {
            return true; // every control at an active bound
        }
        let gnorm: f64 = ws
            .free_index
            .iter()
            .map(|&i| ws.grad[i].powi(2))
            .sum::<f64>();
        if gnorm.sqrt() < 1e-12 * (1.0 + g.amax()) {
            return true;
        }
        // Newton step on the free set with the clamped controls fixed:
        // x_f* = −H_ff⁻¹ (g_f + H_fc x_c); search = x* − x on the free set, 0 elsewhere.
        ws.rhs.clear();
        for &i in &ws.free_index {
            let mut s = g[i];
            for j in 0..m {
                if !ws.free[j] {
                    s += h[(i, j)] * ws.x[j];
                }
            }
            ws.rhs.push(-s);
        }
        cholesky_solve_in_place(&ws.factor, nf, &mut ws.rhs);
        ws.search.fill(0.0);
        for (a, &i) in ws.free_index.iter().enumerate() {
            ws.search[i] = ws.rhs[a] - ws.x[i];
        }
        let slope = ws.search.dot(&ws.grad);
        if slope >= 0.0 {
            return true; // no descent direction left: converged
        }
        // Armijo backtracking along the projected path.
        let mut step = 1.0;
        let new_value = loop {
            for i in 0..m {
                ws.trial[i] = (ws.x[i] + step * ws.search[i]).clamp(lower[i], upper[i]);
            }
            let v = qp_value(h, g, &ws.trial);
            if (v - value) / (step * slope) >= 0.1 {
                break Some(v);
            }
            step *= 0.6;
            if step < 1e-20 {
                break None;
            }
        };
        let Some(new_value) = new_value else {
            return true;
        };
        std::mem::swap(&mut ws.x, &mut ws.trial);
        let improvement = value - new_value;
        value = new_value;
        if improvement < 1e-14 * (1.0 + value.abs()) {
            // Recompute the free set and factor at the final point on the next pass.
            factored_free = None;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn box_qp_satisfies_the_kkt_conditions() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let mut ws = BoxQpWorkspace::new(3);
        let mut clamped_seen = 0;
        for _ in 0..50 {
            let a = DMatrix::from_fn(3, 3, |_, _| rng.random_range(-1.0..1.0));
            let h = &a * a.transpose() + DMatrix::identity(3, 3) * 0.1;
            let g = DVector::from_fn(3, |_, _| rng.random_range(-3.0..3.0));
            let lower = DVector::from_fn(3, |_, _| rng.random_range(-1.0..0.0));
            let upper = DVector::from_fn(3, |_, _| rng.random_range(0.0..1.0));
            let x0 = DVector::from_fn(3, |_, _| rng.random_range(-2.0..2.0));
            assert!(box_qp(&h, &g, &lower, &upper, &x0, &mut ws));
            let grad = &g + &h * &ws.x;
            for i in 0..3 {
                let x = ws.x[i];
                assert!(x >= lower[i] && x <= upper[i]);
                if x <= lower[i] {
                    assert!(grad[i] >= -1e-9, "{grad} at {}", ws.x);
                    clamped_seen += 1;
                } else if x >= upper[i] {
                    assert!(grad[i] <= 1e-9, "{grad} at {}", ws.x);
                    clamped_seen += 1;
                } else {
                    assert!(grad[i].abs() < 1e-9, "{grad} at {}", ws.x);
                }
            }
        }
        assert!(clamped_seen > 10, "the test must exercise active bounds");
        // An indefinite Hessian with an interior free set is reported.
        let h = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let mut ws = BoxQpWorkspace::new(2);
        let b = DVector::from_element(2, 1.0);
        assert!(!box_qp(
            &h,
            &DVector::zeros(2),
            &(-&b),
            &b,
            &DVector::zeros(2),
            &mut ws
        ));
    }
}
