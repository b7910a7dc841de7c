//! # The DDP backward pass and the adjoint gradient
//!
//! Along the current trajectory (x̄, ū), from V_x = g_x, V_xx = g_xx at the last state, each
//! step k = N−1 … 0 builds the local quadratic model of the cost-to-go
//!
//! ```text
//! Q_x  = l_x + F_xᵀ V_x'                  Q_u  = l_u + F_uᵀ V_x'
//! Q_xx = l_xx + F_xᵀ V_xx' F_x (+ V_x'·F_xx)    Q_ux = F_uᵀ V_xx' F_x (+ V_x'·F_ux)
//! Q_uu = l_uu + F_uᵀ V_xx' F_u (+ V_x'·F_uu)
//! ```
//!
//! and the affine control law δu = k + K δx minimizing it, k = −(Q_uu + μI)⁻¹ Q_u,
//! K = −(Q_uu + μI)⁻¹ Q_ux (with bounds: k from [`super::box_qp`], rows of K zero for clamped
//! controls), then propagates
//!
//! ```text
//! V_x  = Q_x + Kᵀ Q_uu k + Kᵀ Q_u + Q_uxᵀ k
//! V_xx = Q_xx + Kᵀ Q_uu K + Kᵀ Q_ux + Q_uxᵀ K.
//! ```
//!
//! The terms in parentheses make full DDP; iLQR drops them. Alongside, the adjoint recursion
//! λ_N = g_x, λ_k = l_x + F_xᵀ λ_{k+1} gives the exact gradient ∂J/∂u_k = l_u + F_uᵀ λ_{k+1}
//! ([`cost_gradient`]), which the stopping test uses (projected on the bounds).
//!
//! ## References
//! - D. H. Jacobson, D. Q. Mayne, *Differential Dynamic Programming*, Elsevier, 1970.
//! - Y. Tassa, T. Erez, E. Todorov, *Synthesis and stabilization of complex behaviors through
//!   online trajectory optimization*, IROS 2012.

use super::{box_qp, Buffers, DdpOptions, DdpVariant};
use crate::control::{
    cholesky_in_place, cholesky_solve_in_place, symmetrize, ControlError, QuadraticCost, Rk4Map,
    StageDerivatives,
};
use crate::physics::linearize::Linearize;
use nalgebra::{DMatrix, DVector};

/// Exact gradient ∂J/∂u_k of the total cost for the controls `us` from `x0` (adjoint method).
pub fn cost_gradient<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    x0: &DVector<f64>,
    us: &[DVector<f64>],
) -> Result<Vec<DVector<f64>>, ControlError> {
    let (n, m) = (map.state_dim(), map.control_dim());
    let xs = map.rollout(x0, us)?;
    let mut ws = map.workspace();
    let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
    let mut l = StageDerivatives::new(n, m);
    let mut lam = DVector::zeros(n);
    let mut gxx = DMatrix::zeros(n, n);
    cost.terminal_derivatives(&xs[us.len()], &mut lam, &mut gxx);
    let mut grads = vec![DVector::zeros(m); us.len()];
    for k in (0..us.len()).rev() {
        map.jacobians(&xs[k], &us[k], &mut fx, &mut fu, &mut ws);
        cost.running_derivatives(k, &xs[k], &us[k], &mut l);
        grads[k] = &l.lu + fu.transpose() * &lam;
        lam = &l.lx + fx.transpose() * &lam;
    }
    Ok(grads)
}

/// Result of a successful backward pass: Σ kᵀQ_u, Σ ½ kᵀQ_uu k, projected gradient norm.
pub(super) struct BackwardResult {
    pub(super) dv1: f64,
    pub(super) dv2: f64,
    pub(super) gradient_norm: f64,
}

/// Backward pass at (xs, us) with regularization μ; `None` when Q_uu + μI is not positive
/// definite at some step. Does not allocate.
pub(super) fn backward(
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    mu: f64,
    options: &DdpOptions,
    b: &mut Buffers,
) -> Option<BackwardResult> {
    let horizon = us.len();
    let n = xs[0].len();
    let m = us[0].len();
    let full = options.variant == DdpVariant::Full;
    cost.terminal_derivatives(&xs[horizon], &mut b.vx, &mut b.vxx);
    b.lam.copy_from(&b.vx);
    let (mut dv1, mut dv2, mut g2) = (0.0, 0.0, 0.0);
    for k in (0..horizon).rev() {
        let (fx, fu) = (&b.fx[k], &b.fu[k]);
        cost.running_derivatives(k, &xs[k], &us[k], &mut b.l);
        // Exact (adjoint) gradient, projected on the bounds.
        b.gu.copy_from(&b.l.lu);
        b.gu.gemv_tr(1.0, fu, &b.lam, 1.0);
        if let Some(bounds) = &options.bounds {
            for (i, g) in b.gu.iter_mut().enumerate() {
                let u = us[k][i];
                if (u <= bounds.lower[i] && *g > 0.0) || (u >= bounds.upper[i] && *g < 0.0) {
                    *g = 0.0;
                }
            }
        }
        g2 += b.gu.norm_squared();
        b.lam_tmp.copy_from(&b.l.lx);
        b.lam_tmp.gemv_tr(1.0, fx, &b.lam, 1.0);
        std::mem::swap(&mut b.lam, &mut b.lam_tmp);

        // Q function.
        b.qx.copy_from(&b.l.lx);
        b.qx.gemv_tr(1.0, fx, &b.vx, 1.0);
        b.qu.copy_from(&b.l.lu);
        b.qu.gemv_tr(1.0, fu, &b.vx, 1.0);
        b.vxx.mul_to(fx, &mut b.vxx_fx);
        b.vxx.mul_to(fu, &mut b.vxx_fu);
        b.qxx.copy_from(&b.l.lxx);
        b.qxx.gemm_tr(1.0, fx, &b.vxx_fx, 1.0);
        b.quu.copy_from(&b.l.luu);
        b.quu.gemm_tr(1.0, fu, &b.vxx_fu, 1.0);
        b.qux.gemm_tr(1.0, fu, &b.vxx_fx, 0.0);
        if full {
            for (a, hess) in b.fzz[k].iter().enumerate() {
                let w = b.vx[a];
                for j in 0..n {
                    for i in 0..n {
                        b.qxx[(i, j)] += w * hess[(i, j)];
                    }
                    for i in 0..m {
                        b.qux[(i, j)] += w * hess[(n + i, j)];
                    }
                }
                for j in 0..m {
                    for i in 0..m {
                        b.quu[(i, j)] += w * hess[(n + i, n + j)];
                    }
                }
            }
        }
        b.quu_reg.copy_from(&b.quu);
        for i in 0..m {
            b.quu_reg[(i, i)] += mu;
        }

        // Gains.
        let (kff, gain) = (&mut b.kff[k], &mut b.gains[k]);
        match &options.bounds {
            None => {
                if !cholesky_in_place(&mut b.quu_reg, m) {
                    return None;
                }
                for i in 0..m {
                    kff[i] = -b.qu[i];
                }
                cholesky_solve_in_place(&b.quu_reg, m, kff.as_mut_slice());
                gain.copy_from(&b.qux);
                gain.neg_mut();
                for j in 0..n {
                    cholesky_solve_in_place(&b.quu_reg, m, gain.column_mut(j).as_mut_slice());
                }
            }
            Some(bounds) => {
                b.lo.copy_from(&bounds.lower);
                b.lo -= &us[k];
                b.hi.copy_from(&bounds.upper);
                b.hi -= &us[k];
                // Warm start from the previous iteration's feedforward step.
                if !box_qp(&b.quu_reg, &b.qu, &b.lo, &b.hi, kff, &mut b.qp) {
                    return None;
                }
                kff.copy_from(&b.qp.x);
                gain.fill(0.0);
                let nf = b.qp.free_index.len();
                for j in 0..n {
                    b.qp.rhs.clear();
                    for &i in &b.qp.free_index {
                        b.qp.rhs.push(-b.qux[(i, j)]);
                    }
                    cholesky_solve_in_place(&b.qp.factor, nf, &mut b.qp.rhs);
                    for (a, &i) in b.qp.free_index.iter().enumerate() {
                        gain[(i, j)] = b.qp.rhs[a];
                    }
                }
            }
        }

        // Expected reduction and value update.
        b.tm.gemv(1.0, &b.quu, kff, 0.0);
        dv1 += kff.dot(&b.qu);
        dv2 += 0.5 * kff.dot(&b.tm);
        b.vx.copy_from(&b.qx);
        b.vx.gemv_tr(1.0, gain, &b.tm, 1.0);
        b.vx.gemv_tr(1.0, gain, &b.qu, 1.0);
        b.vx.gemv_tr(1.0, &b.qux, kff, 1.0);
        b.tmn.gemm(1.0, &b.quu, gain, 0.0);
        b.vxx.copy_from(&b.qxx);
        b.vxx.gemm_tr(1.0, gain, &b.tmn, 1.0);
        b.vxx.gemm_tr(1.0, gain, &b.qux, 1.0);
        b.vxx.gemm_tr(1.0, &b.qux, gain, 1.0);
        symmetrize(&mut b.vxx);
    }
    Some(BackwardResult {
        dv1,
        dv2,
        gradient_norm: g2.sqrt(),
    })
}
